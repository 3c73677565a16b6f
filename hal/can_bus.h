/* SPDX-License-Identifier: MIT */
/*
 * CanBus: where pose frames leave and command frames arrive.
 *
 * send() never blocks: frames go into a bounded transmit queue (its depth set
 * at open) and on to the bus as fast as the bus takes them. When the queue is
 * full the oldest queued frame is dropped and counted (stale pose data is
 * worth less than fresh); a frame whose deadline_ns passes while it waits is
 * dropped and counted too (tx_expired), never sent late. ENOBUFS from the kernel, error frames and bus-off
 * are counted and reported in CanStats, and recovered from (the queue waits,
 * the bus restarts), never by blocking the frame loop.
 *
 * Threads: every call from the frame thread (the owner), except stats(),
 * which is safe from any thread.
 *
 * Allocates: open() allocates; send(), poll(), receive() and stats() never.
 */
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "hal/status.h"

namespace dockpose::hal {

struct CanFrame {
	std::uint32_t id = 0; /* 11-bit, or 29-bit when extended */
	bool extended = false;
	bool fd = false; /* CAN FD frame (backends may refuse) */
	std::uint8_t len = 0; /* data bytes: 0..8 classic, up to 64 FD */
	std::array<std::uint8_t, 64> data{};
	std::int64_t timestamp_ns = 0; /* reception (or send) time, CLOCK_MONOTONIC */
	/* Sending only: a frame still in the transmit queue at this time (CLOCK_MONOTONIC) is
	 * dropped unsent and counted in tx_expired; 0: it never expires. */
	std::int64_t deadline_ns = 0;
};

/*
 * Why a frame cannot go on a bus (nullptr: it can): an id wider than its
 * format (11 or 29 bits), a classic frame longer than 8 bytes, an FD frame
 * longer than 64, or an FD frame on a bus opened without FD. Every backend's send() checks with
 * this one function. Allocates: never.
 */
const char *canFrameProblem(const CanFrame &frame, bool fd_enabled);
/* The CAN FD length len data bytes (0..64) go as: the next of 0..8, 12, 16, 20, 24, 32, 48, 64. */
std::uint8_t canFdLength(std::uint8_t len);
/* A frame as it goes on the wire: an FD frame's length rounded up by canFdLength, the padding
 * zero; a classic frame unchanged. Every backend sends this. Allocates: never. */
CanFrame canWireFrame(const CanFrame &frame);

/* A received frame passes when (frame.id & mask) == (id & mask). */
struct CanFilter {
	std::uint32_t id = 0;
	std::uint32_t mask = 0x7ff;
	bool extended = false;
};

enum class CanState : std::uint8_t {
	Closed,
	ErrorActive,
	ErrorWarning,
	ErrorPassive,
	BusOff,
	Down, /* the interface is down or gone; the backend keeps trying to reopen it */
};

const char *canStateName(CanState state);

/* The deepest transmit queue a bus takes (can.tx_queue_depth's upper bound). */
constexpr std::size_t kMaxCanTxQueueDepth = 4096;

struct CanOptions {
	int tx_queue_depth = 32; /* frames; 1 .. kMaxCanTxQueueDepth */
	bool fd = false; /* enable CAN FD on the socket */
};

struct CanStats {
	std::uint64_t tx_frames = 0; /* handed to the bus */
	std::uint64_t tx_dropped = 0; /* dropped from a full transmit queue */
	std::uint64_t tx_expired = 0; /* dropped unsent at their deadline_ns */
	std::uint64_t tx_enobufs = 0; /* times the kernel said ENOBUFS/EAGAIN */
	std::uint64_t tx_errors = 0; /* other send errors */
	std::uint64_t rx_frames = 0; /* received through the filters */
	std::uint64_t error_frames = 0; /* CAN error frames seen */
	std::uint64_t bus_off = 0; /* bus-off events */
	std::uint64_t restarts = 0; /* recoveries (bus-off restarts, reopenings) */
	std::uint32_t tx_queued = 0; /* frames waiting in the queue now */
	CanState state = CanState::Closed;
};

class CanBus
{
public:
	virtual ~CanBus() = default;
	CanBus() = default;
	CanBus(const CanBus &) = delete;
	CanBus &operator=(const CanBus &) = delete;

	virtual std::string name() const = 0;
	/* Open the bus; only frames matching one of filters are received (none: receive nothing). */
	virtual Status open(std::span<const CanFilter> filters, const CanOptions &options) = 0;
	virtual void close() = 0;

	/* Queue a frame and push what the bus takes. False when a frame had to be dropped. */
	virtual bool send(const CanFrame &frame) = 0;
	/* Push queued frames, read error frames, retry a lost interface. Never blocks. */
	virtual void poll() = 0;
	/* One received frame, if any. Never blocks. */
	virtual bool receive(CanFrame *frame) = 0;

	virtual CanStats stats() const = 0;
	virtual std::string lastError() const = 0;
};

} /* namespace dockpose::hal */

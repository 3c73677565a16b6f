/* SPDX-License-Identifier: MIT */
/*
 * CanBusBase: what every CanBus backend shares, as AP_HAL's CANIface does for
 * its drivers: the transmit queue, the receive ring, the statistics, the
 * last error, and send()'s checks. A backend adds only how queued frames
 * reach its bus (transmit()) and how frames arrive from it (it hands each
 * one to received()).
 *
 * send() (the same on every backend):
 *  - a closed bus, or a frame canFrameProblem() refuses: tx_errors + 1,
 *    lastError() says why, false; nothing is queued;
 *  - otherwise the frame as the wire carries it (canWireFrame()), stamped
 *    with the time it was queued (CLOCK_MONOTONIC), joins the transmit queue
 *    (CanOptions::tx_queue_depth frames, at most kMaxCanTxQueueDepth); a full
 *    queue drops its oldest frame (tx_dropped + 1) and send() returns false;
 *    then transmit() writes what the bus takes now;
 *  - a queued frame whose deadline_ns has passed is dropped unsent
 *    (tx_expired + 1): backends take the next frame with nextToSend(), which
 *    drops the expired ones ahead of it, and send() and expire() drop those at
 *    the head of the queue; a full queue first drops the expired frames
 *    anywhere in it, so that a frame still in time (a heartbeat queued ahead
 *    of reports that expire sooner) is not pushed out by stale ones.
 *
 * Reception: the backend hands every frame that passed its filters to
 * received(): rx_frames + 1, and it joins a ring of the depth the backend
 * gave openQueues() (at most kMaxRxDepth); a full ring drops its oldest frame
 * (rxDropped() + 1; a backend adds what its bus lost before that with
 * countRxLost()). receive() returns the oldest frame of the ring; when the
 * ring is empty it first calls fetch() (SocketCAN reads its socket there).
 *
 * Statistics: the owner updates stats_ (frame thread); publish(), at the end
 * of every call that changed it, copies it for stats() with the queue's
 * depth and drops.
 *
 * Threads: open(), close(), send(), poll() and receive() from the frame
 * thread (the owner); received(), stats() and rxDropped() from any thread
 * (one mutex guards the ring, the receive counts and the published copy).
 * lastError() from the frame thread.
 *
 * Allocates: the constructor (the name); openQueues() never (the rings are
 * part of the object); send(), received(), receive(), stats(), rxDropped()
 * never; name() and lastError() return a new string.
 */
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <span>
#include <string>

#include "hal/can_bus.h"
#include "hal/ring_buffer.h"

namespace dockpose::hal {

class CanBusBase : public CanBus
{
public:
	/* The deepest receive ring a backend may ask for. */
	static constexpr std::size_t kMaxRxDepth = 256;

	std::string name() const final { return name_; }
	bool send(const CanFrame &frame) final;
	bool receive(CanFrame *frame) final;
	CanStats stats() const override;
	std::string lastError() const final { return std::string(error_.data()); }

	/* Received frames lost: a full receive ring, plus what the bus lost (countRxLost). */
	std::uint64_t rxDropped() const;

protected:
	using TxQueue = RingBuffer<CanFrame, kMaxCanTxQueueDepth>;

	/* name: what name() returns and every message starts with ("socketcan:can0"). */
	explicit CanBusBase(std::string name);

	/*
	 * open()'s shared part, before the backend opens its bus: checks
	 * options (tx_queue_depth in 1..kMaxCanTxQueueDepth), empties both
	 * queues to their depths (rx_depth clamped to 1..kMaxRxDepth), zeroes
	 * the statistics and the error. A failure is also lastError().
	 */
	Status openQueues(const CanOptions &options, std::size_t rx_depth);
	/* The backend's bus is open: send() queues from now on, state ErrorActive. */
	void markOpen();
	/* close()'s shared part: both queues emptied, state Closed, send() refuses. */
	void closeQueues();
	bool isOpen() const { return open_; }
	bool fdEnabled() const { return fd_; }

	/* Write queued frames (nextToSend(), tx_.pop()) as far as the bus takes them now. */
	virtual void transmit() = 0;
	/* The oldest queued frame that has not expired at now_ns (the expired ones
	 * ahead of it are dropped, tx_expired), or nullptr when none is left. */
	const CanFrame *nextToSend(std::int64_t now_ns);
	/* Drop the expired frames at the head of the queue (a bus that takes
	 * nothing still gets rid of them); the backend's poll() calls it. */
	void expire(std::int64_t now_ns);
	/* Drop the expired frames anywhere in the queue (send() does, when it is full). */
	void expireAll(std::int64_t now_ns);
	/* receive() found the ring empty: fetch what the bus has, if it can. */
	virtual void fetch() {}

	/* A frame that passed the filters arrived (any thread). */
	void received(const CanFrame &frame);
	/* The bus itself lost count frames before they reached the ring (any thread). */
	void countRxLost(std::uint64_t count);

	/* lastError(): a printf-formatted message (truncated to the buffer). */
	void setError(const char *format, ...) __attribute__((format(printf, 2, 3)));
	/* The buffer lastError() reads, for a callee that writes a message into it. */
	std::span<char> errorBuffer() { return error_; }
	/* Make stats_ and the queue's depth what stats() returns. */
	void publish();

	TxQueue tx_; /* frame thread */
	CanStats stats_; /* frame thread; rx_frames and tx_queued/tx_dropped are the base's */

private:
	const std::string name_;
	bool open_ = false;
	bool fd_ = false;
	std::array<char, 512> error_{};

	mutable std::mutex mutex_; /* guards everything below */
	RingBuffer<CanFrame, kMaxRxDepth> rx_;
	std::uint64_t rx_frames_ = 0;
	std::uint64_t rx_lost_ = 0;
	bool rx_open_ = false; /* received() keeps frames only while open */
	CanStats published_;
};

} /* namespace dockpose::hal */

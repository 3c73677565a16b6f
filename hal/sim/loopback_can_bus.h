/* SPDX-License-Identifier: MIT */
/*
 * An in-process CAN bus for tests: LoopbackCanBus endpoints share a
 * LoopbackHub. A frame one endpoint sends is received by every OTHER open
 * endpoint of the hub whose filters pass it (sim_can.h), and recorded in the
 * hub's traffic, in the order frames crossed the bus.
 *
 * Each endpoint sends through its own hal::CanTxQueue (depth
 * CanOptions::tx_queue_depth): send() and poll() move its queued frames
 * across the bus at once, unless the hub is blocked (setBlocked: a stuck bus,
 * arbitration always lost) or bus-off (setBusOff): then frames wait, and a
 * full queue drops its oldest frame (counted in tx_dropped). Each endpoint
 * receives into a queue of kRxCapacity frames; when full, its oldest frame is
 * dropped (rxDropped()).
 *
 * State: ErrorActive, or BusOff while the hub is bus-off; every switch to
 * bus-off counts in bus_off, every recovery in restarts (events since the
 * endpoint was opened).
 *
 * Threads: endpoints may live on different threads (the hub's mutex guards
 * the crossing); each endpoint is owned by one thread as CanBus says; the
 * hub's calls are safe from any thread. Allocates: the hub's constructor (the
 * traffic ring), open() (queues, filters); send(), poll(), receive() never.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "hal/can_bus.h"
#include "hal/can_tx_queue.h"

namespace dockpose::hal {

class LoopbackCanBus;

class LoopbackHub
{
public:
	/* The hub remembers this many of the most recent frames. */
	static constexpr std::size_t kTrafficCapacity = 16384;

	LoopbackHub();
	LoopbackHub(const LoopbackHub &) = delete;
	LoopbackHub &operator=(const LoopbackHub &) = delete;

	/* Frames stop leaving the senders' queues (bus stuck / arbitration lost). */
	void setBlocked(bool blocked);
	/* Test hook: the bus goes bus-off (true) or recovers (false). */
	void setBusOff(bool bus_off);

	/* Every frame that crossed the bus, in order (the most recent kTrafficCapacity). */
	std::vector<CanFrame> traffic() const;
	/* How many frames crossed the bus in all. */
	std::uint64_t trafficCount() const;

private:
	friend class LoopbackCanBus;

	void attach(LoopbackCanBus *endpoint);
	void detach(LoopbackCanBus *endpoint);

	mutable std::mutex mutex_;
	std::vector<LoopbackCanBus *> endpoints_;
	std::vector<CanFrame> traffic_;
	std::uint64_t traffic_count_ = 0;
	bool blocked_ = false;
	bool bus_off_ = false;
	std::atomic<bool> bus_off_now_{ false };
	std::atomic<std::uint64_t> bus_off_events_{ 0 };
	std::atomic<std::uint64_t> restarts_{ 0 };
};

class LoopbackCanBus : public CanBus
{
public:
	static constexpr std::size_t kRxCapacity = 256;

	LoopbackCanBus(std::shared_ptr<LoopbackHub> hub, std::string name = "loop0");
	~LoopbackCanBus() override;

	std::string name() const override;
	Status open(std::span<const CanFilter> filters, const CanOptions &options) override;
	void close() override;

	bool send(const CanFrame &frame) override;
	void poll() override;
	bool receive(CanFrame *frame) override;

	CanStats stats() const override;
	std::string lastError() const override;

	/* Frames dropped from this endpoint's full receive queue. */
	std::uint64_t rxDropped() const { return rx_dropped_.load(std::memory_order_relaxed); }

private:
	friend class LoopbackHub;

	void pump();
	void deliver(const CanFrame &frame); /* hub mutex held */
	void publishQueue();

	std::shared_ptr<LoopbackHub> hub_;
	std::string name_;

	bool open_ = false;
	bool fd_ = false;
	CanTxQueue tx_;
	const char *error_ = "";
	std::string open_error_;

	/* Receive side: guarded by the hub's mutex. */
	std::vector<CanFilter> filters_;
	std::vector<CanFrame> rx_ring_;
	std::size_t rx_head_ = 0;
	std::size_t rx_count_ = 0;

	std::atomic<std::uint64_t> bus_off_base_{ 0 };
	std::atomic<std::uint64_t> restarts_base_{ 0 };
	std::atomic<bool> stats_open_{ false };
	std::atomic<std::uint64_t> tx_frames_{ 0 };
	std::atomic<std::uint64_t> tx_dropped_{ 0 };
	std::atomic<std::uint64_t> tx_errors_{ 0 };
	std::atomic<std::uint64_t> rx_frames_{ 0 };
	std::atomic<std::uint64_t> rx_dropped_{ 0 };
	std::atomic<std::uint32_t> tx_queued_{ 0 };
};

} /* namespace dockpose::hal */

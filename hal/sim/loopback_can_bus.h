/* SPDX-License-Identifier: MIT */
/*
 * An in-process CAN bus for tests: LoopbackCanBus endpoints share a
 * LoopbackHub. A frame one endpoint sends is received by every OTHER open
 * endpoint of the hub whose filters pass it (sim_can.h), and recorded in the
 * hub's traffic, in the order frames crossed the bus.
 *
 * Each endpoint is a CanBusBase (its transmit queue CanOptions::tx_queue_depth
 * deep, its receive ring, its statistics): send() and poll() move its queued frames
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
 * hub's calls are safe from any thread. Allocates: the constructors, open()
 * (the filters), traffic() (its copy); send(), poll(), receive() never.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "hal/can_bus_base.h"
#include "hal/ring_buffer.h"

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
	RingBuffer<CanFrame, kTrafficCapacity> traffic_;
	bool blocked_ = false;
	bool bus_off_ = false;
	std::atomic<bool> bus_off_now_{ false };
	std::atomic<std::uint64_t> bus_off_events_{ 0 };
	std::atomic<std::uint64_t> restarts_{ 0 };
};

class LoopbackCanBus : public CanBusBase
{
public:
	static constexpr std::size_t kRxCapacity = kMaxRxDepth;

	LoopbackCanBus(std::shared_ptr<LoopbackHub> hub, const std::string &name = "loop0");
	~LoopbackCanBus() override;

	Status open(std::span<const CanFilter> filters, const CanOptions &options) override;
	void close() override;
	void poll() override;

	/* CanBusBase's, with the hub's bus-off state and its events since open(). */
	CanStats stats() const override;

private:
	friend class LoopbackHub;

	void transmit() override;
	void deliver(const CanFrame &frame); /* hub mutex held */

	std::shared_ptr<LoopbackHub> hub_;

	/* Guarded by the hub's mutex. */
	std::vector<CanFilter> filters_;

	std::atomic<std::uint64_t> bus_off_base_{ 0 };
	std::atomic<std::uint64_t> restarts_base_{ 0 };
};

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * RecordingStrobe: a Strobe without hardware that records every change of
 * the LED's level with its time (hal::monotonicNs()), for tests, demos and
 * the sim board (where the StrobeController drives it like a GPIO line).
 *
 * Recording: set(), open() and close() record an event when the level
 * changes (set(true) on a lit LED records nothing). The most recent
 * kCapacity events are kept (a hal::RingBuffer allocated in the constructor,
 * so a long-running demo does not grow and the strobe stays small on a
 * stack); eventCount() counts them all.
 *
 * forceOff() is async-signal-safe: it only stores atomics (the LED level,
 * the time of the call from clock_gettime, and a counter); it takes no lock,
 * so it cannot append to the event list itself. The next set(), open() or
 * close() records the pending "off" at the time forceOff() happened, and
 * events() shows it meanwhile, so the history reads in order (if several
 * forceOff() calls come between two of those calls, the last one is what is
 * recorded; a forceOff() of a dark LED records nothing).
 *
 * Test hooks: failNextSet(message) makes the next set() fail with that
 * message (the level stays); everOpened() and closed() tell whether the
 * line was taken and released.
 *
 * Threads: every call is thread-safe. Allocates: the constructor (the ring)
 * and failNextSet(); set() only for the message of a failure; forceOff()
 * never.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "hal/ring_buffer.h"
#include "hal/strobe.h"

namespace dockpose::hal {

class RecordingStrobe : public Strobe
{
public:
	static constexpr std::size_t kCapacity = 65536;

	struct Event {
		std::int64_t time_ns; /* CLOCK_MONOTONIC */
		bool on;
	};

	RecordingStrobe();

	std::string name() const override { return "recording strobe"; }
	Status open() override;
	Status set(bool on) override;
	bool isOn() const override { return on_.load(); }
	void forceOff() noexcept override;
	void close() override;

	/* The recorded level changes, oldest first (a copy). */
	std::vector<Event> events() const;
	/* Every level change recorded so far (including any no longer kept). */
	std::uint64_t eventCount() const;
	/* open() succeeded at least once. */
	bool everOpened() const { return ever_opened_.load(); }
	/* close() was called after the last open(). */
	bool closed() const { return closed_.load(); }
	/* How often forceOff() was called. */
	std::uint64_t forceOffCount() const { return force_off_count_.load(); }

	/* Test hook: the next set() returns this error and changes nothing. */
	void failNextSet(std::string message);

private:
	void record(std::int64_t time_ns, bool on); /* mutex_ held */
	void absorbForceOff(); /* mutex_ held */
	void change(bool on); /* mutex_ held */

	mutable std::mutex mutex_;
	std::unique_ptr<RingBuffer<Event, kCapacity>> ring_; /* the most recent events */
	bool recorded_on_ = false; /* level of the last recorded event */
	bool open_ = false;
	bool fail_next_ = false;
	std::string fail_message_;

	std::atomic<bool> on_{ false };
	std::atomic<bool> ever_opened_{ false };
	std::atomic<bool> closed_{ false };
	std::atomic<std::int64_t> force_off_ns_{ 0 };
	std::atomic<std::uint64_t> force_off_count_{ 0 };
	std::uint64_t force_off_seen_ = 0; /* mutex_ held */
};

} /* namespace dockpose::hal */

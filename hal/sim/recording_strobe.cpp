/* SPDX-License-Identifier: MIT */
/*
 * The recording strobe (see recording_strobe.h).
 */
#include "hal/sim/recording_strobe.h"

#include <ctime>
#include <utility>

#include "hal/clock.h"

namespace dockpose::hal {

static_assert(std::atomic<std::int64_t>::is_always_lock_free &&
		      std::atomic<std::uint64_t>::is_always_lock_free &&
		      std::atomic<bool>::is_always_lock_free,
	      "forceOff() needs lock-free atomics to be async-signal-safe");

RecordingStrobe::RecordingStrobe()
	: ring_(std::make_unique<RingBuffer<Event, kCapacity>>())
{
}

void RecordingStrobe::record(std::int64_t time_ns, bool on)
{
	ring_->push(Event{ time_ns, on });
	recorded_on_ = on;
}

void RecordingStrobe::absorbForceOff()
{
	const std::uint64_t n = force_off_count_.load();
	if (n == force_off_seen_)
		return;
	force_off_seen_ = n;
	if (recorded_on_)
		record(force_off_ns_.load(), false);
}

void RecordingStrobe::change(bool on)
{
	absorbForceOff();
	on_.store(on);
	if (on != recorded_on_)
		record(monotonicNs(), on);
}

Status RecordingStrobe::open()
{
	std::lock_guard<std::mutex> lock(mutex_);
	change(false);
	open_ = true;
	ever_opened_.store(true);
	closed_.store(false);
	return Status::ok();
}

Status RecordingStrobe::set(bool on)
{
	std::lock_guard<std::mutex> lock(mutex_);
	if (fail_next_) {
		fail_next_ = false;
		return Status::error(std::move(fail_message_));
	}
	if (!open_)
		return Status::error("recording strobe: set() on a line that is not open");
	change(on);
	return Status::ok();
}

void RecordingStrobe::forceOff() noexcept
{
	/* Signal handler path: atomics and clock_gettime only. */
	on_.store(false);
	timespec ts{};
	clock_gettime(CLOCK_MONOTONIC, &ts);
	force_off_ns_.store(static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec);
	force_off_count_.fetch_add(1);
}

void RecordingStrobe::close()
{
	std::lock_guard<std::mutex> lock(mutex_);
	change(false);
	if (open_)
		closed_.store(true);
	open_ = false;
}

std::vector<RecordingStrobe::Event> RecordingStrobe::events() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	std::vector<Event> out;
	out.reserve(ring_->size() + 1);
	for (std::size_t i = 0; i < ring_->size(); ++i)
		out.push_back((*ring_)[i]);
	/* A forceOff() not yet absorbed by a later call. */
	if (force_off_count_.load() != force_off_seen_ && recorded_on_)
		out.push_back(Event{ force_off_ns_.load(), false });
	return out;
}

std::uint64_t RecordingStrobe::eventCount() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	/* Every event recorded: those kept and those the ring dropped. */
	return ring_->size() + ring_->dropped() +
	       (force_off_count_.load() != force_off_seen_ && recorded_on_ ? 1 : 0);
}

void RecordingStrobe::failNextSet(std::string message)
{
	std::lock_guard<std::mutex> lock(mutex_);
	fail_next_ = true;
	fail_message_ = std::move(message);
}

} /* namespace dockpose::hal */

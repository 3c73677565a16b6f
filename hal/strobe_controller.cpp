/* SPDX-License-Identifier: MIT */
/*
 * StrobeController: the thread that switches the strobe at the right times.
 *
 * The thread sleeps on a condition variable (CLOCK_MONOTONIC through
 * std::chrono::steady_clock, which libstdc++ implements with clock_gettime
 * (CLOCK_MONOTONIC) and pthread_cond_clockwait) until kSpinNs before the next
 * event, then spins on the clock for the rest, so a switch happens within a
 * few microseconds of its time on an idle machine instead of the scheduler's
 * wake-up latency and timer slack (tens to hundreds of microseconds).
 *
 * Every call to Strobe::set is recorded with the time just before it and the
 * time it returned: the line switched somewhere in between, so lighting()
 * treats that whole interval as "switching" and never claims a window that
 * overlaps it.
 *
 * Allocates: start() creates the thread; nothing else allocates (a failing
 * Strobe::set allocates its own error message; it is copied into a fixed
 * buffer here).
 */
#include <pthread.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <limits>
#include <system_error>

#include "hal/clock.h"
#include "hal/strobe.h"

namespace dockpose::hal {

namespace {

/* Spin on the clock for the last part of a wait. */
constexpr std::int64_t kSpinNs = 200000;
/* After a failed Strobe::set, wait this long before trying again. */
constexpr std::int64_t kRetryNs = 10000000;
constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();

std::chrono::steady_clock::time_point steadyTime(std::int64_t monotonic_ns)
{
	/* steady_clock is CLOCK_MONOTONIC with the same epoch (libstdc++ on Linux). */
	return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(monotonic_ns));
}

} /* namespace */

StrobeController::StrobeController(Strobe *strobe, int stall_timeout_ms)
	: strobe_(strobe),
	  stall_timeout_ns_(static_cast<std::int64_t>(stall_timeout_ms) * 1000000)
{
}

StrobeController::~StrobeController()
{
	stop();
}

Status StrobeController::start()
{
	std::unique_lock<std::mutex> lock(mutex_);
	if (running_)
		return Status::ok();
	if (!strobe_)
		return Status::error("strobe controller: no strobe");

	/* The LED off first, recorded as the start of the history. */
	line_on_ = false;
	line_known_ = false;
	drive(false, true);
	if (!line_known_)
		return Status::error(std::string("strobe controller: cannot switch the LED off: ") +
				     last_error_.data());

	pulse_count_ = 0;
	retry_ns_ = 0;
	last_kick_ns_ = monotonicNs();
	stalled_.store(false, std::memory_order_relaxed);
	running_ = true;
	try {
		thread_ = std::thread(&StrobeController::run, this);
	} catch (const std::system_error &e) {
		running_ = false;
		return Status::error(std::string("strobe controller: cannot start the thread: ") +
				     e.what());
	}
	pthread_setname_np(thread_.native_handle(), "strobe");
	return Status::ok();
}

void StrobeController::stop()
{
	{
		std::lock_guard<std::mutex> lock(mutex_);
		if (!running_)
			return;
		running_ = false;
		pulse_count_ = 0;
		constant_on_ = false;
	}
	wake_.notify_all();
	if (thread_.joinable())
		thread_.join();

	std::lock_guard<std::mutex> lock(mutex_);
	drive(false, true);
}

void StrobeController::setOn(bool on)
{
	std::lock_guard<std::mutex> lock(mutex_);
	constant_on_ = on;
	pulse_count_ = 0;
	if (running_) {
		update(monotonicNs());
		wake_.notify_one();
	}
}

bool StrobeController::schedulePulse(std::int64_t start_ns, std::int64_t duration_ns)
{
	if (duration_ns <= 0 || start_ns > kNever - duration_ns)
		return false;

	std::lock_guard<std::mutex> lock(mutex_);
	std::int64_t now_ns = monotonicNs();
	if (start_ns < now_ns || stalled_.load(std::memory_order_relaxed))
		return false;

	/* Make room: pulses that are over need no more work (a line still on
	 * from one is switched off by the next update, as nothing wants it on). */
	auto end = std::remove_if(pulses_.begin(), pulses_.begin() + pulse_count_,
				  [now_ns](const Pulse &p) { return p.end_ns <= now_ns; });
	pulse_count_ = static_cast<int>(end - pulses_.begin());
	if (pulse_count_ >= kMaxPulses)
		return false;

	pulses_[pulse_count_++] = { start_ns, start_ns + duration_ns };
	if (running_)
		wake_.notify_one();
	return true;
}

void StrobeController::cancelPulses()
{
	std::lock_guard<std::mutex> lock(mutex_);
	pulse_count_ = 0;
	if (running_) {
		update(monotonicNs());
		wake_.notify_one();
	}
}

void StrobeController::kick()
{
	std::lock_guard<std::mutex> lock(mutex_);
	std::int64_t now_ns = monotonicNs();
	last_kick_ns_ = now_ns;
	if (stalled_.load(std::memory_order_relaxed)) {
		stalled_.store(false, std::memory_order_relaxed);
		if (running_) {
			update(now_ns);
			wake_.notify_one();
		}
	}
	/* Otherwise the thread wakes at the old deadline and finds it moved. */
}

Lighting StrobeController::lighting(std::int64_t start_ns, std::int64_t end_ns) const
{
	if (end_ns < start_ns)
		return Lighting::Mixed;

	std::lock_guard<std::mutex> lock(mutex_);
	/* A window that is not over may still see a switch. */
	if (end_ns > monotonicNs())
		return Lighting::Mixed;

	const std::size_t n = history_.size();
	for (std::size_t i = 0; i < n; i++) {
		const Switch &s = history_[n - 1 - i];
		if (s.before_ns <= end_ns && s.after_ns >= start_ns)
			return Lighting::Mixed;
		if (s.after_ns < start_ns) {
			/* The newest switch before the window sets its level. */
			if (!s.known)
				return Lighting::Mixed;
			return s.on ? Lighting::Lit : Lighting::Unlit;
		}
	}
	/* Every recorded switch is after the window (or none at all). */
	return Lighting::Mixed;
}

bool StrobeController::isOn() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	return line_on_;
}

std::string StrobeController::lastError() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	return std::string(last_error_.data());
}

void StrobeController::run()
{
	std::unique_lock<std::mutex> lock(mutex_);
	while (running_) {
		std::int64_t now_ns = monotonicNs();
		update(now_ns);

		std::int64_t next_ns = nextEventNs(now_ns);
		if (next_ns == kNever) {
			wake_.wait(lock);
			continue;
		}
		if (next_ns - now_ns > kSpinNs) {
			wake_.wait_until(lock, steadyTime(next_ns - kSpinNs));
			continue;
		}
		/* Close to the event: spin without the lock so callers are not held up. */
		lock.unlock();
		while (monotonicNs() < next_ns) {
		}
		lock.lock();
	}
}

void StrobeController::update(std::int64_t now_ns)
{
	if (stall_timeout_ns_ > 0 && !stalled_.load(std::memory_order_relaxed) &&
	    now_ns - last_kick_ns_ >= stall_timeout_ns_) {
		stalled_.store(true, std::memory_order_relaxed);
		stall_count_.fetch_add(1, std::memory_order_relaxed);
		pulse_count_ = 0;
	}

	auto end = std::remove_if(pulses_.begin(), pulses_.begin() + pulse_count_,
				  [now_ns](const Pulse &p) { return p.end_ns <= now_ns; });
	pulse_count_ = static_cast<int>(end - pulses_.begin());

	/* An unknown level (after a failed set) is driven again too, off included. */
	bool want = wantOn(now_ns);
	if ((want != line_on_ || !line_known_) && now_ns >= retry_ns_)
		drive(want, false);
}

bool StrobeController::wantOn(std::int64_t now_ns) const
{
	if (stalled_.load(std::memory_order_relaxed))
		return false;
	if (constant_on_)
		return true;
	for (int i = 0; i < pulse_count_; i++) {
		if (pulses_[i].start_ns <= now_ns && now_ns < pulses_[i].end_ns)
			return true;
	}
	return false;
}

std::int64_t StrobeController::nextEventNs(std::int64_t now_ns) const
{
	std::int64_t next_ns = kNever;
	if (stall_timeout_ns_ > 0 && !stalled_.load(std::memory_order_relaxed))
		next_ns = last_kick_ns_ + stall_timeout_ns_;
	for (int i = 0; i < pulse_count_; i++) {
		const Pulse &p = pulses_[i];
		next_ns = std::min(next_ns, p.start_ns > now_ns ? p.start_ns : p.end_ns);
	}
	if ((wantOn(now_ns) != line_on_ || !line_known_) && retry_ns_ > now_ns)
		next_ns = std::min(next_ns, retry_ns_);
	return next_ns;
}

void StrobeController::drive(bool on, bool force)
{
	if (!force && line_known_ && on == line_on_)
		return;

	std::int64_t before_ns = monotonicNs();
	Status status = strobe_->set(on);
	std::int64_t after_ns = monotonicNs();

	bool was_known = line_known_;
	bool was_on = line_on_;
	if (status) {
		line_on_ = on;
		line_known_ = true;
		if (!was_known || was_on != on) {
			if (was_known)
				switches_.fetch_add(1, std::memory_order_relaxed);
			history_.push({ before_ns, after_ns, on, true });
		}
		return;
	}

	/* Failed: assume off (the caller's safe guess), but the level is unknown. */
	errors_.fetch_add(1, std::memory_order_relaxed);
	std::size_t len = std::min(status.message().size(), last_error_.size() - 1);
	std::memcpy(last_error_.data(), status.message().data(), len);
	last_error_[len] = '\0';
	line_on_ = false;
	line_known_ = false;
	retry_ns_ = after_ns + kRetryNs;
	/* One unknown entry until the next success: a run of failures adds nothing. */
	if (was_known) {
		history_.push({ before_ns, after_ns, false, false });
	}
}

} /* namespace dockpose::hal */

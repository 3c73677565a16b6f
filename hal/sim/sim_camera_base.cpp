/* SPDX-License-Identifier: MIT */
/*
 * The capture machinery of the simulated cameras (see sim_camera_base.h).
 *
 * Buffer slots move Free -> Filling (capture thread) -> Queued (in the
 * FrameQueue) -> Held (the frame thread has it) -> Free (releaseFrame). The
 * capture thread takes only Free slots, or the oldest Queued one out of the
 * queue (a drop); the FrameQueue's compare-and-swap makes sure the frame
 * thread and the capture thread never both get the same queued slot. A
 * condition variable only wakes a waiting frame thread; the queue itself is
 * lock-free.
 */
#include "hal/sim/sim_camera_base.h"

#include <pthread.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <ctime>
#include <system_error>

#include "hal/clock.h"

namespace dockpose::hal {

namespace {

/* Longest single sleep, so stop() is noticed promptly. */
constexpr std::int64_t kSleepSliceNs = 20'000'000;

timespec toTimespec(std::int64_t ns)
{
	timespec ts{};
	ts.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
	ts.tv_nsec = static_cast<long>(ns % 1'000'000'000);
	return ts;
}

} /* namespace */

SimCameraBase::SimCameraBase(LatePolicy late_policy)
	: late_policy_(late_policy)
{
	for (auto &s : state_)
		s.store(kFree, std::memory_order_relaxed);
}

SimCameraBase::~SimCameraBase()
{
	stop();
}

Status SimCameraBase::fail(std::string message)
{
	std::lock_guard<std::mutex> lock(mutex_);
	last_error_ = message;
	return Status::error(std::move(message));
}

Status SimCameraBase::setup(const CameraConfig &config, int width, int height)
{
	if (running_.load())
		return fail(name() + ": cannot configure while running (stop() first)");
	if (config.buffer_count < 1 || config.buffer_count > kMaxBuffers)
		return fail(name() + ": buffer_count " + std::to_string(config.buffer_count) +
			    " is out of range [1, " + std::to_string(kMaxBuffers) + "]");
	const int fixed_us = config.frameDurationUs();
	if (fixed_us < 0)
		return fail(name() + ": frame_rate_hz " + std::to_string(config.frame_rate_hz) +
			    " is negative or not a number");
	const int duration_us = fixed_us > 0 ? fixed_us : kDefaultFrameDurationUs;
	if (config.exposure_us <= 0 || config.exposure_us > duration_us)
		return fail(name() + ": exposure_us " + std::to_string(config.exposure_us) +
			    " is out of range [1, " + std::to_string(duration_us) +
			    "] (the frame duration)");
	if (!std::isfinite(config.analogue_gain) || config.analogue_gain <= 0.0)
		return fail(name() + ": analogue_gain " + std::to_string(config.analogue_gain) +
			    " must be positive");
	if (width <= 0 || height <= 0)
		return fail(name() + ": invalid frame size " + std::to_string(width) + "x" +
			    std::to_string(height));

	period_ns_ = static_cast<std::int64_t>(duration_us) * 1000;
	exposure_us_.store(config.exposure_us);
	gain_.store(config.analogue_gain);
	width_ = width;
	height_ = height;
	buffer_count_ = config.buffer_count;
	buffers_.assign(static_cast<std::size_t>(buffer_count_), Image(width, height));
	drainQueue();
	return Status::ok();
}

void SimCameraBase::setDisconnected(bool disconnected)
{
	if (disconnected)
		(void)fail(name() + ": disconnected");
	disconnected_.store(disconnected, std::memory_order_relaxed);
	frame_ready_.notify_all();
}

Status SimCameraBase::start()
{
	if (disconnected_.load(std::memory_order_relaxed))
		return fail(name() + ": disconnected");
	if (int n = failing_starts_.load(std::memory_order_relaxed); n > 0) {
		failing_starts_.store(n - 1, std::memory_order_relaxed);
		return fail(name() + ": start() failed (test)");
	}
	if (running_.load())
		return Status::ok();
	if (buffers_.empty())
		return fail(name() + ": start() before a successful configure()");
	drainQueue();
	stopping_.store(false);
	finished_.store(false);
	t0_ns_ = monotonicNs();
	try {
		thread_ = std::thread(&SimCameraBase::run, this);
	} catch (const std::system_error &e) {
		return fail(name() + ": cannot start the capture thread: " + e.what());
	}
	pthread_setname_np(thread_.native_handle(), "sim-camera");
	running_.store(true);
	return Status::ok();
}

void SimCameraBase::stop()
{
	if (thread_.joinable()) {
		stopping_.store(true);
		thread_.join();
	}
	{
		std::lock_guard<std::mutex> lock(mutex_);
		running_.store(false);
	}
	frame_ready_.notify_all();
	drainQueue();
}

void SimCameraBase::drainQueue()
{
	std::int32_t slot;
	while (queue_.pop(&slot)) {
	}
	for (auto &s : state_)
		s.store(kFree, std::memory_order_release);
}

bool SimCameraBase::sleepUntil(std::int64_t deadline_ns) const
{
	for (;;) {
		if (stopping_.load(std::memory_order_relaxed))
			return false;
		const std::int64_t now = monotonicNs();
		if (now >= deadline_ns)
			return true;
		const timespec ts = toTimespec(std::min(deadline_ns, now + kSleepSliceNs));
		/* EINTR or an early return: the loop checks again. */
		clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
	}
}

int SimCameraBase::acquireSlot()
{
	for (int i = 0; i < buffer_count_; ++i) {
		std::uint8_t expected = kFree;
		if (state_[i].compare_exchange_strong(expected, kFilling,
						      std::memory_order_acq_rel))
			return i;
	}
	/* No free buffer: drop the oldest queued frame and reuse its buffer. */
	std::int32_t slot;
	if (queue_.pop(&slot)) {
		dropped_.fetch_add(1, std::memory_order_relaxed);
		state_[slot].store(kFilling, std::memory_order_relaxed);
		return slot;
	}
	return -1; /* every buffer is held by the frame thread */
}

void SimCameraBase::run()
{
	const std::int64_t t0 = t0_ns_;
	const std::int64_t period = period_ns_;
	std::uint64_t n = 0;
	for (;;) {
		const int exposure_us = exposure_us_.load(std::memory_order_relaxed);
		const double gain = gain_.load(std::memory_order_relaxed);
		const std::int64_t exposure_ns = static_cast<std::int64_t>(exposure_us) * 1000;
		std::int64_t start_ns = t0 + static_cast<std::int64_t>(n) * period;
		if (!sleepUntil(start_ns + exposure_ns))
			break;
		if (stall_.load(std::memory_order_relaxed) ||
		    disconnected_.load(std::memory_order_relaxed)) {
			++n; /* the camera hangs: nothing comes out */
			continue;
		}
		if (late_policy_ == LatePolicy::Skip) {
			/* The newest exposure that has ended by now. */
			const std::int64_t now = monotonicNs();
			const auto latest =
				static_cast<std::uint64_t>((now - t0 - exposure_ns) / period);
			if (latest > n) {
				dropped_.fetch_add(latest - n, std::memory_order_relaxed);
				n = latest;
				start_ns = t0 + static_cast<std::int64_t>(n) * period;
			}
		}

		const int slot = acquireSlot();
		if (slot < 0) {
			dropped_.fetch_add(1, std::memory_order_relaxed);
			++n;
			continue;
		}
		const Exposure exposure{ n, start_ns, start_ns + exposure_ns, exposure_us, gain };
		if (!produceFrame(exposure, &buffers_[slot])) {
			state_[slot].store(kFree, std::memory_order_release);
			{
				std::lock_guard<std::mutex> lock(mutex_);
				finished_.store(true);
			}
			frame_ready_.notify_all();
			break;
		}
		Meta &meta = meta_[slot];
		meta.sequence = n;
		meta.timestamp_ns = start_ns;
		meta.exposure_us = exposure_us;
		meta.analogue_gain = static_cast<float>(gain);
		state_[slot].store(kQueued, std::memory_order_release);
		if (const auto dropped = queue_.push(slot))
			state_[*dropped].store(kFree, std::memory_order_release);
		{
			/* Pairs with the predicate check in waitFrame(): no lost wake-up. */
			std::lock_guard<std::mutex> lock(mutex_);
		}
		frame_ready_.notify_one();
		++n;
	}
}

WaitResult SimCameraBase::waitFrame(Frame *frame, int timeout_ms)
{
	if (!frame)
		return WaitResult::Error;
	const auto deadline = std::chrono::steady_clock::now() +
			      std::chrono::milliseconds(std::max(0, timeout_ms));
	auto deliver = [&](std::int32_t slot) {
		state_[slot].store(kHeld, std::memory_order_relaxed);
		const Meta &meta = meta_[slot];
		frame->image = buffers_[slot].view();
		frame->sequence = meta.sequence;
		frame->timestamp_ns = meta.timestamp_ns;
		frame->exposure_us = meta.exposure_us;
		frame->analogue_gain = meta.analogue_gain;
		frame->slot = slot;
		frames_.fetch_add(1, std::memory_order_relaxed);
		return WaitResult::Frame;
	};

	std::unique_lock<std::mutex> lock(mutex_);
	for (;;) {
		if (disconnected_.load(std::memory_order_relaxed))
			return WaitResult::Error; /* lastError() set by setDisconnected() */
		std::int32_t slot;
		if (queue_.pop(&slot))
			return deliver(slot);
		if (!running_.load())
			return WaitResult::Stopped;
		if (finished_.load()) {
			/* The last frame may have been queued just before the end was. */
			if (queue_.pop(&slot))
				return deliver(slot);
			return WaitResult::Stopped;
		}
		if (frame_ready_.wait_until(lock, deadline) == std::cv_status::timeout) {
			if (queue_.pop(&slot))
				return deliver(slot);
			return running_.load() && !finished_.load() ? WaitResult::Timeout
								    : WaitResult::Stopped;
		}
	}
}

void SimCameraBase::releaseFrame(const Frame &frame)
{
	if (frame.slot < 0 || frame.slot >= buffer_count_)
		return;
	auto &state = state_[frame.slot];
	/* A frame from before a stop()/start() no longer owns its slot. */
	if (state.load(std::memory_order_relaxed) != kHeld ||
	    meta_[frame.slot].sequence != frame.sequence)
		return;
	state.store(kFree, std::memory_order_release);
}

Status SimCameraBase::setControls(int exposure_us, double analogue_gain)
{
	const std::int64_t period_us = period_ns_ / 1000;
	if (exposure_us <= 0 || exposure_us > period_us)
		return fail(name() + ": exposure_us " + std::to_string(exposure_us) +
			    " is out of range [1, " + std::to_string(period_us) +
			    "] (the frame duration)");
	if (!std::isfinite(analogue_gain) || analogue_gain <= 0.0)
		return fail(name() + ": analogue_gain " + std::to_string(analogue_gain) +
			    " must be positive");
	exposure_us_.store(exposure_us, std::memory_order_relaxed);
	gain_.store(analogue_gain, std::memory_order_relaxed);
	return Status::ok();
}

CameraStats SimCameraBase::stats() const
{
	CameraStats s;
	s.frames = frames_.load(std::memory_order_relaxed);
	s.dropped = dropped_.load(std::memory_order_relaxed) + queue_.drops();
	s.errors = 0; /* a simulated frame never completes with an error */
	return s;
}

std::string SimCameraBase::lastError() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	return last_error_;
}

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * SimCameraBase: what the simulated cameras (SyntheticCamera, ReplayCamera)
 * share with a real one: buffers allocated once, a capture thread paced in
 * real time, a hal::FrameQueue to the frame thread, drops counted.
 *
 * Timing: frame n's exposure starts at t0 + n * period (CLOCK_MONOTONIC, a
 * fixed grid from start(), no drift; Frame::timestamp_ns) and ends
 * exposure_us later. The capture thread sleeps (clock_nanosleep,
 * TIMER_ABSTIME) until the exposure has ended, then has the backend produce
 * the frame (produceFrame()) into a free buffer and queues it. Sequence
 * numbers are grid indices, so a frame that was never produced leaves a gap.
 *
 *  - A buffer the frame thread holds (waitFrame() without releaseFrame()) is
 *    never written. When no buffer is free, the oldest queued frame is
 *    dropped and its buffer reused; when every buffer is held, the new frame
 *    is lost. Both count in CameraStats::dropped.
 *  - A backend that paces late (late_policy Skip: rendering slower than the
 *    frame rate) skips to the newest exposure that has ended, like a sensor
 *    whose frames the ISP could not take: the skipped frames count as
 *    dropped. With late_policy CatchUp (replay) every frame is produced, late.
 *  - setStall(true) (test hook) produces nothing while it holds: the camera
 *    hangs, waitFrame() times out; the grid goes on, so frames after the
 *    stall show a gap.
 *  - setDisconnected(true) (test hook) is an unplugged camera: waitFrame()
 *    returns Error at once (a real backend's disconnect), start() fails, and
 *    both say "<name>: disconnected" in lastError(); setDisconnected(false)
 *    plugs it back: a start() then works.
 *  - failStarts(n) (test hook): the next n start() calls fail ("<name>:
 *    start() failed (test)"), as a device that answers but cannot stream.
 *
 * configure() (only while stopped) reallocates the buffers: frames from
 * before it are gone. stop() releases every frame; a start() after it begins
 * a new grid at sequence 0.
 *
 * Derived classes must call stop() in their destructor (the capture thread
 * calls their produceFrame()).
 *
 * Allocates: configure and start (buffers, thread); waitFrame, releaseFrame,
 * setControls and the capture loop never.
 */
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "algo/image.h"
#include "hal/camera.h"
#include "hal/frame_queue.h"

namespace dockpose::hal {

class SimCameraBase : public Camera
{
public:
	/* Buffers per camera: 1 .. kMaxBuffers (the FrameQueue's capacity). */
	static constexpr int kMaxBuffers = 16;
	/* frame_rate_hz 0 ("rate free") runs at this period. */
	static constexpr int kDefaultFrameDurationUs = 16667;

	enum class LatePolicy : std::uint8_t {
		Skip,
		CatchUp
	};

	explicit SimCameraBase(LatePolicy late_policy);
	~SimCameraBase() override;

	Status start() override;
	void stop() override;

	int width() const override { return width_; }
	int height() const override { return height_; }

	WaitResult waitFrame(Frame *frame, int timeout_ms) override;
	void releaseFrame(const Frame &frame) override;
	Status setControls(int exposure_us, double analogue_gain) override;

	CameraStats stats() const override;
	std::string lastError() const override;

	/* Test hook: while true the camera delivers nothing (it hangs). */
	void setStall(bool stall) { stall_.store(stall, std::memory_order_relaxed); }
	void setDisconnected(bool disconnected);
	void failStarts(int n) { failing_starts_.store(n < 0 ? 0 : n, std::memory_order_relaxed); }

	/* The frame period after configure(), ns. */
	std::int64_t periodNs() const { return period_ns_; }

protected:
	/* One exposure, as the capture thread produces it. */
	struct Exposure {
		std::uint64_t sequence;
		std::int64_t start_ns;
		std::int64_t end_ns;
		int exposure_us;
		double analogue_gain;
	};

	/*
	 * Validate the common configuration and allocate buffer_count buffers of
	 * width x height. The derived configure() calls this once it knows its size.
	 */
	Status setup(const CameraConfig &config, int width, int height);

	/*
	 * Capture thread: write the frame of `exposure` into *image (already of the
	 * configured size). False: there is no such frame (the end of a replay);
	 * the camera then reports Stopped once the queued frames are taken.
	 * Allocates: must not.
	 */
	virtual bool produceFrame(const Exposure &exposure, Image *image) = 0;

	/* Remember an error for lastError(); returns it as a Status. */
	Status fail(std::string message);

private:
	enum SlotState : std::uint8_t {
		kFree,
		kFilling,
		kQueued,
		kHeld
	};

	struct Meta {
		std::uint64_t sequence = 0;
		std::int64_t timestamp_ns = 0;
		std::int32_t exposure_us = 0;
		float analogue_gain = 1.0f;
	};

	void run();
	bool sleepUntil(std::int64_t deadline_ns) const;
	int acquireSlot();
	void drainQueue();

	const LatePolicy late_policy_;

	int width_ = 0;
	int height_ = 0;
	std::int64_t period_ns_ = static_cast<std::int64_t>(kDefaultFrameDurationUs) * 1000;
	int buffer_count_ = 0;
	std::vector<Image> buffers_;
	std::array<Meta, kMaxBuffers> meta_{};
	std::array<std::atomic<std::uint8_t>, kMaxBuffers> state_{};
	FrameQueue<kMaxBuffers> queue_;

	std::atomic<int> exposure_us_{ 2000 };
	std::atomic<double> gain_{ 1.0 };
	std::atomic<bool> stall_{ false };
	std::atomic<bool> disconnected_{ false };
	std::atomic<int> failing_starts_{ 0 };

	std::thread thread_;
	std::int64_t t0_ns_ = 0;
	std::atomic<bool> stopping_{ false };
	std::atomic<bool> running_{ false };
	std::atomic<bool> finished_{ false }; /* produceFrame() ran out of frames */

	mutable std::mutex mutex_; /* wakes waitFrame(); guards last_error_ */
	std::condition_variable frame_ready_;
	std::string last_error_;

	std::atomic<std::uint64_t> frames_{ 0 };
	std::atomic<std::uint64_t> dropped_{ 0 }; /* besides the queue's own drops */
};

} /* namespace dockpose::hal */

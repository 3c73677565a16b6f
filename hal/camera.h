/* SPDX-License-Identifier: MIT */
/*
 * Camera: the firmware's source of 8-bit intensity frames.
 *
 * A backend owns its buffers (allocated and, for real cameras, memory-mapped
 * once in configure()). waitFrame() hands out one frame at a time as a view
 * into such a buffer; the view stays valid until releaseFrame(), which gives
 * the buffer back for capture. Per-pixel work (the pipeline) happens on the
 * view outside any virtual call: one virtual call per frame, none per pixel.
 *
 * Threads: configure/start/stop/setControls from the control thread,
 * waitFrame/releaseFrame from the frame thread. Backends deliver frames from
 * their own capture thread through a hal::FrameQueue, which never blocks the
 * capture side: when the frame thread falls behind, the oldest frame is
 * dropped and counted (CameraStats::dropped).
 *
 * Allocates: configure() and start() allocate; waitFrame(), releaseFrame()
 * and setControls() never allocate in steady state.
 */
#pragma once

#include <cmath>
#include <cstdint>
#include <string>

#include "algo/image.h"
#include "hal/status.h"

namespace dockpose::hal {

struct CameraConfig {
	/* Which camera: a libcamera id ("/base/soc/i2c0mux/i2c@1/imx296@1a"), or an index
	 * into the sorted list of cameras when id is empty. Backends without a choice ignore it. */
	std::string id;
	int index = 0;
	/* Requested frame size; 0 keeps the sensor's default. Backends report the size they got
	 * in Camera::width()/height(). */
	int width = 0;
	int height = 0;
	/* Manual exposure (auto-exposure off), analogue gain, and a fixed frame rate
	 * (frame-duration limits min = max = frameDurationUs()); frame_rate_hz 0 leaves the
	 * rate free. */
	int exposure_us = 2000;
	double analogue_gain = 1.0;
	double frame_rate_hz = 60.0;
	/* Buffers (and requests) allocated once. */
	int buffer_count = 4;

	/* The frame duration of frame_rate_hz, rounded to the microsecond; 0 when the rate is
	 * free (0), and -1 when frame_rate_hz is negative or not a number (an error to report). */
	int frameDurationUs() const
	{
		if (frame_rate_hz == 0.0)
			return 0;
		if (!(frame_rate_hz >= 1e-3))
			return -1;
		const long duration_us = std::lround(1e6 / frame_rate_hz);
		return duration_us < 1 ? 1 : static_cast<int>(duration_us);
	}
};

struct Frame {
	ImageView image; /* 8-bit intensity, stride honoured */
	std::uint64_t sequence = 0; /* sensor frame sequence number; gaps = frames lost */
	std::int64_t timestamp_ns = 0; /* start of exposure, CLOCK_MONOTONIC (hal/clock.h) */
	std::int32_t exposure_us = 0; /* exposure the sensor reports for this frame */
	float analogue_gain = 1.0f;
	std::int32_t slot = -1; /* backend's buffer slot: pass back to releaseFrame() */
};

enum class WaitResult : std::uint8_t {
	Frame, /* *frame is valid until releaseFrame() */
	Timeout, /* no frame within the timeout: the camera stalls */
	Stopped, /* the camera is not running, or ran out of frames (replay) */
	Error, /* the camera failed; lastError() says why */
};

struct CameraStats {
	std::uint64_t frames = 0; /* frames delivered to waitFrame() */
	std::uint64_t dropped = 0; /* frames dropped because the frame thread was behind */
	std::uint64_t errors = 0; /* frames that completed with an error / were corrupt */
};

class Camera
{
public:
	virtual ~Camera() = default;
	Camera() = default;
	Camera(const Camera &) = delete;
	Camera &operator=(const Camera &) = delete;

	/* Human-readable backend and camera name, for logs. */
	virtual std::string name() const = 0;

	/* Open and configure; allocates and maps the buffers. */
	virtual Status configure(const CameraConfig &config) = 0;
	virtual Status start() = 0;
	/* Stop capture; every outstanding frame is implicitly released. Idempotent. */
	virtual void stop() = 0;

	/* The frame size after configure(). */
	virtual int width() const = 0;
	virtual int height() const = 0;

	/* Next frame, waiting at most timeout_ms. Allocates: never. */
	virtual WaitResult waitFrame(Frame *frame, int timeout_ms) = 0;
	/* Give a frame's buffer back for capture. Allocates: never. */
	virtual void releaseFrame(const Frame &frame) = 0;

	/* Manual exposure and gain for the following frames (takes effect within a few frames). */
	virtual Status setControls(int exposure_us, double analogue_gain) = 0;

	virtual CameraStats stats() const = 0;
	virtual std::string lastError() const = 0;
};

} /* namespace dockpose::hal */

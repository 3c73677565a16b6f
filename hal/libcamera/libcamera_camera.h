/* SPDX-License-Identifier: MIT */
/*
 * LibcameraCamera: hal::Camera on libcamera (0.0.3 on Debian 12; newer
 * releases, e.g. Raspberry Pi OS, where practical).
 *
 * configure() starts the process's CameraManager (shared, reference counted:
 * libcamera aborts on a second one in a process, so nothing else in the
 * process may create one; a LibcameraCamera holds its reference from
 * configure(), even a failed one, until destruction or the next configure(),
 * and the manager stops when the last reference goes, so a lone camera
 * retrying configure() enumerates the cameras afresh), picks a camera (CameraConfig::id, or CameraConfig::index into the
 * cameras sorted by id), acquires it, configures one processed stream
 * (VideoRecording role, Viewfinder as fallback) in the cheapest format the
 * stream offers for 8-bit intensity:
 *   R8 (mono), then YUV420/YVU420/NV12/NV21/NV16/NV61 (the Y plane in place),
 *   then YUYV/YVYU/UYVY/VYUY, then RGB888/BGR888/XRGB8888/XBGR8888/ARGB8888/
 *   ABGR8888 (reduced to BT.601 luma, hal/intensity.h),
 * allocates the buffers (FrameBufferAllocator), maps every dmabuf once
 * (planes sharing one fd with offsets are mapped once as a whole) and creates
 * one Request per buffer. Nothing of that is created again until the next
 * configure(): start/stop cycles reuse the same Requests and buffers.
 *
 * Controls: AeEnable false (ExposureTimeMode/AnalogueGainMode Manual on
 * libcamera >= 0.5), ExposureTime, AnalogueGain and FrameDurationLimits
 * {d, d} are passed to Camera::start(); setControls() stores new values in
 * atomics and the next request requeued carries them. Only controls the
 * camera lists in Camera::controls() are set (vimc has none of them; its
 * frames then simply run at the pipeline's defaults, manualControlsSupported()
 * says so). Request::reuse() clears a request's ControlList, so each change
 * is set on exactly one request: the first ControlList::set() of a key
 * inserts a node into the list's unordered_map (one allocation per control
 * change, none when nothing changes); ControlValue storage of a scalar is
 * inline. libcamera itself allocates while queueing a request (Request::reuse
 * inserts into a std::unordered_set, Camera::queueRequest posts a message):
 * "never allocates" below is about this class's own code.
 *
 * Frame path: requestCompleted runs on libcamera's thread. It never blocks
 * and never allocates (in this class): a cancelled request (stop) goes back to
 * the idle pool, a completed one is pushed into a FrameQueue and the frame
 * thread is woken through an eventfd. At most one completed frame waits for
 * the frame thread: when a newer one completes, the older one is dropped
 * (counted in stats().dropped) and its request requeued at once from the
 * callback, so libcamera always keeps the other buffers and the frame thread
 * always gets the newest frame. waitFrame() polls the eventfd with the
 * timeout and hands out the frame in place (zero-copy formats) or converted
 * into one of the per-request intensity buffers allocated in configure().
 *
 * Timestamps: Frame::timestamp_ns is exposureStartNs(sensor timestamp,
 * exposure) with the sensor timestamp from controls::SensorTimestamp in the
 * request metadata when the pipeline reports it, else FrameMetadata::timestamp
 * of the buffer. libcamera documents SensorTimestamp as "the time when the
 * first row of the image sensor active array is exposed" on CLOCK_BOOTTIME
 * (control_ids.yaml), but every pipeline handler fills it with the V4L2
 * buffer timestamp of the capture node (the Raspberry Pi handlers copy
 * buffer->metadata().timestamp of Unicam/CFE, whose driver stamps the CSI-2
 * frame start, i.e. the start of readout; vimc stamps frame completion), and
 * V4L2 buffer timestamps are CLOCK_MONOTONIC (videobuf2, ktime_get_ns; on a
 * device that never suspends BOOTTIME equals MONOTONIC anyway). Readout of
 * the first row starts when its exposure ends, hence the subtraction. On vimc
 * the result is only approximately the exposure start.
 *
 * Threads: as hal::Camera. configure/start/stop/setControls from the control
 * thread, waitFrame/releaseFrame from the frame thread; configure() and the
 * destructor only while the frame thread neither waits nor holds a frame
 * (they free the buffers). stop() may run while the frame thread waits: the
 * wait returns Stopped.
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "hal/camera.h"
#include "hal/intensity.h"
#include "hal/status.h"

namespace dockpose::hal {

class LibcameraCamera : public Camera
{
public:
	/* Cheap: libcamera is first touched by configure(). Allocates: the private state. */
	LibcameraCamera();
	/* stop(), frees requests and buffers (munmap), releases the camera, stops the
	 * CameraManager when this was its last user. */
	~LibcameraCamera() override;

	/* "libcamera <camera id>", or "libcamera" before configure(). */
	std::string name() const override;

	/* Allocates: everything (manager, camera, buffers, mappings, requests). A second
	 * configure() first tears the previous configuration down. */
	Status configure(const CameraConfig &config) override;
	/* Queues every idle request. Allocates: libcamera's start ControlList. */
	Status start() override;
	/* Camera::stop(): outstanding requests complete as cancelled; frames waiting for
	 * the frame thread are discarded; a frame the frame thread holds stays valid
	 * until releaseFrame(). Idempotent. */
	void stop() override;

	int width() const override;
	int height() const override;

	/* timeout_ms < 0 waits without limit. Returns Stopped when not started, Error
	 * after a fatal failure (camera unplugged). Frames that completed with an error
	 * or truncated are counted in stats().errors, requeued, and waiting goes on.
	 * Allocates: never. */
	WaitResult waitFrame(Frame *frame, int timeout_ms) override;
	/* Requeues the frame's request (reuse(ReuseBuffers), pending controls). Allocates: never. */
	void releaseFrame(const Frame &frame) override;

	/* exposure_us > 0, analogue_gain >= 1.0 (libcamera's floor). Allocates: never. */
	Status setControls(int exposure_us, double analogue_gain) override;

	CameraStats stats() const override;
	std::string lastError() const override;

	/* After configure(): the libcamera pixel format ("BGR888", "R8", ...), the
	 * stride of its first plane in bytes, and whether frames are used in place. */
	std::string pixelFormatName() const;
	int strideBytes() const;
	bool zeroCopy() const;
	/* Requests created by configure() (one per buffer); never changes until the
	 * next configure(). */
	std::size_t requestCount() const;
	/* Camera::queueRequest() calls that succeeded / failed, since configure(). */
	std::uint64_t requestsQueued() const;
	std::uint64_t queueFailures() const;
	/* Whether the camera lists ExposureTime and AnalogueGain among its controls. */
	bool manualControlsSupported() const;

private:
	class Impl;
	std::unique_ptr<Impl> impl_;
};

/*
 * Pure helpers (no libcamera), public for tests.
 */

/* The layout of a DRM fourcc as libcamera names it (formats.h), or nullopt when
 * the format carries no usable 8-bit intensity plane (Bayer, 10-bit, MJPEG,
 * any modifier such as CSI-2 packing). */
std::optional<PixelLayout> pixelLayoutForFourcc(std::uint32_t fourcc, std::uint64_t modifier = 0);

/* Lower is better: 0 mono, 1 planar/semi-planar YUV (Y plane in place),
 * 2 packed YUV, 3 RGB. */
int pixelLayoutCost(PixelLayout layout);

/*
 * Which camera of ids (sorted) to open: `id` when not empty (exact match),
 * else ids[index]. Errors name the problem and list the cameras:
 *   libcamera: no cameras found (...)
 *   libcamera: no camera with id "x" (cameras: a, b)
 *   libcamera: camera index 2 out of range (2 cameras: a, b)
 */
Status selectCamera(const std::vector<std::string> &ids, const std::string &id, int index,
		    std::size_t *chosen);

/* Checks a CameraConfig before libcamera is touched (buffer_count 2..16,
 * exposure_us > 0 and <= the frame duration when the rate is fixed, frame_rate_hz >= 0,
 * gain >= 1, sizes >= 0). */
Status checkCameraConfig(const CameraConfig &config);

/* Exposure start of the first row from a frame-start (readout) timestamp. */
inline std::int64_t exposureStartNs(std::int64_t frame_start_ns, std::int32_t exposure_us)
{
	return exposure_us > 0 ? frame_start_ns - static_cast<std::int64_t>(exposure_us) * 1000
			       : frame_start_ns;
}

} /* namespace dockpose::hal */

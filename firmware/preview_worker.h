/* SPDX-License-Identifier: MIT */
/*
 * PreviewWorker: the operator preview off the frame loop. The frame thread
 * describes a frame (the pipeline's blobs, the pose, the LEDs projected: a
 * few KB, PreviewWriter::describe) and hands the worker that description and
 * the camera frame itself, still held: the frame thread does not release the
 * frame's buffer but leaves it to the worker, which downscales its pixels
 * into the ring and publishes it (PreviewWriter::publishDescribed), then
 * gives the frame back. The frame thread collects it (reclaim()) and releases
 * it to the camera: the camera is only ever called from the frame thread.
 *
 * The frame thread never waits for the worker: while the worker still has a
 * frame, the next preview frame is skipped and counted (skipped()). So at
 * most one camera buffer is held for the preview at a time; the daemon uses
 * the worker only when the camera has at least 3 buffers (one held, two
 * capturing). Before the camera is stopped (a stall's restart, shutdown) the
 * frame thread calls drain(), which waits for the frame in hand (one
 * downscale, about a millisecond) and gives it back: then, and only then,
 * the frame thread waits.
 *
 * The worker thread runs at nice 19 (SCHED_OTHER, the lowest weight): on a
 * 2-core board it uses the core the frame loop leaves; sharing a core, it
 * gets little time beside the frame loop (a real-time frame thread, none)
 * and preview frames are skipped rather than the loop delayed.
 *
 * Threads and ownership: state_ says who owns job_: Idle and Done the frame
 * thread, Pending the worker. start(), stop(), submit(), reclaim(), drain()
 * from the frame thread (start/stop: the thread that owns the daemon);
 * skipped() and handed() from any thread. The PreviewWriter is written by
 * the worker while it runs; the frame thread only calls its describe()
 * (const, reads what open() set) meanwhile.
 *
 * Allocates: start() (the thread, the description); never after.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>

#include "algo/pipeline.h"
#include "firmware/preview.h"
#include "hal/camera.h"
#include "hal/status.h"

namespace dockpose::firmware {

class PreviewWorker
{
public:
	PreviewWorker() = default;
	PreviewWorker(const PreviewWorker &) = delete;
	PreviewWorker &operator=(const PreviewWorker &) = delete;
	/* Stops the thread: call drain() first if a frame may be in hand. */
	~PreviewWorker();

	/* Start the thread publishing into *writer (open, outliving the worker). Allocates. */
	hal::Status start(PreviewWriter *writer);
	/* Finish the frame in hand (it stays to be reclaimed) and join the thread. Idempotent. */
	void stop();
	bool running() const { return thread_.joinable(); }

	/*
	 * Hand over `frame` (held, not released) described from `pipeline`'s last
	 * process() and `result`. True: the worker has it, and the caller must not
	 * release it but reclaim() it later. False: the worker is still busy (or
	 * not running): the preview frame is skipped and counted; release the
	 * frame as usual. Never waits. Allocates: never.
	 */
	bool submit(const hal::Frame &frame, const Pipeline &pipeline, const PoseResult *result,
		    PreviewStatus status);
	/* True, with *frame: a handed-over frame the worker is done with, to release. Never waits. */
	bool reclaim(hal::Frame *frame);
	/* Wait until the worker is done with its frame; true, with *frame, if there was one. */
	bool drain(hal::Frame *frame);

	/* Preview frames skipped because the worker was busy. Any thread. */
	std::uint64_t skipped() const { return skipped_.load(std::memory_order_relaxed); }
	/* Preview frames handed to the worker. Any thread. */
	std::uint64_t handed() const { return handed_.load(std::memory_order_relaxed); }

private:
	enum State : std::uint32_t {
		Idle,
		Pending,
		Done
	};

	void loop();

	PreviewWriter *writer_ = nullptr;
	std::unique_ptr<PreviewFrame> meta_; /* the job's description (no pixels used) */
	hal::Frame frame_; /* the job's frame */
	std::atomic<std::uint32_t> state_{ Idle };
	std::atomic<std::uint32_t> wake_{ 0 }; /* bumped to wake the worker */
	std::atomic<bool> stopping_{ false };
	std::atomic<std::uint64_t> skipped_{ 0 };
	std::atomic<std::uint64_t> handed_{ 0 };
	std::thread thread_;
};

} /* namespace dockpose::firmware */

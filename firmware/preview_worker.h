/* SPDX-License-Identifier: MIT */
/*
 * PreviewWorker: the operator preview off the frame loop. For a preview
 * frame the frame thread copies a PreviewSnapshot (the pose, the blobs: about
 * 1.3 KB of plain data, firmware/preview.h) and hands the worker that and the
 * camera frame itself, still held: the frame thread does not release the
 * frame's buffer but leaves it to the worker, which projects the LEDs,
 * downscales the pixels into the ring and publishes them
 * (PreviewWriter::beginPublish() and publishRows()), then gives the frame
 * back. The frame thread collects it (reclaim()) and releases it to the
 * camera: the camera is only ever called from the frame thread.
 *
 * The worker does that work only while the frame loop is idle, waiting for
 * the camera: the frame thread says so with setLoopBusy() (busy from the
 * moment a frame is dequeued, idle just before it waits for the next), one
 * relaxed atomic store each. The worker takes a job up only while the loop
 * is idle, and downscales in steps of about kPreviewBlockPixels frame pixels
 * (a few µs), looking at the flag before each: busy, it stops (the slot stays
 * unpublished, the frame held) and goes on in the loop's next idle time.
 * So the preview's pixel work never competes with the frame loop for a core,
 * the cache or the memory bus, on one core or several, beyond the one step
 * under way when a frame arrives. A loop that is never idle long enough
 * (frames back to back) leaves the job unfinished; the next preview frames
 * are then skipped (counted), never the loop delayed.
 *
 * The hand-over is a store of an atomic state, no system call: waking a
 * sleeping thread (a futex wake) costs the waker several µs, more than the
 * rest of the hand-over. The worker instead polls the state (and, with a
 * job, the busy flag) every kPreviewPollNs, sleeping in between; that delays
 * a preview frame by a poll period or a few, a small part of the preview's
 * period (preview.rate_hz is at most 10 Hz: 100 ms or more).
 *
 * The frame thread never waits for the worker: while the worker still has a
 * frame, the next preview frame is skipped and counted (skipped()). So at
 * most one camera buffer is held for the preview at a time; the daemon uses
 * the worker only when the camera has at least 3 buffers (one held, two
 * capturing). Before the camera is stopped (a stall's restart, shutdown) the
 * frame thread calls drain(), which marks the loop idle, waits for the frame
 * in hand (at most a poll period, then the rest of one downscale) and gives
 * it back: then, and only then, the frame thread waits.
 *
 * The worker thread runs at nice 19 (SCHED_OTHER, the lowest weight): on a
 * 2-core board it uses the core the frame loop leaves; sharing a core, it
 * gets little time beside the frame loop (a real-time frame thread, none).
 *
 * Threads and ownership: state_ says who owns the job (snapshot_, frame_):
 * Idle and Done the frame thread, Pending and Working the worker. start(),
 * stop(), submit(), reclaim(), drain() and setLoopBusy() from the frame
 * thread (start/stop: the thread that owns the daemon); skipped(), handed(),
 * deferred(), paused() and pending() from any thread. The busy flag orders
 * no data (the job's hand-over is state_'s release/acquire): it only says
 * when the worker may run. The PreviewWriter is the worker's while it runs;
 * the worker has its own copies of the target and camera models (taken by
 * start()).
 *
 * Allocates: start() (the thread, the models' copies); never after.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <thread>

#include "algo/camera_model.h"
#include "algo/pipeline.h"
#include "algo/target_model.h"
#include "firmware/preview.h"
#include "hal/camera.h"
#include "hal/status.h"

namespace dockpose::firmware {

/*
 * The worker's poll period, ns: how often it looks for a handed frame, and,
 * with one, whether the frame loop is idle (the most a handed frame waits to
 * be taken up while the loop is idle).
 */
constexpr std::int64_t kPreviewPollNs = 2'000'000;

class PreviewWorker
{
public:
	PreviewWorker() = default;
	PreviewWorker(const PreviewWorker &) = delete;
	PreviewWorker &operator=(const PreviewWorker &) = delete;
	/* Stops the thread: call drain() first if a frame may be in hand. */
	~PreviewWorker();

	/*
	 * Start the thread publishing into *writer (open, outliving the worker)
	 * the frames of `pipeline` (its target and camera models are copied).
	 * Allocates.
	 */
	hal::Status start(PreviewWriter *writer, const Pipeline &pipeline);
	/*
	 * Finish the frame in hand (it stays to be reclaimed) and join the
	 * thread: marks the loop idle (the caller waits, within a poll period
	 * and the rest of one downscale). Idempotent. Allocates: never.
	 */
	void stop();
	bool running() const { return thread_.joinable(); }

	/*
	 * Hand over `frame` (held, not released) with a snapshot of `pipeline`'s
	 * last process() and `result` (the pipeline given to start()). True: the
	 * worker has it, and the caller must not release it but reclaim() it
	 * later. False: the worker is still busy (or not running): the preview
	 * frame is skipped and counted; release the frame as usual. Never waits,
	 * no system call. Allocates: never.
	 */
	bool submit(const hal::Frame &frame, const Pipeline &pipeline, const PoseResult *result,
		    PreviewStatus status);
	/*
	 * True, with *frame: a handed-over frame the worker is done with, to
	 * release. Never waits, no system call. Allocates: never.
	 */
	bool reclaim(hal::Frame *frame);
	/*
	 * Wait until the worker is done with its frame (marking the loop idle:
	 * the caller waits); true, with *frame, if there was one. Waits at most
	 * a poll period and the rest of one downscale. Allocates: never.
	 */
	bool drain(hal::Frame *frame);

	/*
	 * The frame loop is working on a frame (true: from when it is dequeued)
	 * or idle (false: just before it waits for the camera). The worker does
	 * its pixel work only while idle. One relaxed atomic store, no system
	 * call; works whether or not the worker runs. Allocates: never. Frame
	 * thread.
	 */
	void setLoopBusy(bool busy) { loop_busy_.store(busy, std::memory_order_relaxed); }

	/* The counts below: relaxed loads, any thread, never allocate. */
	/* Preview frames skipped because the worker was busy. Any thread. */
	std::uint64_t skipped() const { return skipped_.load(std::memory_order_relaxed); }
	/* Preview frames handed to the worker. Any thread. */
	std::uint64_t handed() const { return handed_.load(std::memory_order_relaxed); }
	/* Jobs the worker took up only after waiting for the loop to go idle. Any thread. */
	std::uint64_t deferred() const { return deferred_.load(std::memory_order_relaxed); }
	/* Times a downscale stopped between steps because the loop turned busy. Any thread. */
	std::uint64_t paused() const { return paused_.load(std::memory_order_relaxed); }
	/* A frame is handed over and the worker has not taken it up yet (its next poll). Any thread. */
	bool pending() const { return state_.load(std::memory_order_relaxed) == Pending; }

private:
	enum State : std::uint32_t {
		Idle,
		Pending,
		Working,
		Done
	};

	void loop();
	/* Publish the job, step by step, each step only while the loop is idle. Worker thread. */
	void work();
	/* Sleep in poll periods while the loop is busy; true if it was (it waited). */
	bool waitForIdle();

	PreviewWriter *writer_ = nullptr;
	TargetModel target_;
	std::optional<CameraModel> camera_; /* set by start() */
	PreviewSnapshot snapshot_; /* the job's pose and blobs */
	hal::Frame frame_; /* the job's frame */
	std::atomic<std::uint32_t> state_{ Idle };
	std::atomic<bool> stopping_{ false };
	std::atomic<bool> loop_busy_{ false };
	std::atomic<std::uint64_t> deferred_{ 0 };
	std::atomic<std::uint64_t> paused_{ 0 };
	std::atomic<std::uint64_t> skipped_{ 0 };
	std::atomic<std::uint64_t> handed_{ 0 };
	std::thread thread_;
};

} /* namespace dockpose::firmware */

/* SPDX-License-Identifier: MIT */
#include "firmware/preview_worker.h"

#include <sys/resource.h>
#include <unistd.h>

#include <ctime>

namespace dockpose::firmware {

namespace {

void nap(std::int64_t ns)
{
	const timespec t{ static_cast<time_t>(ns / 1'000'000'000),
			  static_cast<long>(ns % 1'000'000'000) };
	(void)clock_nanosleep(CLOCK_MONOTONIC, 0, &t, nullptr);
}

} /* namespace */

PreviewWorker::~PreviewWorker()
{
	stop();
}

hal::Status PreviewWorker::start(PreviewWriter *writer, const Pipeline &pipeline)
{
	if (running())
		return hal::Status::ok();
	if (!writer || !writer->isOpen())
		return hal::Status::error("preview worker: the preview ring is not open");
	writer_ = writer;
	target_ = pipeline.target();
	camera_.emplace(pipeline.camera());
	stopping_.store(false, std::memory_order_relaxed);
	thread_ = std::thread([this] { loop(); });
	return hal::Status::ok();
}

void PreviewWorker::stop()
{
	if (!running())
		return;
	/* The caller waits for the join: the loop is idle, and the frame in hand is finished. */
	setLoopBusy(false);
	stopping_.store(true, std::memory_order_release);
	thread_.join(); /* within a poll period (and the frame in hand, if any) */
}

bool PreviewWorker::submit(const hal::Frame &frame, const Pipeline &pipeline,
			   const PoseResult *result, PreviewStatus status)
{
	if (!running() || state_.load(std::memory_order_acquire) != Idle) {
		skipped_.fetch_add(1, std::memory_order_relaxed);
		return false;
	}
	/* Idle: the job is the frame thread's until Pending is stored. */
	previewSnapshot(&snapshot_, frame.sequence, frame.timestamp_ns, frame.image.width,
			frame.image.height, pipeline, result, status);
	frame_ = frame;
	state_.store(Pending, std::memory_order_release);
	handed_.fetch_add(1, std::memory_order_relaxed);
	return true;
}

bool PreviewWorker::reclaim(hal::Frame *frame)
{
	if (state_.load(std::memory_order_acquire) != Done)
		return false;
	*frame = frame_;
	state_.store(Idle, std::memory_order_relaxed);
	return true;
}

bool PreviewWorker::drain(hal::Frame *frame)
{
	/* The caller waits here: the loop is idle, and the worker may finish. */
	setLoopBusy(false);
	for (;;) {
		const std::uint32_t s = state_.load(std::memory_order_acquire);
		if (s == Idle)
			return false;
		if (s == Done)
			return reclaim(frame);
		/* Pending or Working: the worker notifies when it stores Done. */
		state_.wait(s, std::memory_order_acquire);
	}
}

void PreviewWorker::loop()
{
	/* Below every normal thread (Linux: a thread's own nice value): the preview takes the
	 * time the frame loop leaves. Not SCHED_IDLE: on a core kept busy by others that would
	 * starve it, and every preview frame would be skipped. */
	(void)setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);
	for (;;) {
		if (state_.load(std::memory_order_acquire) == Pending) {
			/* Only this thread moves the state on from Pending. */
			state_.store(Working, std::memory_order_relaxed);
			work();
			state_.store(Done, std::memory_order_release);
			state_.notify_one(); /* drain() may wait for it */
			continue;
		}
		if (stopping_.load(std::memory_order_acquire))
			return;
		nap(kPreviewPollNs);
	}
}

void PreviewWorker::work()
{
	/* Every step reads the frame or writes the ring: none while the frame loop works. */
	if (waitForIdle())
		deferred_.fetch_add(1, std::memory_order_relaxed);
	if (!writer_->beginPublish(snapshot_, frame_.image, target_, *camera_))
		return;
	const int rows = writer_->rowsPerBlock();
	for (;;) {
		if (waitForIdle())
			paused_.fetch_add(1, std::memory_order_relaxed);
		if (writer_->publishRows(rows))
			return;
	}
}

bool PreviewWorker::waitForIdle()
{
	if (!loop_busy_.load(std::memory_order_relaxed))
		return false;
	do
		nap(kPreviewPollNs);
	while (loop_busy_.load(std::memory_order_relaxed));
	return true;
}

} /* namespace dockpose::firmware */

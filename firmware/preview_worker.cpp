/* SPDX-License-Identifier: MIT */
#include "firmware/preview_worker.h"

#include <sys/resource.h>
#include <unistd.h>

namespace dockpose::firmware {

PreviewWorker::~PreviewWorker()
{
	stop();
}

hal::Status PreviewWorker::start(PreviewWriter *writer)
{
	if (running())
		return hal::Status::ok();
	if (!writer || !writer->isOpen())
		return hal::Status::error("preview worker: the preview ring is not open");
	writer_ = writer;
	if (!meta_)
		meta_ = std::make_unique<PreviewFrame>();
	stopping_.store(false, std::memory_order_relaxed);
	thread_ = std::thread([this] { loop(); });
	return hal::Status::ok();
}

void PreviewWorker::stop()
{
	if (!running())
		return;
	stopping_.store(true, std::memory_order_release);
	wake_.fetch_add(1, std::memory_order_release);
	wake_.notify_one();
	thread_.join();
}

bool PreviewWorker::submit(const hal::Frame &frame, const Pipeline &pipeline,
			   const PoseResult *result, PreviewStatus status)
{
	if (!running() || state_.load(std::memory_order_acquire) != Idle) {
		skipped_.fetch_add(1, std::memory_order_relaxed);
		return false;
	}
	/* Idle: job_ is the frame thread's until Pending is stored. */
	writer_->describe(meta_.get(), frame.sequence, frame.timestamp_ns, frame.image.width,
			  frame.image.height, pipeline, result, status);
	frame_ = frame;
	state_.store(Pending, std::memory_order_release);
	handed_.fetch_add(1, std::memory_order_relaxed);
	wake_.fetch_add(1, std::memory_order_release);
	wake_.notify_one();
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
	for (;;) {
		const std::uint32_t s = state_.load(std::memory_order_acquire);
		if (s == Idle)
			return false;
		if (s == Done)
			return reclaim(frame);
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
		const std::uint32_t seen = wake_.load(std::memory_order_acquire);
		if (state_.load(std::memory_order_acquire) == Pending) {
			writer_->publishDescribed(*meta_, frame_.image);
			state_.store(Done, std::memory_order_release);
			state_.notify_one(); /* drain() may wait for it */
			continue;
		}
		if (stopping_.load(std::memory_order_acquire))
			return;
		wake_.wait(seen, std::memory_order_acquire);
	}
}

} /* namespace dockpose::firmware */

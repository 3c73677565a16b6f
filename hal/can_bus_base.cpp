/* SPDX-License-Identifier: MIT */
/*
 * What every CanBus backend shares (see can_bus_base.h).
 */
#include "hal/can_bus_base.h"

#include <cstdarg>
#include <cstdio>
#include <utility>

#include "hal/clock.h"

namespace dockpose::hal {

CanBusBase::CanBusBase(std::string name)
	: name_(std::move(name))
{
}

Status CanBusBase::openQueues(const CanOptions &options, std::size_t rx_depth)
{
	open_ = false;
	stats_ = CanStats{};
	error_[0] = '\0';
	tx_.reset(options.tx_queue_depth < 1 ? 1
					     : static_cast<std::size_t>(options.tx_queue_depth));
	{
		std::lock_guard<std::mutex> lock(mutex_);
		rx_.reset(rx_depth);
		rx_frames_ = 0;
		rx_lost_ = 0;
		rx_open_ = false;
	}
	if (options.tx_queue_depth < 1 ||
	    static_cast<std::size_t>(options.tx_queue_depth) > kMaxCanTxQueueDepth)
		setError("%s: tx_queue_depth %d must be in [1, %zu]", name_.c_str(),
			 options.tx_queue_depth, kMaxCanTxQueueDepth);
	fd_ = options.fd;
	publish();
	if (error_[0] != '\0')
		return Status::error(error_.data());
	return Status::ok();
}

void CanBusBase::markOpen()
{
	open_ = true;
	stats_.state = CanState::ErrorActive;
	{
		std::lock_guard<std::mutex> lock(mutex_);
		rx_open_ = true;
	}
	publish();
}

void CanBusBase::closeQueues()
{
	open_ = false;
	tx_.clear();
	{
		std::lock_guard<std::mutex> lock(mutex_);
		rx_.clear();
		rx_open_ = false;
	}
	stats_.state = CanState::Closed;
	publish();
}

bool CanBusBase::send(const CanFrame &frame)
{
	if (!open_) {
		++stats_.tx_errors;
		setError("%s: send() while the bus is closed; frame 0x%x dropped", name_.c_str(),
			 static_cast<unsigned>(frame.id));
		publish();
		return false;
	}
	if (const char *problem = canFrameProblem(frame, fd_)) {
		++stats_.tx_errors;
		setError("%s: frame 0x%x not sent: %s", name_.c_str(),
			 static_cast<unsigned>(frame.id), problem);
		publish();
		return false;
	}
	CanFrame queued = canWireFrame(frame);
	queued.timestamp_ns = monotonicNs();
	expire(queued.timestamp_ns);
	if (tx_.full())
		expireAll(queued.timestamp_ns);
	const bool kept = tx_.push(queued);
	transmit();
	publish();
	return kept;
}

const CanFrame *CanBusBase::nextToSend(std::int64_t now_ns)
{
	expire(now_ns);
	return tx_.empty() ? nullptr : &tx_.front();
}

void CanBusBase::expire(std::int64_t now_ns)
{
	while (!tx_.empty()) {
		const std::int64_t deadline_ns = tx_.front().deadline_ns;
		if (deadline_ns == 0 || now_ns < deadline_ns)
			return;
		tx_.pop();
		++stats_.tx_expired;
	}
}

void CanBusBase::expireAll(std::int64_t now_ns)
{
	/* Once round the ring: the frames still in time go back in order, the others go. */
	for (std::size_t n = tx_.size(); n > 0; --n) {
		CanFrame frame;
		tx_.pop(&frame);
		if (frame.deadline_ns != 0 && now_ns >= frame.deadline_ns)
			++stats_.tx_expired;
		else
			tx_.push(frame);
	}
}

bool CanBusBase::receive(CanFrame *frame)
{
	if (!open_ || !frame)
		return false;
	for (int attempt = 0; attempt < 2; ++attempt) {
		{
			std::lock_guard<std::mutex> lock(mutex_);
			if (rx_.pop(frame))
				return true;
		}
		if (attempt == 0)
			fetch();
	}
	return false;
}

void CanBusBase::received(const CanFrame &frame)
{
	CanFrame stored = frame;
	if (stored.timestamp_ns == 0)
		stored.timestamp_ns = monotonicNs();
	std::lock_guard<std::mutex> lock(mutex_);
	if (!rx_open_)
		return;
	++rx_frames_;
	rx_.push(stored);
}

void CanBusBase::countRxLost(std::uint64_t count)
{
	std::lock_guard<std::mutex> lock(mutex_);
	rx_lost_ += count;
}

CanStats CanBusBase::stats() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	CanStats s = published_;
	s.rx_frames = rx_frames_;
	return s;
}

std::uint64_t CanBusBase::rxDropped() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	return rx_.dropped() + rx_lost_;
}

void CanBusBase::setError(const char *format, ...)
{
	va_list args;
	va_start(args, format);
	std::vsnprintf(error_.data(), error_.size(), format, args);
	va_end(args);
}

void CanBusBase::publish()
{
	stats_.tx_queued = static_cast<std::uint32_t>(tx_.size());
	stats_.tx_dropped = tx_.dropped();
	std::lock_guard<std::mutex> lock(mutex_);
	published_ = stats_;
}

} /* namespace dockpose::hal */

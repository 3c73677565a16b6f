/* SPDX-License-Identifier: MIT */
/*
 * The in-process CAN bus (see loopback_can_bus.h).
 */
#include "hal/sim/loopback_can_bus.h"

#include <algorithm>
#include <utility>

#include "hal/clock.h"
#include "hal/sim/sim_can.h"

namespace dockpose::hal {

LoopbackHub::LoopbackHub()
	: traffic_(kTrafficCapacity)
{
	endpoints_.reserve(8);
}

void LoopbackHub::setBlocked(bool blocked)
{
	std::lock_guard<std::mutex> lock(mutex_);
	blocked_ = blocked;
}

void LoopbackHub::setBusOff(bool bus_off)
{
	std::lock_guard<std::mutex> lock(mutex_);
	if (bus_off == bus_off_)
		return;
	bus_off_ = bus_off;
	bus_off_now_.store(bus_off);
	if (bus_off)
		bus_off_events_.fetch_add(1);
	else
		restarts_.fetch_add(1);
}

std::vector<CanFrame> LoopbackHub::traffic() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	const std::uint64_t kept = std::min<std::uint64_t>(traffic_count_, kTrafficCapacity);
	std::vector<CanFrame> out;
	out.reserve(static_cast<std::size_t>(kept));
	for (std::uint64_t i = traffic_count_ - kept; i < traffic_count_; ++i)
		out.push_back(traffic_[i % kTrafficCapacity]);
	return out;
}

std::uint64_t LoopbackHub::trafficCount() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	return traffic_count_;
}

void LoopbackHub::attach(LoopbackCanBus *endpoint)
{
	/* mutex_ held by the caller */
	if (std::find(endpoints_.begin(), endpoints_.end(), endpoint) == endpoints_.end())
		endpoints_.push_back(endpoint);
}

void LoopbackHub::detach(LoopbackCanBus *endpoint)
{
	/* mutex_ held by the caller */
	endpoints_.erase(std::remove(endpoints_.begin(), endpoints_.end(), endpoint),
			 endpoints_.end());
}

LoopbackCanBus::LoopbackCanBus(std::shared_ptr<LoopbackHub> hub, std::string name)
	: hub_(std::move(hub)),
	  name_(std::move(name))
{
}

LoopbackCanBus::~LoopbackCanBus()
{
	close();
}

std::string LoopbackCanBus::name() const
{
	return "loopback CAN bus " + name_;
}

Status LoopbackCanBus::open(std::span<const CanFilter> filters, const CanOptions &options)
{
	close();
	if (!hub_) {
		open_error_ = name() + ": no hub";
		error_ = open_error_.c_str();
		return Status::error(open_error_);
	}
	if (options.tx_queue_depth < 1) {
		open_error_ = name() + ": tx_queue_depth " +
			      std::to_string(options.tx_queue_depth) + " must be at least 1";
		error_ = open_error_.c_str();
		return Status::error(open_error_);
	}
	tx_.reset(options.tx_queue_depth);
	fd_ = options.fd;
	{
		std::lock_guard<std::mutex> lock(hub_->mutex_);
		filters_.assign(filters.begin(), filters.end());
		rx_ring_.assign(kRxCapacity, CanFrame{});
		rx_head_ = 0;
		rx_count_ = 0;
		bus_off_base_ = hub_->bus_off_events_.load();
		restarts_base_ = hub_->restarts_.load();
		hub_->attach(this);
	}
	open_ = true;
	error_ = "";
	stats_open_.store(true);
	publishQueue();
	return Status::ok();
}

void LoopbackCanBus::close()
{
	if (!open_)
		return;
	{
		std::lock_guard<std::mutex> lock(hub_->mutex_);
		hub_->detach(this);
		rx_count_ = 0;
	}
	tx_.clear();
	open_ = false;
	stats_open_.store(false);
	publishQueue();
}

void LoopbackCanBus::publishQueue()
{
	tx_queued_.store(static_cast<std::uint32_t>(tx_.size()), std::memory_order_relaxed);
	tx_dropped_.store(tx_.dropped(), std::memory_order_relaxed);
}

void LoopbackCanBus::deliver(const CanFrame &frame)
{
	if (!canFilterPasses(filters_, frame))
		return;
	if (rx_count_ == rx_ring_.size()) {
		rx_head_ = (rx_head_ + 1) % rx_ring_.size();
		--rx_count_;
		rx_dropped_.fetch_add(1, std::memory_order_relaxed);
	}
	rx_ring_[(rx_head_ + rx_count_) % rx_ring_.size()] = frame;
	++rx_count_;
}

void LoopbackCanBus::pump()
{
	if (tx_.empty())
		return;
	{
		std::lock_guard<std::mutex> lock(hub_->mutex_);
		if (hub_->blocked_ || hub_->bus_off_)
			return;
		while (!tx_.empty()) {
			CanFrame frame = tx_.front();
			tx_.pop();
			frame.timestamp_ns = monotonicNs();
			hub_->traffic_[hub_->traffic_count_ % LoopbackHub::kTrafficCapacity] =
				frame;
			++hub_->traffic_count_;
			for (LoopbackCanBus *endpoint : hub_->endpoints_)
				if (endpoint != this)
					endpoint->deliver(frame);
			tx_frames_.fetch_add(1, std::memory_order_relaxed);
		}
	}
	publishQueue();
}

bool LoopbackCanBus::send(const CanFrame &frame)
{
	if (!open_) {
		tx_errors_.fetch_add(1, std::memory_order_relaxed);
		error_ = "send() on a closed bus";
		return false;
	}
	if (const char *problem = canFrameProblem(frame, fd_)) {
		tx_errors_.fetch_add(1, std::memory_order_relaxed);
		error_ = problem;
		return false;
	}
	const bool kept = tx_.push(canWireFrame(frame));
	publishQueue();
	pump();
	return kept;
}

void LoopbackCanBus::poll()
{
	if (open_)
		pump();
}

bool LoopbackCanBus::receive(CanFrame *frame)
{
	if (!open_ || !frame)
		return false;
	std::lock_guard<std::mutex> lock(hub_->mutex_);
	if (rx_count_ == 0)
		return false;
	*frame = rx_ring_[rx_head_];
	rx_head_ = (rx_head_ + 1) % rx_ring_.size();
	--rx_count_;
	rx_frames_.fetch_add(1, std::memory_order_relaxed);
	return true;
}

CanStats LoopbackCanBus::stats() const
{
	CanStats s;
	s.tx_frames = tx_frames_.load(std::memory_order_relaxed);
	s.tx_dropped = tx_dropped_.load(std::memory_order_relaxed);
	s.tx_errors = tx_errors_.load(std::memory_order_relaxed);
	s.rx_frames = rx_frames_.load(std::memory_order_relaxed);
	s.tx_queued = tx_queued_.load(std::memory_order_relaxed);
	if (stats_open_.load(std::memory_order_relaxed) && hub_) {
		s.bus_off = hub_->bus_off_events_.load() - bus_off_base_;
		s.restarts = hub_->restarts_.load() - restarts_base_;
		s.state = hub_->bus_off_now_.load() ? CanState::BusOff : CanState::ErrorActive;
	} else {
		s.state = CanState::Closed;
	}
	return s;
}

std::string LoopbackCanBus::lastError() const
{
	return error_;
}

} /* namespace dockpose::hal */

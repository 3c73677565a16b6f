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
	std::vector<CanFrame> out;
	out.reserve(traffic_.size());
	for (std::size_t i = 0; i < traffic_.size(); ++i)
		out.push_back(traffic_[i]);
	return out;
}

std::uint64_t LoopbackHub::trafficCount() const
{
	std::lock_guard<std::mutex> lock(mutex_);
	return traffic_.size() + traffic_.dropped();
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

LoopbackCanBus::LoopbackCanBus(std::shared_ptr<LoopbackHub> hub, const std::string &name)
	: CanBusBase("loopback CAN bus " + name),
	  hub_(std::move(hub))
{
}

LoopbackCanBus::~LoopbackCanBus()
{
	close();
}

Status LoopbackCanBus::open(std::span<const CanFilter> filters, const CanOptions &options)
{
	close();
	if (Status s = openQueues(options, kRxCapacity); !s.isOk())
		return s;
	if (!hub_) {
		setError("%s: no hub", name().c_str());
		publish();
		return Status::error(lastError());
	}
	{
		std::lock_guard<std::mutex> lock(hub_->mutex_);
		filters_.assign(filters.begin(), filters.end());
		bus_off_base_ = hub_->bus_off_events_.load();
		restarts_base_ = hub_->restarts_.load();
		hub_->attach(this);
	}
	markOpen();
	return Status::ok();
}

void LoopbackCanBus::close()
{
	if (!isOpen())
		return;
	{
		std::lock_guard<std::mutex> lock(hub_->mutex_);
		hub_->detach(this);
	}
	closeQueues();
}

void LoopbackCanBus::deliver(const CanFrame &frame)
{
	if (canFilterPasses(filters_, frame))
		received(frame);
}

void LoopbackCanBus::transmit()
{
	if (tx_.empty())
		return;
	std::lock_guard<std::mutex> lock(hub_->mutex_);
	if (hub_->blocked_ || hub_->bus_off_) {
		expire(monotonicNs());
		return;
	}
	while (const CanFrame *next = nextToSend(monotonicNs())) {
		CanFrame frame = *next;
		tx_.pop();
		frame.timestamp_ns = monotonicNs();
		hub_->traffic_.push(frame);
		for (LoopbackCanBus *endpoint : hub_->endpoints_)
			if (endpoint != this)
				endpoint->deliver(frame);
		++stats_.tx_frames;
	}
}

void LoopbackCanBus::poll()
{
	if (!isOpen())
		return;
	transmit();
	publish();
}

CanStats LoopbackCanBus::stats() const
{
	CanStats s = CanBusBase::stats();
	if (s.state != CanState::Closed && hub_) {
		s.bus_off = hub_->bus_off_events_.load() - bus_off_base_;
		s.restarts = hub_->restarts_.load() - restarts_base_;
		s.state = hub_->bus_off_now_.load() ? CanState::BusOff : CanState::ErrorActive;
	}
	return s;
}

} /* namespace dockpose::hal */

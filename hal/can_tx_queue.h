/* SPDX-License-Identifier: MIT */
/*
 * CanTxQueue: the bounded transmit queue every CanBus backend puts in front of
 * its bus. Fixed capacity chosen at start-up; when full, push() drops the
 * oldest frame (stale pose data is worth less than fresh) and counts it.
 * Single-threaded (the frame thread owns the bus).
 *
 * Allocates: reset() allocates the ring; push(), front(), pop() never.
 */
#pragma once

#include <cstdint>
#include <vector>

#include "hal/can_bus.h"

namespace dockpose::hal {

class CanTxQueue
{
public:
	/* Capacity in frames (at least 1). Allocates. */
	void reset(int capacity)
	{
		ring_.assign(static_cast<std::size_t>(capacity < 1 ? 1 : capacity), CanFrame{});
		head_ = 0;
		count_ = 0;
		dropped_ = 0;
	}

	/* False when the oldest frame was dropped to make room. */
	bool push(const CanFrame &frame)
	{
		bool dropped = false;
		if (count_ == ring_.size()) {
			head_ = (head_ + 1) % ring_.size();
			--count_;
			++dropped_;
			dropped = true;
		}
		ring_[(head_ + count_) % ring_.size()] = frame;
		++count_;
		return !dropped;
	}

	bool empty() const { return count_ == 0; }
	std::size_t size() const { return count_; }
	std::size_t capacity() const { return ring_.size(); }
	const CanFrame &front() const { return ring_[head_]; }
	void pop()
	{
		if (count_ == 0)
			return;
		head_ = (head_ + 1) % ring_.size();
		--count_;
	}
	void clear()
	{
		head_ = 0;
		count_ = 0;
	}
	std::uint64_t dropped() const { return dropped_; }

private:
	std::vector<CanFrame> ring_;
	std::size_t head_ = 0;
	std::size_t count_ = 0;
	std::uint64_t dropped_ = 0;
};

} /* namespace dockpose::hal */

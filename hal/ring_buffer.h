/* SPDX-License-Identifier: MIT */
/*
 * RingBuffer: the one bounded FIFO of hal (the CAN backends' transmit and
 * receive queues, the loopback hub's traffic, the strobe histories).
 *
 * Storage is inline: Capacity entries of T, default-constructed with the
 * ring. A ring may be limited at run time to fewer entries (reset(limit),
 * 1 <= limit <= Capacity) when the depth is configured, e.g. the CAN
 * transmit queue's can.tx_queue_depth; it then behaves exactly as a ring of
 * limit entries.
 *
 * What push() does when the ring is full is the Overflow parameter:
 *  - RingOverflow::DropOldest: the oldest entry makes room (stale data is
 *    worth less than fresh), push() stores the new one and returns false;
 *  - RingOverflow::Reject: the new entry is not stored, push() returns false.
 * Either way dropped() counts it (entries lost since the last reset()).
 *
 * Entries are indexed from the oldest: (*this)[0] is front(), (*this)[size()
 * - 1] is back().
 *
 * Threads: none of its own. A ring is single-threaded: its owner calls it
 * from one thread, or guards every call with its own mutex (every user in
 * hal does one or the other; none needs a lock-free ring across threads:
 * the camera's lock-free slot queue is hal::FrameQueue).
 *
 * Allocates: never (the storage is part of the object).
 */
#pragma once

#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>

namespace dockpose::hal {

enum class RingOverflow : std::uint8_t {
	DropOldest, /* a full ring drops its oldest entry to take the new one */
	Reject, /* a full ring refuses the new entry */
};

template<typename T, std::size_t Capacity, RingOverflow Overflow = RingOverflow::DropOldest>
class RingBuffer
{
	static_assert(Capacity >= 1, "a ring holds at least one entry");

public:
	using value_type = T;

	static constexpr std::size_t maxCapacity() { return Capacity; }
	static constexpr RingOverflow overflow() { return Overflow; }

	/* Empty, limited to limit entries (clamped to 1..Capacity), dropped() zero. */
	void reset(std::size_t limit = Capacity)
	{
		limit_ = limit < 1 ? 1 : (limit > Capacity ? Capacity : limit);
		head_ = 0;
		count_ = 0;
		dropped_ = 0;
	}

	/*
	 * Append value. False when the ring was full: DropOldest dropped the
	 * oldest entry and stored value, Reject did not store value; either
	 * way dropped() counts one.
	 */
	bool push(const T &value)
	{
		if (count_ == limit_) {
			++dropped_;
			if constexpr (Overflow == RingOverflow::Reject)
				return false;
			head_ = next(head_);
			--count_;
			slots_[slot(count_)] = value;
			++count_;
			return false;
		}
		slots_[slot(count_)] = value;
		++count_;
		return true;
	}

	/* The oldest entry; the ring must not be empty. */
	const T &front() const
	{
		assert(count_ > 0);
		return slots_[head_];
	}
	/* The newest entry; the ring must not be empty. */
	const T &back() const
	{
		assert(count_ > 0);
		return slots_[slot(count_ - 1)];
	}
	/* The index-th oldest entry (0: front()); index < size(). */
	const T &operator[](std::size_t index) const
	{
		assert(index < count_);
		return slots_[slot(index)];
	}

	/* Take the oldest entry out; nothing when empty. */
	void pop()
	{
		if (count_ == 0)
			return;
		head_ = next(head_);
		--count_;
	}
	/* Move the oldest entry to *out and take it out. False (and *out untouched) when empty. */
	bool pop(T *out)
	{
		if (count_ == 0)
			return false;
		*out = slots_[head_];
		pop();
		return true;
	}

	/* Empty; the limit and dropped() stay. */
	void clear()
	{
		head_ = 0;
		count_ = 0;
	}

	bool empty() const { return count_ == 0; }
	bool full() const { return count_ == limit_; }
	std::size_t size() const { return count_; }
	/* Entries it holds at most: the limit of the last reset() (Capacity until then). */
	std::size_t capacity() const { return limit_; }
	/* Entries lost to a full ring since the last reset(). */
	std::uint64_t dropped() const { return dropped_; }

private:
	std::size_t next(std::size_t index) const { return index + 1 == limit_ ? 0 : index + 1; }
	/* The storage slot of the index-th oldest entry (index < limit_). */
	std::size_t slot(std::size_t index) const
	{
		const std::size_t s = head_ + index;
		return s >= limit_ ? s - limit_ : s;
	}

	std::array<T, Capacity> slots_{};
	std::size_t limit_ = Capacity;
	std::size_t head_ = 0;
	std::size_t count_ = 0;
	std::uint64_t dropped_ = 0;
};

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * FrameQueue: a fixed-capacity lock-free queue of small integers (buffer or
 * request slots) from one producer (a camera's completion callback) to one
 * consumer (the frame thread).
 *
 * push() never blocks and never fails: when the queue is full it takes the
 * oldest entry out, counts a drop and hands the dropped slot back to the
 * producer so the buffer can be recycled at once. The producer and the
 * consumer both take entries from the head with a compare-and-swap, so a
 * dropping producer and a popping consumer can never both get the same slot.
 *
 * Allocates: never. Capacity is a power of two. Values are int32.
 */
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <optional>

namespace dockpose::hal {

template<std::size_t Capacity>
class FrameQueue
{
	static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0,
		      "capacity must be a power of two");

public:
	FrameQueue()
	{
		for (auto &s : slots_)
			s.store(-1, std::memory_order_relaxed);
	}

	/*
	 * Producer only. Returns the value dropped to make room (the oldest
	 * entry), if the queue was full; the caller recycles it.
	 */
	std::optional<std::int32_t> push(std::int32_t value)
	{
		std::optional<std::int32_t> dropped;
		const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
		while (tail - head_.load(std::memory_order_acquire) >= Capacity) {
			std::int32_t v;
			if (takeHead(&v)) {
				dropped = v;
				drops_.fetch_add(1, std::memory_order_relaxed);
				break;
			}
		}
		slots_[tail & (Capacity - 1)].store(value, std::memory_order_relaxed);
		tail_.store(tail + 1, std::memory_order_release);
		return dropped;
	}

	/* Consumer (or producer, see above). False when empty. */
	bool pop(std::int32_t *value) { return takeHead(value); }

	std::size_t size() const
	{
		const std::uint64_t t = tail_.load(std::memory_order_acquire);
		const std::uint64_t h = head_.load(std::memory_order_acquire);
		return t > h ? static_cast<std::size_t>(t - h) : 0;
	}
	bool empty() const { return size() == 0; }
	std::uint64_t drops() const { return drops_.load(std::memory_order_relaxed); }
	static constexpr std::size_t capacity() { return Capacity; }

private:
	bool takeHead(std::int32_t *value)
	{
		std::uint64_t head = head_.load(std::memory_order_acquire);
		for (;;) {
			if (head >= tail_.load(std::memory_order_acquire))
				return false;
			const std::int32_t v =
				slots_[head & (Capacity - 1)].load(std::memory_order_relaxed);
			if (head_.compare_exchange_weak(head, head + 1, std::memory_order_acq_rel,
							std::memory_order_acquire)) {
				*value = v;
				return true;
			}
		}
	}

	std::array<std::atomic<std::int32_t>, Capacity> slots_;
	alignas(64) std::atomic<std::uint64_t> head_{ 0 };
	alignas(64) std::atomic<std::uint64_t> tail_{ 0 };
	std::atomic<std::uint64_t> drops_{ 0 };
};

} /* namespace dockpose::hal */

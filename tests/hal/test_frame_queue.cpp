/* SPDX-License-Identifier: MIT */
/*
 * hal::FrameQueue: order, drop-oldest, and a two-thread stress test in which
 * every pushed value is either popped exactly once, in order, or dropped.
 */
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "hal/frame_queue.h"

namespace dockpose::hal {
namespace {

TEST(FrameQueue, FifoOrder)
{
	FrameQueue<8> q;
	EXPECT_TRUE(q.empty());
	std::int32_t v = -1;
	EXPECT_FALSE(q.pop(&v));
	for (std::int32_t i = 0; i < 5; ++i)
		EXPECT_FALSE(q.push(i * 10).has_value());
	EXPECT_EQ(q.size(), 5u);
	for (std::int32_t i = 0; i < 5; ++i) {
		ASSERT_TRUE(q.pop(&v));
		EXPECT_EQ(v, i * 10);
	}
	EXPECT_FALSE(q.pop(&v));
	EXPECT_TRUE(q.empty());
	EXPECT_EQ(q.drops(), 0u);
}

TEST(FrameQueue, WrapsAround)
{
	FrameQueue<4> q;
	std::int32_t v;
	for (std::int32_t i = 0; i < 100; ++i) {
		EXPECT_FALSE(q.push(i).has_value());
		EXPECT_FALSE(q.push(i + 1000).has_value());
		ASSERT_TRUE(q.pop(&v));
		EXPECT_EQ(v, i);
		ASSERT_TRUE(q.pop(&v));
		EXPECT_EQ(v, i + 1000);
	}
	EXPECT_EQ(q.drops(), 0u);
}

TEST(FrameQueue, FullQueueDropsOldestAndReturnsIt)
{
	FrameQueue<4> q;
	for (std::int32_t i = 0; i < 4; ++i)
		EXPECT_FALSE(q.push(i).has_value());
	EXPECT_EQ(q.size(), 4u);

	auto dropped = q.push(4);
	ASSERT_TRUE(dropped.has_value());
	EXPECT_EQ(*dropped, 0);
	EXPECT_EQ(q.drops(), 1u);
	dropped = q.push(5);
	ASSERT_TRUE(dropped.has_value());
	EXPECT_EQ(*dropped, 1);
	EXPECT_EQ(q.drops(), 2u);
	EXPECT_EQ(q.size(), 4u);

	std::int32_t v;
	for (std::int32_t expect : { 2, 3, 4, 5 }) {
		ASSERT_TRUE(q.pop(&v));
		EXPECT_EQ(v, expect);
	}
	EXPECT_FALSE(q.pop(&v));
}

TEST(FrameQueue, TwoThreadStressLosesAndDuplicatesNothing)
{
	constexpr std::int32_t kCount = 100000;
	FrameQueue<4> q;
	std::vector<std::uint8_t> popped_seen(kCount, 0);
	std::vector<std::uint8_t> dropped_seen(kCount, 0);
	std::atomic<bool> done{ false };
	std::uint64_t popped = 0, out_of_order = 0, bad = 0;

	std::thread consumer([&] {
		std::int32_t last = -1;
		std::int32_t v;
		for (;;) {
			const bool finished = done.load(std::memory_order_acquire);
			if (q.pop(&v)) {
				if (v < 0 || v >= kCount) {
					++bad;
					continue;
				}
				if (v <= last)
					++out_of_order;
				last = v;
				++popped_seen[v];
				++popped;
			} else if (finished) {
				break;
			}
		}
	});

	std::uint64_t dropped = 0;
	std::atomic<int> spin{ 0 };
	for (std::int32_t i = 0; i < kCount; ++i) {
		if (const auto d = q.push(i)) {
			ASSERT_GE(*d, 0);
			ASSERT_LT(*d, kCount);
			++dropped_seen[*d];
			++dropped;
		}
		/* Vary the producer's pace so the consumer both keeps up and falls behind:
		 * pops and drops then race for the same head. */
		for (int k = 0; k < ((i >> 10) % 4) * 60; ++k)
			spin.fetch_add(1, std::memory_order_relaxed);
	}
	done.store(true, std::memory_order_release);
	consumer.join();

	EXPECT_EQ(bad, 0u);
	EXPECT_EQ(out_of_order, 0u) << "popped values must be increasing";
	EXPECT_EQ(popped + dropped, static_cast<std::uint64_t>(kCount));
	EXPECT_EQ(dropped, q.drops());
	std::int32_t lost = 0, twice = 0;
	for (std::int32_t i = 0; i < kCount; ++i) {
		const int n = popped_seen[i] + dropped_seen[i];
		lost += n == 0;
		twice += n > 1;
	}
	EXPECT_EQ(lost, 0) << "values neither popped nor dropped";
	EXPECT_EQ(twice, 0) << "values popped or dropped more than once";
	/* Both paths were exercised (a FrameQueue<4> cannot keep up with a tight producer loop
	 * all the time, nor can it drop everything while the consumer spins). */
	EXPECT_GT(popped, 0u);
	std::printf("popped %llu, dropped %llu\n", static_cast<unsigned long long>(popped),
		    static_cast<unsigned long long>(dropped));
}

} /* namespace */
} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * hal::RingBuffer: both overflow policies, wrap-around, drop counting, the
 * run-time limit, full and empty.
 */
#include <cstddef>
#include <deque>
#include <vector>

#include <gtest/gtest.h>

#include "hal/ring_buffer.h"

namespace dockpose::hal {
namespace {

template<typename Ring>
std::vector<int> contents(const Ring &ring)
{
	std::vector<int> out;
	for (std::size_t i = 0; i < ring.size(); ++i)
		out.push_back(ring[i]);
	return out;
}

TEST(RingBuffer, StartsEmptyAtFullCapacity)
{
	RingBuffer<int, 4> ring;
	EXPECT_TRUE(ring.empty());
	EXPECT_FALSE(ring.full());
	EXPECT_EQ(ring.size(), 0u);
	EXPECT_EQ(ring.capacity(), 4u);
	EXPECT_EQ(ring.maxCapacity(), 4u);
	EXPECT_EQ(ring.dropped(), 0u);
	int out = 7;
	EXPECT_FALSE(ring.pop(&out));
	EXPECT_EQ(out, 7);
	ring.pop(); /* on an empty ring: nothing */
	EXPECT_TRUE(ring.empty());
}

TEST(RingBuffer, FifoOrderUntilFull)
{
	RingBuffer<int, 3> ring;
	EXPECT_TRUE(ring.push(1));
	EXPECT_TRUE(ring.push(2));
	EXPECT_FALSE(ring.full());
	EXPECT_TRUE(ring.push(3));
	EXPECT_TRUE(ring.full());
	EXPECT_EQ(ring.front(), 1);
	EXPECT_EQ(ring.back(), 3);
	EXPECT_EQ(contents(ring), (std::vector<int>{ 1, 2, 3 }));
	int out = 0;
	ASSERT_TRUE(ring.pop(&out));
	EXPECT_EQ(out, 1);
	ASSERT_TRUE(ring.pop(&out));
	EXPECT_EQ(out, 2);
	ASSERT_TRUE(ring.pop(&out));
	EXPECT_EQ(out, 3);
	EXPECT_TRUE(ring.empty());
	EXPECT_EQ(ring.dropped(), 0u);
}

TEST(RingBuffer, DropOldestKeepsTheNewestAndCounts)
{
	RingBuffer<int, 3, RingOverflow::DropOldest> ring;
	for (int i = 1; i <= 3; ++i)
		EXPECT_TRUE(ring.push(i));
	EXPECT_FALSE(ring.push(4));
	EXPECT_FALSE(ring.push(5));
	EXPECT_EQ(ring.size(), 3u);
	EXPECT_EQ(ring.dropped(), 2u);
	EXPECT_EQ(contents(ring), (std::vector<int>{ 3, 4, 5 }));
	EXPECT_EQ(ring.front(), 3);
	EXPECT_EQ(ring.back(), 5);
}

TEST(RingBuffer, RejectKeepsTheOldestAndCounts)
{
	RingBuffer<int, 3, RingOverflow::Reject> ring;
	for (int i = 1; i <= 3; ++i)
		EXPECT_TRUE(ring.push(i));
	EXPECT_FALSE(ring.push(4));
	EXPECT_FALSE(ring.push(5));
	EXPECT_EQ(ring.size(), 3u);
	EXPECT_EQ(ring.dropped(), 2u);
	EXPECT_EQ(contents(ring), (std::vector<int>{ 1, 2, 3 }));
	/* Room again after a pop. */
	ring.pop();
	EXPECT_TRUE(ring.push(6));
	EXPECT_EQ(contents(ring), (std::vector<int>{ 2, 3, 6 }));
	EXPECT_EQ(ring.dropped(), 2u);
}

/* Against a std::deque model over many interleaved pushes and pops, so the indices wrap often. */
template<RingOverflow Overflow>
void checkAgainstModel(std::size_t limit)
{
	RingBuffer<int, 5, Overflow> ring;
	ring.reset(limit);
	std::deque<int> model;
	std::uint64_t model_dropped = 0;
	unsigned state = 12345;
	for (int step = 0; step < 2000; ++step) {
		state = state * 1103515245u + 12345u;
		const bool push = (state >> 16) % 3 != 0; /* two pushes per pop: often full */
		if (push) {
			bool fits = model.size() < limit;
			if (!fits) {
				++model_dropped;
				if (Overflow == RingOverflow::DropOldest) {
					model.pop_front();
					model.push_back(step);
				}
			} else {
				model.push_back(step);
			}
			EXPECT_EQ(ring.push(step), fits) << "step " << step;
		} else {
			int out = -1;
			const bool had = !model.empty();
			EXPECT_EQ(ring.pop(&out), had) << "step " << step;
			if (had) {
				EXPECT_EQ(out, model.front()) << "step " << step;
				model.pop_front();
			}
		}
		ASSERT_EQ(ring.size(), model.size()) << "step " << step;
		EXPECT_EQ(ring.full(), model.size() == limit);
		EXPECT_EQ(ring.empty(), model.empty());
		EXPECT_EQ(ring.dropped(), model_dropped);
		for (std::size_t i = 0; i < model.size(); ++i)
			ASSERT_EQ(ring[i], model[i]) << "step " << step << " index " << i;
	}
	EXPECT_GT(model_dropped, 100u);
}

TEST(RingBuffer, WrapsAroundLikeADequeDropOldest)
{
	for (std::size_t limit = 1; limit <= 5; ++limit)
		checkAgainstModel<RingOverflow::DropOldest>(limit);
}

TEST(RingBuffer, WrapsAroundLikeADequeReject)
{
	for (std::size_t limit = 1; limit <= 5; ++limit)
		checkAgainstModel<RingOverflow::Reject>(limit);
}

TEST(RingBuffer, ResetLimitsClampsAndZeroesDrops)
{
	RingBuffer<int, 8> ring;
	ring.reset(2);
	EXPECT_EQ(ring.capacity(), 2u);
	EXPECT_TRUE(ring.push(1));
	EXPECT_TRUE(ring.push(2));
	EXPECT_TRUE(ring.full());
	EXPECT_FALSE(ring.push(3));
	EXPECT_EQ(ring.dropped(), 1u);
	EXPECT_EQ(contents(ring), (std::vector<int>{ 2, 3 }));

	ring.reset(0);
	EXPECT_EQ(ring.capacity(), 1u);
	EXPECT_TRUE(ring.empty());
	EXPECT_EQ(ring.dropped(), 0u);

	ring.reset(100);
	EXPECT_EQ(ring.capacity(), 8u);
	ring.reset();
	EXPECT_EQ(ring.capacity(), 8u);
}

TEST(RingBuffer, ClearEmptiesButKeepsTheLimitAndTheDropCount)
{
	RingBuffer<int, 4> ring;
	ring.reset(2);
	ring.push(1);
	ring.push(2);
	ring.push(3);
	ring.clear();
	EXPECT_TRUE(ring.empty());
	EXPECT_EQ(ring.capacity(), 2u);
	EXPECT_EQ(ring.dropped(), 1u);
	EXPECT_TRUE(ring.push(4));
	EXPECT_EQ(ring.front(), 4);
}

TEST(RingBuffer, CapacityOneAlwaysHoldsTheNewest)
{
	RingBuffer<int, 1> ring;
	EXPECT_TRUE(ring.push(1));
	EXPECT_FALSE(ring.push(2));
	EXPECT_EQ(ring.front(), 2);
	EXPECT_EQ(ring.back(), 2);
	EXPECT_EQ(ring.dropped(), 1u);
}

TEST(RingBuffer, HoldsStructsByValue)
{
	struct Entry {
		long long time_ns = 0;
		bool on = false;
	};
	RingBuffer<Entry, 2> ring;
	ring.push({ 10, true });
	ring.push({ 20, false });
	ring.push({ 30, true });
	EXPECT_EQ(ring.front().time_ns, 20);
	EXPECT_FALSE(ring.front().on);
	EXPECT_EQ(ring.back().time_ns, 30);
	EXPECT_TRUE(ring.back().on);
}

} /* namespace */
} /* namespace dockpose::hal */

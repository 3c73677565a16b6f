/* SPDX-License-Identifier: MIT */
/*
 * RecordingStrobe: level changes recorded with monotonic times, forceOff
 * (also from a signal handler), failNextSet, open/close bookkeeping.
 */
#include <csignal>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "hal/clock.h"
#include "hal/sim/recording_strobe.h"

namespace dockpose::hal {
namespace {

TEST(RecordingStrobe, StartsClosedAndDark)
{
	RecordingStrobe strobe;
	EXPECT_FALSE(strobe.everOpened());
	EXPECT_FALSE(strobe.closed());
	EXPECT_FALSE(strobe.isOn());
	EXPECT_TRUE(strobe.events().empty());
	EXPECT_FALSE(strobe.name().empty());

	const Status s = strobe.set(true);
	EXPECT_FALSE(s.isOk());
	EXPECT_NE(s.message().find("not open"), std::string::npos) << s.message();
	EXPECT_FALSE(strobe.isOn());
	EXPECT_TRUE(strobe.events().empty());
}

TEST(RecordingStrobe, RecordsLevelChangesInOrderWithTimes)
{
	RecordingStrobe strobe;
	ASSERT_TRUE(strobe.open().isOk());
	EXPECT_TRUE(strobe.everOpened());
	EXPECT_FALSE(strobe.isOn());
	EXPECT_TRUE(strobe.events().empty()) << "open() of a dark LED changes nothing";

	const std::int64_t before = monotonicNs();
	ASSERT_TRUE(strobe.set(true).isOk());
	EXPECT_TRUE(strobe.isOn());
	ASSERT_TRUE(strobe.set(true).isOk()); /* no change: not recorded */
	ASSERT_TRUE(strobe.set(false).isOk());
	EXPECT_FALSE(strobe.isOn());
	ASSERT_TRUE(strobe.set(true).isOk());
	const std::int64_t after = monotonicNs();

	const auto events = strobe.events();
	ASSERT_EQ(events.size(), 3u);
	EXPECT_TRUE(events[0].on);
	EXPECT_FALSE(events[1].on);
	EXPECT_TRUE(events[2].on);
	for (std::size_t i = 0; i < events.size(); ++i) {
		EXPECT_GE(events[i].time_ns, before);
		EXPECT_LE(events[i].time_ns, after);
		if (i > 0) {
			EXPECT_GE(events[i].time_ns, events[i - 1].time_ns);
		}
	}
	EXPECT_EQ(strobe.eventCount(), 3u);

	strobe.close();
	EXPECT_TRUE(strobe.closed());
	EXPECT_FALSE(strobe.isOn());
	const auto closed_events = strobe.events();
	ASSERT_EQ(closed_events.size(), 4u);
	EXPECT_FALSE(closed_events[3].on) << "close() switches the LED off";
	strobe.close(); /* idempotent */
	EXPECT_EQ(strobe.events().size(), 4u);
	EXPECT_FALSE(strobe.set(true).isOk()) << "set() after close()";

	ASSERT_TRUE(strobe.open().isOk());
	EXPECT_FALSE(strobe.closed());
}

TEST(RecordingStrobe, ForceOffSwitchesOffAndIsRecordedInOrder)
{
	RecordingStrobe strobe;
	ASSERT_TRUE(strobe.open().isOk());
	ASSERT_TRUE(strobe.set(true).isOk());
	const std::int64_t before = monotonicNs();
	strobe.forceOff();
	const std::int64_t after = monotonicNs();
	EXPECT_FALSE(strobe.isOn());
	EXPECT_EQ(strobe.forceOffCount(), 1u);

	auto events = strobe.events();
	ASSERT_EQ(events.size(), 2u);
	EXPECT_FALSE(events[1].on);
	EXPECT_GE(events[1].time_ns, before);
	EXPECT_LE(events[1].time_ns, after);

	/* A later set() keeps the forced "off" in its place in the history. */
	ASSERT_TRUE(strobe.set(true).isOk());
	events = strobe.events();
	ASSERT_EQ(events.size(), 3u);
	EXPECT_TRUE(events[0].on);
	EXPECT_FALSE(events[1].on);
	EXPECT_TRUE(events[2].on);
	EXPECT_GE(events[2].time_ns, events[1].time_ns);

	/* forceOff of a dark LED records nothing. */
	ASSERT_TRUE(strobe.set(false).isOk());
	strobe.forceOff();
	EXPECT_EQ(strobe.events().size(), 4u);
	EXPECT_EQ(strobe.forceOffCount(), 2u);
}

RecordingStrobe *g_strobe = nullptr;

void onSignal(int)
{
	g_strobe->forceOff();
}

TEST(RecordingStrobe, ForceOffFromASignalHandler)
{
	RecordingStrobe strobe;
	ASSERT_TRUE(strobe.open().isOk());
	ASSERT_TRUE(strobe.set(true).isOk());
	g_strobe = &strobe;
	struct sigaction sa = {};
	struct sigaction old = {};
	sa.sa_handler = onSignal;
	sigemptyset(&sa.sa_mask);
	ASSERT_EQ(sigaction(SIGUSR1, &sa, &old), 0);
	ASSERT_EQ(raise(SIGUSR1), 0);
	sigaction(SIGUSR1, &old, nullptr);
	g_strobe = nullptr;

	EXPECT_FALSE(strobe.isOn());
	const auto events = strobe.events();
	ASSERT_EQ(events.size(), 2u);
	EXPECT_FALSE(events.back().on);
}

TEST(RecordingStrobe, FailNextSetFailsOnceAndChangesNothing)
{
	RecordingStrobe strobe;
	ASSERT_TRUE(strobe.open().isOk());
	strobe.failNextSet("gpiochip0: line 17: Device or resource busy");
	const Status failed = strobe.set(true);
	ASSERT_FALSE(failed.isOk());
	EXPECT_EQ(failed.message(), "gpiochip0: line 17: Device or resource busy");
	EXPECT_FALSE(strobe.isOn());
	EXPECT_TRUE(strobe.events().empty());

	ASSERT_TRUE(strobe.set(true).isOk()) << "only the next set() fails";
	EXPECT_TRUE(strobe.isOn());
	EXPECT_EQ(strobe.events().size(), 1u);
}

TEST(RecordingStrobe, KeepsTheMostRecentEventsAndCountsAll)
{
	RecordingStrobe strobe;
	ASSERT_TRUE(strobe.open().isOk());
	const std::size_t n = RecordingStrobe::kCapacity + 101;
	for (std::size_t i = 0; i < n; ++i)
		ASSERT_TRUE(strobe.set(i % 2 == 0).isOk());
	EXPECT_EQ(strobe.eventCount(), n);
	const auto events = strobe.events();
	ASSERT_EQ(events.size(), RecordingStrobe::kCapacity);
	/* The last event is the last set(): n - 1 is even -> on. */
	EXPECT_EQ(events.back().on, (n - 1) % 2 == 0);
	for (std::size_t i = 1; i < events.size(); ++i) {
		ASSERT_NE(events[i].on, events[i - 1].on);
		ASSERT_GE(events[i].time_ns, events[i - 1].time_ns);
	}
}

} /* namespace */
} /* namespace dockpose::hal */

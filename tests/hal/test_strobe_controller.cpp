/* SPDX-License-Identifier: MIT */
/*
 * StrobeController against an in-test fake Strobe that records every set()
 * with the monotonic times around it. Timing checks are one-sided where
 * causality allows (a switch never happens before its time) and generous
 * where the scheduler is involved (this machine is shared).
 */
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hal/can_bus.h"
#include "hal/clock.h"
#include "hal/strobe.h"

using namespace dockpose::hal;
using ::testing::HasSubstr;

namespace {

constexpr std::int64_t kMs = 1000000;
/* Scheduler delay allowed for a switch after its time: generous, because this
 * runs on shared, loaded machines, where a sleeping thread can wake several
 * milliseconds late. HundredsOfPulsesInARow checks the typical precision. */
constexpr std::int64_t kLateNs = 20 * kMs;

class FakeStrobe : public Strobe
{
public:
	struct Call {
		std::int64_t before_ns;
		std::int64_t after_ns;
		bool on;
		bool ok;
	};

	FakeStrobe() { calls_.reserve(16384); }

	std::string name() const override { return "fake"; }
	Status open() override { return Status::ok(); }
	Status set(bool on) override
	{
		std::lock_guard<std::mutex> lock(mutex_);
		Call call{ monotonicNs(), 0, on, !fail_ };
		if (!fail_)
			on_ = on;
		call.after_ns = monotonicNs();
		calls_.push_back(call);
		if (!call.ok)
			return Status::error("fake: injected failure");
		return Status::ok();
	}
	bool isOn() const override
	{
		std::lock_guard<std::mutex> lock(mutex_);
		return on_;
	}
	void forceOff() noexcept override { on_ = false; }
	void close() override { on_ = false; }

	void setFail(bool fail)
	{
		std::lock_guard<std::mutex> lock(mutex_);
		fail_ = fail;
	}
	std::vector<Call> calls() const
	{
		std::lock_guard<std::mutex> lock(mutex_);
		return calls_;
	}
	std::vector<Call> successfulSwitches(bool on) const
	{
		std::vector<Call> out;
		for (const Call &c : calls())
			if (c.ok && c.on == on)
				out.push_back(c);
		return out;
	}

private:
	mutable std::mutex mutex_;
	bool on_ = false;
	bool fail_ = false;
	std::vector<Call> calls_;
};

bool waitFor(const std::function<bool()> &done, int timeout_ms = 2000)
{
	std::int64_t deadline = monotonicNs() + timeout_ms * kMs;
	while (!done()) {
		if (monotonicNs() > deadline)
			return false;
		std::this_thread::sleep_for(std::chrono::milliseconds(1));
	}
	return true;
}

void sleepUntil(std::int64_t t_ns)
{
	while (monotonicNs() < t_ns)
		std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

} /* namespace */

TEST(HalNames, LightingAndCanState)
{
	EXPECT_STREQ(lightingName(Lighting::Unlit), "unlit");
	EXPECT_STREQ(lightingName(Lighting::Lit), "lit");
	EXPECT_STREQ(lightingName(Lighting::Mixed), "mixed");
	EXPECT_STREQ(lightingName(static_cast<Lighting>(77)), "invalid");
	EXPECT_STREQ(canStateName(CanState::Closed), "closed");
	EXPECT_STREQ(canStateName(CanState::ErrorActive), "error-active");
	EXPECT_STREQ(canStateName(CanState::ErrorWarning), "error-warning");
	EXPECT_STREQ(canStateName(CanState::ErrorPassive), "error-passive");
	EXPECT_STREQ(canStateName(CanState::BusOff), "bus-off");
	EXPECT_STREQ(canStateName(CanState::Down), "down");
	EXPECT_STREQ(canStateName(static_cast<CanState>(99)), "invalid");
}

/* wait_until on steady_clock is only right if it is CLOCK_MONOTONIC. */
TEST(StrobeController, SteadyClockIsMonotonicClock)
{
	std::int64_t a = monotonicNs();
	std::int64_t s = std::chrono::duration_cast<std::chrono::nanoseconds>(
				 std::chrono::steady_clock::now().time_since_epoch())
				 .count();
	std::int64_t b = monotonicNs();
	EXPECT_GE(s, a);
	EXPECT_LE(s, b);
}

TEST(StrobeController, StartSwitchesOffAndConstantOnOff)
{
	FakeStrobe fake;
	ASSERT_TRUE(fake.set(true));
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());
	EXPECT_FALSE(fake.isOn());
	EXPECT_FALSE(control.isOn());
	ASSERT_EQ(fake.calls().size(), 2u);
	EXPECT_FALSE(fake.calls().back().on);

	control.setOn(true);
	EXPECT_TRUE(fake.isOn());
	EXPECT_TRUE(control.isOn());
	control.setOn(true);
	control.setOn(false);
	EXPECT_FALSE(fake.isOn());
	EXPECT_FALSE(control.isOn());
	EXPECT_EQ(control.switchCount(), 2u);
	/* No repeated set() for a level the line already has. */
	EXPECT_EQ(fake.calls().size(), 4u);
	EXPECT_EQ(control.errorCount(), 0u);
	EXPECT_EQ(control.lastError(), "");
}

TEST(StrobeController, StopLeavesTheLedOff)
{
	FakeStrobe fake;
	{
		StrobeController control(&fake, 0);
		ASSERT_TRUE(control.start());
		control.setOn(true);
		ASSERT_TRUE(fake.isOn());
		control.stop();
		EXPECT_FALSE(fake.isOn());
		EXPECT_FALSE(control.isOn());
		control.stop(); /* idempotent */

		/* Restart: constant mode was reset by stop. */
		ASSERT_TRUE(control.start());
		EXPECT_FALSE(fake.isOn());
		control.setOn(true);
		ASSERT_TRUE(fake.isOn());
		/* The destructor stops. */
	}
	EXPECT_FALSE(fake.isOn());
	EXPECT_FALSE(fake.calls().back().on);
}

TEST(StrobeController, SetOnBeforeStartAppliesOnceStarted)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	control.setOn(true);
	EXPECT_TRUE(fake.calls().empty());
	ASSERT_TRUE(control.start());
	EXPECT_TRUE(waitFor([&] { return fake.isOn(); }));
}

TEST(StrobeController, PulseLightsItsWindowOnly)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());

	std::int64_t start_ns = monotonicNs() + 40 * kMs;
	std::int64_t end_ns = start_ns + 60 * kMs;
	ASSERT_TRUE(control.schedulePulse(start_ns, end_ns - start_ns));
	EXPECT_FALSE(fake.isOn());

	ASSERT_TRUE(waitFor([&] { return fake.successfulSwitches(false).size() >= 2; }));
	std::vector<FakeStrobe::Call> ons = fake.successfulSwitches(true);
	std::vector<FakeStrobe::Call> offs = fake.successfulSwitches(false);
	ASSERT_EQ(ons.size(), 1u);
	ASSERT_EQ(offs.size(), 2u); /* start(), then the pulse end */
	const FakeStrobe::Call &on = ons[0];
	const FakeStrobe::Call &off = offs[1];
	/* Never early, and on time within the tolerance. */
	EXPECT_GE(on.before_ns, start_ns);
	EXPECT_LE(on.before_ns, start_ns + kLateNs);
	EXPECT_GE(off.before_ns, end_ns);
	EXPECT_LE(off.before_ns, end_ns + kLateNs);
	EXPECT_EQ(control.switchCount(), 2u);

	sleepUntil(off.after_ns + 20 * kMs);
	/* Inside the lit interval (margins cover the controller's own timestamps). */
	EXPECT_EQ(control.lighting(on.after_ns + 3 * kMs, off.before_ns - 3 * kMs), Lighting::Lit);
	/* Before the pulse, after start(). */
	EXPECT_EQ(control.lighting(start_ns - 30 * kMs, on.before_ns - 3 * kMs), Lighting::Unlit);
	/* After the pulse. */
	EXPECT_EQ(control.lighting(off.after_ns + 3 * kMs, off.after_ns + 15 * kMs),
		  Lighting::Unlit);
	/* Across either switch, or the whole pulse. */
	EXPECT_EQ(control.lighting(on.before_ns - kMs, on.after_ns + kMs), Lighting::Mixed);
	EXPECT_EQ(control.lighting(off.before_ns - kMs, off.after_ns + kMs), Lighting::Mixed);
	EXPECT_EQ(control.lighting(start_ns - 5 * kMs, end_ns + 5 * kMs), Lighting::Mixed);
	/* Exactly at the switch instants. */
	EXPECT_EQ(control.lighting(on.before_ns, on.before_ns), Lighting::Mixed);
	EXPECT_EQ(control.lighting(off.after_ns, off.after_ns), Lighting::Mixed);
}

TEST(StrobeController, LightingOutsideHistoryOrInTheFutureIsMixed)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	std::int64_t before_start = monotonicNs();
	EXPECT_EQ(control.lighting(before_start - 10 * kMs, before_start - 5 * kMs),
		  Lighting::Mixed);
	std::this_thread::sleep_for(std::chrono::milliseconds(2));
	ASSERT_TRUE(control.start());
	std::int64_t t = monotonicNs();
	std::this_thread::sleep_for(std::chrono::milliseconds(10));
	/* Before start(): nothing is known. */
	EXPECT_EQ(control.lighting(before_start - 10 * kMs, before_start - 5 * kMs),
		  Lighting::Mixed);
	/* After start(): off. */
	EXPECT_EQ(control.lighting(t + 1, t + 5 * kMs), Lighting::Unlit);
	/* Not over yet. */
	std::int64_t now = monotonicNs();
	EXPECT_EQ(control.lighting(now - kMs, now + 100 * kMs), Lighting::Mixed);
	/* Backwards window. */
	EXPECT_EQ(control.lighting(t + 5 * kMs, t + 1), Lighting::Mixed);

	control.setOn(true);
	std::int64_t lit_from = monotonicNs() + 1;
	std::this_thread::sleep_for(std::chrono::milliseconds(10));
	EXPECT_EQ(control.lighting(lit_from, lit_from + 5 * kMs), Lighting::Lit);
	EXPECT_EQ(control.lighting(t + 1, lit_from + 5 * kMs), Lighting::Mixed);
}

TEST(StrobeController, RejectsPastPulsesBadDurationsAndAFullQueue)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());
	std::int64_t now = monotonicNs();
	EXPECT_FALSE(control.schedulePulse(now - kMs, 10 * kMs));
	EXPECT_FALSE(control.schedulePulse(now - 20 * kMs, 5 * kMs));
	EXPECT_FALSE(control.schedulePulse(now + 100 * kMs, 0));
	EXPECT_FALSE(control.schedulePulse(now + 100 * kMs, -kMs));

	std::int64_t base = now + 1000 * kMs;
	for (int i = 0; i < StrobeController::kMaxPulses; i++)
		EXPECT_TRUE(control.schedulePulse(base + i * 10 * kMs, 2 * kMs)) << i;
	EXPECT_FALSE(control.schedulePulse(base + 500 * kMs, 2 * kMs));
	control.cancelPulses();
	EXPECT_TRUE(control.schedulePulse(base + 500 * kMs, 2 * kMs));
	control.cancelPulses();
	std::this_thread::sleep_for(std::chrono::milliseconds(5));
	EXPECT_FALSE(fake.isOn());
}

TEST(StrobeController, OverlappingPulsesLightTheirUnion)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());
	std::int64_t a = monotonicNs() + 30 * kMs;
	ASSERT_TRUE(control.schedulePulse(a + 10 * kMs, 20 * kMs)); /* [a+10, a+30) */
	ASSERT_TRUE(control.schedulePulse(a, 15 * kMs)); /* [a, a+15) */
	ASSERT_TRUE(waitFor([&] { return fake.successfulSwitches(false).size() >= 2; }));
	sleepUntil(a + 40 * kMs);
	std::vector<FakeStrobe::Call> ons = fake.successfulSwitches(true);
	std::vector<FakeStrobe::Call> offs = fake.successfulSwitches(false);
	ASSERT_EQ(ons.size(), 1u);
	ASSERT_EQ(offs.size(), 2u);
	EXPECT_GE(ons[0].before_ns, a);
	EXPECT_LE(ons[0].before_ns, a + kLateNs);
	EXPECT_GE(offs[1].before_ns, a + 30 * kMs);
	EXPECT_LE(offs[1].before_ns, a + 30 * kMs + kLateNs);
}

TEST(StrobeController, SetOnAndCancelDropPendingPulses)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());
	std::int64_t a = monotonicNs() + 20 * kMs;
	ASSERT_TRUE(control.schedulePulse(a, 10 * kMs));
	control.setOn(false);
	ASSERT_TRUE(control.schedulePulse(a + 5 * kMs, 10 * kMs));
	control.cancelPulses();
	sleepUntil(a + 40 * kMs);
	EXPECT_TRUE(fake.successfulSwitches(true).empty());

	/* Constant on replaces a pulse: still on after the pulse's end. */
	std::int64_t b = monotonicNs() + 20 * kMs;
	ASSERT_TRUE(control.schedulePulse(b, 5 * kMs));
	control.setOn(true);
	sleepUntil(b + 30 * kMs);
	EXPECT_TRUE(fake.isOn());
	EXPECT_EQ(fake.successfulSwitches(true).size(), 1u);
}

TEST(StrobeController, CancelDuringAPulseSwitchesOff)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());
	std::int64_t a = monotonicNs() + 10 * kMs;
	ASSERT_TRUE(control.schedulePulse(a, 10000 * kMs));
	ASSERT_TRUE(waitFor([&] { return fake.isOn(); }));
	control.cancelPulses();
	EXPECT_FALSE(fake.isOn());
	EXPECT_FALSE(control.isOn());
}

TEST(StrobeController, DeadManSwitchesOffUntilKicked)
{
	FakeStrobe fake;
	StrobeController control(&fake, 60);
	std::int64_t t0 = monotonicNs();
	ASSERT_TRUE(control.start());
	control.setOn(true);
	ASSERT_TRUE(fake.isOn());
	ASSERT_TRUE(control.schedulePulse(monotonicNs() + 200 * kMs, 10 * kMs));

	ASSERT_TRUE(waitFor([&] { return control.stalled(); }));
	EXPECT_EQ(control.stallCount(), 1u);
	EXPECT_FALSE(fake.isOn());
	EXPECT_FALSE(control.isOn());
	std::vector<FakeStrobe::Call> offs = fake.successfulSwitches(false);
	ASSERT_EQ(offs.size(), 2u);
	EXPECT_GE(offs[1].before_ns, t0 + 60 * kMs); /* not before the timeout */
	EXPECT_LE(offs[1].before_ns, t0 + 60 * kMs + 100 * kMs);

	/* Stays off, the pending pulse was cancelled, new pulses are refused. */
	EXPECT_FALSE(control.schedulePulse(monotonicNs() + 10 * kMs, 5 * kMs));
	sleepUntil(t0 + 300 * kMs);
	EXPECT_FALSE(fake.isOn());
	EXPECT_EQ(fake.successfulSwitches(true).size(), 1u);
	EXPECT_EQ(control.stallCount(), 1u);

	/* A kick resumes constant on, and the timer runs again. */
	control.kick();
	EXPECT_FALSE(control.stalled());
	EXPECT_TRUE(fake.isOn());
	EXPECT_TRUE(control.isOn());
	ASSERT_TRUE(waitFor([&] { return control.stalled(); }));
	EXPECT_EQ(control.stallCount(), 2u);
	EXPECT_FALSE(fake.isOn());
}

TEST(StrobeController, KicksKeepItAlive)
{
	FakeStrobe fake;
	StrobeController control(&fake, 250);
	ASSERT_TRUE(control.start());
	control.setOn(true);
	std::int64_t end = monotonicNs() + 600 * kMs;
	while (monotonicNs() < end) {
		control.kick();
		std::this_thread::sleep_for(std::chrono::milliseconds(5));
	}
	EXPECT_FALSE(control.stalled());
	EXPECT_EQ(control.stallCount(), 0u);
	EXPECT_TRUE(fake.isOn());
	EXPECT_EQ(fake.successfulSwitches(false).size(), 1u); /* only start() */
}

TEST(StrobeController, SetErrorsAreCountedAndTheLineAssumedOff)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());
	fake.setFail(true);
	control.setOn(true);
	EXPECT_GE(control.errorCount(), 1u);
	EXPECT_FALSE(control.isOn());
	EXPECT_THAT(control.lastError(), HasSubstr("injected failure"));
	std::int64_t t = monotonicNs();
	std::this_thread::sleep_for(std::chrono::milliseconds(30));
	/* Retried (every 10 ms), still failing; the level is unknown. */
	EXPECT_GE(control.errorCount(), 2u);
	EXPECT_EQ(control.lighting(t, t + 10 * kMs), Lighting::Mixed);

	fake.setFail(false);
	/* control.isOn() is true once the switch is recorded (under its lock). */
	ASSERT_TRUE(waitFor([&] { return control.isOn(); }));
	std::uint64_t errors = control.errorCount();
	EXPECT_TRUE(fake.isOn());
	std::int64_t lit_from = monotonicNs() + 1;
	std::this_thread::sleep_for(std::chrono::milliseconds(20));
	EXPECT_EQ(control.lighting(lit_from, lit_from + 10 * kMs), Lighting::Lit);
	EXPECT_EQ(control.errorCount(), errors);
}

TEST(StrobeController, StartFailsWhenTheLedCannotBeSwitchedOff)
{
	FakeStrobe fake;
	fake.setFail(true);
	StrobeController control(&fake, 0);
	Status status = control.start();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("cannot switch the LED off"));
	EXPECT_THAT(status.message(), HasSubstr("injected failure"));
	control.stop();
	fake.setFail(false);
	EXPECT_TRUE(control.start());

	StrobeController none(nullptr, 0);
	EXPECT_FALSE(none.start());
}

TEST(StrobeController, HundredsOfPulsesInARow)
{
	FakeStrobe fake;
	StrobeController control(&fake, 0);
	ASSERT_TRUE(control.start());

	constexpr int kPulses = 300;
	constexpr std::int64_t kPeriod = 6 * kMs;
	constexpr std::int64_t kWidth = 2 * kMs;
	std::int64_t base = monotonicNs() + 20 * kMs;
	std::vector<std::int64_t> starts;
	int skipped = 0;
	for (int i = 0; i < kPulses;) {
		std::int64_t start = base + i * kPeriod;
		/* Keep about 6 pulses queued, as the frame loop would. */
		if (start < monotonicNs() + 36 * kMs) {
			if (control.schedulePulse(start, kWidth)) {
				starts.push_back(start);
			} else {
				/* Only refused when this thread was so late the pulse is past. */
				ASSERT_LT(start, monotonicNs())
					<< "future pulse " << i << " refused";
				skipped++;
			}
			i++;
		} else {
			std::this_thread::sleep_for(std::chrono::milliseconds(1));
		}
	}
	EXPECT_LT(skipped, kPulses / 10);
	sleepUntil(starts.back() + kWidth + 20 * kMs);

	std::vector<FakeStrobe::Call> calls = fake.calls();
	std::vector<std::int64_t> late;
	int ons = 0;
	for (std::size_t i = 1; i < calls.size(); i++) {
		const FakeStrobe::Call &c = calls[i];
		ASSERT_TRUE(c.ok);
		/* The pulse this switch belongs to: the latest one started by then. */
		auto it = std::upper_bound(starts.begin(), starts.end(), c.before_ns);
		ASSERT_NE(it, starts.begin()) << "switch before the first pulse";
		std::int64_t start = *(it - 1);
		if (c.on) {
			ons++;
			/* On inside its pulse, never early. */
			EXPECT_LT(c.before_ns, start + kWidth);
			late.push_back(c.before_ns - start);
		} else {
			/* Off after the pulse's end, before the next one starts. */
			EXPECT_GE(c.before_ns, start + kWidth);
			EXPECT_LT(c.before_ns, start + kPeriod);
		}
		/* Alternating levels. */
		EXPECT_NE(c.on, calls[i - 1].on);
	}
	/* Every pulse lit once, except where the thread woke after a pulse's end
	 * (lost) or after the gap (merged): rare when idle, a few percent when
	 * the machine is loaded. */
	int scheduled = static_cast<int>(starts.size());
	EXPECT_GE(ons, scheduled / 2);
	EXPECT_LE(ons, scheduled);
	EXPECT_EQ(control.switchCount(), static_cast<std::uint64_t>(2 * ons));
	std::sort(late.begin(), late.end());
	std::int64_t median = late[late.size() / 2];
	EXPECT_LT(median, kMs) << "median lateness " << median << " ns";
	std::printf("%d of %d pulses lit; on-switch lateness: median %lld us, max %lld us\n", ons,
		    scheduled, static_cast<long long>(median / 1000),
		    static_cast<long long>(late.back() / 1000));

	/* The history holds the last pulses only. */
	std::int64_t first = starts.front();
	EXPECT_EQ(control.lighting(first + kWidth / 4, first + kWidth / 2), Lighting::Mixed);
	std::int64_t last_off_after = calls.back().after_ns;
	EXPECT_EQ(control.lighting(last_off_after + kMs, last_off_after + 10 * kMs),
		  Lighting::Unlit);
	EXPECT_FALSE(fake.isOn());
}

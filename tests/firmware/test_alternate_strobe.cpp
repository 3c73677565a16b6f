/* SPDX-License-Identifier: MIT */
/*
 * AlternateStrobe (firmware/alternate_strobe.h) on its own, with hand-made hal::Frame values:
 *
 *  - the period estimate: the configured period until frames come, the first interval taken
 *    whole, then 1/8 of each new one; frames without a timestamp, intervals across a stall
 *    and backward or repeated sequence numbers are no samples; a sequence gap divides the
 *    interval;
 *  - the pulse scheduling on a hal::StrobeController driving a hal::RecordingStrobe: pulses
 *    at the next two even frames, the exposure grown by the margin on both sides, only the
 *    new ones on the next frame, none within 0.2 ms of now (a late frame looks further ahead).
 *    Edges are checked one-sided (a switch never comes before its time) and 60 ms late at
 *    most: the machine is shared and loaded;
 *  - the difference: lit − unlit per pixel, saturated at 0, only with an unlit frame at most
 *    two frames older, never for mixed frames, not after forgetAmbient() or restart().
 */
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "alternate_strobe_fixtures.h"
#include "firmware/alternate_strobe.h"
#include "hal/camera.h"
#include "hal/clock.h"
#include "hal/sim/recording_strobe.h"
#include "hal/strobe.h"

namespace dockpose::firmware {
namespace {

constexpr std::int64_t kMs = 1000000;
constexpr std::int64_t kPeriod60HzNs = 16666667;
constexpr std::int64_t kPeriod30HzNs = 33333333;
constexpr std::int64_t kMaxIntervalNs = 100 * kMs;
/* AlternateStrobe's documented lead: no pulse starts before now + 0.2 ms. */
constexpr std::int64_t kLeadNs = 200000;
/* How late a switch may come on a loaded machine (pulses of 30 ms, 200 ms apart: no mix-up). */
constexpr std::int64_t kLateNs = 60 * kMs;
/* Any timestamp > 0 will do for the period estimate: it never reads the clock. */
constexpr std::int64_t kT0 = 1000 * kMs;

constexpr int kWidth = 8;
constexpr int kHeight = 6;
/* Test images have padding after each row, to check the stride is honoured. */
constexpr int kStride = 11;

AlternateStrobeConfig periodConfig()
{
	return test::alternateStrobeConfig(kWidth, kHeight, kPeriod60HzNs, kMaxIntervalNs, kMs / 2);
}

hal::Frame timedFrame(std::uint64_t sequence, std::int64_t timestamp_ns,
		      std::int32_t exposure_us = 2000)
{
	hal::Frame frame;
	frame.sequence = sequence;
	frame.timestamp_ns = timestamp_ns;
	frame.exposure_us = exposure_us;
	return frame;
}

/* An 8x6 image with a stride wider than its rows; the padding holds 0xee. */
class StridedImage
{
public:
	StridedImage()
		: bytes_(static_cast<std::size_t>(kStride) * kHeight, 0xee)
	{
		for (int y = 0; y < kHeight; ++y)
			for (int x = 0; x < kWidth; ++x)
				set(x, y, 0);
	}

	void set(int x, int y, int value)
	{
		bytes_[static_cast<std::size_t>(y) * kStride + x] =
			static_cast<std::uint8_t>(value);
	}
	int get(int x, int y) const { return bytes_[static_cast<std::size_t>(y) * kStride + x]; }
	ImageView view() const { return ImageView{ bytes_.data(), kWidth, kHeight, kStride }; }

private:
	std::vector<std::uint8_t> bytes_;
};

hal::Frame imageFrame(std::uint64_t sequence, const StridedImage &image)
{
	hal::Frame frame = timedFrame(sequence, kT0 + static_cast<std::int64_t>(sequence) * kMs);
	frame.image = image.view();
	return frame;
}

/* The estimate after n samples of `interval` from `start`, smoothed by 1/8 each. */
double smoothed(double start, double interval, int n)
{
	return interval + (start - interval) * std::pow(7.0 / 8.0, n);
}

/* A StrobeController that drives a RecordingStrobe; started or not (pulses are accepted
 * either way; only a started one switches the line). */
struct StrobeRig {
	hal::RecordingStrobe strobe;
	hal::StrobeController control{ &strobe, 0 }; /* no dead-man switch */

	bool start() { return strobe.open().isOk() && control.start().isOk(); }

	struct Span {
		std::int64_t on_ns;
		std::int64_t off_ns;
	};
	/* The lit spans the line recorded (a span still on ends at INT64_MAX). */
	std::vector<Span> litSpans() const
	{
		std::vector<Span> spans;
		for (const hal::RecordingStrobe::Event &e : strobe.events()) {
			if (e.on)
				spans.push_back({ e.time_ns, INT64_MAX });
			else if (!spans.empty() && spans.back().off_ns == INT64_MAX)
				spans.back().off_ns = e.time_ns;
		}
		return spans;
	}
};

void sleepUntil(std::int64_t t_ns)
{
	while (hal::monotonicNs() < t_ns)
		std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

/* A recorded span against the pulse [start_ns, end_ns]: never early, at most kLateNs late. */
void expectSpan(const StrobeRig::Span &span, std::int64_t start_ns, std::int64_t end_ns,
		const char *what)
{
	SCOPED_TRACE(what);
	EXPECT_GE(span.on_ns, start_ns);
	EXPECT_LE(span.on_ns, start_ns + kLateNs);
	EXPECT_GE(span.off_ns, end_ns);
	EXPECT_LE(span.off_ns, end_ns + kLateNs);
}

/* Pulse timing: frames 100 ms apart, so pulses two frames apart cannot be confused with
 * kLateNs of slack. */
constexpr std::int64_t kPulsePeriodNs = 100 * kMs;
constexpr std::int64_t kPulseMarginNs = 5 * kMs;
constexpr std::int32_t kPulseExposureUs = 20000;
constexpr std::int64_t kPulseExposureNs = kPulseExposureUs * 1000LL;

AlternateStrobeConfig pulseConfig()
{
	AlternateStrobeConfig config = periodConfig();
	config.period_ns = kPulsePeriodNs;
	config.max_interval_ns = 10 * kPulsePeriodNs;
	config.pulse_margin_ns = kPulseMarginNs;
	return config;
}

/* Where the pulse for the frame k periods after a frame exposed from t_ns must start. */
std::int64_t pulseStart(std::int64_t t_ns, int k)
{
	return t_ns + k * kPulsePeriodNs - kPulseMarginNs;
}
std::int64_t pulseEnd(std::int64_t t_ns, int k)
{
	return pulseStart(t_ns, k) + kPulseExposureNs + 2 * kPulseMarginNs;
}

/* ---------------------------------------------------------------------------------------- */
/* The period estimate */

TEST(AlternateStrobe, PeriodStartsAtTheConfiguredPeriod)
{
	AlternateStrobe alternate(periodConfig());
	EXPECT_EQ(alternate.periodNs(), kPeriod60HzNs);
	/* One frame is no interval yet. */
	alternate.measurePeriod(timedFrame(1, kT0));
	EXPECT_EQ(alternate.periodNs(), kPeriod60HzNs);
}

TEST(AlternateStrobe, ThirtyHzCameraConfiguredAtSixtyTakesTheFirstIntervalThenSmooths)
{
	AlternateStrobe alternate(periodConfig());
	/* A 30 Hz camera whose first interval is 36 ms (one late timestamp), then 33.3 ms. */
	constexpr std::int64_t kFirstNs = 36 * kMs;
	std::int64_t t = kT0;
	alternate.measurePeriod(timedFrame(1, t));
	t += kFirstNs;
	alternate.measurePeriod(timedFrame(2, t));
	EXPECT_EQ(alternate.periodNs(), kFirstNs) << "the first interval replaces the configured";

	for (int n = 1; n <= 40; ++n) {
		t += kPeriod30HzNs;
		alternate.measurePeriod(timedFrame(2 + n, t));
		/* Integer steps truncate by under 1 ns each, so the estimate stays within 8 ns
		 * of the real-valued recursion. */
		EXPECT_NEAR(static_cast<double>(alternate.periodNs()),
			    smoothed(kFirstNs, kPeriod30HzNs, n), 10.0)
			<< "after " << n << " samples of 33.3 ms";
	}
	EXPECT_NEAR(static_cast<double>(alternate.periodNs()), kPeriod30HzNs, 20000.0)
		<< "converged to 33.3 ms within 20 us";
}

TEST(AlternateStrobe, FramesWithoutATimestampAreIgnored)
{
	AlternateStrobe alternate(periodConfig());
	alternate.measurePeriod(timedFrame(1, kT0));
	alternate.measurePeriod(timedFrame(2, 0)); /* no timestamp */
	EXPECT_EQ(alternate.periodNs(), kPeriod60HzNs);
	/* Measured against frame 1, two frames back: had frame 2 become the reference, the
	 * interval would be the whole timestamp, a stall. */
	alternate.measurePeriod(timedFrame(3, kT0 + 2 * kPeriod30HzNs));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);

	AlternateStrobe never_timed(periodConfig());
	for (std::uint64_t s = 1; s <= 5; ++s)
		never_timed.measurePeriod(timedFrame(s, 0));
	EXPECT_EQ(never_timed.periodNs(), kPeriod60HzNs);
}

TEST(AlternateStrobe, AnIntervalAcrossAStallIsNoSample)
{
	AlternateStrobe alternate(periodConfig());
	std::int64_t t = kT0;
	alternate.measurePeriod(timedFrame(1, t));
	t += kPeriod30HzNs;
	alternate.measurePeriod(timedFrame(2, t));
	ASSERT_EQ(alternate.periodNs(), kPeriod30HzNs);

	t += kMaxIntervalNs; /* exactly max_interval_ns: a stall */
	alternate.measurePeriod(timedFrame(3, t));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);
	/* The frames after the stall are samples again, smoothed into the estimate. */
	t += 30 * kMs;
	alternate.measurePeriod(timedFrame(4, t));
	EXPECT_NEAR(static_cast<double>(alternate.periodNs()), smoothed(kPeriod30HzNs, 30 * kMs, 1),
		    1.0);

	/* A stall before any sample: the configured period stays, and the first real interval
	 * (one nanosecond short of a stall) is taken whole. */
	AlternateStrobe stalled_first(periodConfig());
	stalled_first.measurePeriod(timedFrame(1, kT0));
	stalled_first.measurePeriod(timedFrame(2, kT0 + kMaxIntervalNs));
	EXPECT_EQ(stalled_first.periodNs(), kPeriod60HzNs);
	stalled_first.measurePeriod(timedFrame(3, kT0 + 2 * kMaxIntervalNs - 1));
	EXPECT_EQ(stalled_first.periodNs(), kMaxIntervalNs - 1);
}

TEST(AlternateStrobe, ASequenceGapDividesTheInterval)
{
	AlternateStrobe alternate(periodConfig());
	/* Frames 11 to 14 lost: 5 periods between 10 and 15. Together longer than
	 * max_interval_ns (166.7 ms), but one period each, which is what is compared. */
	alternate.measurePeriod(timedFrame(10, kT0));
	alternate.measurePeriod(timedFrame(15, kT0 + 5 * kPeriod30HzNs));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);

	/* A gap whose per-frame interval is a stall is no sample. */
	const std::int64_t t = kT0 + 5 * kPeriod30HzNs;
	alternate.measurePeriod(timedFrame(17, t + 2 * kMaxIntervalNs));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);
	/* And a gap smooths like any sample: 3 frames in 90 ms, 30 ms each. */
	alternate.measurePeriod(timedFrame(20, t + 2 * kMaxIntervalNs + 90 * kMs));
	EXPECT_NEAR(static_cast<double>(alternate.periodNs()), smoothed(kPeriod30HzNs, 30 * kMs, 1),
		    1.0);
}

TEST(AlternateStrobe, ABackwardOrRepeatedSequenceIsNoSample)
{
	AlternateStrobe alternate(periodConfig());
	alternate.measurePeriod(timedFrame(5, kT0));
	alternate.measurePeriod(timedFrame(6, kT0 + kPeriod30HzNs));
	ASSERT_EQ(alternate.periodNs(), kPeriod30HzNs);

	/* The same sequence again, later: no interval (and no division by a gap of 0). */
	alternate.measurePeriod(timedFrame(6, kT0 + kPeriod30HzNs + 10 * kMs));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);
	/* The sequence back (the camera restarted). */
	alternate.measurePeriod(timedFrame(2, kT0 + 2 * kPeriod30HzNs));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);
	/* The sequence forward, the timestamp back. */
	alternate.measurePeriod(timedFrame(3, kT0));
	EXPECT_EQ(alternate.periodNs(), kPeriod30HzNs);

	/* A restarted camera is measured from its own frames on (the last frame is the
	 * reference), not frozen until its sequence passes the old one. */
	alternate.measurePeriod(timedFrame(4, kT0 + 30 * kMs));
	EXPECT_NEAR(static_cast<double>(alternate.periodNs()), smoothed(kPeriod30HzNs, 30 * kMs, 1),
		    1.0);
}

/* ---------------------------------------------------------------------------------------- */
/* The pulse scheduling */

TEST(AlternateStrobe, PulsesAimAtTheNextTwoEvenFramesGrownByTheMargin)
{
	/* From an odd frame the next even frames are 1 and 3 periods on; from an even one, 2
	 * and 4. */
	struct Case {
		std::uint64_t sequence;
		int first_k;
	};
	for (const Case c : { Case{ 1, 1 }, Case{ 2, 2 } }) {
		SCOPED_TRACE(c.sequence);
		StrobeRig rig;
		ASSERT_TRUE(rig.start());
		AlternateStrobe alternate(pulseConfig());

		const std::int64_t now = hal::monotonicNs();
		const std::int64_t t = now - 5 * kMs; /* exposure began 5 ms ago */
		EXPECT_EQ(alternate.schedulePulses(timedFrame(c.sequence, t, kPulseExposureUs), now,
						   rig.control),
			  2);

		const int last_k = c.first_k + 2;
		sleepUntil(pulseEnd(t, last_k) + 2 * kLateNs);
		rig.control.stop();
		const std::vector<StrobeRig::Span> spans = rig.litSpans();
		ASSERT_EQ(spans.size(), 2u);
		expectSpan(spans[0], pulseStart(t, c.first_k), pulseEnd(t, c.first_k), "first");
		expectSpan(spans[1], pulseStart(t, last_k), pulseEnd(t, last_k), "second");
	}
}

TEST(AlternateStrobe, TheNextFrameSchedulesOnlyTheNewPulse)
{
	StrobeRig rig;
	ASSERT_TRUE(rig.start());
	AlternateStrobe alternate(pulseConfig());

	const std::int64_t now = hal::monotonicNs();
	const std::int64_t t = now - 5 * kMs;
	/* Frames 1 to 4 as they come: 1 aims at 2 and 4; 2 adds 6; 3 has 4 and 6 already; 4
	 * adds 8. */
	const int expected[] = { 2, 1, 0, 1 };
	for (int i = 0; i < 4; ++i) {
		const hal::Frame frame = timedFrame(static_cast<std::uint64_t>(i) + 1,
						    t + i * kPulsePeriodNs, kPulseExposureUs);
		EXPECT_EQ(alternate.schedulePulses(frame, hal::monotonicNs(), rig.control),
			  expected[i])
			<< "frame " << frame.sequence;
	}

	sleepUntil(pulseEnd(t, 7) + 2 * kLateNs);
	rig.control.stop();
	/* Frames 2, 4, 6 and 8 lit, once each. */
	const std::vector<StrobeRig::Span> spans = rig.litSpans();
	ASSERT_EQ(spans.size(), 4u);
	for (int i = 0; i < 4; ++i) {
		const int k = 1 + 2 * i;
		SCOPED_TRACE(k + 1);
		expectSpan(spans[static_cast<std::size_t>(i)], pulseStart(t, k), pulseEnd(t, k),
			   "frame");
	}
}

TEST(AlternateStrobe, ALateFrameLooksFurtherAhead)
{
	StrobeRig rig;
	ASSERT_TRUE(rig.start());
	AlternateStrobe alternate(pulseConfig());

	/* Frame 1 arrives 230 ms after its exposure began: frame 2's pulse would have started
	 * 135 ms ago, so frames 4 and 6 are lit. */
	const std::int64_t now = hal::monotonicNs();
	const std::int64_t t = now - 230 * kMs;
	EXPECT_EQ(alternate.schedulePulses(timedFrame(1, t, kPulseExposureUs), now, rig.control),
		  2);

	sleepUntil(pulseEnd(t, 5) + 2 * kLateNs);
	rig.control.stop();
	const std::vector<StrobeRig::Span> spans = rig.litSpans();
	ASSERT_EQ(spans.size(), 2u);
	expectSpan(spans[0], pulseStart(t, 3), pulseEnd(t, 3), "frame 4");
	expectSpan(spans[1], pulseStart(t, 5), pulseEnd(t, 5), "frame 6");
}

TEST(AlternateStrobe, NoPulseStartsWithinTheLeadOfNow)
{
	/* Frame 1 exposed 200 ms ago: frame 2's pulse start (k = 1) is 105 ms in the past for
	 * the controller, which refuses it; frames 4 and 6 are ahead. The now passed in decides
	 * whether frame 2 is a candidate at all: its start exactly now + 0.2 ms is, and the
	 * refusal stops the call (documented: it stops at the first pulse refused); 1 ns
	 * later is not, so frames 4 and 6 get theirs. */
	const std::int64_t t = hal::monotonicNs() - 200 * kMs;
	const hal::Frame frame = timedFrame(1, t, kPulseExposureUs);
	const std::int64_t first_start = pulseStart(t, 1);
	{
		StrobeRig rig;
		AlternateStrobe alternate(pulseConfig());
		EXPECT_EQ(alternate.schedulePulses(frame, first_start - kLeadNs, rig.control), 0)
			<< "frame 2 starting exactly at now + 0.2 ms is aimed at";
	}
	{
		StrobeRig rig;
		AlternateStrobe alternate(pulseConfig());
		EXPECT_EQ(alternate.schedulePulses(frame, first_start - kLeadNs + 1, rig.control),
			  2)
			<< "frame 2 starting 1 ns short of now + 0.2 ms is left out";
	}
}

TEST(AlternateStrobe, NoTimestampNoPulseAndRestartForgetsTheScheduledOnes)
{
	/* Controllers not started: they take pulses in the future all the same (the count is
	 * what is checked here, not the line). */
	StrobeRig rig;
	AlternateStrobe alternate(pulseConfig());
	const std::int64_t now = hal::monotonicNs();
	EXPECT_EQ(alternate.schedulePulses(timedFrame(1, 0, kPulseExposureUs), now, rig.control),
		  0);

	const hal::Frame frame = timedFrame(1, now, kPulseExposureUs);
	EXPECT_EQ(alternate.schedulePulses(frame, now, rig.control), 2);
	EXPECT_EQ(alternate.schedulePulses(frame, now, rig.control), 0) << "2 and 4 are scheduled";
	alternate.restart();
	EXPECT_EQ(alternate.schedulePulses(frame, now, rig.control), 2)
		<< "after restart() no pulse is taken as scheduled";
}

/* ---------------------------------------------------------------------------------------- */
/* The difference */

TEST(AlternateStrobe, UnlitThenLitGivesLitMinusUnlitSaturatedAtZero)
{
	AlternateStrobe alternate(periodConfig());
	StridedImage unlit;
	StridedImage lit;
	for (int y = 0; y < kHeight; ++y) {
		for (int x = 0; x < kWidth; ++x) {
			const int u = 10 + 3 * x + 5 * y;
			unlit.set(x, y, u);
			/* Every third pixel darker when lit (noise): saturates at 0. */
			lit.set(x, y, (x + y) % 3 == 0 ? u - 7 : u + 100 + x);
		}
	}
	unlit.set(0, 1, 0); /* the extremes */
	lit.set(0, 1, 255);
	unlit.set(7, 5, 200);
	lit.set(7, 5, 200);

	EXPECT_FALSE(alternate.difference(imageFrame(1, unlit), hal::Lighting::Unlit).valid());
	/* The unlit frame is copied: its buffer may go back to the camera. */
	StridedImage expected_unlit = unlit;
	for (int y = 0; y < kHeight; ++y)
		for (int x = 0; x < kWidth; ++x)
			unlit.set(x, y, 255);

	const ImageView d = alternate.difference(imageFrame(2, lit), hal::Lighting::Lit);
	ASSERT_TRUE(d.valid());
	ASSERT_EQ(d.width, kWidth);
	ASSERT_EQ(d.height, kHeight);
	for (int y = 0; y < kHeight; ++y) {
		for (int x = 0; x < kWidth; ++x) {
			const int want = std::max(lit.get(x, y) - expected_unlit.get(x, y), 0);
			EXPECT_EQ(d.at(x, y), want) << "at (" << x << ", " << y << ")";
		}
	}
	EXPECT_EQ(d.at(0, 1), 255);
	EXPECT_EQ(d.at(7, 5), 0);
	EXPECT_EQ(d.at(0, 0), 0) << "lit darker than unlit saturates at 0";
}

TEST(AlternateStrobe, ALitFrameWithoutAnAmbientFrameGivesNothing)
{
	AlternateStrobe alternate(periodConfig());
	StridedImage lit;
	lit.set(3, 3, 200);
	EXPECT_FALSE(alternate.difference(imageFrame(2, lit), hal::Lighting::Lit).valid());
	EXPECT_FALSE(alternate.difference(imageFrame(4, lit), hal::Lighting::Lit).valid());
}

TEST(AlternateStrobe, TheAmbientFrameServesTwoFramesAtMost)
{
	AlternateStrobe alternate(periodConfig());
	StridedImage unlit;
	StridedImage lit;
	lit.set(3, 3, 200);
	alternate.difference(imageFrame(10, unlit), hal::Lighting::Unlit);
	EXPECT_TRUE(alternate.difference(imageFrame(11, lit), hal::Lighting::Lit).valid());
	EXPECT_TRUE(alternate.difference(imageFrame(12, lit), hal::Lighting::Lit).valid())
		<< "two frames older";
	EXPECT_FALSE(alternate.difference(imageFrame(13, lit), hal::Lighting::Lit).valid())
		<< "three frames older";
	EXPECT_FALSE(alternate.difference(imageFrame(20, lit), hal::Lighting::Lit).valid());
}

TEST(AlternateStrobe, MixedFramesGiveNothing)
{
	AlternateStrobe alternate(periodConfig());
	StridedImage unlit;
	StridedImage frame;
	frame.set(3, 3, 200);
	EXPECT_FALSE(alternate.difference(imageFrame(1, frame), hal::Lighting::Mixed).valid())
		<< "without an ambient frame";
	alternate.difference(imageFrame(2, unlit), hal::Lighting::Unlit);
	EXPECT_FALSE(alternate.difference(imageFrame(3, frame), hal::Lighting::Mixed).valid())
		<< "with an ambient frame one older";
	/* A mixed frame is not the ambient frame: the unlit frame 2 still serves frame 4. */
	const ImageView d = alternate.difference(imageFrame(4, frame), hal::Lighting::Lit);
	ASSERT_TRUE(d.valid());
	EXPECT_EQ(d.at(3, 3), 200);
}

TEST(AlternateStrobe, ForgetAmbientAndRestartWaitForANewUnlitFrame)
{
	StridedImage unlit;
	StridedImage lit;
	unlit.set(1, 1, 20);
	lit.set(1, 1, 70);

	AlternateStrobe forgetting(periodConfig());
	AlternateStrobe restarting(periodConfig());
	for (AlternateStrobe *alternate : { &forgetting, &restarting }) {
		SCOPED_TRACE(alternate == &forgetting ? "forgetAmbient()" : "restart()");
		alternate->difference(imageFrame(1, unlit), hal::Lighting::Unlit);
		ASSERT_TRUE(alternate->difference(imageFrame(2, lit), hal::Lighting::Lit).valid());
		if (alternate == &forgetting)
			alternate->forgetAmbient();
		else
			alternate->restart();
		EXPECT_FALSE(alternate->difference(imageFrame(3, lit), hal::Lighting::Lit).valid());
		alternate->difference(imageFrame(4, unlit), hal::Lighting::Unlit);
		const ImageView d = alternate->difference(imageFrame(5, lit), hal::Lighting::Lit);
		ASSERT_TRUE(d.valid()) << "a new unlit frame serves again";
		EXPECT_EQ(d.at(1, 1), 50);
	}
}

} /* namespace */
} /* namespace dockpose::firmware */

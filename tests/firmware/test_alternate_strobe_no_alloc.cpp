/* SPDX-License-Identifier: MIT */
/*
 * AlternateStrobe allocates in its constructor only (firmware/alternate_strobe.h): after it,
 * 60 frames at 200 Hz of what the frame thread calls in alternate mode (measurePeriod,
 * schedulePulses on a running hal::StrobeController that drives a hal::RecordingStrobe, and
 * difference, odd frames unlit and even ones lit) make no operator new / malloc in the whole
 * process, the controller's thread included (tests/common/counting_allocator.h).
 */
#include <chrono>
#include <cstdint>
#include <thread>

#include <gtest/gtest.h>

#include "../common/counting_allocator.h"
#include "algo/image.h"
#include "alternate_strobe_fixtures.h"
#include "firmware/alternate_strobe.h"
#include "hal/camera.h"
#include "hal/clock.h"
#include "hal/sim/recording_strobe.h"
#include "hal/strobe.h"

namespace dockpose::firmware {
namespace {

constexpr std::int64_t kMs = 1000000;
constexpr int kWidth = 8;
constexpr int kHeight = 6;
constexpr std::int64_t kPeriodNs = 5 * kMs;
constexpr std::int32_t kExposureUs = 1000;
constexpr int kFrames = 60;

AlternateStrobeConfig config()
{
	return test::alternateStrobeConfig(kWidth, kHeight, kPeriodNs, 20 * kPeriodNs, kMs / 5);
}

TEST(AlternateStrobeNoAlloc, TheConstructorAllocatesAndTheHooksSeeIt)
{
	/* The counter is live: the ambient and the difference frames are two allocations. */
	test::armAllocationCounter();
	{
		const AlternateStrobe alternate(config());
	}
	EXPECT_GE(test::disarmAllocationCounter(), 2);
}

TEST(AlternateStrobeNoAlloc, SixtyFramesAllocateNothing)
{
	hal::RecordingStrobe strobe;
	hal::StrobeController control(&strobe, 0);
	ASSERT_TRUE(strobe.open().isOk());
	ASSERT_TRUE(control.start().isOk());
	AlternateStrobe alternate(config());
	const Image unlit(kWidth, kHeight, 30);
	Image lit(kWidth, kHeight, 30);
	lit.at(4, 3) = 230;

	/* Frames are handed over in real time, 0.5 ms after their exposure ends, so the
	 * controller's pulses run out and its queue never fills. */
	const std::int64_t t0 = hal::monotonicNs() + 10 * kMs;
	int scheduled = 0;
	int differences = 0;
	test::armAllocationCounter();
	for (int i = 0; i < kFrames; ++i) {
		hal::Frame frame;
		frame.sequence = static_cast<std::uint64_t>(i) + 1;
		frame.timestamp_ns = t0 + i * kPeriodNs;
		frame.exposure_us = kExposureUs;
		const bool is_lit = frame.sequence % 2 == 0;
		frame.image = is_lit ? lit.view() : unlit.view();
		const std::int64_t arrival_ns = frame.timestamp_ns + kExposureUs * 1000LL + kMs / 2;
		while (hal::monotonicNs() < arrival_ns)
			std::this_thread::sleep_for(std::chrono::microseconds(200));

		alternate.measurePeriod(frame);
		scheduled += alternate.schedulePulses(frame, hal::monotonicNs(), control);
		const ImageView d = alternate.difference(frame, is_lit ? hal::Lighting::Lit
								       : hal::Lighting::Unlit);
		if (d.valid() && d.at(4, 3) == 200)
			++differences;
	}
	const long allocations = test::disarmAllocationCounter();
	control.stop();

	/* The calls did their work (the frames were real samples, pulses were taken, every lit
	 * frame had the unlit one before it). */
	EXPECT_EQ(alternate.periodNs(), kPeriodNs);
	EXPECT_GE(scheduled, kFrames / 4) << "pulses scheduled";
	EXPECT_EQ(differences, kFrames / 2);
	EXPECT_EQ(allocations, 0) << allocations << " allocations over " << kFrames << " frames";
}

} /* namespace */
} /* namespace dockpose::firmware */

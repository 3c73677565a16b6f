/* SPDX-License-Identifier: MIT */
/*
 * The slow approach that bench_pipeline times and test_pipeline_e2e tracks:
 * the wedge on the 1456x1088 camera coming in from 1200 mm, 10 mm a frame,
 * through a scene that stays put (6 reflections, 2 glints, hot pixels, a
 * gradient: clutter_seed fixed), played back and forth so that a steady
 * track never jumps but twice a cycle reverses. Test-only, header-only.
 * Allocates: as render() does (the caller's Image, when not of the camera's size).
 */
#pragma once

#include <cstddef>
#include <cstdint>

#include "algo/synth/renderer.h"

namespace dockpose::test {

constexpr int kSlowApproachFrames = 32;

/* Frame i (0 .. kSlowApproachFrames - 1) of the approach: its pose, rendered into *out. */
inline Pose renderSlowApproach(const FrameRenderer &renderer, const CameraIntrinsics &camera,
			       const TargetModel &target, int i, Image *out,
			       RenderTruth *truth = nullptr)
{
	RenderOptions o;
	o.reflections = 6;
	o.glints = 2;
	o.hot_pixels = 20;
	o.noise_sigma = 2.0;
	o.gradient = 20.0;
	o.clutter_seed = 77; /* the scene stays where it is; the target moves */
	const Pose pose = poseAt(camera, target, 1200.0 - 10.0 * i,
				 { 8.0 - 0.2 * i, -10.0 + 0.3 * i, 5.0 }, 0.45 + 0.002 * i, 0.5);
	renderer.render(pose, o, 1000 + static_cast<std::uint64_t>(i), out, truth);
	return pose;
}

/* The approach's frame shown at step i, back and forth: 0 .. 31, 31 .. 0, 0 .. */
inline std::size_t backAndForth(std::size_t i)
{
	constexpr auto n = static_cast<std::size_t>(kSlowApproachFrames);
	const std::size_t k = i % (2 * n);
	return k < n ? k : 2 * n - 1 - k;
}

} /* namespace dockpose::test */

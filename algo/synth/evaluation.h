/* SPDX-License-Identifier: MIT */
/*
 * Accuracy evaluation on rendered frames with known truth: the loop behind
 * the end-to-end tests and the `dockpose-accuracy` tool, so both measure the
 * same thing.
 *
 * A pose is correct when its rotation is within 2° of the truth and its
 * translation within max(5 mm, 2% of range); a pose reported as found that is
 * not correct is a wrong pose (worse than none).
 *
 * Allocates: the renderer's frame once; per-frame results go to the callback.
 */
#pragma once

#include <cstdint>
#include <functional>

#include "algo/pipeline.h"
#include "algo/synth/renderer.h"

namespace dockpose {

struct EvaluationConfig {
	int frames = 100;
	std::uint64_t seed = 1;
	double min_range_mm = 150.0;
	double max_range_mm = 2100.0;
	double max_angle_deg = 30.0; /* roll, pan, tilt uniform in ±this */
	bool clutter = true;	     /* up to 8 reflections, 2 glints, 30 hot pixels, one LED hidden half the time */
	bool track = false;	     /* keep tracking between frames (else each frame is solved cold) */
	double max_rot_err_deg = 2.0;
	double min_trans_err_mm = 5.0;
	double trans_err_frac = 0.02;
	/* A frame is solvable when it shows this many LEDs (the full search needs five). */
	int min_visible_leds = 5;
};

struct FrameOutcome {
	int index = 0;
	double range_mm = 0.0;
	Pose truth;
	RenderTruth render;
	const PoseResult *result = nullptr;
	double rot_err_deg = 0.0;
	double trans_err_mm = 0.0;
	bool correct = false;
};

struct EvaluationTally {
	int frames = 0, found = 0, correct = 0, wrong = 0;
	/* Frames that show at least min_visible_leds LEDs, and the correct poses among them. */
	int solvable = 0, solvable_correct = 0;
	double worst_rot_err_deg = 0.0;	  /* over correct poses */
	double worst_trans_err_frac = 0.0; /* over correct poses, of range */
};

EvaluationTally evaluate(const TargetModel &target, const CameraIntrinsics &camera, const PipelineConfig &pipeline_config,
			 const EvaluationConfig &config,
			 const std::function<void(const FrameOutcome &, const Image &)> &on_frame = {});

} /* namespace dockpose */

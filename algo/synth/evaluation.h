/* SPDX-License-Identifier: MIT */
/*
 * Accuracy evaluation on rendered frames with known truth: the loop behind
 * the end-to-end tests and the `dockpose-accuracy` tool, so both measure the
 * same thing.
 *
 * A pose is correct when its rotation is within 2° of the truth and its
 * translation within max(5 mm, 2% of range); a pose reported as found that is
 * not correct is a wrong pose (worse than none). On a target-free frame every
 * pose found is wrong.
 *
 * Scenarios: Legacy is the historical evaluation (the `clutter` flag: up to 8
 * reflections, 2 glints, 30 hot pixels and one LED hidden half the time, or
 * none of it), unchanged frame for frame. The others (see scenarioName() and
 * evaluation.cpp for their parameters) each add one hard effect to light
 * clutter; Combined stacks several; Mix draws one of them per frame. A frame
 * is face-complete when at least one face has all four LEDs drawn (facing the
 * camera, not occluded, not washed out, inside the frame): the frames on
 * which a cold search must find the pose.
 *
 * Poses: by default the legacy approach (roll, pan, tilt in ±max_angle_deg,
 * the target near the frame's centre); with any_side, the camera looks at a
 * random face from inside its emission cone (sampleSideView), from any
 * direction, with any roll, the target anywhere in the frame.
 *
 * Allocates: the renderer's frame once; per-frame results go to the callback.
 */
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>

#include "algo/pipeline.h"
#include "algo/synth/renderer.h"

namespace dockpose {

enum class Scenario : std::uint8_t {
	Legacy = 0, /* the historical frames, `clutter` on or off */
	Clean, /* noise and a gradient only */
	Cluttered, /* Legacy's clutter: up to 8 reflections, 2 glints, 30 hot pixels, 1 LED hidden half the time */
	HeavyClutter, /* 12-30 LED-like reflections (a share near the target, elliptic), 2-6 glints */
	Bloom, /* overexposed, saturated LEDs with a halo 2-3x their size */
	Blur, /* linear motion blur, 3-12 px, random direction */
	Dim, /* one or two LEDs at 25-40% brightness */
	Sunlit, /* 1-3 sunlit patches (may saturate, may cover the target), strong gradients */
	OneFace, /* every LED not on one complete face hidden */
	TwoHidden, /* two LEDs hidden */
	TargetFree, /* clutter of every kind, no target */
	Combined, /* heavy clutter with several of the effects above at once */
	Scrambled, /* the target's LEDs displaced by 15-60 % of its size, light clutter: no true pose */
	Mix, /* one of the scenarios above (not Legacy, not Scrambled) drawn per frame */
};

/* Scenarios that frames are rendered in (Legacy .. Scrambled; Mix only draws them). */
inline constexpr int kScenarioCount = static_cast<int>(Scenario::Mix);
/* PoseStatus values tallied (statuses beyond are counted in the last). */
inline constexpr int kStatusSlots = 16;

const char *scenarioName(Scenario scenario);
/* Every scenario's name, in order, joined by ", " (for help texts). Allocates: the string. */
std::string scenarioNames();
/* Parse a scenario name (as scenarioName() writes it); false when unknown. */
bool parseScenario(const std::string &name, Scenario *scenario);

struct EvaluationConfig {
	int frames = 100;
	std::uint64_t seed = 1;
	/*
	 * Frames first_frame .. first_frame + frames - 1 of the seed's sequence:
	 * one frame of a long run (its CSV's `frame`) solved again alone. The
	 * legacy frames share one random stream, so theirs are drawn, not solved.
	 */
	int first_frame = 0;
	double min_range_mm = 150.0;
	double max_range_mm = 2100.0;
	double max_angle_deg = 30.0; /* roll, pan, tilt uniform in ±this */
	bool clutter =
		true; /* Legacy: up to 8 reflections, 2 glints, 30 hot pixels, one LED hidden half the time */
	bool track = false; /* keep tracking between frames (else each frame is solved cold) */
	double max_rot_err_deg = 2.0;
	double min_trans_err_mm = 5.0;
	double trans_err_frac = 0.02;
	/* A frame is solvable when it shows this many LEDs (the full search needs five). */
	int min_visible_leds = 5;

	Scenario scenario = Scenario::Legacy;
	/* Mix: the weight of target-free frames (every other scenario weighs 1). */
	double mix_target_free_weight = 1.5;
	/* Look at a random face from inside its emission cone, up to side_max_angle_deg off its normal. */
	bool any_side = false;
	double side_max_angle_deg = 60.0;
	/* Faster approximate read noise in the new scenarios (RenderOptions::fast_noise); Legacy keeps its own. */
	bool fast_noise = true;
	/*
	 * New scenarios and any-side poses: a pose equal to the truth composed
	 * with a rigid symmetry of the LED set is correct (it shows the same
	 * image; the wedge has one, a half turn about z). Legacy frames compare
	 * with the truth alone, as they always did.
	 */
	bool modulo_symmetry = true;
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
	Scenario scenario = Scenario::Legacy;
	bool face_complete = false; /* some face has its four LEDs drawn */
	bool target_free = false; /* no target drawn, or a scrambled one: any pose found is wrong */
	bool wrong = false; /* a pose found that is not correct */
	/* The any-side view (face -1 with the legacy poses) and whether the target fitted in the frame. */
	int view_face = -1;
	double view_angle_deg = 0.0;
	bool in_frame = true;
	/* The symmetry the errors are measured against (0: the truth itself). */
	int symmetry = 0;
};

/* One scenario's counts. */
struct ScenarioTally {
	int frames = 0, target_free = 0, face_complete = 0;
	int found = 0, correct = 0, wrong = 0;
	int face_complete_correct = 0;
	/* Face-complete frames without a correct pose: no pose, by PoseStatus (index), or a wrong one. */
	std::array<int, kStatusSlots> misses{};
	int face_complete_wrong = 0;
	/* Wrong poses on target-free frames (part of wrong). */
	int target_free_wrong = 0;
};

struct EvaluationTally {
	int frames = 0, found = 0, correct = 0, wrong = 0;
	/* Frames that show at least min_visible_leds LEDs, and the correct poses among them. */
	int solvable = 0, solvable_correct = 0;
	double worst_rot_err_deg = 0.0; /* over correct poses */
	double worst_trans_err_frac = 0.0; /* over correct poses, of range */
	/* Face-complete frames and the correct poses among them; target-free frames. */
	int face_complete = 0, face_complete_correct = 0, target_free = 0;
	/* Per scenario (index: Scenario), and the sum over all. */
	std::array<ScenarioTally, kScenarioCount> scenarios{};
	ScenarioTally total;
};

/* Add b's counts to a (for several evaluate() runs). */
void accumulate(ScenarioTally *a, const ScenarioTally &b);

EvaluationTally
evaluate(const TargetModel &target, const CameraIntrinsics &camera,
	 const PipelineConfig &pipeline_config, const EvaluationConfig &config,
	 const std::function<void(const FrameOutcome &, const Image &)> &on_frame = {});

/*
 * The render options of one frame of `scenario` (not Legacy nor Mix),
 * deterministic for a seed: what evaluate() renders, for tests and tools that
 * want the same frames.
 */
RenderOptions scenarioOptions(Scenario scenario, std::uint64_t seed);

} /* namespace dockpose */

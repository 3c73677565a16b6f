/* SPDX-License-Identifier: MIT */
/*
 * The false-alarm bound, measured (issue 8, item 1: "prove the bound"). The
 * acceptance rule (algo/correspondence.h) accepts a pose when its number of
 * false alarms, NFA, is at most 10^max_log10_nfa: the expected number of
 * chance matches that good in a frame of that clutter. On frames where no
 * true pose exists, any pose accepted is a false alarm, so over N such
 * frames the count must stay below N x 10^max_log10_nfa (give or take
 * Poisson noise): a bound that held only on paper would show here.
 *
 * Frames (algo/synth/evaluation.h): target-free (0-30 LED-like reflections,
 * near where the target would be too, glints, hot pixels, sunlit patches,
 * bloom, blur) and scrambled targets (the target's LEDs drawn displaced by
 * 15-60 % of its size: LEDs at the right scale and brightness in no rigid
 * arrangement of the model), cold searches, for the wedge and the box corner
 * on the 512 px camera and the asymmetric pyramid seen from any side.
 *
 * At the default bound (10^-4) the test needs >= 2000 target-free frames and
 * expects 0 false poses (the bound allows 0.2 + noise). At looser bounds
 * (10^-1, 10^-2) false alarms become observable, so the bound itself is
 * tested, not only its consequence: the measured rate must not exceed it.
 */
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <tuple>

#include <gtest/gtest.h>

#include "algo/io/model_json.h"
#include "algo/pipeline.h"
#include "algo/pose.h"
#include "algo/synth/evaluation.h"
#include "tests/algo/fixtures.h"

namespace dockpose {
namespace {

struct Count {
	int frames = 0;
	int false_poses = 0;
};

Count falsePoses(const char *target_file, const char *camera_file, Scenario scenario, int frames,
		 double max_log10_nfa, bool any_side, std::uint64_t seed)
{
	const auto target = loadTargetModel(test::dataPath(target_file));
	const auto camera = loadCameraIntrinsics(test::dataPath(camera_file));
	EXPECT_TRUE(target.isOk() && camera.isOk()) << target_file << ", " << camera_file;
	Count run;
	if (!target.isOk() || !camera.isOk())
		return run;
	PipelineConfig pipeline;
	pipeline.correspondence.max_log10_nfa = max_log10_nfa; /* the early exit follows */
	EvaluationConfig e;
	e.scenario = scenario;
	e.frames = frames;
	e.seed = seed;
	e.any_side = any_side;
	e.fast_noise = true;
	const EvaluationTally t = evaluate(target.value(), camera.value(), pipeline, e);
	const ScenarioTally &st = t.scenarios[static_cast<int>(scenario)];
	EXPECT_EQ(st.frames, frames);
	EXPECT_EQ(st.target_free, frames) << "every frame is without a true pose";
	run.frames = st.frames;
	run.false_poses = st.target_free_wrong;
	return run;
}

/* The most false poses N frames may show at bound 10^b: its mean plus four Poisson sigmas, plus one. */
int allowed(int frames, double max_log10_nfa)
{
	const double mean = frames * std::pow(10.0, max_log10_nfa);
	return static_cast<int>(std::floor(mean + 4.0 * std::sqrt(mean) + 1.0));
}

void report(const char *what, const Count &run, double max_log10_nfa)
{
	std::printf(
		"[ false-alarm ] %s: %d false poses in %d frames at NFA <= 1e%.0f (the bound's mean: %.3g)\n",
		what, run.false_poses, run.frames, max_log10_nfa,
		run.frames * std::pow(10.0, max_log10_nfa));
}

TEST(FalseAlarmBound, NoPoseOnTwoThousandTargetFreeFrames)
{
	Count total;
	for (const auto &[target, camera, frames, any_side] :
	     { std::tuple{ "wedge.json", "cam512.json", 1000, false },
	       std::tuple{ "corner.json", "cam512.json", 600, false },
	       std::tuple{ "pyramid.json", "cam512.json", 400, true } }) {
		const Count run = falsePoses(target, camera, Scenario::TargetFree, frames, -4.0,
					     any_side, 11);
		report(target, run, -4.0);
		total.frames += run.frames;
		total.false_poses += run.false_poses;
	}
	EXPECT_GE(total.frames, 2000);
	/* 2000 frames x 1e-4: 0.2 expected. A wrong pose is worse than none: none is the only pass. */
	EXPECT_EQ(total.false_poses, 0);
}

TEST(FalseAlarmBound, NoPoseOnScrambledTargets)
{
	Count total;
	for (const auto &[target, frames, any_side] :
	     { std::tuple{ "wedge.json", 300, false }, std::tuple{ "corner.json", 300, false },
	       std::tuple{ "roof.json", 200, true } }) {
		const Count run = falsePoses(target, "cam512.json", Scenario::Scrambled, frames,
					     -4.0, any_side, 12);
		report(target, run, -4.0);
		total.frames += run.frames;
		total.false_poses += run.false_poses;
	}
	EXPECT_EQ(total.false_poses, 0);
}

TEST(FalseAlarmBound, LooserBoundsAdmitNoMoreThanTheyPromise)
{
	for (double b : { -1.0, -2.0 }) {
		for (Scenario scenario : { Scenario::TargetFree, Scenario::Scrambled }) {
			const int frames = 400;
			const Count run = falsePoses("wedge.json", "cam512.json", scenario, frames,
						     b, false, 13);
			report(scenarioName(scenario), run, b);
			EXPECT_LE(run.false_poses, allowed(frames, b))
				<< scenarioName(scenario) << " at NFA <= 1e" << b;
		}
	}
}

/*
 * Structural rivals: wrong poses the false-alarm bound cannot refuse (they
 * are no chance alignments but near-congruent copies of the target), refused
 * or outrun by the search. Single frames of the 20 000-frame runs
 * (docs/accuracy.md), found where a rule was missing.
 */
struct OneFrame {
	bool found = false, correct = false, wrong = false;
	PoseStatus status = PoseStatus::NoFrame;
};

/*
 * Frame `frame` of evaluate()'s sequence for `e` (its scenario and seed),
 * solved alone with `pipeline`: its outcome to `visit`, once.
 */
void solveFrame(const char *target_file, const char *camera_file, const PipelineConfig &pipeline,
		EvaluationConfig e, int frame,
		const std::function<void(const FrameOutcome &)> &visit)
{
	const auto target = loadTargetModel(test::dataPath(target_file));
	const auto camera = loadCameraIntrinsics(test::dataPath(camera_file));
	ASSERT_TRUE(target.isOk() && camera.isOk()) << target_file << ", " << camera_file;
	e.first_frame = frame;
	e.frames = 1;
	const EvaluationTally t = evaluate(target.value(), camera.value(), pipeline, e,
					   [&](const FrameOutcome &o, const Image &) {
						   EXPECT_EQ(o.index, frame);
						   visit(o);
					   });
	EXPECT_EQ(t.frames, 1);
}

OneFrame solveOneFrame(const char *target_file, int frame, std::uint64_t seed, double max_log10_nfa)
{
	PipelineConfig pipeline;
	pipeline.correspondence.max_log10_nfa = max_log10_nfa;
	EvaluationConfig e;
	e.scenario = Scenario::Mix;
	e.any_side = true;
	e.seed = seed;
	OneFrame one;
	solveFrame(target_file, "cam512.json", pipeline, e, frame, [&](const FrameOutcome &o) {
		one.found = o.result->found;
		one.status = o.result->status;
		one.correct = o.correct;
		one.wrong = o.wrong;
	});
	return one;
}

/*
 * Single frames of the 20 000-frame runs (docs/accuracy.md: `--frames 5000
 * --scenario mix --any-side --seed 2026`, cam512) that a rule of the search
 * turned from no pose (or a wrong one) into the true pose, at the default
 * bound; each case fails without its rule.
 */
struct SolvedFrame {
	const char *rule;
	const char *target;
	int frame;
};
const SolvedFrame kSolvedFrames[] = {
	/*
	 * A far box corner (1.42 m, 6 spots, nothing else in the frame): five of
	 * the six fit a wrong pose as their covariance predicts (log10 NFA -8.3),
	 * two hypotheses before the true pose explains all six. An early exit
	 * there returned the wrong pose (beside a six-LED copy that fits only
	 * within the px floor); the exit now waits while a candidate near the
	 * target is left unexplained.
	 */
	{ "TheEarlyExitWaitsForACandidateLeftNearTheTarget", "corner.json", 4123 },
	/*
	 * A box corner at 378 mm, five spots, nothing else in the frame: a wrong
	 * pose explained all five with one LED seen at 89 degrees from its face's
	 * normal (edge-on, where it makes no spot), at log10 NFA -11.4 against the
	 * true pose's -11.0, and the frame was ambiguous. An LED may now be
	 * matched only where the pose predicts it visible (max_view_angle_deg).
	 */
	{ "AnLedSeenEdgeOnExplainsNoSpot", "corner.json", 1450 },
	/*
	 * The other side of the rule below: a box corner at 488 mm, six spots, the
	 * true pose on all six (log10 NFA -14.4) within the px floor (0.05 px) at
	 * chi2 33, just past its 99.9 % point (22.7), beside a four-LED pose that
	 * fits its covariance (chi2 1.5, log10 NFA -4.0) and leaves two of the
	 * spots unexplained. The frame was ambiguous; a fewer-LED rival now counts
	 * only against a pose whose error is beyond twice what its covariance
	 * predicts.
	 */
	{ "ATruePoseJustPastItsChiSquareBoundKeepsItsExtraLeds", "corner.json", 1928 },
	/*
	 * A five-face pyramid at 242 mm among 20 reflections: the budget counted a
	 * quadrilateral's four assignments that see a face from behind
	 * (quadShape()'s sign rule refuses them at once), spent its 20 000 on them
	 * as well and stopped before the true face (error_too_large). They are no
	 * hypotheses now.
	 */
	{ "AssignmentsThatSeeAFaceFromBehindAreNoHypotheses", "pyramid.json", 250 },
	/*
	 * One face of the pyramid alone, 507 mm away, nothing else in the frame:
	 * log10 NFA -4.26 with the tests counted as the search forms them (4
	 * assignments of a quadrilateral to each face), -3.96 when the 4 it never
	 * forms were counted too, and the frame gave no pose.
	 */
	{ "TheBoundCountsOnlyTheHypothesesTheSearchForms", "pyramid.json", 833 },
	/*
	 * The pyramid at 318 mm, six LEDs among 32 reflections (35 candidates):
	 * three LEDs of one face clip, its fourth and the top face's other two
	 * do not (peaks 70-135 against reflections of 150-255), and no LED has
	 * three of a face's others among its nine nearest candidates, so no
	 * quadrilateral is the target's and the budget ran out (error_too_large).
	 * The clipped spots' triangle puts the other three LEDs on their spots
	 * (log10 NFA -10.8).
	 */
	{ "ClippedTrianglesReachAFaceTheNeighboursMiss", "pyramid.json", 13 },
};

class SolvedFrames : public ::testing::TestWithParam<SolvedFrame>
{
};

TEST_P(SolvedFrames, TheTruePoseIsFound)
{
	const SolvedFrame &s = GetParam();
	const OneFrame one = solveOneFrame(s.target, s.frame, 2026, -4.0);
	EXPECT_TRUE(one.correct) << s.rule;
	EXPECT_FALSE(one.wrong) << s.rule;
}

INSTANTIATE_TEST_SUITE_P(OneFrame, SolvedFrames, ::testing::ValuesIn(kSolvedFrames),
			 [](const ::testing::TestParamInfo<SolvedFrame> &param_info) {
				 return std::string(param_info.param.rule);
			 });

/*
 * The rule the case above bounds: the box corner half-turned in a combined-scenario frame: six LEDs within
 * the px floor (0.21 px) but not as their covariance predicts, while a pose
 * on fewer LEDs fits it. At the bound 10^-2 (log10 NFA -3.0) the half-turned
 * copy was reported; a rival that fits the covariance now counts although it
 * explains fewer LEDs, and the frame is ambiguous.
 */
TEST(StructuralRivals, AFitWithinThePxFloorYieldsToOneThatFitsTheCovariance)
{
	const OneFrame one = solveOneFrame("corner.json", 61, 7, -2.0);
	EXPECT_FALSE(one.wrong);
	EXPECT_EQ(one.status, PoseStatus::Ambiguous);
}

/*
 * The early exit in heavy clutter (the benchmark's frames: the wedge on the
 * 1456 px camera, 19-33 candidates, seed 43). A pose on every LED of the model
 * stops the search whatever lies near it (no competitor can explain more);
 * one on five of six with reflections near the target narrows the rest of
 * the search to the candidates there. Either way the pose is the one the
 * search without an early exit reports, for a fraction of its hypotheses.
 */
struct ExitFrame {
	const char *rule;
	int frame;
};
const ExitFrame kExitFrames[] = {
	{ "APoseOnEveryLedStops", 4 },
	{ "ACandidateLeftNearTheTargetNarrowsTheSearch", 6 },
};

struct Solved {
	bool correct = false;
	Pose pose;
	int hypotheses = 0;
};

Solved solveHeavyClutter(int frame, double early_exit_log10_nfa)
{
	PipelineConfig pipeline;
	pipeline.correspondence.early_exit_log10_nfa = early_exit_log10_nfa;
	EvaluationConfig e;
	e.scenario = Scenario::HeavyClutter;
	e.seed = 43;
	Solved s;
	solveFrame("wedge.json", "cam1456.json", pipeline, e, frame, [&](const FrameOutcome &o) {
		s.correct = o.correct;
		s.pose.R = o.result->R;
		s.pose.t_mm = o.result->t_mm;
		s.hypotheses = o.result->hypotheses;
	});
	return s;
}

class EarlyExit : public ::testing::TestWithParam<ExitFrame>
{
};

TEST_P(EarlyExit, FindsTheExhaustiveSearchsPoseSooner)
{
	const ExitFrame &x = GetParam();
	const Solved exhaustive = solveHeavyClutter(x.frame, -1e9);
	const Solved early =
		solveHeavyClutter(x.frame, CorrespondenceConfig{}.early_exit_log10_nfa);
	ASSERT_TRUE(exhaustive.correct) << x.rule;
	EXPECT_TRUE(early.correct) << x.rule;
	EXPECT_LT((early.pose.t_mm - exhaustive.pose.t_mm).norm(), 1e-6) << x.rule;
	EXPECT_LT((early.pose.R - exhaustive.pose.R).norm(), 1e-9) << x.rule;
	/* Without its rule either frame's search runs on to about the exhaustive count. */
	EXPECT_LT(2 * early.hypotheses, exhaustive.hypotheses) << x.rule;
	std::printf("[ early exit ] %s: %d hypotheses, %d without the early exit\n", x.rule,
		    early.hypotheses, exhaustive.hypotheses);
}

INSTANTIATE_TEST_SUITE_P(HeavyClutter, EarlyExit, ::testing::ValuesIn(kExitFrames),
			 [](const ::testing::TestParamInfo<ExitFrame> &param_info) {
				 return std::string(param_info.param.rule);
			 });

/*
 * The strongest candidates' quadrilaterals first
 * (CorrespondenceConfig::strongest_first): the same hypotheses in another
 * order, so every frame ends as the anchor-by-anchor search alone ends it
 * (the same status; the same pose, up to the refinement's convergence from
 * another start), and frames whose LEDs are among the strongest spots end
 * sooner. The benchmark's heavy-clutter frames (the wedge on the 1456 px
 * camera, seed 43): in three of the 36 the search formed 931, 907 and 1227
 * hypotheses before, 3, 3 and 49 with the prefix.
 */
TEST(StrongestFirst, TheSameOutcomesForFewerHypotheses)
{
	const auto target = loadTargetModel(test::dataPath("wedge.json"));
	const auto camera = loadCameraIntrinsics(test::dataPath("cam1456.json"));
	ASSERT_TRUE(target.isOk() && camera.isOk());
	PipelineConfig plain;
	plain.correspondence.strongest_first = 0;
	ASSERT_GT(PipelineConfig{}.correspondence.strongest_first, 4);
	Pipeline anchors_only(target.value(), camera.value(), plain);
	EvaluationConfig e;
	e.scenario = Scenario::HeavyClutter;
	e.seed = 43;
	e.frames = 36;
	int found = 0, sooner = 0, later = 0;
	long hypotheses = 0, hypotheses_plain = 0;
	evaluate(target.value(), camera.value(), PipelineConfig{}, e,
		 [&](const FrameOutcome &o, const Image &img) {
			 anchors_only.reset();
			 const PoseResult &p = anchors_only.process(img.view());
			 const PoseResult &r = *o.result;
			 EXPECT_EQ(r.status, p.status) << "frame " << o.index;
			 if (r.found && p.found) {
				 ++found;
				 EXPECT_LT((r.t_mm - p.t_mm).norm(), 1e-3) << "frame " << o.index;
				 EXPECT_LT(rotationAngleDeg(r.R, p.R), 1e-4) << "frame " << o.index;
				 EXPECT_EQ(r.led_mask, p.led_mask) << "frame " << o.index;
			 }
			 hypotheses += r.hypotheses;
			 hypotheses_plain += p.hypotheses;
			 sooner += r.hypotheses < p.hypotheses;
			 later += r.hypotheses > p.hypotheses;
		 });
	EXPECT_GT(found, 20);
	EXPECT_LT(hypotheses, hypotheses_plain);
	EXPECT_GT(sooner, later);
	std::printf("[ strongest first ] %d frames with a pose; %ld hypotheses in all against %ld; "
		    "%d frames sooner, %d later\n",
		    found, hypotheses, hypotheses_plain, sooner, later);
}

} /* namespace */
} /* namespace dockpose */

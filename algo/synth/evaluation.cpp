/* SPDX-License-Identifier: MIT */
#include "algo/synth/evaluation.h"

#include <algorithm>
#include <cmath>
#include <random>

namespace dockpose {

EvaluationTally evaluate(const TargetModel &target, const CameraIntrinsics &camera, const PipelineConfig &pipeline_config,
			 const EvaluationConfig &config,
			 const std::function<void(const FrameOutcome &, const Image &)> &on_frame)
{
	FrameRenderer renderer(target, camera);
	Pipeline pipeline(target, camera, pipeline_config);
	std::mt19937_64 rng(config.seed);
	std::uniform_real_distribution<double> unit(0.0, 1.0);
	auto symmetric = [&](double a) { return a * (2.0 * unit(rng) - 1.0); };
	Image frame;
	EvaluationTally tally;
	for (int i = 0; i < config.frames; ++i) {
		/* Log-uniform range; the target anywhere it fits, nearer the centre when close. */
		const double range =
			config.min_range_mm * std::pow(config.max_range_mm / config.min_range_mm, unit(rng));
		const Eigen::Vector3d rpy{ symmetric(config.max_angle_deg), symmetric(config.max_angle_deg),
					   symmetric(config.max_angle_deg) };
		const double spread = std::min(0.3, 0.3 * range / config.max_range_mm + 0.05);
		FrameOutcome out;
		out.index = i;
		out.range_mm = range;
		out.truth = poseAt(camera, target, range, rpy, 0.5 + symmetric(spread), 0.5 + symmetric(spread));

		RenderOptions o;
		o.noise_sigma = 1.0 + 2.0 * unit(rng);
		o.gradient = 30.0 * unit(rng);
		if (config.clutter) {
			o.reflections = static_cast<int>(9 * unit(rng));
			o.glints = static_cast<int>(3 * unit(rng));
			o.hot_pixels = static_cast<int>(30 * unit(rng));
			o.occluded_leds = unit(rng) < 0.5 ? 1 : 0;
		}
		renderer.render(out.truth, o, config.seed * 1000003u + static_cast<std::uint64_t>(i), &frame,
				&out.render);
		if (!config.track)
			pipeline.reset();
		const PoseResult &r = pipeline.process(frame.view());
		out.result = &r;
		++tally.frames;
		const bool solvable = __builtin_popcount(out.render.visible_mask) >= config.min_visible_leds;
		tally.solvable += solvable ? 1 : 0;
		if (r.found) {
			++tally.found;
			out.rot_err_deg = rotationAngleDeg(out.truth.R, r.R);
			out.trans_err_mm = (out.truth.t_mm - r.t_mm).norm();
			out.correct = out.rot_err_deg <= config.max_rot_err_deg &&
				      out.trans_err_mm <= std::max(config.min_trans_err_mm,
								   config.trans_err_frac * out.truth.t_mm.norm());
			if (out.correct) {
				++tally.correct;
				tally.solvable_correct += solvable ? 1 : 0;
				tally.worst_rot_err_deg = std::max(tally.worst_rot_err_deg, out.rot_err_deg);
				tally.worst_trans_err_frac =
					std::max(tally.worst_trans_err_frac, out.trans_err_mm / out.truth.t_mm.norm());
			} else {
				++tally.wrong;
			}
		}
		if (on_frame)
			on_frame(out, frame);
	}
	return tally;
}

} /* namespace dockpose */

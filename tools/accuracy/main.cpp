/* SPDX-License-Identifier: MIT */
/*
 * dockpose-accuracy: the acceptance figures. Renders thousands of frames with
 * known truth (clutter, a hidden LED), solves each one cold (or tracking),
 * and prints found / correct / wrong rates and error statistics per range
 * bin; --csv writes one line per frame for plotting (scripts/plot-accuracy).
 */
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <vector>

#include <CLI/CLI.hpp>

#include "algo/io/model_json.h"
#include "algo/synth/evaluation.h"

using namespace dockpose;

int main(int argc, char **argv)
{
	CLI::App app{ "dockpose-accuracy: pose accuracy and robustness on rendered frames with known truth" };
	std::string target_path, camera_path, csv_path;
	EvaluationConfig e;
	e.frames = 1000;
	bool clean = false;
	app.add_option("--target", target_path, "target model JSON")->required();
	app.add_option("--camera", camera_path, "camera JSON")->required();
	app.add_option("--frames", e.frames, "frames to render and solve")->check(CLI::Range(1, 10000000));
	app.add_option("--seed", e.seed, "random seed");
	app.add_option("--min-range-mm", e.min_range_mm, "nearest range")->check(CLI::PositiveNumber);
	app.add_option("--max-range-mm", e.max_range_mm, "farthest range")->check(CLI::PositiveNumber);
	app.add_option("--max-angle-deg", e.max_angle_deg, "roll, pan, tilt drawn in ±this")->check(CLI::Range(0.0, 80.0));
	app.add_flag("--clean", clean, "no clutter and no occlusion");
	app.add_flag("--track", e.track, "track between frames instead of solving each frame cold");
	app.add_option("--csv", csv_path, "write one line per frame");
	CLI11_PARSE(app, argc, argv);
	e.clutter = !clean;

	const auto target = loadTargetModel(target_path);
	if (!target) {
		std::fprintf(stderr, "dockpose-accuracy: %s\n", target.error.c_str());
		return 2;
	}
	const auto camera = loadCameraIntrinsics(camera_path);
	if (!camera) {
		std::fprintf(stderr, "dockpose-accuracy: %s\n", camera.error.c_str());
		return 2;
	}

	std::ofstream csv;
	if (!csv_path.empty()) {
		csv.open(csv_path);
		if (!csv) {
			std::fprintf(stderr, "dockpose-accuracy: cannot write %s\n", csv_path.c_str());
			return 2;
		}
		csv << "frame,range_mm,found,correct,status,leds,visible,rms_px,rot_err_deg,trans_err_mm,"
		       "ex_mm,ey_mm,ez_mm,sigma_x_mm,sigma_y_mm,sigma_z_mm,clutter\n";
	}

	/* Per range bin (log-spaced): errors of found poses. */
	struct Bin {
		int frames = 0, found = 0, wrong = 0;
		std::vector<double> rot, trans, z;
	};
	std::map<int, Bin> bins;
	const double bin_ratio = std::pow(e.max_range_mm / e.min_range_mm, 1.0 / 6.0);
	auto binOf = [&](double range) {
		return std::clamp(static_cast<int>(std::log(range / e.min_range_mm) / std::log(bin_ratio)), 0, 5);
	};

	const EvaluationTally t = evaluate(target.value, camera.value, PipelineConfig{}, e,
					   [&](const FrameOutcome &f, const Image &) {
						   Bin &b = bins[binOf(f.range_mm)];
						   ++b.frames;
						   const PoseResult &r = *f.result;
						   if (r.found) {
							   ++b.found;
							   b.wrong += f.correct ? 0 : 1;
							   b.rot.push_back(f.rot_err_deg);
							   b.trans.push_back(f.trans_err_mm);
							   b.z.push_back(std::abs(f.truth.t_mm.z() - r.t_mm.z()));
						   }
						   if (csv.is_open()) {
							   const Eigen::Vector3d d = r.t_mm - f.truth.t_mm;
							   csv << f.index << ',' << f.range_mm << ',' << r.found << ','
							       << f.correct << ',' << poseStatusName(r.status) << ','
							       << r.leds_used << ','
							       << __builtin_popcount(f.render.visible_mask) << ','
							       << r.rms_px << ',' << f.rot_err_deg << ',' << f.trans_err_mm
							       << ',' << d.x() << ',' << d.y() << ',' << d.z() << ','
							       << r.sigma_t_mm.x() << ',' << r.sigma_t_mm.y() << ','
							       << r.sigma_t_mm.z() << ',' << f.render.clutter_blobs << '\n';
						   }
					   });

	auto median = [](std::vector<double> v) {
		if (v.empty())
			return 0.0;
		std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
		return v[v.size() / 2];
	};
	auto maxOf = [](const std::vector<double> &v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); };

	std::printf("target %s, camera %dx%d, %d frames, %s, %s\n", target.value.name.c_str(), camera.value.width,
		    camera.value.height, t.frames, e.clutter ? "clutter + occlusion" : "clean",
		    e.track ? "tracking" : "each frame cold");
	std::printf("%-17s %7s %7s %6s %12s %12s %12s %12s\n", "range mm", "frames", "found%", "wrong",
		    "rot med °", "rot max °", "|t| med mm", "|z| med mm");
	for (const auto &[index, b] : bins) {
		const double lo = e.min_range_mm * std::pow(bin_ratio, index);
		std::printf("%7.0f - %7.0f %7d %6.1f%% %6d %12.3f %12.3f %12.2f %12.2f\n", lo, lo * bin_ratio, b.frames,
			    100.0 * b.found / std::max(1, b.frames), b.wrong, median(b.rot), maxOf(b.rot),
			    median(b.trans), median(b.z));
	}
	std::printf("correct %d of %d (%.2f%%), found %d, wrong %d; worst correct: %.2f°, %.2f%% of range\n", t.correct,
		    t.frames, 100.0 * t.correct / std::max(1, t.frames), t.found, t.wrong, t.worst_rot_err_deg,
		    100.0 * t.worst_trans_err_frac);
	return t.wrong == 0 ? 0 : 1;
}

/* SPDX-License-Identifier: MIT */
/*
 * dockpose-accuracy: the acceptance figures. Renders thousands of frames with
 * known truth, solves each one cold (or tracking), and prints found / correct
 * / wrong rates and error statistics per range bin, then per scenario: frames,
 * face-complete frames (some face with all four LEDs drawn) and the correct
 * poses among them, wrong poses (on target-free frames every pose is wrong)
 * and the misses by pipeline status. --scenario picks the scenes (legacy: the
 * historical clutter and a hidden LED, or --clean; mix: one scenario drawn
 * per frame), --any-side the poses (any face, from inside its emission
 * cone); --csv writes one line per frame for plotting (scripts/plot-accuracy),
 * --json a summary. Exit status 1 when any pose was wrong.
 */
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "algo/io/model_json.h"
#include "algo/synth/evaluation.h"

using namespace dockpose;

namespace {

std::vector<std::string> splitList(const std::string &text)
{
	std::vector<std::string> out;
	std::stringstream ss(text);
	std::string item;
	while (std::getline(ss, item, ','))
		if (!item.empty())
			out.push_back(item);
	return out;
}

double percent(int a, int b)
{
	return b > 0 ? 100.0 * a / b : 0.0;
}

/* "no_match 3, ambiguous 1" (misses of face-complete frames), or "-". */
std::string missText(const ScenarioTally &t)
{
	std::string s;
	for (int k = 0; k < kStatusSlots; ++k) {
		if (t.misses[k] == 0)
			continue;
		if (!s.empty())
			s += ", ";
		s += poseStatusName(static_cast<PoseStatus>(k));
		s += ' ';
		s += std::to_string(t.misses[k]);
	}
	return s.empty() ? "-" : s;
}

void jsonTally(std::ostream &os, const ScenarioTally &t)
{
	os << "{ \"frames\": " << t.frames << ", \"face_complete\": " << t.face_complete
	   << ", \"face_complete_correct\": " << t.face_complete_correct
	   << ", \"face_complete_correct_percent\": "
	   << percent(t.face_complete_correct, t.face_complete) << ", \"found\": " << t.found
	   << ", \"correct\": " << t.correct << ", \"wrong\": " << t.wrong
	   << ", \"target_free\": " << t.target_free
	   << ", \"target_free_wrong\": " << t.target_free_wrong
	   << ", \"face_complete_wrong\": " << t.face_complete_wrong << ", \"misses\": {";
	bool first = true;
	for (int k = 0; k < kStatusSlots; ++k) {
		if (t.misses[k] == 0)
			continue;
		os << (first ? " " : ", ") << '"' << poseStatusName(static_cast<PoseStatus>(k))
		   << "\": " << t.misses[k];
		first = false;
	}
	os << (first ? "}" : " }") << " }";
}

/* What the command line asks for. */
struct ToolOptions {
	std::string target_path, camera_path, csv_path, json_path, scenario_list = "legacy";
	EvaluationConfig eval;
};

/*
 * Parse the command line into *o. Returns the exit status when the tool ends
 * here (--help, a bad option), else nothing.
 */
std::optional<int> parseOptions(int argc, char **argv, ToolOptions *o)
{
	CLI::App app{
		"dockpose-accuracy: pose accuracy and robustness on rendered frames with known truth"
	};
	EvaluationConfig &e = o->eval;
	e.frames = 1000;
	bool clean = false, exact_noise = false;
	app.add_option("--target", o->target_path, "target model JSON")->required();
	app.add_option("--camera", o->camera_path, "camera JSON")->required();
	app.add_option("--frames", e.frames, "frames to render and solve (per scenario listed)")
		->check(CLI::Range(1, 10000000));
	app.add_option("--seed", e.seed, "random seed (the k-th scenario listed uses seed + k)");
	app.add_option(
		   "--first-frame", e.first_frame,
		   "start at this frame of the seed's sequence (a CSV's `frame`: solve it again alone)")
		->check(CLI::Range(0, 10000000));
	app.add_option("--min-range-mm", e.min_range_mm, "nearest range")
		->check(CLI::PositiveNumber);
	app.add_option("--max-range-mm", e.max_range_mm, "farthest range")
		->check(CLI::PositiveNumber);
	app.add_option("--max-angle-deg", e.max_angle_deg, "roll, pan, tilt drawn in ±this")
		->check(CLI::Range(0.0, 80.0));
	app.add_flag("--clean", clean, "legacy scenario: no clutter and no occlusion");
	app.add_flag("--track", e.track, "track between frames instead of solving each frame cold");
	app.add_option(
		"--scenario", o->scenario_list,
		"comma-separated scenarios, each run for --frames frames: " + scenarioNames() +
			" (mix: one of the others but legacy and scrambled drawn per frame)");
	app.add_flag(
		"--any-side", e.any_side,
		"look at a random face from inside its emission cone, any roll, the target anywhere "
		"in the frame (range: to that face's centre)");
	app.add_option(
		   "--side-max-angle-deg", e.side_max_angle_deg,
		   "with --any-side: largest angle between the line of sight and the face's normal")
		->check(CLI::Range(0.0, 89.0));
	app.add_option("--target-free-weight", e.mix_target_free_weight,
		       "mix: weight of target-free frames (others weigh 1)")
		->check(CLI::Range(0.0, 100.0));
	app.add_flag(
		"--exact-noise", exact_noise,
		"new scenarios: the renderer's exact Gaussian read noise (slower) instead of the fast one");
	app.add_option("--csv", o->csv_path, "write one line per frame");
	app.add_option("--json", o->json_path, "write a summary (per scenario and totals) as JSON");
	CLI11_PARSE(app, argc, argv);
	e.clutter = !clean;
	e.fast_noise = !exact_noise;
	return std::nullopt;
}

/* Parse the comma-separated scenario list into *scenarios; false (with a message) if bad. */
bool parseScenarios(const std::string &list, std::vector<Scenario> *scenarios)
{
	for (const std::string &name : splitList(list)) {
		Scenario s;
		if (!parseScenario(name, &s)) {
			std::fprintf(stderr, "dockpose-accuracy: unknown scenario '%s'\n",
				     name.c_str());
			return false;
		}
		scenarios->push_back(s);
	}
	if (scenarios->empty()) {
		std::fprintf(stderr, "dockpose-accuracy: --scenario names no scenario\n");
		return false;
	}
	return true;
}

/* Open the per-frame CSV and write its header; false (with a message) if it cannot be written. */
bool openCsv(const std::string &path, std::ofstream *csv)
{
	csv->open(path);
	if (!*csv) {
		std::fprintf(stderr, "dockpose-accuracy: cannot write %s\n", path.c_str());
		return false;
	}
	*csv << "frame,range_mm,found,correct,status,leds,visible,rms_px,rot_err_deg,trans_err_mm,"
		"ex_mm,ey_mm,ez_mm,sigma_x_mm,sigma_y_mm,sigma_z_mm,clutter,"
		"scenario,face_complete,target_free,wrong,view_face,view_angle_deg,in_frame,"
		"log10_nfa\n";
	return true;
}

/* One range bin (log-spaced): errors of found poses on frames with the target. */
struct RangeBin {
	int frames = 0, found = 0, wrong = 0;
	std::vector<double> rot, trans, z;
};

/* What the report gathers frame by frame. */
struct FrameStats {
	/* Six log-spaced range bins from min_range_mm, each bin_ratio wide. */
	double min_range_mm = 0.0, bin_ratio = 1.0;
	std::map<int, RangeBin> bins;
	/*
	 * Face-complete frames by the LEDs drawn: [n] = { frames, correct }. Four
	 * is one face alone (no other LED to tell it from chance or from a
	 * congruent face); more are what the search has beyond one face.
	 */
	std::map<int, std::array<int, 2>> by_drawn;
};

/* The range bin of a range. */
int binOf(const FrameStats &stats, double range)
{
	return std::clamp(
		static_cast<int>(std::log(range / stats.min_range_mm) / std::log(stats.bin_ratio)),
		0, 5);
}

/* Write one frame's line of the CSV. */
void writeCsvLine(std::ostream &csv, const FrameOutcome &f)
{
	const PoseResult &r = *f.result;
	const Eigen::Vector3d d = r.t_mm - f.truth.t_mm;
	csv << f.index << ',' << f.range_mm << ',' << r.found << ',' << f.correct << ','
	    << poseStatusName(r.status) << ',' << r.leds_used << ','
	    << __builtin_popcount(f.render.visible_mask) << ',' << r.rms_px << ',' << f.rot_err_deg
	    << ',' << f.trans_err_mm << ',' << d.x() << ',' << d.y() << ',' << d.z() << ','
	    << r.sigma_t_mm.x() << ',' << r.sigma_t_mm.y() << ',' << r.sigma_t_mm.z() << ','
	    << f.render.clutter_blobs << ',' << scenarioName(f.scenario) << ',' << f.face_complete
	    << ',' << f.target_free << ',' << f.wrong << ',' << f.view_face << ','
	    << f.view_angle_deg << ',' << f.in_frame << ',' << r.log10_nfa << '\n';
}

/* Count one frame into *stats, and write its CSV line when the CSV is open. */
void recordFrame(const FrameOutcome &f, FrameStats *stats, std::ofstream *csv)
{
	const PoseResult &r = *f.result;
	if (f.face_complete) {
		auto &c = stats->by_drawn[__builtin_popcount(f.render.visible_mask)];
		++c[0];
		c[1] += f.correct ? 1 : 0;
	}
	if (!f.target_free) {
		RangeBin &b = stats->bins[binOf(*stats, f.range_mm)];
		++b.frames;
		if (r.found) {
			++b.found;
			b.wrong += f.correct ? 0 : 1;
			b.rot.push_back(f.rot_err_deg);
			b.trans.push_back(f.trans_err_mm);
			b.z.push_back(std::abs(f.truth.t_mm.z() - r.t_mm.z()));
		}
	}
	if (csv->is_open())
		writeCsvLine(*csv, f);
}

/*
 * Evaluate every scenario listed (the k-th with seed + k), calling on_frame on
 * each frame; returns the totals and sums the per-scenario counts into *per.
 */
EvaluationTally
runScenarios(const TargetModel &target, const CameraIntrinsics &camera, const EvaluationConfig &e,
	     const std::vector<Scenario> &scenarios,
	     const std::function<void(const FrameOutcome &, const Image &)> &on_frame,
	     std::array<ScenarioTally, kScenarioCount> *per)
{
	EvaluationTally t;
	for (std::size_t k = 0; k < scenarios.size(); ++k) {
		EvaluationConfig ek = e;
		ek.scenario = scenarios[k];
		ek.seed = e.seed + k;
		const EvaluationTally tk = evaluate(target, camera, PipelineConfig{}, ek, on_frame);
		t.frames += tk.frames;
		t.found += tk.found;
		t.correct += tk.correct;
		t.wrong += tk.wrong;
		t.solvable += tk.solvable;
		t.solvable_correct += tk.solvable_correct;
		t.worst_rot_err_deg = std::max(t.worst_rot_err_deg, tk.worst_rot_err_deg);
		t.worst_trans_err_frac = std::max(t.worst_trans_err_frac, tk.worst_trans_err_frac);
		for (int s = 0; s < kScenarioCount; ++s)
			accumulate(&(*per)[s], tk.scenarios[s]);
		accumulate(&t.total, tk.total);
	}
	return t;
}

/* The median of v (0 when empty). */
double median(std::vector<double> v)
{
	if (v.empty())
		return 0.0;
	std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
	return v[v.size() / 2];
}

/* The largest of v (0 when empty). */
double maxOf(const std::vector<double> &v)
{
	return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
}

/* Print the report's first line: target, camera, frames, scenarios, poses, solving. */
void printHeading(const TargetModel &target, const CameraIntrinsics &camera, int frames,
		  const EvaluationConfig &e, const std::vector<Scenario> &scenarios)
{
	std::string what;
	for (Scenario s : scenarios) {
		if (!what.empty())
			what += ",";
		what += s == Scenario::Legacy ? (e.clutter ? "clutter + occlusion" : "clean")
					      : scenarioName(s);
	}
	std::printf("target %s, camera %dx%d, %d frames, %s, %s, %s\n", target.name.c_str(),
		    camera.width, camera.height, frames, what.c_str(),
		    e.any_side ? "any side" : "legacy poses",
		    e.track ? "tracking" : "each frame cold");
}

/* Print the table of range bins. */
void printRangeBins(const FrameStats &stats, const EvaluationConfig &e)
{
	std::printf("%-17s %7s %7s %6s %12s %12s %12s %12s\n", "range mm", "frames", "found%",
		    "wrong", "rot med °", "rot max °", "|t| med mm", "|z| med mm");
	for (const auto &[index, b] : stats.bins) {
		const double lo = e.min_range_mm * std::pow(stats.bin_ratio, index);
		std::printf("%7.0f - %7.0f %7d %6.1f%% %6d %12.3f %12.3f %12.2f %12.2f\n", lo,
			    lo * stats.bin_ratio, b.frames, 100.0 * b.found / std::max(1, b.frames),
			    b.wrong, median(b.rot), maxOf(b.rot), median(b.trans), median(b.z));
	}
}

/* Print one row of the scenario table. */
void printScenarioRow(const char *name, const ScenarioTally &s)
{
	char free_text[32];
	std::snprintf(free_text, sizeof(free_text), "%d/%d", s.target_free, s.target_free_wrong);
	std::string misses = missText(s);
	if (s.face_complete_wrong > 0)
		misses += ", wrong " + std::to_string(s.face_complete_wrong);
	std::printf("%-14s %7d %9d %9d %7.2f%% %6d %11s  %s\n", name, s.frames, s.face_complete,
		    s.face_complete_correct, percent(s.face_complete_correct, s.face_complete),
		    s.wrong, free_text, misses.c_str());
}

/* Print the scenario table (the scenarios run, then the total) and the totals' lines. */
void printScenarios(const std::array<ScenarioTally, kScenarioCount> &per, const EvaluationTally &t,
		    double seconds)
{
	std::printf("\n%-14s %7s %9s %9s %8s %6s %11s  %s\n", "scenario", "frames", "complete",
		    "correct", "correct%", "wrong", "free/wrong", "misses of face-complete frames");
	for (int s = 0; s < kScenarioCount; ++s)
		if (per[s].frames > 0)
			printScenarioRow(scenarioName(static_cast<Scenario>(s)), per[s]);
	printScenarioRow("total", t.total);
	std::printf(
		"correct %d of %d (%.2f%%), found %d, wrong %d; worst correct: %.2f°, %.2f%% of range\n",
		t.correct, t.frames, 100.0 * t.correct / std::max(1, t.frames), t.found, t.wrong,
		t.worst_rot_err_deg, 100.0 * t.worst_trans_err_frac);
	std::printf("face-complete frames correct: %d of %d (%.2f%%); %.1f s, %.1f frames/s\n",
		    t.total.face_complete_correct, t.total.face_complete,
		    percent(t.total.face_complete_correct, t.total.face_complete), seconds,
		    t.frames / std::max(1e-9, seconds));
}

/* Print the face-complete frames' success by the number of LEDs drawn. */
void printByDrawn(const FrameStats &stats)
{
	std::string drawn_text;
	for (const auto &[leds, c] : stats.by_drawn) {
		char item[80];
		std::snprintf(item, sizeof(item), "%s%d LEDs %d/%d (%.1f%%)",
			      drawn_text.empty() ? "" : ", ", leds, c[1], c[0],
			      percent(c[1], c[0]));
		drawn_text += item;
	}
	std::printf("face-complete frames correct, by LEDs drawn: %s\n", drawn_text.c_str());
}

/* Write the JSON summary; false (with a message) if it cannot be written. */
bool writeJson(const std::string &path, const TargetModel &target, const CameraIntrinsics &camera,
	       const EvaluationConfig &e, double seconds, const EvaluationTally &t,
	       const std::array<ScenarioTally, kScenarioCount> &per)
{
	std::ofstream js(path);
	if (!js) {
		std::fprintf(stderr, "dockpose-accuracy: cannot write %s\n", path.c_str());
		return false;
	}
	js << "{\n  \"target\": \"" << target.name << R"(", "camera": ")" << camera.width << "x"
	   << camera.height << R"(", "seed": )" << e.seed
	   << ", \"frames_per_scenario\": " << e.frames << ", \"min_range_mm\": " << e.min_range_mm
	   << ", \"max_range_mm\": " << e.max_range_mm
	   << ", \"any_side\": " << (e.any_side ? "true" : "false")
	   << ", \"side_max_angle_deg\": " << e.side_max_angle_deg
	   << ", \"track\": " << (e.track ? "true" : "false") << ", \"seconds\": " << seconds
	   << ",\n  \"worst_correct_rot_err_deg\": " << t.worst_rot_err_deg
	   << ", \"worst_correct_trans_err_frac\": " << t.worst_trans_err_frac
	   << ",\n  \"scenarios\": {";
	bool first = true;
	for (int s = 0; s < kScenarioCount; ++s) {
		if (per[s].frames == 0)
			continue;
		js << (first ? "\n    \"" : ",\n    \"") << scenarioName(static_cast<Scenario>(s))
		   << "\": ";
		jsonTally(js, per[s]);
		first = false;
	}
	js << "\n  },\n  \"total\": ";
	jsonTally(js, t.total);
	js << "\n}\n";
	return true;
}

/* The tool itself; main() turns an unexpected exception into a message and exit 2. */
int run(int argc, char **argv)
{
	ToolOptions o;
	if (const std::optional<int> status = parseOptions(argc, argv, &o))
		return *status;
	const EvaluationConfig &e = o.eval;

	std::vector<Scenario> scenarios;
	if (!parseScenarios(o.scenario_list, &scenarios))
		return 2;

	const auto target = loadTargetModel(o.target_path);
	if (!target) {
		std::fprintf(stderr, "dockpose-accuracy: %s\n", target.message().c_str());
		return 2;
	}
	const auto camera = loadCameraIntrinsics(o.camera_path);
	if (!camera) {
		std::fprintf(stderr, "dockpose-accuracy: %s\n", camera.message().c_str());
		return 2;
	}

	std::ofstream csv;
	if (!o.csv_path.empty() && !openCsv(o.csv_path, &csv))
		return 2;

	FrameStats stats;
	stats.min_range_mm = e.min_range_mm;
	stats.bin_ratio = std::pow(e.max_range_mm / e.min_range_mm, 1.0 / 6.0);
	auto on_frame = [&](const FrameOutcome &f, const Image &) {
		recordFrame(f, &stats, &csv);
	};

	const auto start = std::chrono::steady_clock::now();
	std::array<ScenarioTally, kScenarioCount> per{};
	const EvaluationTally t =
		runScenarios(target.value(), camera.value(), e, scenarios, on_frame, &per);
	const double seconds =
		std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

	printHeading(target.value(), camera.value(), t.frames, e, scenarios);
	printRangeBins(stats, e);
	printScenarios(per, t, seconds);
	printByDrawn(stats);

	if (!o.json_path.empty() &&
	    !writeJson(o.json_path, target.value(), camera.value(), e, seconds, t, per))
		return 2;
	return t.wrong == 0 ? 0 : 1;
}

} /* namespace */

int main(int argc, char **argv)
{
	try {
		return run(argc, argv);
	} catch (const std::exception &e) {
		std::fprintf(stderr, "dockpose-accuracy: %s\n", e.what());
		return 2;
	}
}

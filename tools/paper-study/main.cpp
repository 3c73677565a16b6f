/* SPDX-License-Identifier: MIT */
/*
 * dockpose-paper-study: the paper's relative-move study (method.md §7) on rendered frames.
 *
 *   dockpose-paper-study grid --camera TRUE.json --dir DIR [--views N] [--seed S]
 *	frames of a dot grid through the true camera (algo/synth/dot_grid.h) and the grid
 *	file, for `dockpose calibrate --grid DIR/grid.json DIR/view-*.pgm`;
 *   dockpose-paper-study run --target T.json --camera TRUE.json --solve-camera CAL.json
 *			  --csv OUT.csv [--readings N] [--distances LIST] ...
 *	the target aligned with the camera at each distance, moved by 5 and 15 mm along x, y,
 *	z and by 5, 10, 20 degrees in roll, pan, tilt; every reading renders a fresh frame
 *	(fresh read noise) of the start pose and one of the moved pose, solves both cold with
 *	the Pipeline and the solve camera, and takes the difference of the two poses as the
 *	measured move. The frames are rendered with the true camera and the LEDs displaced
 *	from the nominal model (a built target's tolerance, fixed for the run), the solver
 *	uses the nominal model. One CSV line per set: mean, min, max, std of the measured
 *	move, the mean error in % of the move, and the absolute z error of the start poses.
 *
 * Moves are symmetric about the aligned pose (start -m/2, end +m/2), so the target stays as
 * near the frame's centre as it can. Angles are dockpose's (roll, pan, tilt) with
 * R = Rx(roll) Ry(pan) Rz(tilt) (algo/pose.h). The wedge's half turn about its z axis shows
 * the same image: each solved pose is taken modulo the target's symmetries, the one nearest
 * the truth (a physical reading of a symmetric target cannot tell them apart).
 *
 * Exit status: 0 done, 1 a file could not be read or written, 2 a bad command line.
 */
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>

#include "algo/io/model_json.h"
#include "algo/io/pgm.h"
#include "algo/pipeline.h"
#include "algo/synth/dot_grid.h"
#include "algo/synth/renderer.h"
#include "algo/synth/rng.h"

using namespace dockpose;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct GridArgs {
	std::string camera_path, dir;
	int views = 15;
	std::uint64_t seed = 1;
	double noise_sigma = 2.0;
};

struct RunArgs {
	std::string target_path, camera_path, solve_camera_path, csv_path;
	int readings = 100;
	std::string distances = "150,300,400,600,900,1200,1500,1800,2100";
	std::uint64_t seed = 1;
	double noise_sigma = 2.0;
	double led_sigma_mm = 0.1;
	/* The optics' blur (Gaussian sigma, px): RenderOptions' default unless given. */
	double blur_sigma_px = RenderOptions{}.blur_sigma_px;
};

/* One set's axis: translations index t_mm, rotations (roll, pan, tilt). */
struct Axis {
	const char *name;
	bool rotation;
	int index;
	std::vector<double> moves;
};

std::vector<double> parseList(const std::string &text, bool *ok)
{
	std::vector<double> out;
	std::stringstream ss(text);
	std::string item;
	*ok = true;
	while (std::getline(ss, item, ',')) {
		if (item.empty())
			continue;
		char *end = nullptr;
		const double v = std::strtod(item.c_str(), &end);
		if (end == item.c_str() || *end != '\0' || !(v > 0.0))
			*ok = false;
		out.push_back(v);
	}
	*ok = *ok && !out.empty();
	return out;
}

int runGrid(const GridArgs &a)
{
	const Result<CameraIntrinsics> k = loadCameraIntrinsics(a.camera_path);
	if (!k.isOk()) {
		std::fprintf(stderr, "dockpose-paper-study: %s\n", k.message().c_str());
		return 1;
	}
	const CameraModel camera(k.value());
	const DotGrid grid;
	std::filesystem::create_directories(a.dir);
	std::ofstream(a.dir + "/grid.json") << grid.json();
	synth::Rng rng(a.seed);
	for (int n = 0; n < a.views; ++n) {
		Pose pose;
		if (!dotGridView(camera, grid, n, &rng, &pose)) {
			std::fprintf(stderr,
				     "dockpose-paper-study: view %d: the grid does not fit\n", n);
			return 1;
		}
		const std::string path = a.dir + "/view-" + std::to_string(n) + ".pgm";
		const Image image = renderDotGrid(camera, grid, pose, a.noise_sigma,
						  a.seed * 1000 + static_cast<std::uint64_t>(n));
		const Status written = writePgm(path, image.view());
		if (!written.isOk()) {
			std::fprintf(stderr, "dockpose-paper-study: %s\n",
				     written.message().c_str());
			return 1;
		}
	}
	std::printf("%d views of a %dx%d grid (%.0f mm pitch, %.1f mm dots, noise %.1f) in %s\n",
		    a.views, grid.rows, grid.cols, grid.spacing_mm, 2.0 * grid.dot_radius_mm,
		    a.noise_sigma, a.dir.c_str());
	return 0;
}

/* The proper rotations about the target's origin that map its LEDs onto themselves. */
std::vector<Eigen::Matrix3d> symmetries(const TargetModel &target)
{
	std::vector<Eigen::Matrix3d> out{ Eigen::Matrix3d::Identity() };
	for (int axis = 0; axis < 3; ++axis) {
		const Eigen::Matrix3d s =
			Eigen::AngleAxisd(kPi, Eigen::Vector3d::Unit(axis)).toRotationMatrix();
		bool maps = true;
		for (const Eigen::Vector3d &p : target.points_mm) {
			double nearest_mm = std::numeric_limits<double>::infinity();
			for (const Eigen::Vector3d &q : target.points_mm)
				nearest_mm = std::min(nearest_mm, (s * p - q).norm());
			maps = maps && nearest_mm < 0.5;
		}
		if (maps)
			out.push_back(s);
	}
	return out;
}

/* The solved rotation modulo the symmetries, nearest the truth. */
Eigen::Matrix3d nearestRotation(const Eigen::Matrix3d &solved, const Eigen::Matrix3d &truth,
				const std::vector<Eigen::Matrix3d> &syms)
{
	Eigen::Matrix3d best = solved;
	double best_deg = rotationAngleDeg(solved, truth);
	for (const Eigen::Matrix3d &s : syms) {
		const double deg = rotationAngleDeg(solved * s, truth);
		if (deg < best_deg) {
			best_deg = deg;
			best = solved * s;
		}
	}
	return best;
}

void printCamera(const char *label, const CameraIntrinsics &k)
{
	std::printf("%s: fx %.3f fy %.3f cx %.3f cy %.3f k1 %.5f k2 %.5f p1 %.6f p2 %.6f\n", label,
		    k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.p1, k.p2);
}

int runStudy(const RunArgs &a)
{
	bool ok = false;
	const std::vector<double> distances = parseList(a.distances, &ok);
	if (!ok) {
		std::fprintf(stderr, "dockpose-paper-study: --distances: positive numbers, "
				     "comma-separated\n");
		return 2;
	}
	const Result<TargetModel> target = loadTargetModel(a.target_path);
	const Result<CameraIntrinsics> truth_k = loadCameraIntrinsics(a.camera_path);
	const Result<CameraIntrinsics> solve_k = loadCameraIntrinsics(a.solve_camera_path);
	for (const std::string &m : { target.isOk() ? std::string() : target.message(),
				      truth_k.isOk() ? std::string() : truth_k.message(),
				      solve_k.isOk() ? std::string() : solve_k.message() })
		if (!m.empty()) {
			std::fprintf(stderr, "dockpose-paper-study: %s\n", m.c_str());
			return 1;
		}
	std::ofstream csv(a.csv_path);
	if (!csv) {
		std::fprintf(stderr, "dockpose-paper-study: cannot write %s\n", a.csv_path.c_str());
		return 1;
	}

	/* The built target: every LED displaced by a Gaussian of led_sigma_mm per coordinate. */
	const TargetModel &nominal = target.value();
	TargetModel built = nominal;
	synth::Rng led_rng(a.seed * 7919u + 17u);
	double worst_mm = 0.0;
	for (Eigen::Vector3d &p : built.points_mm) {
		const Eigen::Vector3d d(led_rng.normal(), led_rng.normal(), led_rng.normal());
		p += a.led_sigma_mm * d;
		worst_mm = std::max(worst_mm, a.led_sigma_mm * d.norm());
	}
	printCamera("true camera (rendering)", truth_k.value());
	printCamera("solve camera", solve_k.value());
	std::printf("LEDs displaced by sigma %.3f mm per coordinate (largest %.3f mm), "
		    "read noise %.2f levels (Gaussian), blur sigma %.2f px, %d readings per set\n",
		    a.led_sigma_mm, worst_mm, a.noise_sigma, a.blur_sigma_px, a.readings);

	const FrameRenderer renderer(built, truth_k.value());
	PipelineConfig config;
	config.tracking = false;
	Pipeline pipeline(nominal, solve_k.value(), config);
	const std::vector<Eigen::Matrix3d> syms = symmetries(nominal);
	RenderOptions options;
	options.noise_sigma = a.noise_sigma;
	options.blur_sigma_px = a.blur_sigma_px;
	const std::vector<Axis> axes = {
		{ "x", false, 0, { 5.0, 15.0 } },	 { "y", false, 1, { 5.0, 15.0 } },
		{ "z", false, 2, { 5.0, 15.0 } },	 { "roll", true, 0, { 5.0, 10.0, 20.0 } },
		{ "pan", true, 1, { 5.0, 10.0, 20.0 } }, { "tilt", true, 2, { 5.0, 10.0, 20.0 } },
	};

	csv << "distance_mm,axis,unit,move,readings,valid,mean,min,max,std,mean_error_percent,"
	       "z_true_mm,z_abs_error_mean_mm,z_abs_error_percent\n";
	std::printf("%8s %5s %6s %5s %10s %10s %10s %8s %8s\n", "dist_mm", "axis", "move", "valid",
		    "mean", "min", "max", "std", "err_%");
	const auto started = std::chrono::steady_clock::now();
	Image frame;
	std::uint64_t frame_seed = a.seed * 1000003u;
	long frames = 0;
	for (const double d_mm : distances) {
		for (const Axis &axis : axes) {
			for (const double move : axis.moves) {
				Pose start, end;
				if (axis.rotation) {
					Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
					rpy[axis.index] = 0.5 * move;
					start = poseAt(truth_k.value(), nominal, d_mm, -rpy);
					end = poseAt(truth_k.value(), nominal, d_mm, rpy);
				} else {
					start = end = poseAt(truth_k.value(), nominal, d_mm,
							     Eigen::Vector3d::Zero());
					start.t_mm[axis.index] -= 0.5 * move;
					end.t_mm[axis.index] += 0.5 * move;
				}
				std::vector<double> measured;
				double z_err_sum_mm = 0.0;
				for (int r = 0; r < a.readings; ++r) {
					Pose solved[2];
					bool found = true;
					for (int k = 0; k < 2; ++k) {
						const Pose &t = k == 0 ? start : end;
						renderer.render(t, options, ++frame_seed, &frame);
						++frames;
						pipeline.reset();
						const PoseResult &res =
							pipeline.process(frame.view());
						found = found && res.found;
						solved[k].R = nearestRotation(res.R, t.R, syms);
						solved[k].t_mm = res.t_mm;
					}
					if (!found)
						continue;
					z_err_sum_mm += solved[0].t_mm.z() - start.t_mm.z();
					if (axis.rotation)
						measured.push_back(
							rollPanTiltDegFromRotation(
								solved[1].R)[axis.index] -
							rollPanTiltDegFromRotation(
								solved[0].R)[axis.index]);
					else
						measured.push_back(solved[1].t_mm[axis.index] -
								   solved[0].t_mm[axis.index]);
				}
				const int n = static_cast<int>(measured.size());
				double mean = 0.0, lo = 0.0, hi = 0.0, var = 0.0;
				if (n > 0) {
					for (const double m : measured)
						mean += m / n;
					lo = *std::min_element(measured.begin(), measured.end());
					hi = *std::max_element(measured.begin(), measured.end());
					for (const double m : measured)
						var += (m - mean) * (m - mean) / std::max(1, n - 1);
				}
				const double err_pct = 100.0 * (mean - move) / move;
				const double z_err_mm = n > 0 ? z_err_sum_mm / n : 0.0;
				char line[320];
				std::snprintf(
					line, sizeof(line),
					"%.0f,%s,%s,%g,%d,%d,%.5f,%.5f,%.5f,%.5f,%.3f,%.3f,%.4f,%.4f\n",
					d_mm, axis.name, axis.rotation ? "deg" : "mm", move,
					a.readings, n, mean, lo, hi, std::sqrt(var), err_pct,
					start.t_mm.z(), z_err_mm,
					100.0 * z_err_mm / start.t_mm.z());
				csv << line;
				std::printf("%8.0f %5s %6g %5d %10.4f %10.4f %10.4f %8.4f %8.2f\n",
					    d_mm, axis.name, move, n, mean, lo, hi, std::sqrt(var),
					    err_pct);
				std::fflush(stdout);
			}
		}
	}
	const double seconds =
		std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
	std::printf("%ld frames rendered and solved in %.1f s\n", frames, seconds);
	if (!csv.flush()) {
		std::fprintf(stderr, "dockpose-paper-study: cannot write %s\n", a.csv_path.c_str());
		return 1;
	}
	return 0;
}

int mainChecked(int argc, char **argv)
{
	CLI::App app{ "dockpose-paper-study: the paper's relative-move study on rendered frames" };
	app.require_subcommand(1);
	GridArgs g;
	CLI::App *grid =
		app.add_subcommand("grid", "render dot-grid frames for dockpose calibrate");
	grid->add_option("--camera", g.camera_path, "true camera JSON")->required();
	grid->add_option("--dir", g.dir, "output folder (grid.json, view-N.pgm)")->required();
	grid->add_option("--views", g.views, "frames")->check(CLI::Range(4, 200));
	grid->add_option("--seed", g.seed, "random seed");
	grid->add_option("--noise-sigma", g.noise_sigma, "read noise, levels")
		->check(CLI::Range(0.0, 50.0));
	RunArgs r;
	CLI::App *run = app.add_subcommand("run", "the relative-move study, one CSV line per set");
	run->add_option("--target", r.target_path, "target model JSON (nominal)")->required();
	run->add_option("--camera", r.camera_path, "true camera JSON (rendering)")->required();
	run->add_option("--solve-camera", r.solve_camera_path, "camera JSON the solver uses")
		->required();
	run->add_option("--csv", r.csv_path, "output CSV")->required();
	run->add_option("--readings", r.readings, "readings per set")->check(CLI::Range(1, 100000));
	run->add_option("--distances", r.distances, "comma-separated distances, mm");
	run->add_option("--seed", r.seed, "random seed (LED displacements, frames)");
	run->add_option("--noise-sigma", r.noise_sigma, "read noise, levels")
		->check(CLI::Range(0.0, 50.0));
	run->add_option("--blur-sigma-px", r.blur_sigma_px,
			"the optics' blur of each LED's spot: Gaussian sigma, px")
		->check(CLI::Range(0.3, 5.0));
	run->add_option("--led-sigma-mm", r.led_sigma_mm,
			"LED position tolerance: sigma per coordinate, mm")
		->check(CLI::Range(0.0, 10.0));
	CLI11_PARSE(app, argc, argv);
	if (grid->parsed())
		return runGrid(g);
	return runStudy(r);
}

} /* namespace */

int main(int argc, char **argv)
{
	try {
		return mainChecked(argc, argv);
	} catch (const std::exception &e) {
		std::fprintf(stderr, "dockpose-paper-study: %s\n", e.what());
		return 1;
	}
}

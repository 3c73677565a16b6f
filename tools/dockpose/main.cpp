/* SPDX-License-Identifier: MIT */
/*
 * dockpose: the host tool.
 *
 *   dockpose solve  --target T.json --camera C.json [--threshold auto|N] [--track]
 *                   [--annotate DIR] IMAGE...
 *       One JSON object per line per image, in input order (the contract other
 *       tools parse):
 *         {"image": <path as given>, "found": bool, "status": "...", "blobs": n,
 *          "t_mm": [x, y, z], "q_wxyz": [w, x, y, z], "rpy_deg": [roll, pan, tilt],
 *          "rms_px": r, "log10_nfa": l, "leds": n, "led_mask": m, "tracked": bool,
 *          "sigma_t_mm": [..], "sigma_rpy_deg": [..], "covariance": [[6 x 6]]}
 *       (pose fields only when found; log10_nfa: log10 of the number of false
 *       alarms of the match, one decimal, <= -4 for an accepted pose). An
 *       image that cannot be read, or whose size is not the camera's, gives
 *       {"image": .., "found": false, "error": ".."} and a message on stderr.
 *       Exit code: 0 all images read, 1 some image could not be read (or its
 *       annotation not written), 2 bad arguments or a bad target/camera file
 *       or an annotation directory that cannot be made.
 *       --annotate DIR also writes DIR/<image stem>.ppm per image read (see
 *       annotate.h); it changes nothing in the JSON lines.
 *
 *   dockpose render --target T.json --camera C.json
 *                   (--pose "x,y,z,roll,pan,tilt" ... | --range-mm R [--rpy r,p,t] [--at u,v])
 *                   -o DIR [--count K] [--seed S] [clutter and noise options]
 *       Synthetic PGM frames DIR/frame_NNNN.pgm and DIR/truth.jsonl with one
 *       line per frame: {"file", "seed", "t_mm", "q_wxyz", "rpy_deg",
 *       "visible_mask", "occluded_mask", "clutter_blobs", "led_px"}.
 *
 *   dockpose calibrate --grid GRID.json -o CAMERA.json IMAGE...
 *       The camera's intrinsics from PGM frames of a dot grid (calibrate.h,
 *       docs/calibration.md). Built only where OpenCV is found; a dockpose
 *       built without it says so and exits 2.
 *
 *   dockpose view [--can IFACE | --can-log FILE] [--preview NAME] [--bind ADDR] [--port N]
 *                 [--camera C.json] [--base-id ID] [--allow-commands [--key FILE]]
 *       The operator's live page (view/view.h, docs/operator-view.md). Built only
 *       where cpp-httplib is found; a dockpose built without it says so and exits 2.
 */
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "algo/io/model_json.h"
#include "algo/io/pgm.h"
#include "algo/pipeline.h"
#include "algo/pose.h"
#include "algo/synth/renderer.h"
#include "tools/dockpose/annotate.h"
#include "tools/dockpose/calibrate.h"
#include "tools/dockpose/json_line.h"
#include "tools/dockpose/view/view.h"

namespace {

using namespace dockpose;
using dockpose::tool::JsonLine;

constexpr int kExitOk = 0;
constexpr int kExitImageFailed = 1;
constexpr int kExitUsage = 2;
constexpr int kExitInternal = 3; /* an unexpected exception: a bug, or out of memory */

/* "a,b,c,..." -> exactly n finite numbers, else an error sentence. */
std::string parseNumbers(const std::string &text, std::size_t n, const char *what,
			 std::vector<double> *out)
{
	out->clear();
	std::stringstream ss(text);
	std::string item;
	while (std::getline(ss, item, ',')) {
		char *end = nullptr;
		const double v = std::strtod(item.c_str(), &end);
		while (end && *end == ' ')
			++end;
		if (item.empty() || !end || *end != '\0' || !std::isfinite(v)) {
			std::string problem = what;
			problem.append(" \"").append(text).append("\": '").append(item);
			return problem.append("' is not a number");
		}
		out->push_back(v);
	}
	if (out->size() != n)
		return std::string(what) + " \"" + text + "\" must have " + std::to_string(n) +
		       " comma-separated numbers, not " + std::to_string(out->size());
	return {};
}

struct Files {
	TargetModel target;
	CameraIntrinsics camera;
};

/* Load the target and camera files; prints the problem and returns false. */
bool loadFiles(const std::string &target_path, const std::string &camera_path, Files *files)
{
	auto target = loadTargetModel(target_path);
	if (!target) {
		std::cerr << "dockpose: bad target model: " << target.message() << "\n";
		return false;
	}
	auto camera = loadCameraIntrinsics(camera_path);
	if (!camera) {
		std::cerr << "dockpose: bad camera file: " << camera.message() << "\n";
		return false;
	}
	files->target = std::move(target).value();
	files->camera = camera.value();
	return true;
}

/* The pose fields of a found line, appended to *out. Allocates: never (see JsonLine). */
void poseJson(const PoseResult &r, JsonLine *out)
{
	out->raw(", \"t_mm\": ").numbers(r.t_mm, 3, "%.4f");
	const double q[4] = { r.q.w(), r.q.x(), r.q.y(), r.q.z() };
	out->raw(", \"q_wxyz\": ").numbers(q, 4, "%.9f");
	out->raw(", \"rpy_deg\": ").numbers(r.rpy_deg, 3, "%.5f");
	out->raw(", \"rms_px\": ").number(r.rms_px, "%.4f");
	out->raw(", \"log10_nfa\": ").number(r.log10_nfa, "%.1f");
	out->raw(", \"leds\": ").integer(r.leds_used);
	out->raw(", \"led_mask\": ").integer(r.led_mask);
	out->raw(", \"tracked\": ").boolean(r.tracked);
	out->raw(", \"sigma_t_mm\": ").numbers(r.sigma_t_mm, 3, "%.6g");
	out->raw(", \"sigma_rpy_deg\": ").numbers(r.sigma_rpy_deg, 3, "%.6g");
	out->raw(", \"covariance\": [");
	for (int i = 0; i < 6; ++i) {
		if (i)
			out->raw(", ");
		const double row[6] = { r.covariance(i, 0), r.covariance(i, 1), r.covariance(i, 2),
					r.covariance(i, 3), r.covariance(i, 4), r.covariance(i, 5) };
		out->numbers(row, 6, "%.6g");
	}
	out->raw("]");
}

struct SolveArgs {
	std::string target, camera;
	std::string threshold = "auto";
	bool track = false;
	std::string annotate_dir;
	std::vector<std::string> images;
};

int runSolve(const SolveArgs &args)
{
	PipelineConfig config;
	if (args.threshold == "auto") {
		config.threshold.mode = ThresholdMode::Auto;
	} else {
		char *end = nullptr;
		const long level = std::strtol(args.threshold.c_str(), &end, 10);
		if (args.threshold.empty() || *end != '\0' || level < 1 || level > 255) {
			std::cerr
				<< "dockpose solve: --threshold must be 'auto' or a level 1..255, not '"
				<< args.threshold << "'\n";
			return kExitUsage;
		}
		config.threshold.mode = ThresholdMode::Fixed;
		config.threshold.fixed_level = static_cast<int>(level);
	}
	config.tracking = args.track;

	Files files;
	if (!loadFiles(args.target, args.camera, &files))
		return kExitUsage;

	if (!args.annotate_dir.empty()) {
		std::error_code ec;
		std::filesystem::create_directories(args.annotate_dir, ec);
		if (ec || !std::filesystem::is_directory(args.annotate_dir)) {
			std::cerr << "dockpose solve: cannot create the --annotate directory "
				  << args.annotate_dir << ": "
				  << (ec ? ec.message() : std::string("not a directory")) << "\n";
			return kExitUsage;
		}
	}
	const annotate::Style style = annotate::Style::fromWidth(files.camera.width);

	/*
	 * The frame loop allocates nothing after its first frame: every frame is
	 * read into the reader's one buffer (sized for the camera) and solved
	 * where it lies, every line is built in one reused buffer. Only errors
	 * and --annotate allocate.
	 */
	Pipeline pipeline(files.target, files.camera, config);
	PgmReader reader(files.camera.width, files.camera.height);
	JsonLine line;
	int exit_code = kExitOk;
	for (const std::string &path : args.images) {
		line.clear();
		line.raw("{\"image\": ").string(path);
		ImageView frame;
		std::string error = reader.read(path, &frame).message();
		if (error.empty() &&
		    (frame.width != files.camera.width || frame.height != files.camera.height))
			error = path + ": the image is " + std::to_string(frame.width) + "x" +
				std::to_string(frame.height) + ", the camera " + args.camera +
				" is " + std::to_string(files.camera.width) + "x" +
				std::to_string(files.camera.height);
		if (!error.empty()) {
			std::cerr << "dockpose solve: " << error << "\n";
			line.raw(R"(, "found": false, "error": )").string(error).raw("}");
			line.writeTo(stdout);
			exit_code = kExitImageFailed;
			continue;
		}
		if (!args.track)
			pipeline.reset();
		const PoseResult &r = pipeline.process(frame);
		line.raw(", \"found\": ").boolean(r.found);
		line.raw(", \"status\": ").string(poseStatusName(r.status));
		line.raw(", \"blobs\": ").integer(r.blobs);
		if (r.found)
			poseJson(r, &line);
		line.raw("}");
		line.writeTo(stdout);

		if (!args.annotate_dir.empty()) {
			annotate::RgbImage picture = annotate::RgbImage::fromGrey(frame);
			annotate::annotateFrame(&picture, pipeline.camera(), pipeline.target(),
						pipeline.blobs(), r, style);
			const std::filesystem::path out =
				std::filesystem::path(args.annotate_dir) /
				(std::filesystem::path(path).stem().string() + ".ppm");
			const std::string err = annotate::writePpm(out.string(), picture);
			if (!err.empty()) {
				std::cerr << "dockpose solve: --annotate: " << err << "\n";
				exit_code = kExitImageFailed;
			}
		}
	}
	return exit_code;
}

struct RenderArgs {
	std::string target, camera, out_dir;
	std::vector<std::string> poses;
	double range_mm = 0.0;
	std::string rpy = "0,0,0";
	std::string at = "0.5,0.5";
	int count = 1;
	std::uint64_t seed = 1;
	RenderOptions options;
};

int runRender(const RenderArgs &args)
{
	std::vector<Pose> poses;
	std::vector<double> v;
	for (const std::string &text : args.poses) {
		const std::string err = parseNumbers(text, 6, "--pose", &v);
		if (!err.empty()) {
			std::cerr << "dockpose render: " << err << "\n";
			return kExitUsage;
		}
		Pose p;
		p.t_mm = Eigen::Vector3d(v[0], v[1], v[2]);
		p.R = rotationFromRollPanTiltDeg(Eigen::Vector3d(v[3], v[4], v[5]));
		poses.push_back(p);
	}

	Files files;
	if (!loadFiles(args.target, args.camera, &files))
		return kExitUsage;

	if (poses.empty()) {
		std::vector<double> rpy, at;
		std::string err = parseNumbers(args.rpy, 3, "--rpy", &rpy);
		if (err.empty())
			err = parseNumbers(args.at, 2, "--at", &at);
		if (err.empty() && !(args.range_mm > 0.0))
			err = "one of --pose or --range-mm (> 0) is required";
		if (!err.empty()) {
			std::cerr << "dockpose render: " << err << "\n";
			return kExitUsage;
		}
		poses.push_back(poseAt(files.camera, files.target, args.range_mm,
				       Eigen::Vector3d(rpy[0], rpy[1], rpy[2]), at[0], at[1]));
	}

	std::error_code ec;
	std::filesystem::create_directories(args.out_dir, ec);
	if (ec || !std::filesystem::is_directory(args.out_dir)) {
		std::cerr << "dockpose render: cannot create the output directory " << args.out_dir
			  << ": " << ec.message() << "\n";
		return kExitUsage;
	}
	const std::filesystem::path dir(args.out_dir);
	const std::string truth_path = (dir / "truth.jsonl").string();
	std::ofstream truth_file(truth_path, std::ios::trunc);
	if (!truth_file) {
		std::cerr << "dockpose render: cannot create " << truth_path << "\n";
		return kExitUsage;
	}

	FrameRenderer renderer(files.target, files.camera);
	Image frame(files.camera.width, files.camera.height);
	RenderTruth truth;
	JsonLine line;
	int index = 0;
	for (const Pose &pose : poses) {
		for (int c = 0; c < args.count; ++c, ++index) {
			const std::uint64_t seed = args.seed + static_cast<std::uint64_t>(index);
			renderer.render(pose, args.options, seed, &frame, &truth);
			char name[32];
			std::snprintf(name, sizeof(name), "frame_%04d.pgm", index);
			const Status written = writePgm((dir / name).string(), frame.view());
			if (!written) {
				std::cerr << "dockpose render: " << written.message() << "\n";
				return kExitImageFailed;
			}
			const Eigen::Quaterniond q = quaternionFromRotation(pose.R);
			const double qv[4] = { q.w(), q.x(), q.y(), q.z() };
			line.clear();
			line.raw("{\"file\": ").string(name);
			line.raw(", \"seed\": ").integer(static_cast<std::int64_t>(seed));
			line.raw(", \"t_mm\": ").numbers(pose.t_mm, 3, "%.6f");
			line.raw(", \"q_wxyz\": ").numbers(qv, 4, "%.12f");
			line.raw(", \"rpy_deg\": ")
				.numbers(rollPanTiltDegFromRotation(pose.R), 3, "%.8f");
			line.raw(", \"visible_mask\": ").integer(truth.visible_mask);
			line.raw(", \"occluded_mask\": ").integer(truth.occluded_mask);
			line.raw(", \"clutter_blobs\": ").integer(truth.clutter_blobs);
			line.raw(", \"led_px\": [");
			for (std::size_t i = 0; i < truth.led_px.size(); ++i) {
				if (i)
					line.raw(", ");
				if (truth.led_px[i].allFinite())
					line.numbers(truth.led_px[i], 2, "%.5f");
				else
					line.raw("null");
			}
			line.raw("]}");
			truth_file << line.str() << "\n";
		}
	}
	truth_file.close();
	if (!truth_file) {
		std::cerr << "dockpose render: write failed: " << truth_path << "\n";
		return kExitImageFailed;
	}
	std::cerr << "dockpose render: wrote " << index << " frame(s) and " << truth_path << "\n";
	return kExitOk;
}

/* `dockpose calibrate`: its options into *args. */
CLI::App *addCalibrateCommand(CLI::App *app, dockpose::tool::CalibrateArgs *args)
{
	CLI::App *cmd = app->add_subcommand(
		"calibrate", "Camera intrinsics (camera file) from PGM frames of a dot grid.");
	cmd->add_option("--grid", args->grid_path,
			R"(Grid file: {"rows", "cols", "spacing_mm", "layout"})")
		->required();
	cmd->add_option("-o,--output", args->output_path, "Camera file to write (CAMERA.json)")
		->required();
	cmd->add_option("images", args->images, "PGM frames of the grid")->required();
	return cmd;
}

/* `dockpose calibrate`, where this dockpose was built with OpenCV; the exit status. */
int runCalibrateCommand(const dockpose::tool::CalibrateArgs &args)
{
#ifdef DOCKPOSE_HAVE_OPENCV
	return dockpose::tool::runCalibrate(args);
#else
	(void)args;
	std::cerr << "dockpose calibrate: this dockpose was built without OpenCV (calibrate "
		     "uses its calib3d; install libopencv-dev and rebuild the host tool)\n";
	return kExitUsage;
#endif
}

/* `dockpose view`: its options into *args. */
CLI::App *addViewCommand(CLI::App *app, dockpose::tool::ViewArgs *args)
{
	CLI::App *cmd = app->add_subcommand(
		"view",
		"The operator's live page: preview with overlays, pose and status from CAN.");
	CLI::Option *can = cmd->add_option("--can", args->can_interface,
					   "SocketCAN interface to read the sensor's reports from");
	CLI::Option *log = cmd->add_option("--can-log", args->can_log,
					   "candump log to follow as it grows (candump -L format)");
	can->excludes(log);
	cmd->add_option("--preview", args->preview,
			"The daemon's preview ring: /dev/shm/NAME (preview.name)")
		->default_val(args->preview);
	cmd->add_option("--bind", args->bind, "Address to listen on")->default_val(args->bind);
	cmd->add_option("--port", args->port, "Port to listen on; 0: any free one (printed)")
		->default_val(args->port);
	cmd->add_option("--camera", args->camera,
			"Camera intrinsics JSON: draws the target's axes projected from the pose");
	cmd->add_option("--base-id", args->base_id, "The sensor's CAN base identifier")
		->default_val(args->base_id);
	cmd->add_flag("--allow-commands", args->allow_commands,
		      "Add controls that send DP_Command (with --can only)");
	/* Its needs (--can, --allow-commands) are checked by runView(), which names them. */
	cmd->add_option("--key", args->key_file,
			"The sensor's CAN key file (can.key_file: 32 hex digits, mode 0600/0400): "
			"commands go out signed (DP_CommandAuth), and the sensor's frames are "
			"verified with it before they are shown (with --can and --allow-commands)")
		->type_name("FILE");
	return cmd;
}

/* `dockpose view`, where this dockpose was built with cpp-httplib; the exit status. */
int runViewCommand(const dockpose::tool::ViewArgs &args)
{
#ifdef DOCKPOSE_HAVE_VIEW
	return dockpose::tool::runView(args);
#else
	(void)args;
	std::cerr << "dockpose view: not built: this dockpose was built without cpp-httplib "
		     "(install libcpp-httplib-dev and rebuild the host tool)\n";
	return kExitUsage;
#endif
}

/* `dockpose solve`: its options into *solve. */
CLI::App *addSolveCommand(CLI::App *app, SolveArgs *solve)
{
	CLI::App *solve_cmd = app->add_subcommand(
		"solve", "Find the target's pose in PGM frames; one JSON line per image.");
	solve_cmd
		->add_option("--target,-t", solve->target,
			     "Target model JSON (LED points and faces, mm)")
		->required();
	solve_cmd->add_option("--camera,-c", solve->camera, "Camera intrinsics JSON")->required();
	solve_cmd
		->add_option(
			"--threshold", solve->threshold,
			"Segmentation level: 'auto' (per tile from background and noise) or a fixed level 1..255")
		->default_val("auto");
	solve_cmd->add_flag(
		"--track", solve->track,
		"Treat the images as a sequence: predict from the last pose (default: solve each image on its own)");
	solve_cmd->add_option(
		"--annotate", solve->annotate_dir,
		"Also write DIR/<image stem>.ppm per image: the frame in grey, candidate blobs (yellow "
		"crosses), matched LEDs (green circles), LEDs predicted but not matched (red circles), "
		"the faces (green lines); a red border when no pose was found");
	solve_cmd
		->add_option("images", solve->images,
			     "Binary 8-bit PGM (P5) frames of the camera's size")
		->required();
	return solve_cmd;
}

/* `dockpose render`: its options into *render; *range_opt is --range-mm (it or --pose is
 * required). */
CLI::App *addRenderCommand(CLI::App *app, RenderArgs *render, CLI::Option **range_opt)
{
	CLI::App *render_cmd = app->add_subcommand(
		"render", "Render synthetic PGM frames with known truth (DIR/truth.jsonl).");
	render_cmd->add_option("--target,-t", render->target, "Target model JSON")->required();
	render_cmd->add_option("--camera,-c", render->camera, "Camera intrinsics JSON")->required();
	CLI::Option *pose_opt = render_cmd->add_option(
		"--pose", render->poses,
		"Pose \"x,y,z,roll,pan,tilt\" (mm, degrees), X_c = R X_t + t; repeatable");
	*range_opt = render_cmd->add_option(
		"--range-mm", render->range_mm,
		"Instead of --pose: target centre at this depth on the axis (mm)");
	render_cmd->add_option("--rpy", render->rpy, "With --range-mm: roll,pan,tilt in degrees")
		->default_val("0,0,0");
	render_cmd
		->add_option("--at", render->at,
			     "With --range-mm: target centre at this fraction u,v of the frame")
		->default_val("0.5,0.5");
	pose_opt->excludes(*range_opt);
	render_cmd->add_option("-o,--out", render->out_dir, "Output directory (created if needed)")
		->required();
	render_cmd->add_option("--count", render->count, "Frames per pose (each with its own seed)")
		->default_val(1)
		->check(CLI::Range(1, 100000));
	render_cmd
		->add_option("--seed", render->seed,
			     "Seed of the first frame; frame i uses seed + i")
		->default_val(1);
	RenderOptions &o = render->options;
	render_cmd->add_option("--noise", o.noise_sigma, "Gaussian read noise, levels (sigma)")
		->default_val(o.noise_sigma)
		->check(CLI::Range(0.0, 100.0));
	render_cmd
		->add_option("--gradient", o.gradient, "Ambient gradient across the frame, levels")
		->default_val(o.gradient)
		->check(CLI::Range(-255.0, 255.0));
	render_cmd->add_option("--background", o.background, "Background level at the frame centre")
		->default_val(o.background)
		->check(CLI::Range(0.0, 255.0));
	render_cmd->add_option("--blur-px", o.blur_sigma_px, "Optical blur, sigma in pixels")
		->default_val(o.blur_sigma_px)
		->check(CLI::Range(0.3, 20.0));
	render_cmd
		->add_option("--led-radius-mm", o.led_radius_mm,
			     "Radius of an LED's emitting disc, mm")
		->default_val(o.led_radius_mm)
		->check(CLI::Range(0.01, 100.0));
	render_cmd
		->add_option("--led-peak", o.led_peak,
			     "Peak level of an LED head-on at the reference range")
		->default_val(o.led_peak)
		->check(CLI::Range(0.0, 10000.0));
	render_cmd->add_option("--hot-pixels", o.hot_pixels, "Single saturated pixels")
		->default_val(0)
		->check(CLI::Range(0, 100000));
	render_cmd
		->add_option("--reflections", o.reflections,
			     "LED-like round reflections (at most 64)")
		->default_val(0)
		->check(CLI::Range(0, 64));
	render_cmd->add_option("--glints", o.glints, "Long thin bright streaks (at most 64)")
		->default_val(0)
		->check(CLI::Range(0, 64));
	render_cmd
		->add_option("--occlude", o.occluded_leds,
			     "Hide this many randomly chosen visible LEDs")
		->default_val(0)
		->check(CLI::Range(0, 32));
	render_cmd
		->add_option("--occlusion-mask", o.occlusion_mask,
			     "Also hide these LEDs (bit i hides LED i)")
		->default_val(0);
	return render_cmd;
}

/* The tool itself; main() turns an unexpected exception into a message and exit 3. */
int run(int argc, char **argv)
{
	CLI::App app{
		"dockpose: 6-DoF pose of an infrared LED docking target from 8-bit frames.\n"
		"Conventions: camera frame x right, y down, z forward, mm; pose X_c = R X_t + t;\n"
		"quaternion (w, x, y, z) with w >= 0; R = Rx(roll) Ry(pan) Rz(tilt), degrees.\n"
		"Exit codes: 0 success, 1 an image could not be read or written, 2 bad arguments\n"
		"or a bad target/camera file, 3 an unexpected error (a bug; its message on stderr).",
		"dockpose"
	};
	app.require_subcommand(1);

	SolveArgs solve;
	CLI::App *solve_cmd = addSolveCommand(&app, &solve);
	RenderArgs render;
	CLI::Option *range_opt = nullptr;
	CLI::App *render_cmd = addRenderCommand(&app, &render, &range_opt);
	dockpose::tool::CalibrateArgs calibrate;
	CLI::App *calibrate_cmd = addCalibrateCommand(&app, &calibrate);
	dockpose::tool::ViewArgs view;
	CLI::App *view_cmd = addViewCommand(&app, &view);

	try {
		app.parse(argc, argv);
	} catch (const CLI::ParseError &e) {
		const int code = app.exit(e);
		return code == 0 ? kExitOk : kExitUsage;
	}

	if (solve_cmd->parsed())
		return runSolve(solve);
	if (render_cmd->parsed()) {
		if (render.poses.empty() && range_opt->count() == 0) {
			std::cerr << "dockpose render: one of --pose or --range-mm is required\n";
			return kExitUsage;
		}
		return runRender(render);
	}
	if (calibrate_cmd->parsed())
		return runCalibrateCommand(calibrate);
	if (view_cmd->parsed())
		return runViewCommand(view);
	return kExitUsage;
}

} /* namespace */

int main(int argc, char **argv)
{
	try {
		return run(argc, argv);
	} catch (const std::exception &e) {
		std::cerr << "dockpose: " << e.what() << "\n";
		return kExitInternal;
	}
}

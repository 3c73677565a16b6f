/* SPDX-License-Identifier: MIT */
/*
 * `dockpose calibrate` as outside tools run it, on frames of a planar dot grid rendered with
 * known intrinsics: the grid's dots are discs on the plane z = 0 of the grid, drawn by
 * casting 4 x 4 rays per pixel through the true camera model (distortion included) onto the
 * plane, so a pixel's level is the fraction of its area the dot covers; then read noise.
 * Several lenses (f 500-1800 px, k1 down to -0.35), 15 views each, tilted 30-45 degrees,
 * with dots in the corners and along the edges of the frame.
 *
 * Built only where OpenCV is found (the tool's calibrate is).
 */
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "algo/camera_model.h"
#include "algo/image.h"
#include "algo/io/model_json.h"
#include "algo/io/pgm.h"
#include "algo/pose.h"
#include "algo/synth/dot_grid.h"
#include "algo/synth/rng.h"

namespace {

using namespace dockpose;
using dockpose::synth::Rng;

#ifdef DOCKPOSE_TOOL_EMULATOR
const std::string kEmulator = std::string(DOCKPOSE_TOOL_EMULATOR) + " ";
#else
const std::string kEmulator;
#endif

std::string slurp(const std::string &path)
{
	std::ifstream in(path);
	std::stringstream ss;
	ss << in.rdbuf();
	return ss.str();
}

/*
 * The calibration grid: dots 5 mm across at a 20 mm pitch (DotGrid's default). A tilted
 * disc's image centroid is not the image of its centre (perspective): with 8 mm dots fx came
 * out 0.023 % low on the f 1000 lens and the poses 1.37x worse than with the true file; 5 mm:
 * 0.007 % and 1.07x (docs/calibration.md: dots at most a quarter of the pitch). Rendered with
 * algo/synth/dot_grid.h, the renderer scripts/paper-study calibrates with.
 */
using Grid = DotGrid;

/* Dots beside the grid: extra bright discs at these target-plane points (mm). */
using Extras = std::vector<Eigen::Vector3d>;

Image renderGrid(const CameraModel &camera, const Grid &grid, const Pose &pose, double noise_sigma,
		 std::uint64_t seed, const Extras &extras = {})
{
	return renderDotGrid(camera, grid, pose, noise_sigma, seed, extras);
}

/* View n of a calibration set (dotGridView); a view that does not fit fails the test. */
Pose calibrationView(const CameraModel &camera, const Grid &grid, int n, Rng *rng,
		     bool centre_only = false)
{
	Pose pose;
	if (!dotGridView(camera, grid, n, rng, &pose, centre_only))
		ADD_FAILURE() << "view " << n << ": the grid does not fit the frame";
	return pose;
}

struct Lens {
	const char *name;
	CameraIntrinsics k;
};

CameraIntrinsics lens(int w, int h, double fx, double fy, double cx, double cy, double k1,
		      double k2, double p1, double p2)
{
	CameraIntrinsics k;
	k.width = w;
	k.height = h;
	k.fx = fx;
	k.fy = fy;
	k.cx = cx;
	k.cy = cy;
	k.k1 = k1;
	k.k2 = k2;
	k.p1 = p1;
	k.p2 = p2;
	return k;
}

class Calibrate : public ::testing::Test
{
protected:
	void SetUp() override
	{
		char dir_template[] = "/tmp/dockpose-calibrate.XXXXXX";
		ASSERT_NE(mkdtemp(dir_template), nullptr);
		dir_ = dir_template;
		std::ofstream(dir_ + "/grid.json") << grid_.json();
	}
	/* A failed test keeps its frames for a look. */
	void TearDown() override
	{
		if (HasFailure())
			std::printf("frames kept in %s\n", dir_.c_str());
		else
			std::filesystem::remove_all(dir_);
	}

	std::string write(const std::string &name, const Image &image)
	{
		const std::string path = dir_ + "/" + name;
		EXPECT_TRUE(writePgm(path, image.view()).isOk()) << path;
		return path;
	}

	/* `dockpose calibrate`; its exit status, stdout and stderr. */
	int calibrate(const std::vector<std::string> &images, const std::string &out,
		      std::string *report, std::string *err)
	{
		std::string cmd = kEmulator + DOCKPOSE_TOOL + std::string(" calibrate --grid '") +
				  dir_ + "/grid.json' -o '" + out + "'";
		for (const std::string &i : images)
			cmd += " '" + i + "'";
		cmd += " >'" + dir_ + "/report.txt' 2>'" + dir_ + "/err.txt'";
		const int raw = std::system(cmd.c_str());
		*report = slurp(dir_ + "/report.txt");
		*err = slurp(dir_ + "/err.txt");
		return WIFEXITED(raw) ? WEXITSTATUS(raw) : 128 + WTERMSIG(raw);
	}

	/* 15 views of the grid through the lens, 2 levels of noise. */
	std::vector<std::string> renderSet(const CameraIntrinsics &k, const std::string &stem,
					   std::uint64_t seed, bool centre_only = false)
	{
		const CameraModel camera(k);
		Rng rng(seed);
		std::vector<std::string> paths;
		for (int n = 0; n < 15; ++n) {
			const Pose pose = calibrationView(camera, grid_, n, &rng, centre_only);
			paths.push_back(
				write(stem + "-" + std::to_string(n) + ".pgm",
				      renderGrid(camera, grid_, pose, 2.0, seed * 100 + n)));
		}
		return paths;
	}

	Grid grid_;
	std::string dir_;
};

TEST_F(Calibrate, RecoversTheIntrinsicsOfSeveralLenses)
{
	const Lens lenses[] = {
		{ "wide 640x480, f 500, k1 -0.35",
		  lens(640, 480, 500.0, 502.0, 326.0, 236.0, -0.35, 0.12, 0.0008, -0.0005) },
		{ "imx296-like 1456x1088, f 1000, k1 -0.2",
		  lens(1456, 1088, 1000.0, 1000.0, 720.0, 550.0, -0.2, 0.08, 0.0, 0.0) },
		{ "narrow 1456x1088, f 1800, k1 +0.15",
		  lens(1456, 1088, 1800.0, 1797.0, 731.0, 540.0, 0.15, -0.1, -0.0004, 0.0003) },
	};
	int index = 0;
	for (const Lens &l : lenses) {
		SCOPED_TRACE(l.name);
		ASSERT_TRUE(l.k.validate().isOk()) << l.k.validate().message();
		const std::vector<std::string> images =
			renderSet(l.k, "lens" + std::to_string(index), 11 + index);
		const std::string out = dir_ + "/camera" + std::to_string(index) + ".json";
		++index;
		std::string report, err;
		ASSERT_EQ(calibrate(images, out, &report, &err), 0) << err << report;
		EXPECT_EQ(err.find("skipped"), std::string::npos) << err;

		/* The product reads what was written. */
		Result<CameraIntrinsics> got = loadCameraIntrinsics(out);
		ASSERT_TRUE(got.isOk()) << got.message();
		const CameraIntrinsics &k = got.value();
		EXPECT_EQ(k.width, l.k.width);
		EXPECT_EQ(k.height, l.k.height);
		EXPECT_NEAR(k.fx / l.k.fx, 1.0, 0.003) << report;
		EXPECT_NEAR(k.fy / l.k.fy, 1.0, 0.003) << report;
		EXPECT_NEAR(k.cx, l.k.cx, 2.0) << report;
		EXPECT_NEAR(k.cy, l.k.cy, 2.0) << report;
		EXPECT_NEAR(k.k1, l.k.k1, 0.01) << report;
		/* Every parameter has its 1 sigma, and the truth is within a few of them. */
		EXPECT_GT(k.sigma.fx, 0.0);
		EXPECT_GT(k.sigma.k1, 0.0);
		EXPECT_GT(k.sigma.p2, 0.0);
		std::printf("%s: fx %.2f (true %.2f, 1 sigma %.2f), cx %.2f (%.2f), k1 %.4f "
			    "(%.4f +- %.4f)\n",
			    l.name, k.fx, l.k.fx, k.sigma.fx, k.cx, l.k.cx, k.k1, l.k.k1,
			    k.sigma.k1);

		const std::string json = slurp(out);
		for (const char *key : { "\"rms_px\"", "\"sigma\"", "\"frames\"", "\"date\"" })
			EXPECT_NE(json.find(key), std::string::npos) << key << " in " << json;
		EXPECT_NE(report.find(" rms "), std::string::npos) << report;
		EXPECT_NE(report.find("+-"), std::string::npos) << report;
		std::printf("%s", report.c_str());
	}
}

/* The camera file of k, as the product reads it. */
std::string cameraJson(const CameraIntrinsics &k)
{
	nlohmann::json j = { { "width", k.width }, { "height", k.height }, { "fx", k.fx },
			     { "fy", k.fy },	   { "cx", k.cx },	   { "cy", k.cy },
			     { "k1", k.k1 },	   { "k2", k.k2 },	   { "p1", k.p1 },
			     { "p2", k.p2 } };
	return j.dump();
}

TEST_F(Calibrate, PosesWithTheCalibratedFileAreAsGoodAsWithTheTrueOne)
{
	const CameraIntrinsics truth =
		lens(1456, 1088, 1000.0, 1000.0, 720.0, 550.0, -0.2, 0.08, 0.0004, -0.0003);
	const std::string calibrated = dir_ + "/calibrated.json";
	std::string report, err;
	ASSERT_EQ(calibrate(renderSet(truth, "grid", 21), calibrated, &report, &err), 0)
		<< err << report;
	const std::string true_file = dir_ + "/true.json";
	std::ofstream(true_file) << cameraJson(truth);

	/* The wedge (tests/data) through the true lens, in the centre and out towards the corners,
	 * 0.8-2.5 m, 6 noisy frames per pose. */
	const std::string target = std::string(DOCKPOSE_TEST_DATA) + "/wedge.json";
	const char *poses[] = { "0,0,1500,0,0,0",	   "600,300,1500,0,20,0",
				"-700,-350,1500,10,-20,5", "800,-450,2000,-5,10,15",
				"-300,200,900,0,10,0",	   "-1100,600,2500,0,-15,-10" };
	std::string cmd = kEmulator + DOCKPOSE_TOOL + std::string(" render --target '") + target +
			  "' --camera '" + true_file + "' -o '" + dir_ +
			  "/wedge' --count 6 --seed 4";
	for (const char *p : poses)
		cmd += std::string(" --pose ") + p;
	cmd += " 2>'" + dir_ + "/render.err'";
	ASSERT_EQ(std::system(cmd.c_str()), 0) << slurp(dir_ + "/render.err");

	std::vector<nlohmann::json> truths;
	{
		std::ifstream in(dir_ + "/wedge/truth.jsonl");
		for (std::string line; std::getline(in, line);)
			if (!line.empty())
				truths.push_back(nlohmann::json::parse(line));
	}
	ASSERT_EQ(truths.size(), 36u);
	/* Mean position error (mm) of dockpose solve with a camera file over the frames it
	 * found a pose in; *found: how many. */
	const auto meanError = [&](const std::string &camera_file, int *found) {
		std::string solve = kEmulator + DOCKPOSE_TOOL + std::string(" solve --target '") +
				    target + "' --camera '" + camera_file + "'";
		for (const nlohmann::json &t : truths)
			solve += " '" + dir_ + "/wedge/" + t.at("file").get<std::string>() + "'";
		solve += " >'" + dir_ + "/solve.jsonl' 2>'" + dir_ + "/solve.err'";
		EXPECT_EQ(std::system(solve.c_str()), 0) << slurp(dir_ + "/solve.err");
		std::ifstream in(dir_ + "/solve.jsonl");
		double sum_mm = 0.0;
		*found = 0;
		std::size_t i = 0;
		for (std::string line; std::getline(in, line) && i < truths.size(); ++i) {
			const nlohmann::json got = nlohmann::json::parse(line);
			if (!got.at("found").get<bool>())
				continue;
			Eigen::Vector3d d;
			for (int a = 0; a < 3; ++a)
				d[a] = got.at("t_mm")[a].get<double>() -
				       truths[i].at("t_mm")[a].get<double>();
			sum_mm += d.norm();
			++*found;
		}
		EXPECT_EQ(i, truths.size());
		return *found > 0 ? sum_mm / *found : 0.0;
	};
	int found_truth = 0, found_calibrated = 0;
	const double with_truth_mm = meanError(true_file, &found_truth);
	const double with_calibration_mm = meanError(calibrated, &found_calibrated);
	std::printf("mean position error: %.3f mm over %d of %zu frames with the true camera "
		    "file, %.3f mm over %d with the calibrated one\n",
		    with_truth_mm, found_truth, truths.size(), with_calibration_mm,
		    found_calibrated);
	ASSERT_GE(found_truth, 30);
	EXPECT_GE(found_calibrated, found_truth);
	EXPECT_LE(with_calibration_mm, 1.2 * with_truth_mm);
}

TEST_F(Calibrate, SkipsAFrameWithoutTheWholeGridAndKeepsOneWithExtraBlobs)
{
	const CameraIntrinsics k = lens(640, 480, 600.0, 600.0, 320.0, 240.0, -0.2, 0.05, 0, 0);
	const CameraModel camera(k);
	std::vector<std::string> images = renderSet(k, "set", 5);

	/* No grid at all: the background and its noise. */
	Image empty(k.width, k.height, 15);
	images.push_back(write("empty.pgm", empty));
	/* Half the grid out of the frame. */
	Pose off;
	off.t_mm = Eigen::Vector3d(60.0, -60.0, 300.0);
	images.push_back(write("cut.pgm", renderGrid(camera, grid_, off, 2.0, 7)));
	/* Four extra dots beside the grid (reflections, LEDs in the scene). */
	Rng rng(3);
	const Pose tilted = calibrationView(camera, grid_, 8, &rng);
	const Extras extras = { { -45.0, 30.0, 0.0 },
				{ grid_.centre().x() * 2 + 40.0, 50.0, 0.0 },
				{ 60.0, -40.0, 0.0 },
				{ 100.0, grid_.centre().y() * 2 + 35.0, 0.0 } };
	images.push_back(write("extra.pgm", renderGrid(camera, grid_, tilted, 2.0, 9, extras)));

	std::string report, err;
	ASSERT_EQ(calibrate(images, dir_ + "/camera.json", &report, &err), 0) << err << report;
	EXPECT_NE(err.find("empty.pgm: skipped: 0 dot(s) found, the 7x10 grid has 70"),
		  std::string::npos)
		<< err;
	EXPECT_NE(err.find("cut.pgm: skipped: "), std::string::npos) << err;
	EXPECT_EQ(err.find("extra.pgm"), std::string::npos) << err;
	EXPECT_NE(report.find("extra.pgm: 70 dots"), std::string::npos) << report;
	ASSERT_TRUE(loadCameraIntrinsics(dir_ + "/camera.json").isOk());
}

TEST_F(Calibrate, DropsAFrameOfAnotherLensAndSaysSo)
{
	const CameraIntrinsics k = lens(640, 480, 600.0, 600.0, 320.0, 240.0, -0.2, 0.05, 0, 0);
	std::vector<std::string> images = renderSet(k, "set", 8);
	/* The same grid through a lens with 5 % more focal length and other distortion: no
	 * extrinsics fit it with the others' intrinsics. */
	CameraIntrinsics other = k;
	other.fx *= 1.05;
	other.fy *= 1.05;
	other.k1 = -0.1;
	Rng rng(2);
	const CameraModel other_camera(other);
	images.push_back(write("other.pgm",
			       renderGrid(other_camera, grid_,
					  calibrationView(other_camera, grid_, 3, &rng), 2.0, 4)));
	std::string report, err;
	ASSERT_EQ(calibrate(images, dir_ + "/camera.json", &report, &err), 0) << err << report;
	EXPECT_NE(report.find("dropped " + dir_ + "/other.pgm: rms "), std::string::npos) << report;
	EXPECT_EQ(report.find("frame " + dir_ + "/other.pgm"), std::string::npos) << report;
	EXPECT_NE(report.find("15 frame(s) used of 16 image(s)"), std::string::npos) << report;
	const Result<CameraIntrinsics> got = loadCameraIntrinsics(dir_ + "/camera.json");
	ASSERT_TRUE(got.isOk());
	EXPECT_NEAR(got.value().fx / k.fx, 1.0, 0.003) << report;
}

TEST_F(Calibrate, WarnsWhenTheDotsLeaveTheCornersUncovered)
{
	const CameraIntrinsics k = lens(640, 480, 600.0, 600.0, 320.0, 240.0, -0.2, 0.05, 0, 0);
	std::string report, err;
	ASSERT_EQ(calibrate(renderSet(k, "centre", 6, true), dir_ + "/camera.json", &report, &err),
		  0)
		<< err << report;
	EXPECT_NE(report.find("warning: no dot in the border cell(s) (row 0, col 0)"),
		  std::string::npos)
		<< report;
	EXPECT_NE(report.find("warning: the dots reach only"), std::string::npos) << report;

	/* The views spread over the frame: no warning. */
	ASSERT_EQ(calibrate(renderSet(k, "spread", 6), dir_ + "/camera.json", &report, &err), 0)
		<< err << report;
	EXPECT_EQ(report.find("warning"), std::string::npos) << report;
}

TEST_F(Calibrate, AnAsymmetricGridToo)
{
	/* OpenCV's usual 4 x 11 asymmetric grid; nearest dots sqrt(2) x 10 mm apart, 3.5 mm dots. */
	grid_.rows = 11;
	grid_.cols = 4;
	grid_.spacing_mm = 10.0;
	grid_.dot_radius_mm = 1.75;
	grid_.asymmetric = true;
	std::ofstream(dir_ + "/grid.json") << grid_.json();
	const CameraIntrinsics k =
		lens(1456, 1088, 1200.0, 1201.0, 735.0, 540.0, -0.25, 0.1, 0.0003, 0.0002);
	std::string report, err;
	ASSERT_EQ(calibrate(renderSet(k, "asym", 31), dir_ + "/camera.json", &report, &err), 0)
		<< err << report;
	EXPECT_EQ(err.find("skipped"), std::string::npos) << err;
	const Result<CameraIntrinsics> got = loadCameraIntrinsics(dir_ + "/camera.json");
	ASSERT_TRUE(got.isOk()) << got.message();
	EXPECT_NEAR(got.value().fx / k.fx, 1.0, 0.003) << report;
	EXPECT_NEAR(got.value().fy / k.fy, 1.0, 0.003) << report;
	EXPECT_NEAR(got.value().cx, k.cx, 2.0) << report;
	EXPECT_NEAR(got.value().cy, k.cy, 2.0) << report;
	EXPECT_NEAR(got.value().k1, k.k1, 0.01) << report;
}

TEST_F(Calibrate, BadGridFilesAreRefusedNamingTheKey)
{
	struct Case {
		const char *text, *expected;
	} const cases[] = {
		{ "{\"rows\": 7, \"cols\": 7, \"spacing_mm\": 20}", "needs rows != cols" },
		{ "{\"rows\": 7, \"spacing_mm\": 20}", "key 'cols' is missing" },
		{ "{\"rows\": 7.5, \"cols\": 9, \"spacing_mm\": 20}", "'rows' must be an integer" },
		{ "{\"rows\": 7, \"cols\": 9, \"spacing_mm\": -1}", "'spacing_mm' must be in" },
		{ "{\"rows\": 7, \"cols\": 9, \"spacing_mm\": 20, \"layout\": \"hex\"}",
		  "'layout' must be \"symmetric\" or \"asymmetric\"" },
		{ "{\"rows\": 7, \"cols\": 9, \"spacing\": 20}", "unknown key 'spacing'" },
		{ "[7, 9]", "must be a JSON object" },
		{ "{\"rows\": 7,", "not valid JSON" },
	};
	const std::string grid = dir_ + "/grid.json";
	for (const Case &c : cases) {
		std::ofstream(grid) << c.text;
		std::string report, err;
		EXPECT_EQ(calibrate({ dir_ + "/none.pgm" }, dir_ + "/c.json", &report, &err), 2)
			<< c.text;
		EXPECT_NE(err.find(grid + ": "), std::string::npos) << err;
		EXPECT_NE(err.find(c.expected), std::string::npos) << c.text << ": " << err;
	}
}

} /* namespace */

/* SPDX-License-Identifier: MIT */
/*
 * The host tool, run as a program: `dockpose render` frames with known truth,
 * `dockpose solve` them, and compare; and the error contract of `solve`
 * (exit codes 0/1/2, one JSON line per image in input order, the exact fields,
 * strings escaped byte for byte as nlohmann::json escapes them); the tool's
 * reused line buffer (tools/dockpose/json_line.h); and the annotated frames of
 * `solve --annotate`, read back as PPM files.
 */
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "algo/pose.h"
#include "tools/dockpose/json_line.h"

/* The counting hooks interpose malloc, which the sanitizers' allocator does not allow. */
#include "../common/sanitizer.h"
#if !DOCKPOSE_SANITIZED
#define DOCKPOSE_COUNT_ALLOCATIONS 1
#include "../common/counting_allocator.h"
#endif

namespace {

std::string nlohmannDump(const std::string &text)
{
	return nlohmann::json(text).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

} /* namespace */

/* The tool's strings are nlohmann's, byte for byte: every single byte, and random mixes of ASCII,
 * control characters, good and broken UTF-8. */
TEST(JsonLine, EscapesStringsLikeNlohmann)
{
	using dockpose::tool::JsonLine;
	JsonLine line;
	for (int b = 0; b < 256; ++b) {
		const std::string text(1, static_cast<char>(b));
		line.clear();
		line.string(text);
		EXPECT_EQ(line.str(), nlohmannDump(text)) << "byte " << b;
	}
	const std::vector<std::string> pieces = {
		"a",
		"Z",
		" ",
		"/",
		"\\",
		"\"",
		"\x7f",
		"\n",
		"\t",
		"\x01",
		"\x1f",
		"\xc3\xa9" /* é */,
		"\xe2\x82\xac" /* € */,
		"\xf0\x9f\x98\x80" /* U+1F600 */,
		"\xc3" /* cut short */,
		"\xc0\xaf" /* overlong */,
		"\xed\xa0\x80" /* surrogate */,
		"\xf4\x90\x80\x80" /* > U+10FFFF */,
		"\xe0\x80\x80",
		"\xff",
		"\x80",
		"\xef\xbf\xbd",
	};
	std::mt19937 rng(7);
	for (int i = 0; i < 3000; ++i) {
		std::string text;
		const int n = static_cast<int>(rng() % 8);
		for (int k = 0; k < n; ++k)
			text += pieces[rng() % pieces.size()];
		line.clear();
		line.string(text);
		ASSERT_EQ(line.str(), nlohmannDump(text)) << nlohmann::json(text).dump(
			-1, ' ', true, nlohmann::json::error_handler_t::replace);
	}
	EXPECT_TRUE(JsonLine::validUtf8("plain \xc3\xa9 \xf0\x9f\x98\x80"));
	EXPECT_FALSE(JsonLine::validUtf8("\xed\xa0\x80"));
}

TEST(JsonLine, NumbersAsTheToolPrintsThem)
{
	dockpose::tool::JsonLine line;
	const double v[3] = { -0.00001, 1.23456, std::nan("") };
	line.numbers(v, 3, "%.4f")
		.raw(" ")
		.integer(-42)
		.raw(" ")
		.integer(4294967295LL)
		.raw(" ")
		.boolean(true);
	line.raw(" ").number(-12.34, "%.1f").raw(" ").number(-HUGE_VAL, "%.1f");
	EXPECT_EQ(line.str(), "[0.0000, 1.2346, null] -42 4294967295 true -12.3 null");
}

#ifdef DOCKPOSE_COUNT_ALLOCATIONS
/* A line buffer that has held a line allocates nothing for the next ones. */
TEST(JsonLine, ReusedLineAllocatesNothing)
{
	dockpose::tool::JsonLine line;
	const std::string path = "/tmp/frames/frame_0001 \"quoted\" \xc3\xa9.pgm";
	const double cov[6] = { 1e-3, -2e-5, 3.5, 0, 1e300, -7 };
	auto build = [&] {
		line.clear();
		line.raw("{\"image\": ").string(path).raw(", \"found\": ").boolean(true);
		for (int i = 0; i < 6; ++i)
			line.raw(", ").numbers(cov, 6, "%.6g");
		line.raw(", \"leds\": ").integer(6).raw("}");
	};
	build();
	const std::string first = line.str();
	dockpose::test::armAllocationCounter();
	for (int i = 0; i < 100; ++i)
		build();
	const long allocations = dockpose::test::disarmAllocationCounter();
	EXPECT_EQ(allocations, 0);
	EXPECT_EQ(line.str(), first);

	/* The hooks do count: a fresh line allocates its buffer. */
	dockpose::test::armAllocationCounter();
	dockpose::tool::JsonLine fresh;
	fresh.raw("x");
	EXPECT_GT(dockpose::test::disarmAllocationCounter(), 0);
}
#endif

#ifndef DOCKPOSE_TOOL

TEST(Cli, RequiresTheTool)
{
	GTEST_SKIP() << "the dockpose tool target does not exist in this build";
}

#else

using nlohmann::json;
namespace fs = std::filesystem;

namespace {

const std::string kData = DOCKPOSE_TEST_DATA;
#ifdef DOCKPOSE_TOOL_EMULATOR
const char *const kEmulator = DOCKPOSE_TOOL_EMULATOR;
#else
const char *const kEmulator = "";
#endif

struct ToolRun {
	int code = -1;
	std::string out, err;
	std::vector<json> lines; /* stdout parsed line by line */
};

class Cli : public ::testing::Test
{
protected:
	void SetUp() override
	{
		ASSERT_TRUE(fs::exists(DOCKPOSE_TOOL))
			<< DOCKPOSE_TOOL << " is missing: build the dockpose target";
		const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
		dir_ = fs::temp_directory_path() /
		       ("dockpose_cli_" + std::to_string(static_cast<long>(::getpid())) + "_" +
			info->name());
		fs::remove_all(dir_);
		fs::create_directories(dir_);
		/*
		 * A cross-built tool runs through the build's emulator
		 * (DOCKPOSE_TOOL_EMULATOR, e.g. qemu-aarch64); without one it
		 * cannot run on this machine, which is a skip, not a failure.
		 */
		const ToolRun probe = run("--help", false);
		if (probe.code == 126 || probe.code == 127)
			GTEST_SKIP() << "cannot execute " << DOCKPOSE_TOOL << " here (" << probe.err
				     << "); a cross build must define DOCKPOSE_TOOL_EMULATOR";
	}
	void TearDown() override
	{
		if (!HasFailure())
			fs::remove_all(dir_);
	}

	std::string path(const std::string &name) const { return (dir_ / name).string(); }

	ToolRun run(const std::string &args, bool json_lines = true) const
	{
		ToolRun r;
		const std::string err_file = path("stderr.txt");
		const std::string cmd = std::string(kEmulator) + " '" + DOCKPOSE_TOOL + "' " +
					args + " 2>'" + err_file + "'";
		FILE *p = ::popen(cmd.c_str(), "r");
		if (!p) {
			ADD_FAILURE() << "popen failed: " << cmd;
			return r;
		}
		char buf[4096];
		std::size_t n;
		while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0)
			r.out.append(buf, n);
		const int status = ::pclose(p);
		r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
		std::ifstream e(err_file);
		std::stringstream ss;
		ss << e.rdbuf();
		r.err = ss.str();
		if (!json_lines)
			return r;
		std::stringstream lines(r.out);
		std::string line;
		while (std::getline(lines, line)) {
			try {
				r.lines.push_back(json::parse(line));
			} catch (const json::exception &ex) {
				ADD_FAILURE() << "not a JSON line: '" << line << "': " << ex.what();
			}
		}
		return r;
	}

	std::vector<json> readTruth(const std::string &dir) const
	{
		std::vector<json> truth;
		std::ifstream in(dir + "/truth.jsonl");
		std::string line;
		while (std::getline(in, line))
			truth.push_back(json::parse(line));
		return truth;
	}

	fs::path dir_;
};

std::set<std::string> keys(const json &j)
{
	std::set<std::string> k;
	for (auto it = j.begin(); it != j.end(); ++it)
		k.insert(it.key());
	return k;
}

const std::set<std::string> kFoundKeys = { "image",	 "found",	  "status",    "blobs",
					   "t_mm",	 "q_wxyz",	  "rpy_deg",   "rms_px",
					   "log10_nfa",	 "leds",	  "led_mask",  "tracked",
					   "sigma_t_mm", "sigma_rpy_deg", "covariance" };
const std::set<std::string> kNotFoundKeys = { "image", "found", "status", "blobs" };
const std::set<std::string> kErrorKeys = { "image", "found", "error" };

Eigen::Vector3d vec3(const json &j)
{
	return { j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>() };
}

Eigen::Matrix3d rotationOf(const json &q_wxyz)
{
	return Eigen::Quaterniond(q_wxyz.at(0).get<double>(), q_wxyz.at(1).get<double>(),
				  q_wxyz.at(2).get<double>(), q_wxyz.at(3).get<double>())
		.toRotationMatrix();
}

/* Every field of a found line, and its agreement with the rendered truth. */
void checkFound(const json &line, const json &truth, const std::string &image, double t_tol_mm,
		double angle_tol_deg)
{
	SCOPED_TRACE(line.dump());
	EXPECT_EQ(keys(line), kFoundKeys);
	EXPECT_EQ(line.at("image"), image);
	ASSERT_EQ(line.at("found"), true);
	EXPECT_EQ(line.at("status"), "found");
	EXPECT_FALSE(line.at("tracked").get<bool>());

	const json &q = line.at("q_wxyz");
	ASSERT_EQ(q.size(), 4u);
	const Eigen::Vector4d qv(q[0].get<double>(), q[1].get<double>(), q[2].get<double>(),
				 q[3].get<double>());
	EXPECT_NEAR(qv.norm(), 1.0, 1e-7);
	EXPECT_GE(qv[0], 0.0);
	const Eigen::Matrix3d R = rotationOf(q);
	ASSERT_EQ(line.at("rpy_deg").size(), 3u);
	EXPECT_LT(dockpose::rotationAngleDeg(
			  R, dockpose::rotationFromRollPanTiltDeg(vec3(line.at("rpy_deg")))),
		  1e-3);

	const Eigen::Vector3d t = vec3(line.at("t_mm"));
	const Eigen::Vector3d t_true = vec3(truth.at("t_mm"));
	EXPECT_LT((t - t_true).norm(), t_tol_mm)
		<< "t " << t.transpose() << " truth " << t_true.transpose();
	EXPECT_LT(dockpose::rotationAngleDeg(R, rotationOf(truth.at("q_wxyz"))), angle_tol_deg);

	const std::uint32_t visible = truth.at("visible_mask").get<std::uint32_t>();
	EXPECT_EQ(line.at("led_mask").get<std::uint32_t>(), visible);
	EXPECT_EQ(line.at("leds").get<int>(), std::popcount(visible));
	EXPECT_GE(line.at("blobs").get<int>(), std::popcount(visible));
	EXPECT_LT(line.at("rms_px").get<double>(), 0.5);
	EXPECT_GE(line.at("rms_px").get<double>(), 0.0);
	/* log10 NFA: a number with one decimal, never above 1 false alarm for a found pose. */
	ASSERT_TRUE(line.at("log10_nfa").is_number()) << line.at("log10_nfa");
	const double nfa = line.at("log10_nfa").get<double>();
	EXPECT_LE(nfa, 0.0);
	EXPECT_NEAR(nfa * 10.0, std::round(nfa * 10.0), 1e-6);

	const json &cov = line.at("covariance");
	ASSERT_EQ(cov.size(), 6u);
	for (int i = 0; i < 6; ++i) {
		ASSERT_EQ(cov[i].size(), 6u);
		for (int j = 0; j < 6; ++j)
			EXPECT_NEAR(cov[i][j].get<double>(), cov[j][i].get<double>(),
				    1e-5 * std::abs(cov[i][j].get<double>()) + 1e-12);
		EXPECT_GT(cov[i][i].get<double>(), 0.0);
	}
	const json &st = line.at("sigma_t_mm");
	ASSERT_EQ(st.size(), 3u);
	for (int i = 0; i < 3; ++i)
		EXPECT_NEAR(st[i].get<double>(), std::sqrt(cov[i][i].get<double>()),
			    1e-4 * st[i].get<double>());
	ASSERT_EQ(line.at("sigma_rpy_deg").size(), 3u);
	for (int i = 0; i < 3; ++i)
		EXPECT_GT(line.at("sigma_rpy_deg")[i].get<double>(), 0.0);
	/* The error is within a few sigma of what the pose reports (sigma floored at 0.05 mm). */
	for (int i = 0; i < 3; ++i)
		EXPECT_LT(std::abs(t[i] - t_true[i]), 6.0 * std::max(st[i].get<double>(), 0.05))
			<< "axis " << i;
}

/* A binary PGM (P5) or PPM (P6) file, header parsed here, independently of the tool's code. */
struct Netpbm {
	std::string magic;
	int width = 0, height = 0, maxval = 0, channels = 0;
	std::vector<std::uint8_t> pixels; /* rows top to bottom, `channels` bytes per pixel */

	const std::uint8_t *at(int x, int y) const
	{
		return pixels.data() +
		       (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
			static_cast<std::size_t>(x)) *
			       static_cast<std::size_t>(channels);
	}
	bool inside(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
};

/* Empty string when read, else the problem. */
std::string readNetpbm(const std::string &file, Netpbm *img)
{
	std::ifstream in(file, std::ios::binary);
	if (!in)
		return file + ": cannot open";
	const std::string bytes((std::istreambuf_iterator<char>(in)),
				std::istreambuf_iterator<char>());
	std::size_t pos = 0;
	/* The next header token; whitespace and '#' comments between tokens. */
	auto token = [&]() {
		for (;;) {
			while (pos < bytes.size() &&
			       std::isspace(static_cast<unsigned char>(bytes[pos])))
				++pos;
			if (pos < bytes.size() && bytes[pos] == '#') {
				while (pos < bytes.size() && bytes[pos] != '\n')
					++pos;
				continue;
			}
			break;
		}
		const std::size_t start = pos;
		while (pos < bytes.size() && !std::isspace(static_cast<unsigned char>(bytes[pos])))
			++pos;
		return bytes.substr(start, pos - start);
	};
	img->magic = token();
	if (img->magic != "P5" && img->magic != "P6")
		return file + ": magic '" + img->magic + "' is not P5 or P6";
	img->channels = img->magic == "P5" ? 1 : 3;
	try {
		img->width = std::stoi(token());
		img->height = std::stoi(token());
		img->maxval = std::stoi(token());
	} catch (const std::exception &) {
		return file + ": bad header";
	}
	if (pos >= bytes.size() || !std::isspace(static_cast<unsigned char>(bytes[pos])))
		return file + ": no whitespace after the header";
	++pos; /* exactly one whitespace byte before the raster */
	const std::size_t n = static_cast<std::size_t>(img->width) *
			      static_cast<std::size_t>(img->height) *
			      static_cast<std::size_t>(img->channels);
	if (img->width <= 0 || img->height <= 0 || img->maxval != 255)
		return file + ": unexpected size or maxval";
	if (bytes.size() - pos != n)
		return file + ": raster is " + std::to_string(bytes.size() - pos) +
		       " bytes, expected " + std::to_string(n);
	img->pixels.assign(bytes.begin() + static_cast<std::ptrdiff_t>(pos), bytes.end());
	return {};
}

bool isGreen(const std::uint8_t *p)
{
	return p[1] > 200 && p[0] < 60 && p[2] < 60;
}
bool isRed(const std::uint8_t *p)
{
	return p[0] > 200 && p[1] < 60 && p[2] < 60;
}
bool isYellow(const std::uint8_t *p)
{
	return p[0] > 200 && p[1] > 200 && p[2] < 60;
}

template<typename Pred>
int countNear(const Netpbm &img, double u, double v, double radius_px, Pred pred)
{
	int n = 0;
	const int r = static_cast<int>(std::ceil(radius_px));
	const int x0 = static_cast<int>(std::lround(u)), y0 = static_cast<int>(std::lround(v));
	for (int y = y0 - r; y <= y0 + r; ++y)
		for (int x = x0 - r; x <= x0 + r; ++x)
			if (img.inside(x, y) && std::hypot(x - u, y - v) <= radius_px &&
			    pred(img.at(x, y)))
				++n;
	return n;
}

/*
 * Is there a circle of pixels matching pred centred on (u, v)? March 32 rays
 * out from (u, v) to the first matching pixel: a circle around the point gives
 * the same distance on (nearly) every ray; a line through the point, a mark
 * elsewhere or an off-centre circle does not. *radius_px: the median distance.
 */
template<typename Pred>
bool circleAround(const Netpbm &img, double u, double v, Pred pred, double *radius_px)
{
	constexpr int kRays = 32;
	constexpr double kMaxRadius = 40.0;
	std::vector<double> hits;
	for (int k = 0; k < kRays; ++k) {
		const double a = 2.0 * M_PI * k / kRays;
		for (double s = 0.0; s <= kMaxRadius; s += 0.25) {
			const int x = static_cast<int>(std::lround(u + s * std::cos(a)));
			const int y = static_cast<int>(std::lround(v + s * std::sin(a)));
			if (img.inside(x, y) && pred(img.at(x, y))) {
				hits.push_back(s);
				break;
			}
		}
	}
	*radius_px = 0.0;
	if (hits.size() < kRays * 3 / 4)
		return false;
	std::vector<double> sorted = hits;
	std::nth_element(sorted.begin(),
			 sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
			 sorted.end());
	const double median = sorted[sorted.size() / 2];
	*radius_px = median;
	const auto on_circle = std::count_if(hits.begin(), hits.end(),
					     [&](double s) { return std::abs(s - median) <= 2.0; });
	return median >= 3.0 && on_circle >= kRays * 3 / 4;
}

} /* namespace */

TEST_F(Cli, HelpIsClear)
{
	const ToolRun top = run("--help", false);
	EXPECT_EQ(top.code, 0);
	EXPECT_NE(top.out.find("solve"), std::string::npos);
	EXPECT_NE(top.out.find("render"), std::string::npos);
	EXPECT_NE(top.out.find("calibrate"), std::string::npos);
	EXPECT_NE(top.out.find("Exit codes"), std::string::npos);
	/* Listed with its options whether or not this dockpose was built with OpenCV. */
	const ToolRun calibrate = run("calibrate --help", false);
	EXPECT_EQ(calibrate.code, 0);
	for (const char *opt : { "--grid", "--output", "images" })
		EXPECT_NE(calibrate.out.find(opt), std::string::npos) << opt;
	const ToolRun solve = run("solve --help", false);
	EXPECT_EQ(solve.code, 0);
	EXPECT_NE(solve.out.find("--threshold"), std::string::npos);
	EXPECT_NE(solve.out.find("--track"), std::string::npos);
	EXPECT_NE(solve.out.find("--annotate"), std::string::npos);
	const ToolRun render = run("render --help", false);
	EXPECT_EQ(render.code, 0);
	for (const char *opt :
	     { "--pose", "--range-mm", "--rpy", "--noise", "--gradient", "--hot-pixels",
	       "--reflections", "--glints", "--occlude", "--seed", "--count" })
		EXPECT_NE(render.out.find(opt), std::string::npos) << opt;
}

TEST_F(Cli, RenderThenSolveWedge)
{
	const std::string target = kData + "/wedge.json", camera = kData + "/cam1456.json";
	const std::string out = path("frames");
	const ToolRun r = run("render -t " + target + " -c " + camera +
			      " --pose 20,-15,800,5,10,-3 --pose=-60,40,1100,-8,-20,15" +
			      " --noise 2 --seed 5 -o " + out);
	ASSERT_EQ(r.code, 0) << r.err;
	const std::vector<json> truth = readTruth(out);
	ASSERT_EQ(truth.size(), 2u);
	EXPECT_EQ(truth[0].at("file"), "frame_0000.pgm");
	EXPECT_EQ(truth[1].at("file"), "frame_0001.pgm");
	EXPECT_EQ(truth[0].at("seed"), 5);
	EXPECT_EQ(truth[1].at("seed"), 6);
	EXPECT_LT((vec3(truth[0].at("t_mm")) - Eigen::Vector3d(20, -15, 800)).norm(), 1e-5);
	EXPECT_LT((vec3(truth[1].at("rpy_deg")) - Eigen::Vector3d(-8, -20, 15)).norm(), 1e-6);
	EXPECT_EQ(truth[0].at("led_px").size(), 6u);
	EXPECT_EQ(truth[0].at("visible_mask"), 63);

	const std::string f0 = out + "/frame_0000.pgm", f1 = out + "/frame_0001.pgm";
	const ToolRun s =
		run("solve --target " + target + " --camera " + camera + " " + f0 + " " + f1);
	EXPECT_EQ(s.code, 0) << s.err;
	ASSERT_EQ(s.lines.size(), 2u) << s.out;
	checkFound(s.lines[0], truth[0], f0, 4.0, 0.5);
	checkFound(s.lines[1], truth[1], f1, 5.5, 0.5);

	/* A fixed threshold finds the same pose. */
	const ToolRun fixed = run("solve -t " + target + " -c " + camera + " --threshold 60 " + f0);
	EXPECT_EQ(fixed.code, 0) << fixed.err;
	ASSERT_EQ(fixed.lines.size(), 1u);
	checkFound(fixed.lines[0], truth[0], f0, 4.0, 0.5);
	EXPECT_LT((vec3(fixed.lines[0].at("t_mm")) - vec3(s.lines[0].at("t_mm"))).norm(), 1.0);
}

TEST_F(Cli, RenderThenSolveCornerWithClutter)
{
	const std::string target = kData + "/corner.json", camera = kData + "/cam512.json";
	const std::string out = path("frames");
	const ToolRun r = run(
		"render -t " + target + " -c " + camera +
		" --range-mm 750 --rpy 6,12,5 --at 0.45,0.55 --reflections 3 --glints 2 --hot-pixels 20"
		" --noise 2 --gradient 20 --count 2 --seed 21 -o " +
		out);
	ASSERT_EQ(r.code, 0) << r.err;
	const std::vector<json> truth = readTruth(out);
	ASSERT_EQ(truth.size(), 2u);
	EXPECT_EQ(truth[0].at("t_mm"), truth[1].at("t_mm")); /* --count: same pose, new seed */
	EXPECT_EQ(truth[0].at("clutter_blobs"), 5);
	EXPECT_EQ(truth[0].at("visible_mask"), 127);

	const std::string f0 = out + "/frame_0000.pgm", f1 = out + "/frame_0001.pgm";
	const ToolRun s = run("solve -t " + target + " -c " + camera + " " + f0 + " " + f1);
	EXPECT_EQ(s.code, 0) << s.err;
	ASSERT_EQ(s.lines.size(), 2u) << s.out;
	checkFound(s.lines[0], truth[0], f0, 5.0, 0.6);
	checkFound(s.lines[1], truth[1], f1, 5.0, 0.6);
	EXPECT_GE(s.lines[0].at("blobs").get<int>(),
		  7 + 3); /* the reflections pass the shape filter */

	/* --track: the same answers, the second frame may come from the track. */
	const ToolRun tr =
		run("solve --track -t " + target + " -c " + camera + " " + f0 + " " + f1);
	EXPECT_EQ(tr.code, 0) << tr.err;
	ASSERT_EQ(tr.lines.size(), 2u);
	for (int i = 0; i < 2; ++i) {
		ASSERT_EQ(tr.lines[i].at("found"), true);
		EXPECT_LT((vec3(tr.lines[i].at("t_mm")) - vec3(truth[i].at("t_mm"))).norm(), 5.0);
	}
}

TEST_F(Cli, NoTargetInTheFrame)
{
	const std::string target = kData + "/wedge.json", camera = kData + "/cam512.json";
	const std::string out = path("frames");
	ASSERT_EQ(run("render -t " + target + " -c " + camera +
		      " --pose 0,0,900,0,180,0 --noise 2 -o " + out)
			  .code,
		  0);
	EXPECT_EQ(readTruth(out).at(0).at("visible_mask"), 0);
	const ToolRun s =
		run("solve -t " + target + " -c " + camera + " " + out + "/frame_0000.pgm");
	EXPECT_EQ(s.code, 0) << s.err;
	ASSERT_EQ(s.lines.size(), 1u);
	EXPECT_EQ(keys(s.lines[0]), kNotFoundKeys);
	EXPECT_EQ(s.lines[0].at("found"), false);
	EXPECT_EQ(s.lines[0].at("status"), "too_few_blobs");
	EXPECT_EQ(s.lines[0].at("blobs"), 0);
}

TEST_F(Cli, UnreadableImagesAreReportedAndTheRestSolved)
{
	const std::string target = kData + "/wedge.json", camera = kData + "/cam1456.json";
	const std::string out = path("frames");
	ASSERT_EQ(run("render -t " + target + " -c " + camera +
		      " --range-mm 900 --rpy 0,8,0 --count 2 -o " + out)
			  .code,
		  0);
	const std::string good0 = out + "/frame_0000.pgm", good1 = out + "/frame_0001.pgm";

	/* A truncated copy, an ASCII PGM, a frame of the wrong size, a missing file. */
	const std::string truncated = path("truncated.pgm");
	{
		std::ifstream in(good0, std::ios::binary);
		std::string bytes((std::istreambuf_iterator<char>(in)),
				  std::istreambuf_iterator<char>());
		std::ofstream o(truncated, std::ios::binary);
		o.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
	}
	const std::string ascii = path("ascii.pgm");
	std::ofstream(ascii) << "P2\n2 2\n255\n1 2 3 4\n";
	const std::string small = path("small");
	ASSERT_EQ(run("render -t " + target + " -c " + kData + "/cam512.json --range-mm 900 -o " +
		      small)
			  .code,
		  0);
	const std::string wrong_size = small + "/frame_0000.pgm";
	const std::string missing = path("no_such_frame.pgm");

	const ToolRun s = run("solve -t " + target + " -c " + camera + " " + good0 + " " + missing +
			      " " + truncated + " " + ascii + " " + wrong_size + " " + good1);
	EXPECT_EQ(s.code, 1);
	ASSERT_EQ(s.lines.size(), 6u) << s.out;
	const std::vector<json> truth = readTruth(out);
	checkFound(s.lines[0], truth[0], good0, 5.0, 0.5);
	checkFound(s.lines[5], truth[1], good1, 5.0, 0.5);

	struct Expect {
		std::string image, text;
	};
	const Expect bad[] = {
		{ missing, missing + ": cannot open" },
		{ truncated, truncated + ": truncated PGM" },
		{ ascii, ascii + ": ASCII PGM (P2) is not supported" },
		{ wrong_size,
		  wrong_size + ": the image is 512x512, the camera " + camera + " is 1456x1088" },
	};
	for (int i = 0; i < 4; ++i) {
		const json &line = s.lines[1 + i];
		SCOPED_TRACE(line.dump());
		EXPECT_EQ(keys(line), kErrorKeys);
		EXPECT_EQ(line.at("image"), bad[i].image);
		EXPECT_EQ(line.at("found"), false);
		EXPECT_EQ(line.at("error").get<std::string>().rfind(bad[i].text, 0), 0u);
		EXPECT_NE(s.err.find(bad[i].text), std::string::npos) << s.err;
	}

	/* Only good images: exit code 0. */
	EXPECT_EQ(run("solve -t " + target + " -c " + camera + " " + good1).code, 0);
}

/* Paths with quotes, backslashes, control characters, UTF-8 and broken UTF-8: each line starts with
 * the path as nlohmann::json writes it, found or not. */
TEST_F(Cli, ImagePathsAreEscapedLikeNlohmann)
{
	const std::string target = kData + "/wedge.json", camera = kData + "/cam512.json";
	const std::string out = path("frames");
	ASSERT_EQ(run("render -t " + target + " -c " + camera + " --range-mm 900 -o " + out).code,
		  0);
	const std::string frame = out + "/frame_0000.pgm";
	const std::vector<std::string> names = {
		"plain.pgm",
		"quote\"and\\backslash.pgm",
		"tab\tnewline\nctl\x01.pgm",
		"caf\xc3\xa9 \xe2\x82\xac.pgm",
		"broken\xff\xc3.pgm",
	};
	std::string args;
	std::vector<std::string> paths;
	for (const std::string &name : names) {
		paths.push_back(path(name));
		fs::copy_file(frame, paths.back());
		args += " '" + paths.back() + "'";
	}
	paths.push_back(path("missing \"\x02.pgm"));
	args += " '" + paths.back() + "'";

	const ToolRun s = run("solve -t " + target + " -c " + camera + args, false);
	EXPECT_EQ(s.code, 1) << s.err; /* the missing one */
	std::vector<std::string> lines;
	std::stringstream ss(s.out);
	for (std::string line; std::getline(ss, line);)
		lines.push_back(line);
	ASSERT_EQ(lines.size(), paths.size()) << s.out;
	for (std::size_t i = 0; i < paths.size(); ++i) {
		SCOPED_TRACE(lines[i]);
		const std::string head = "{\"image\": " + nlohmannDump(paths[i]) + ", \"found\": ";
		EXPECT_EQ(lines[i].substr(0, head.size()), head);
		const json j = json::parse(lines[i]);
		if (i + 1 < paths.size()) {
			EXPECT_EQ(j.at("found"), true);
		} else {
			const std::string error =
				paths[i] + ": cannot open (No such file or directory)";
			EXPECT_EQ(lines[i],
				  head + "false, \"error\": " + nlohmannDump(error) + "}");
		}
	}
}

TEST_F(Cli, BadModelOrCameraFileIsExitCode2)
{
	const std::string camera = kData + "/cam512.json", target = kData + "/wedge.json";
	const std::string image = path("x.pgm");
	std::ofstream(image) << "P5\n512 512\n255\n" << std::string(512 * 512, '\x0c');

	const std::string bad_target = path("bad_target.json");
	std::ofstream(bad_target)
		<< R"({"name": "t", "points": [[0,0,0],[1,0,0],[1,1,0],[0,1,0]]})";
	ToolRun r = run("solve -t " + bad_target + " -c " + camera + " " + image);
	EXPECT_EQ(r.code, 2);
	EXPECT_TRUE(r.out.empty()) << r.out;
	EXPECT_NE(r.err.find(bad_target + ": key 'faces' is missing"), std::string::npos) << r.err;

	const std::string short_point = path("short_point.json");
	std::ofstream(short_point)
		<< R"({"points": [[0,0,0],[1,0],[1,1,0],[0,1,0]], "faces": [[0,1,2,3]]})";
	r = run("solve -t " + short_point + " -c " + camera + " " + image);
	EXPECT_EQ(r.code, 2);
	EXPECT_NE(r.err.find(short_point + ": point 1 must be [x, y, z]"), std::string::npos)
		<< r.err;

	const std::string not_json = path("not_json.json");
	std::ofstream(not_json) << "{ points: oops";
	r = run("solve -t " + not_json + " -c " + camera + " " + image);
	EXPECT_EQ(r.code, 2);
	EXPECT_NE(r.err.find(not_json + ": not valid JSON"), std::string::npos) << r.err;

	r = run("solve -t " + path("missing.json") + " -c " + camera + " " + image);
	EXPECT_EQ(r.code, 2);
	EXPECT_NE(r.err.find(path("missing.json") + ": cannot open"), std::string::npos) << r.err;

	const std::string bad_camera = path("bad_camera.json");
	std::ofstream(bad_camera)
		<< R"({"width": 512, "height": 512, "fx": 1200, "cx": 255.5, "cy": 255.5})";
	r = run("solve -t " + target + " -c " + bad_camera + " " + image);
	EXPECT_EQ(r.code, 2);
	EXPECT_TRUE(r.out.empty()) << r.out;
	EXPECT_NE(r.err.find(bad_camera + ": key 'fy' is missing"), std::string::npos) << r.err;

	/* render refuses bad files the same way. */
	r = run("render -t " + bad_target + " -c " + camera + " --range-mm 500 -o " + path("o"));
	EXPECT_EQ(r.code, 2);
	EXPECT_NE(r.err.find(bad_target), std::string::npos) << r.err;
}

TEST_F(Cli, BadArgumentsAreExitCode2)
{
	const std::string files = " -t " + kData + "/wedge.json -c " + kData + "/cam512.json ";
	struct Case {
		std::string args, message;
	};
	const Case cases[] = {
		{ "", "A subcommand is required" },
		{ "frobnicate", "" },
		{ "solve" + files, "images is required" },
		{ "solve -c " + kData + "/cam512.json x.pgm", "--target is required" },
		{ "solve" + files + "--threshold high x.pgm",
		  "--threshold must be 'auto' or a level 1..255, not 'high'" },
		{ "solve" + files + "--threshold 0 x.pgm",
		  "--threshold must be 'auto' or a level 1..255" },
		{ "solve" + files + "--bogus x.pgm", "" },
		{ "render" + files + "-o " + path("o"), "one of --pose or --range-mm is required" },
		{ "render" + files + "--pose 1,2,3 -o " + path("o"),
		  "must have 6 comma-separated numbers, not 3" },
		{ "render" + files + "--pose 1,2,x,0,0,0 -o " + path("o"), "'x' is not a number" },
		{ "render" + files + "--pose 0,0,500,0,0,0 --range-mm 500 -o " + path("o"),
		  "excludes" },
		{ "render" + files + "--range-mm 500 --rpy 1,2 -o " + path("o"),
		  "--rpy \"1,2\" must have 3" },
		{ "render" + files + "--range-mm 500 --noise -1 -o " + path("o"), "" },
	};
	for (const Case &c : cases) {
		const ToolRun r = run(c.args);
		EXPECT_EQ(r.code, 2) << c.args << "\n" << r.err;
		EXPECT_TRUE(r.out.empty()) << c.args << "\n" << r.out;
		EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << "\n" << r.err;
	}
	EXPECT_FALSE(fs::exists(path("o")));
}

TEST_F(Cli, AnnotateMarksBlobsLedsAndFaces)
{
	const std::string target = kData + "/wedge.json", camera = kData + "/cam1456.json";
	const std::string out = path("frames");
	/* LED 0 hidden: the pose comes from the other face, LED 0 is predicted but not matched. */
	ASSERT_EQ(
		run("render -t " + target + " -c " + camera +
		    " --pose 40,-20,850,5,12,-4 --occlusion-mask 1 --reflections 2 --hot-pixels 10"
		    " --noise 2 --seed 11 -o " +
		    out)
			.code,
		0);
	const json truth = readTruth(out).at(0);
	ASSERT_EQ(truth.at("visible_mask"), 62);
	const std::string frame = out + "/frame_0000.pgm";
	const std::string ann = path("ann/nested"); /* created by the tool */

	const ToolRun s =
		run("solve -t " + target + " -c " + camera + " --annotate " + ann + " " + frame);
	ASSERT_EQ(s.code, 0) << s.err;
	ASSERT_EQ(s.lines.size(), 1u) << s.out;
	/* The JSON contract is unchanged by --annotate. */
	checkFound(s.lines[0], truth, frame, 4.0, 0.5);
	const ToolRun plain = run("solve -t " + target + " -c " + camera + " " + frame);
	EXPECT_EQ(plain.out, s.out);

	Netpbm ppm, pgm;
	ASSERT_EQ(readNetpbm(ann + "/frame_0000.ppm", &ppm), "");
	ASSERT_EQ(readNetpbm(frame, &pgm), "");
	EXPECT_EQ(ppm.magic, "P6");
	EXPECT_EQ(ppm.width, 1456);
	EXPECT_EQ(ppm.height, 1088);

	/* Every pixel is either the frame in grey or a marker colour. */
	int grey = 0, coloured = 0, other = 0;
	for (int y = 0; y < ppm.height; ++y)
		for (int x = 0; x < ppm.width; ++x) {
			const std::uint8_t *p = ppm.at(x, y);
			const std::uint8_t g = *pgm.at(x, y);
			if (p[0] == g && p[1] == g && p[2] == g)
				++grey;
			else if (isGreen(p) || isRed(p) || isYellow(p) || (p[0] == 0 && p[2] == 0))
				++coloured;
			else
				++other;
		}
	EXPECT_EQ(other, 0);
	EXPECT_GT(coloured, 500);
	EXPECT_GT(grey, ppm.width * ppm.height * 99 / 100);

	const json &led_px = truth.at("led_px");
	for (int i = 0; i < 6; ++i) {
		SCOPED_TRACE("LED " + std::to_string(i));
		const double u = led_px.at(i).at(0).get<double>(),
			     v = led_px.at(i).at(1).get<double>();
		double green_r = 0.0, red_r = 0.0;
		const bool green = circleAround(ppm, u, v, isGreen, &green_r);
		const bool red = circleAround(ppm, u, v, isRed, &red_r);
		if (i == 0) {
			/* Hidden: a red circle, and no blob there. */
			EXPECT_TRUE(red) << "median radius " << red_r;
			EXPECT_FALSE(green) << "median radius " << green_r;
			EXPECT_EQ(countNear(ppm, u, v, 3.0, isYellow), 0);
		} else {
			/* Matched: a green circle, and the blob's yellow cross at its centre. */
			EXPECT_TRUE(green) << "median radius " << green_r;
			EXPECT_FALSE(red) << "median radius " << red_r;
			EXPECT_GT(countNear(ppm, u, v, 2.5, isYellow), 0);
		}
	}

	/* The faces' outlines: green at the middle of every edge. */
	std::ifstream model_file(target);
	const json model = json::parse(model_file);
	for (const json &face : model.at("faces"))
		for (int e = 0; e < 4; ++e) {
			const int a = face.at(e).get<int>(), b = face.at((e + 1) % 4).get<int>();
			const double u = 0.5 * (led_px.at(a).at(0).get<double>() +
						led_px.at(b).at(0).get<double>());
			const double v = 0.5 * (led_px.at(a).at(1).get<double>() +
						led_px.at(b).at(1).get<double>());
			EXPECT_GT(countNear(ppm, u, v, 3.0, isGreen), 0)
				<< "edge " << a << "-" << b;
		}
	/* No red border when found. */
	EXPECT_FALSE(isRed(ppm.at(0, 0)));
	EXPECT_FALSE(isRed(ppm.at(ppm.width - 1, ppm.height / 2)));
}

TEST_F(Cli, AnnotateNotFoundHasARedBorder)
{
	const std::string target = kData + "/wedge.json", camera = kData + "/cam512.json";
	const std::string out = path("frames");
	/* Turned away: no LED in view, but hot pixels and reflections give blobs. */
	ASSERT_EQ(run("render -t " + target + " -c " + camera +
		      " --pose 0,0,900,0,180,0 --reflections 3 --noise 2 --seed 4 -o " + out)
			  .code,
		  0);
	ASSERT_EQ(readTruth(out).at(0).at("visible_mask"), 0);
	const std::string frame = out + "/frame_0000.pgm";
	const std::string missing = path("missing.pgm");
	const std::string ann = path("ann");

	const ToolRun s = run("solve -t " + target + " -c " + camera + " --annotate " + ann + " " +
			      missing + " " + frame);
	EXPECT_EQ(s.code, 1); /* the missing image */
	ASSERT_EQ(s.lines.size(), 2u) << s.out;
	EXPECT_EQ(keys(s.lines[0]), kErrorKeys);
	EXPECT_EQ(keys(s.lines[1]), kNotFoundKeys);
	EXPECT_EQ(s.lines[1].at("found"), false);
	EXPECT_FALSE(fs::exists(ann + "/missing.ppm"));

	Netpbm ppm, pgm;
	ASSERT_EQ(readNetpbm(ann + "/frame_0000.ppm", &ppm), "");
	ASSERT_EQ(readNetpbm(frame, &pgm), "");
	EXPECT_EQ(ppm.magic, "P6");
	ASSERT_EQ(ppm.width, 512);
	ASSERT_EQ(ppm.height, 512);

	/* A red border all round, at least 3 pixels deep. */
	int border = 0, border_red = 0, green = 0, yellow = 0;
	for (int y = 0; y < ppm.height; ++y)
		for (int x = 0; x < ppm.width; ++x) {
			const std::uint8_t *p = ppm.at(x, y);
			const int edge = std::min({ x, y, ppm.width - 1 - x, ppm.height - 1 - y });
			if (edge < 3) {
				++border;
				border_red += isRed(p) ? 1 : 0;
			}
			green += isGreen(p) ? 1 : 0;
			yellow += isYellow(p) ? 1 : 0;
		}
	EXPECT_EQ(border_red, border);
	EXPECT_EQ(green, 0);
	/* The blobs (reflections) are still marked when they pass the shape filter. */
	if (s.lines[1].at("blobs").get<int>() > 0)
		EXPECT_GT(yellow, 0);
	else
		EXPECT_EQ(yellow, 0);
	/* Inside: the frame in grey. */
	for (int y = 100; y < 400; y += 7)
		for (int x = 100; x < 400; x += 5) {
			const std::uint8_t *p = ppm.at(x, y);
			if (isYellow(p))
				continue;
			const std::uint8_t g = *pgm.at(x, y);
			ASSERT_TRUE(p[0] == g && p[1] == g && p[2] == g) << x << "," << y;
		}

	/* An --annotate path that is a file: bad arguments, nothing solved. */
	const std::string file = path("a_file");
	std::ofstream(file) << "x";
	const ToolRun bad =
		run("solve -t " + target + " -c " + camera + " --annotate " + file + " " + frame);
	EXPECT_EQ(bad.code, 2);
	EXPECT_TRUE(bad.out.empty()) << bad.out;
	EXPECT_NE(bad.err.find("cannot create the --annotate directory " + file), std::string::npos)
		<< bad.err;
}

#endif /* DOCKPOSE_TOOL */

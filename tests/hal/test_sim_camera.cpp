/* SPDX-License-Identifier: MIT */
/*
 * The simulated cameras.
 *
 * SyntheticCamera: frame size, sequences, timestamps on the frame grid,
 * frames that are exactly the renderer's frame of truthAt(sequence), drops
 * counted without touching a held buffer, lighting from a StrobeController
 * (LEDs lit, half lit or dark over the same clutter), fresh noise over
 * fixed clutter, controls in the metadata, stall -> Timeout, stop -> Stopped.
 *
 * ReplayCamera: frames of a folder in name order, Stopped at the end, loop,
 * and the errors for a missing or empty folder, a corrupt PGM, mixed sizes.
 *
 * Nothing here asserts on the machine's speed: timestamps are checked to lie
 * on the period grid (exact multiples), not to arrive on time.
 */
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "algo/io/model_json.h"
#include "algo/io/pgm.h"
#include "algo/pose.h"
#include "algo/synth/renderer.h"
#include "hal/clock.h"
#include "hal/sim/recording_strobe.h"
#include "hal/sim/replay_camera.h"
#include "hal/sim/synthetic_camera.h"
#include "hal/strobe.h"

namespace dockpose::hal {
namespace {

namespace fs = std::filesystem;

const std::string kData = DOCKPOSE_TEST_DATA;

TargetModel wedge()
{
	auto r = loadTargetModel(kData + "/wedge.json");
	EXPECT_TRUE(r.isOk()) << r.message();
	return r.value();
}

CameraIntrinsics cam512()
{
	auto r = loadCameraIntrinsics(kData + "/cam512.json");
	EXPECT_TRUE(r.isOk()) << r.message();
	return r.value();
}

/* A static scene (the target holds still) with clutter and no noise. */
SyntheticScene staticScene()
{
	SyntheticScene s;
	const double pose[6] = { 30.0, -20.0, 700.0, 5.0, 15.0, -3.0 };
	for (int i = 0; i < 6; ++i)
		s.from[i] = s.to[i] = pose[i];
	s.duration_s = 1.0;
	s.loop = false;
	s.reflections = 3;
	s.glints = 1;
	s.hot_pixels = 15;
	s.noise_sigma = 0.0;
	s.seed = 42;
	return s;
}

/* An approach: the target moves a lot from frame to frame. */
SyntheticScene movingScene()
{
	SyntheticScene s = staticScene();
	const double from[6] = { 150.0, -80.0, 1400.0, 4.0, 20.0, -5.0 };
	const double to[6] = { -40.0, 30.0, 400.0, -2.0, -10.0, 6.0 };
	for (int i = 0; i < 6; ++i) {
		s.from[i] = from[i];
		s.to[i] = to[i];
	}
	s.duration_s = 2.0;
	return s;
}

CameraConfig config(int frame_duration_us, int buffers = 4)
{
	CameraConfig c;
	c.frame_rate_hz = frame_duration_us > 0 ? 1e6 / frame_duration_us : 0.0;
	c.exposure_us = 2000;
	c.analogue_gain = 1.0;
	c.buffer_count = buffers;
	return c;
}

/* The render options the synthetic camera documents for a scene and LED gain. */
RenderOptions sceneOptions(const SyntheticScene &scene, double led_gain)
{
	RenderOptions o;
	o.noise_sigma = scene.noise_sigma;
	o.reflections = scene.reflections;
	o.glints = scene.glints;
	o.hot_pixels = scene.hot_pixels;
	o.clutter_seed = scene.seed;
	o.led_gain = led_gain;
	return o;
}

struct Diff {
	long differing = 0;
	int max_abs = 0;
};

Diff compare(const ImageView &a, const ImageView &b)
{
	Diff d;
	if (a.width != b.width || a.height != b.height) {
		d.differing = -1;
		return d;
	}
	for (int y = 0; y < a.height; ++y)
		for (int x = 0; x < a.width; ++x) {
			const int diff = std::abs(int(a.at(x, y)) - int(b.at(x, y)));
			d.differing += diff != 0;
			d.max_abs = std::max(d.max_abs, diff);
		}
	return d;
}

Image copyOf(const ImageView &v)
{
	Image img(v.width, v.height);
	for (int y = 0; y < v.height; ++y)
		for (int x = 0; x < v.width; ++x)
			img.at(x, y) = v.at(x, y);
	return img;
}

/* Collect n frames (copies), releasing each; fails the test on anything but a frame. */
struct Captured {
	std::uint64_t sequence;
	std::int64_t timestamp_ns;
	std::int64_t received_ns;
	std::int32_t exposure_us;
	float gain;
	Image image;
};

std::vector<Captured> capture(Camera &camera, int n)
{
	std::vector<Captured> out;
	for (int i = 0; i < n; ++i) {
		Frame f;
		const WaitResult r = camera.waitFrame(&f, 3000);
		EXPECT_EQ(r, WaitResult::Frame) << "frame " << i << ": " << camera.lastError();
		if (r != WaitResult::Frame)
			break;
		out.push_back({ f.sequence, f.timestamp_ns, monotonicNs(), f.exposure_us,
				f.analogue_gain, copyOf(f.image) });
		camera.releaseFrame(f);
	}
	return out;
}

TEST(SyntheticCamera, ConfigureChecksTheSize)
{
	SyntheticCamera camera(wedge(), cam512(), staticScene(), nullptr);
	EXPECT_NE(camera.name().find("synthetic"), std::string::npos);

	CameraConfig c = config(20000);
	c.width = 640;
	c.height = 480;
	Status s = camera.configure(c);
	ASSERT_FALSE(s.isOk());
	EXPECT_NE(s.message().find("640x480"), std::string::npos) << s.message();
	EXPECT_NE(s.message().find("512x512"), std::string::npos) << s.message();
	EXPECT_EQ(camera.lastError(), s.message());

	c = config(20000, 0);
	s = camera.configure(c);
	ASSERT_FALSE(s.isOk());
	EXPECT_NE(s.message().find("buffer_count"), std::string::npos) << s.message();

	c = config(20000);
	c.exposure_us = 30000;
	s = camera.configure(c);
	ASSERT_FALSE(s.isOk());
	EXPECT_NE(s.message().find("exposure_us 30000"), std::string::npos) << s.message();

	EXPECT_FALSE(camera.start().isOk()) << "start() before a successful configure()";

	c = config(20000);
	c.width = 512;
	c.height = 512;
	ASSERT_TRUE(camera.configure(c).isOk()) << camera.lastError();
	EXPECT_EQ(camera.width(), 512);
	EXPECT_EQ(camera.height(), 512);
	ASSERT_TRUE(camera.configure(config(20000)).isOk()) << "0x0 takes the intrinsics' size";

	Frame f;
	EXPECT_EQ(camera.waitFrame(&f, 10), WaitResult::Stopped) << "not started";
}

TEST(SyntheticCamera, TruthFollowsTheTrajectory)
{
	SyntheticScene scene = movingScene();
	scene.duration_s = 1.0;
	SyntheticCamera camera(wedge(), cam512(), scene, nullptr);
	ASSERT_TRUE(camera.configure(config(20000)).isOk()); /* 50 frames per second */

	auto expect_pose = [](const Pose &p, const double v[6]) {
		EXPECT_NEAR(p.t_mm.x(), v[0], 1e-9);
		EXPECT_NEAR(p.t_mm.y(), v[1], 1e-9);
		EXPECT_NEAR(p.t_mm.z(), v[2], 1e-9);
		const Eigen::Vector3d rpy = rollPanTiltDegFromRotation(p.R);
		EXPECT_NEAR(rpy.x(), v[3], 1e-9);
		EXPECT_NEAR(rpy.y(), v[4], 1e-9);
		EXPECT_NEAR(rpy.z(), v[5], 1e-9);
	};
	expect_pose(camera.truthAt(0), scene.from);
	expect_pose(camera.truthAt(50), scene.to);
	expect_pose(camera.truthAt(500), scene.to); /* holds */
	double mid[6], quarter[6];
	for (int i = 0; i < 6; ++i) {
		mid[i] = 0.5 * (scene.from[i] + scene.to[i]);
		quarter[i] = scene.from[i] + 0.26 * (scene.to[i] - scene.from[i]);
	}
	expect_pose(camera.truthAt(25), mid);
	expect_pose(camera.truthAt(13), quarter);

	scene.loop = true;
	SyntheticCamera looping(wedge(), cam512(), scene, nullptr);
	ASSERT_TRUE(looping.configure(config(20000)).isOk());
	expect_pose(looping.truthAt(50 + 25), mid);
	expect_pose(looping.truthAt(100), scene.from);
}

TEST(SyntheticCamera, FramesHaveTheSizeIncreasingSequencesAndGridTimestamps)
{
	constexpr int kPeriodUs = 20000;
	SyntheticCamera camera(wedge(), cam512(), movingScene(), nullptr);
	ASSERT_TRUE(camera.configure(config(kPeriodUs)).isOk()) << camera.lastError();
	const std::int64_t before = monotonicNs();
	ASSERT_TRUE(camera.start().isOk()) << camera.lastError();
	const auto frames = capture(camera, 12);
	camera.stop();
	ASSERT_EQ(frames.size(), 12u);

	const std::int64_t period_ns = kPeriodUs * 1000LL;
	for (std::size_t i = 0; i < frames.size(); ++i) {
		const Captured &f = frames[i];
		EXPECT_EQ(f.image.width(), 512);
		EXPECT_EQ(f.image.height(), 512);
		EXPECT_EQ(f.exposure_us, 2000);
		EXPECT_FLOAT_EQ(f.gain, 1.0f);
		EXPECT_GE(f.timestamp_ns, before);
		/* Delivered only after its exposure ended (start + exposure). */
		EXPECT_GE(f.received_ns, f.timestamp_ns + 2000 * 1000LL);
		if (i == 0)
			continue;
		EXPECT_GT(f.sequence, frames[i - 1].sequence);
		/* On the grid: the spacing is exactly a whole number of periods. */
		const std::int64_t dt = f.timestamp_ns - frames[i - 1].timestamp_ns;
		EXPECT_EQ(dt % period_ns, 0) << "dt " << dt;
		EXPECT_EQ(dt / period_ns,
			  static_cast<std::int64_t>(f.sequence - frames[i - 1].sequence));
	}
	const CameraStats s = camera.stats();
	EXPECT_EQ(s.frames, 12u);
	EXPECT_EQ(s.errors, 0u);

	Frame f;
	EXPECT_EQ(camera.waitFrame(&f, 100), WaitResult::Stopped) << "after stop()";
}

TEST(SyntheticCamera, FramesAreTheRendererFramesOfTruthAt)
{
	SyntheticScene scene = movingScene();
	scene.noise_sigma = 2.0; /* noise too: frames are exact for the documented seeds */
	SyntheticCamera camera(wedge(), cam512(), scene, nullptr);
	ASSERT_TRUE(camera.configure(config(20000)).isOk());
	ASSERT_TRUE(camera.start().isOk());
	const auto frames = capture(camera, 6);
	camera.stop();
	ASSERT_EQ(frames.size(), 6u);

	FrameRenderer renderer(wedge(), cam512());
	Image expected;
	int with_leds = 0;
	for (const Captured &f : frames) {
		RenderTruth truth;
		renderer.render(camera.truthAt(f.sequence), sceneOptions(scene, 1.0),
				SyntheticCamera::frameSeed(scene.seed, f.sequence), &expected,
				&truth);
		const Diff d = compare(f.image.view(), expected.view());
		EXPECT_EQ(d.differing, 0) << "frame " << f.sequence << ": max diff " << d.max_abs;
		with_leds += truth.visible_mask != 0;
		/*
		 * ... and not the frame of another pose: 30 mm aside (not truthAt of a
		 * later sequence, which on a loaded machine may already hold at `to`).
		 */
		Pose aside = camera.truthAt(f.sequence);
		aside.t_mm.x() += 30.0;
		renderer.render(aside, sceneOptions(scene, 1.0),
				SyntheticCamera::frameSeed(scene.seed, f.sequence), &expected);
		EXPECT_GT(compare(f.image.view(), expected.view()).differing, 0);
	}
	EXPECT_GT(with_leds, 0);
}

TEST(SyntheticCamera, NoiseIsFreshPerFrameOverFixedClutter)
{
	SyntheticScene scene = staticScene();
	scene.noise_sigma = 3.0;
	scene.hot_pixels = 40;
	SyntheticCamera camera(wedge(), cam512(), scene, nullptr);
	ASSERT_TRUE(camera.configure(config(20000)).isOk());
	ASSERT_TRUE(camera.start().isOk());
	const auto frames = capture(camera, 2);
	camera.stop();
	ASSERT_EQ(frames.size(), 2u);

	/* Fresh noise: the frames differ in many pixels, but only by noise (a few sigma). */
	const Diff d = compare(frames[0].image.view(), frames[1].image.view());
	EXPECT_GT(d.differing, 512 * 512 / 4);
	EXPECT_LE(d.max_abs, 45) << "clutter moved between frames";
	/* Hot pixels (isolated saturated pixels) sit at the same places in both frames. */
	const Image &a = frames[0].image;
	auto isolated_hot = [&](int x, int y) {
		if (a.at(x, y) != 255)
			return false;
		for (int dy = -1; dy <= 1; ++dy)
			for (int dx = -1; dx <= 1; ++dx)
				if ((dx || dy) && a.at(x + dx, y + dy) > 200)
					return false;
		return true;
	};
	int hot_both = 0, hot_first = 0;
	for (int y = 1; y < 511; ++y)
		for (int x = 1; x < 511; ++x)
			if (isolated_hot(x, y)) {
				++hot_first;
				hot_both += frames[1].image.at(x, y) == 255;
			}
	EXPECT_GE(hot_first, scene.hot_pixels - 2); /* a few may sit on the border rows */
	EXPECT_EQ(hot_both, hot_first);

	/* Another scene seed puts the clutter elsewhere (the comparison above can fail). */
	FrameRenderer renderer(wedge(), cam512());
	RenderOptions other = sceneOptions(scene, 1.0);
	other.clutter_seed = scene.seed + 1;
	Image elsewhere;
	renderer.render(camera.truthAt(frames[0].sequence), other,
			SyntheticCamera::frameSeed(scene.seed, frames[0].sequence), &elsewhere);
	EXPECT_GT(compare(frames[0].image.view(), elsewhere.view()).max_abs, 45);
}

TEST(SyntheticCamera, HeldBufferIsNeverOverwrittenAndDropsAreCounted)
{
	constexpr int kPeriodUs = 10000;
	SyntheticCamera camera(wedge(), cam512(), movingScene(), nullptr);
	ASSERT_TRUE(camera.configure(config(kPeriodUs, 3)).isOk());
	ASSERT_TRUE(camera.start().isOk());

	Frame held;
	ASSERT_EQ(camera.waitFrame(&held, 3000), WaitResult::Frame);
	const Image held_copy = copyOf(held.image);
	std::vector<std::uint64_t> sequences = { held.sequence };

	/* The frame thread "hangs" on this frame while the camera runs on. */
	std::this_thread::sleep_for(std::chrono::milliseconds(300));
	EXPECT_EQ(compare(held.image, held_copy.view()).differing, 0)
		<< "a held buffer was written";
	EXPECT_GT(camera.stats().dropped, 0u);

	/* The newest frames are waiting; the held one is still intact while we take them. */
	camera.setStall(true);
	std::this_thread::sleep_for(std::chrono::milliseconds(100));
	Frame f;
	while (camera.waitFrame(&f, 200) == WaitResult::Frame) {
		EXPECT_NE(f.slot, held.slot);
		EXPECT_NE(f.image.data, held.image.data);
		sequences.push_back(f.sequence);
		camera.releaseFrame(f);
	}
	EXPECT_EQ(compare(held.image, held_copy.view()).differing, 0);
	camera.releaseFrame(held);
	const CameraStats s = camera.stats();
	camera.stop();

	ASSERT_GE(sequences.size(), 2u);
	/* Every frame before the last one delivered was either delivered or dropped. */
	std::uint64_t gaps = sequences[0];
	for (std::size_t i = 1; i < sequences.size(); ++i) {
		ASSERT_GT(sequences[i], sequences[i - 1]);
		gaps += sequences[i] - sequences[i - 1] - 1;
	}
	EXPECT_EQ(s.dropped, gaps);
	EXPECT_EQ(s.frames, sequences.size());
	/* The frames waiting were the newest: well past the held one. */
	EXPECT_GT(sequences.back(), held.sequence + 10);
}

TEST(SyntheticCamera, StallTimesOutAndResumesOnTheGrid)
{
	constexpr int kPeriodUs = 10000;
	SyntheticCamera camera(wedge(), cam512(), staticScene(), nullptr);
	ASSERT_TRUE(camera.configure(config(kPeriodUs)).isOk());
	ASSERT_TRUE(camera.start().isOk());
	auto first = capture(camera, 1);
	ASSERT_EQ(first.size(), 1u);

	camera.setStall(true);
	Frame f;
	/* Drain what was captured before the stall, then nothing comes. */
	WaitResult r;
	std::uint64_t last_before = first[0].sequence;
	while ((r = camera.waitFrame(&f, 300)) == WaitResult::Frame) {
		last_before = f.sequence;
		camera.releaseFrame(f);
	}
	EXPECT_EQ(r, WaitResult::Timeout);
	EXPECT_EQ(camera.waitFrame(&f, 100), WaitResult::Timeout);

	camera.setStall(false);
	auto after = capture(camera, 2);
	ASSERT_EQ(after.size(), 2u);
	EXPECT_GT(after[0].sequence, last_before + 10) << "the stalled frames are a sequence gap";
	EXPECT_EQ((after[0].timestamp_ns - first[0].timestamp_ns) % (kPeriodUs * 1000LL), 0);
	camera.stop();
	EXPECT_EQ(camera.waitFrame(&f, 10), WaitResult::Stopped);

	/* And it starts again. */
	ASSERT_TRUE(camera.start().isOk());
	EXPECT_EQ(capture(camera, 1).size(), 1u);
	camera.stop();
}

TEST(SyntheticCamera, ControlsAppearInTheMetadata)
{
	SyntheticCamera camera(wedge(), cam512(), staticScene(), nullptr);
	ASSERT_TRUE(camera.configure(config(20000)).isOk());
	EXPECT_FALSE(camera.setControls(0, 1.0).isOk());
	EXPECT_FALSE(camera.setControls(25000, 1.0).isOk()) << "longer than the frame";
	const Status bad_gain = camera.setControls(1000, -1.0);
	ASSERT_FALSE(bad_gain.isOk());
	EXPECT_NE(bad_gain.message().find("analogue_gain"), std::string::npos);

	ASSERT_TRUE(camera.start().isOk());
	ASSERT_TRUE(camera.setControls(8000, 4.0).isOk());
	/* Takes effect within a few frames. */
	bool seen = false;
	for (int i = 0; i < 10 && !seen; ++i) {
		Frame f;
		ASSERT_EQ(camera.waitFrame(&f, 3000), WaitResult::Frame);
		seen = f.exposure_us == 8000 && f.analogue_gain == 4.0f;
		camera.releaseFrame(f);
	}
	EXPECT_TRUE(seen);
	camera.stop();
}

/* Lighting from a StrobeController driving a RecordingStrobe: dark frames, then lit ones. */
TEST(SyntheticCamera, LightingFollowsTheStrobeController)
{
	RecordingStrobe strobe;
	ASSERT_TRUE(strobe.open().isOk());
	StrobeController control(&strobe, 60000);
	ASSERT_TRUE(control.start().isOk());

	const SyntheticScene scene = staticScene();
	SyntheticCamera camera(wedge(), cam512(), scene, &control);
	constexpr int kExposureUs = 2000;
	ASSERT_TRUE(camera.configure(config(20000)).isOk());
	ASSERT_TRUE(camera.start().isOk());
	auto frames = capture(camera, 5);
	control.kick();
	control.setOn(true);
	auto lit = capture(camera, 6);
	control.kick();
	frames.insert(frames.end(), lit.begin(), lit.end());
	camera.stop();
	control.stop();
	ASSERT_EQ(frames.size(), 11u);

	FrameRenderer renderer(wedge(), cam512());
	Image expected;
	RenderTruth truth;
	const Image *unlit = nullptr, *full = nullptr;
	int n_lit = 0, n_unlit = 0;
	for (const Captured &f : frames) {
		/* The controller's answer for this exposure (its history covers these frames). */
		const Lighting l =
			control.lighting(f.timestamp_ns, f.timestamp_ns + kExposureUs * 1000LL);
		const double gain = l == Lighting::Lit ? 1.0 : l == Lighting::Mixed ? 0.5 : 0.0;
		renderer.render(camera.truthAt(f.sequence), sceneOptions(scene, gain),
				SyntheticCamera::frameSeed(scene.seed, f.sequence), &expected,
				&truth);
		EXPECT_EQ(compare(f.image.view(), expected.view()).differing, 0)
			<< "frame " << f.sequence << " lighting " << static_cast<int>(l);
		if (l == Lighting::Lit) {
			++n_lit;
			full = &f.image;
		} else if (l == Lighting::Unlit) {
			++n_unlit;
			unlit = &f.image;
		}
	}
	ASSERT_GT(n_unlit, 0) << "no frame was dark";
	ASSERT_GT(n_lit, 0) << "no frame was lit";
	ASSERT_NE(truth.visible_mask, 0u);

	/* Dark frames show no LEDs; lit frames do. */
	for (std::size_t i = 0; i < truth.led_px.size(); ++i) {
		if (!(truth.visible_mask & (1u << i)))
			continue;
		const int x = static_cast<int>(std::lround(truth.led_px[i].x()));
		const int y = static_cast<int>(std::lround(truth.led_px[i].y()));
		EXPECT_GT(full->at(x, y), unlit->at(x, y) + 30) << "LED " << i;
		EXPECT_LT(unlit->at(x, y), 40) << "LED " << i;
	}
	/* The same clutter in both: they differ only around the LEDs. */
	int clutter_saturated = 0, differ_near = 0, differ_away = 0;
	for (int y = 0; y < 512; ++y)
		for (int x = 0; x < 512; ++x) {
			clutter_saturated += unlit->at(x, y) == 255;
			if (full->at(x, y) == unlit->at(x, y))
				continue;
			double nearest = 1e9;
			for (std::size_t i = 0; i < truth.led_px.size(); ++i)
				if (truth.visible_mask & (1u << i))
					nearest = std::min(
						nearest,
						(truth.led_px[i] - Eigen::Vector2d(x, y)).norm());
			(nearest < 25.0 ? differ_near : differ_away)++;
		}
	EXPECT_GT(differ_near, 0);
	EXPECT_EQ(differ_away, 0) << "pixels away from the LEDs differ: the clutter moved";
	EXPECT_GE(clutter_saturated, scene.hot_pixels) << "the dark frame has its clutter";

	/* The strobe was driven: off at start, then on. */
	const auto events = strobe.events();
	ASSERT_FALSE(events.empty());
	EXPECT_TRUE(events.front().on);
}

/* ---- ReplayCamera ---- */

class TempDir
{
public:
	TempDir()
	{
		std::string pattern =
			(fs::temp_directory_path() / "dockpose_replay_XXXXXX").string();
		if (mkdtemp(pattern.data()))
			path_ = pattern;
	}
	~TempDir()
	{
		std::error_code ec;
		if (!path_.empty())
			fs::remove_all(path_, ec);
	}
	const std::string &path() const { return path_; }

private:
	std::string path_;
};

/* A frame whose pixels say which it is. */
Image patternFrame(int index, int width = 64, int height = 48)
{
	Image img(width, height);
	for (int y = 0; y < height; ++y)
		for (int x = 0; x < width; ++x)
			img.at(x, y) = static_cast<std::uint8_t>((index * 37 + x + 3 * y) & 0xff);
	return img;
}

void writeFrames(const std::string &dir, int count)
{
	for (int i = 0; i < count; ++i) {
		char name[32];
		std::snprintf(name, sizeof(name), "/frame_%04d.pgm", i);
		ASSERT_EQ(writePgm(dir + name, patternFrame(i).view()).message(), "");
	}
}

TEST(ReplayCamera, DeliversTheFolderInOrderThenStops)
{
	TempDir dir;
	ASSERT_FALSE(dir.path().empty());
	writeFrames(dir.path(), 6);
	std::ofstream(dir.path() + "/notes.txt") << "not a frame\n";
	ASSERT_EQ(writePgm(dir.path() + "/other.pgm", patternFrame(99).view()).message(), "");

	ReplayCamera camera(dir.path(), false);
	/* 16 buffers hold the whole replay: nothing is dropped however slow this thread is. */
	ASSERT_TRUE(camera.configure(config(5000, 16)).isOk()) << camera.lastError();
	EXPECT_EQ(camera.frameCount(), 6u);
	EXPECT_EQ(camera.width(), 64);
	EXPECT_EQ(camera.height(), 48);
	ASSERT_TRUE(camera.start().isOk());

	std::vector<Captured> frames = capture(camera, 6);
	ASSERT_EQ(frames.size(), 6u);
	Frame f;
	EXPECT_EQ(camera.waitFrame(&f, 2000), WaitResult::Stopped) << "after the last frame";
	EXPECT_EQ(camera.waitFrame(&f, 10), WaitResult::Stopped);
	for (std::size_t i = 0; i < frames.size(); ++i) {
		EXPECT_EQ(frames[i].sequence, i);
		EXPECT_EQ(compare(frames[i].image.view(), patternFrame(static_cast<int>(i)).view())
				  .differing,
			  0)
			<< "frame " << i;
		EXPECT_EQ(frames[i].timestamp_ns - frames[0].timestamp_ns,
			  static_cast<std::int64_t>(i) * 5000000);
	}
	EXPECT_EQ(camera.stats().dropped, 0u);
	camera.stop();

	/* Again from the start after a restart. */
	ASSERT_TRUE(camera.start().isOk());
	frames = capture(camera, 1);
	ASSERT_EQ(frames.size(), 1u);
	EXPECT_EQ(frames[0].sequence, 0u);
	camera.stop();
}

TEST(ReplayCamera, LoopsWithSequencesCountingOn)
{
	TempDir dir;
	writeFrames(dir.path(), 5);
	ReplayCamera camera(dir.path(), true);
	ASSERT_TRUE(camera.configure(config(5000, 16)).isOk()) << camera.lastError();
	ASSERT_TRUE(camera.start().isOk());
	const auto frames = capture(camera, 13);
	camera.stop();
	ASSERT_EQ(frames.size(), 13u);
	for (std::size_t i = 0; i < frames.size(); ++i) {
		EXPECT_EQ(frames[i].sequence, i);
		EXPECT_EQ(compare(frames[i].image.view(),
				  patternFrame(static_cast<int>(i % 5)).view())
				  .differing,
			  0)
			<< "frame " << i;
	}
}

TEST(ReplayCamera, ErrorsNameTheFolderOrFile)
{
	TempDir dir;
	const std::string missing = dir.path() + "/nowhere";
	{
		ReplayCamera camera(missing, false);
		const Status s = camera.configure(config(5000));
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find(missing), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("does not exist"), std::string::npos) << s.message();
		EXPECT_FALSE(camera.start().isOk());
	}
	{
		const std::string empty = dir.path() + "/empty";
		fs::create_directory(empty);
		std::ofstream(empty + "/readme.txt") << "x";
		ReplayCamera camera(empty, false);
		const Status s = camera.configure(config(5000));
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find(empty), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("no frame_*.pgm"), std::string::npos) << s.message();
	}
	{
		const std::string corrupt = dir.path() + "/corrupt";
		fs::create_directory(corrupt);
		writeFrames(corrupt, 3);
		std::ofstream(corrupt + "/frame_0001.pgm", std::ios::binary | std::ios::trunc)
			<< "P5\n64 48\n255\nshort";
		ReplayCamera camera(corrupt, false);
		const Status s = camera.configure(config(5000));
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find("frame_0001.pgm"), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();
	}
	{
		const std::string mixed = dir.path() + "/mixed";
		fs::create_directory(mixed);
		writeFrames(mixed, 3);
		ASSERT_EQ(writePgm(mixed + "/frame_0002.pgm", patternFrame(2, 32, 32).view())
				  .message(),
			  "");
		ReplayCamera camera(mixed, false);
		const Status s = camera.configure(config(5000));
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find("frame_0002.pgm"), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("32x32"), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("64x48"), std::string::npos) << s.message();
	}
	{
		const std::string good = dir.path() + "/good";
		fs::create_directory(good);
		writeFrames(good, 2);
		ReplayCamera camera(good, false);
		CameraConfig c = config(5000);
		c.width = 640;
		c.height = 480;
		const Status s = camera.configure(c);
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find("64x48"), std::string::npos) << s.message();
	}
}

} /* namespace */
} /* namespace dockpose::hal */

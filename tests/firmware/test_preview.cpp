/* SPDX-License-Identifier: MIT */
/*
 * The operator preview's shared-memory ring (firmware/preview.h): a frame
 * published with the pipeline's findings reads back whole, the seqlock never
 * hands a reader a torn frame while the writer runs flat out, readers get
 * clear errors, the worker publishes off the caller's thread and hands the
 * frame back, only while the frame loop is idle (a publish in steps is
 * invisible until its last row), and the daemon publishes at
 * preview.rate_hz when enabled.
 */
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "algo/io/model_json.h"
#include "algo/pipeline.h"
#include "algo/synth/renderer.h"
#include "board/sim/sim_board.h"
#include "firmware/config.h"
#include "firmware/daemon.h"
#include "firmware/preview.h"
#include "firmware/preview_worker.h"
#include "hal/sim/loopback_can_bus.h"

namespace dockpose::firmware {
namespace {

using namespace std::chrono_literals;

std::string uniqueName(const char *what)
{
	return std::string("dockpose-test-") + what + "-" + std::to_string(getpid());
}

/* The wedge at 600 mm on the 512 px camera, noise-free, solved: the worker tests' frame. */
struct WedgeScene {
	WedgeScene()
		: target(loadTargetModel(std::string(DOCKPOSE_TEST_DATA) + "/wedge.json").value()),
		  camera(loadCameraIntrinsics(std::string(DOCKPOSE_TEST_DATA) + "/cam512.json")
				 .value()),
		  pipeline(target, camera)
	{
		FrameRenderer renderer(target, camera);
		renderer.render(poseAt(camera, target, 600.0, { 5.0, 10.0, -3.0 }), RenderOptions{},
				3, &image);
		result = &pipeline.process(image.view());
	}
	TargetModel target;
	CameraIntrinsics camera;
	Image image;
	Pipeline pipeline;
	const PoseResult *result = nullptr;
};

TEST(Preview, FactorAndBoxDownscale)
{
	EXPECT_EQ(previewFactor(640, 320), 2);
	EXPECT_EQ(previewFactor(1456, 320), 5);
	EXPECT_EQ(previewFactor(1456, 640), 3);
	EXPECT_EQ(previewFactor(320, 640), 1);
	/* A 4x2 image by 2: the mean of each 2x2 block, to within one level (the mean of the
	 * rows' rounded means). */
	const std::uint8_t pixels[] = { 0, 2, 10, 20, 1, 3, 30, 41 };
	ImageView in{ pixels, 4, 2, 4 };
	std::uint8_t out[2] = {};
	downscaleBox(in, 2, out, 2, 1);
	EXPECT_NEAR(out[0], 1.5, 1.0); /* (0 + 2 + 1 + 3) / 4 */
	EXPECT_NEAR(out[1], 25.25, 1.0); /* (10 + 20 + 30 + 41) / 4 */
	/* By 3: exact, rounded. */
	std::uint8_t nine[9 * 2];
	for (int i = 0; i < 18; ++i)
		nine[i] = static_cast<std::uint8_t>(10 * i);
	std::uint8_t by3 = 0;
	downscaleBox(ImageView{ nine, 6, 3, 6 }, 3, &by3, 1, 1);
	/* rows 0..2, columns 0..2 of a 6-wide image: 0 10 20, 60 70 80, 120 130 140 */
	EXPECT_EQ(by3, 70);
	/* Every 2x2 block of a random image within one level of its mean. */
	std::vector<std::uint8_t> img(64 * 32), half(32 * 16);
	for (std::size_t i = 0; i < img.size(); ++i)
		img[i] = static_cast<std::uint8_t>((i * 7919u) % 251u);
	downscaleBox(ImageView{ img.data(), 64, 32, 64 }, 2, half.data(), 32, 16);
	for (int y = 0; y < 16; ++y)
		for (int x = 0; x < 32; ++x) {
			const auto at = [&](int yy, int xx) {
				return img[static_cast<std::size_t>(yy * 64 + xx)];
			};
			const double mean = (at(2 * y, 2 * x) + at(2 * y, 2 * x + 1) +
					     at(2 * y + 1, 2 * x) + at(2 * y + 1, 2 * x + 1)) /
					    4.0;
			ASSERT_NEAR(half[static_cast<std::size_t>(y * 32 + x)], mean, 1.0)
				<< x << "," << y;
		}
}

TEST(Preview, APublishedFrameReadsBackWithThePipelinesFindings)
{
	const std::string data = DOCKPOSE_TEST_DATA;
	const TargetModel target = loadTargetModel(data + "/wedge.json").value();
	const CameraIntrinsics camera = loadCameraIntrinsics(data + "/cam512.json").value();
	FrameRenderer renderer(target, camera);
	RenderOptions options;
	options.noise_sigma = 2.0;
	options.reflections = 3;
	Image frame;
	renderer.render(poseAt(camera, target, 600.0, { 5.0, 10.0, -3.0 }), options, 11, &frame);
	Pipeline pipeline(target, camera);
	const PoseResult &result = pipeline.process(frame.view());
	ASSERT_TRUE(result.found) << poseStatusName(result.status);

	const std::string name = uniqueName("roundtrip");
	PreviewWriter writer;
	ASSERT_TRUE(writer.open(name, camera.width, camera.height, 200).isOk());
	PreviewReader reader;
	ASSERT_TRUE(reader.open(name).isOk());
	auto got = std::make_unique<PreviewFrame>();
	EXPECT_EQ(reader.latest(got.get()), 0u) << "nothing published yet";

	writer.publish(frame.view(), 1234, 5678, pipeline, &result, { 2, 0x10 });
	ASSERT_EQ(reader.latest(got.get()), 1u);
	EXPECT_EQ(reader.latest(got.get(), 1), 0u) << "nothing newer than 1";
	EXPECT_EQ(got->frame_counter, 1234u);
	EXPECT_EQ(got->timestamp_ns, 5678);
	EXPECT_EQ(got->state, 2);
	EXPECT_EQ(got->faults, 0x10);
	/* 512 px at most 200 wide: factor 3, 170 x 170. */
	EXPECT_EQ(got->width, 170);
	EXPECT_EQ(got->height, 170);
	EXPECT_EQ(got->full_width, 512);
	std::vector<std::uint8_t> expected(170u * 170u);
	downscaleBox(frame.view(), 3, expected.data(), 170, 170);
	EXPECT_TRUE(std::equal(expected.begin(), expected.end(), got->pixels));

	EXPECT_EQ(got->found, 1);
	EXPECT_EQ(got->leds_used, result.leds_used);
	EXPECT_EQ(got->led_mask, result.led_mask);
	for (int i = 0; i < 3; ++i) {
		EXPECT_DOUBLE_EQ(got->t_mm[i], result.t_mm[i]);
		EXPECT_DOUBLE_EQ(got->sigma_t_mm[i], result.sigma_t_mm[i]);
	}
	EXPECT_EQ(got->blob_count, pipeline.blobs().size());
	EXPECT_EQ(got->led_count, target.points_mm.size());
	EXPECT_EQ(got->face_count, target.faces.size());
	/* Each matched LED's projection is on a matched blob (the pose's rms is sub-pixel). */
	int matched_leds = 0, matched_blobs = 0;
	for (std::uint32_t i = 0; i < got->led_count; ++i) {
		const PreviewLed &led = got->leds[i];
		EXPECT_EQ(led.index, i);
		if (!led.matched)
			continue;
		++matched_leds;
		EXPECT_EQ(led.visible, 1);
		double best = 1e9;
		for (std::uint32_t k = 0; k < got->blob_count; ++k)
			if (got->blobs[k].matched)
				best = std::min(best, static_cast<double>(std::hypot(
							      got->blobs[k].u_px - led.u_px,
							      got->blobs[k].v_px - led.v_px)));
		EXPECT_LT(best, 1.0) << "LED " << i;
	}
	for (std::uint32_t k = 0; k < got->blob_count; ++k)
		matched_blobs += got->blobs[k].matched;
	EXPECT_EQ(matched_leds, result.leds_used);
	EXPECT_EQ(matched_blobs, result.leds_used);

	/* No pose: the frame still goes out, without pose or LEDs. */
	writer.publish(frame.view(), 1235, 0, pipeline, nullptr, { 1, 0 });
	ASSERT_EQ(reader.latest(got.get()), 2u);
	EXPECT_EQ(got->found, 0);
	EXPECT_EQ(got->leds_used, 0);
	for (std::uint32_t i = 0; i < got->led_count; ++i)
		EXPECT_EQ(got->leds[i].matched + got->leds[i].visible, 0);
}

/* The worker: a handed-over frame is published off the caller's thread, with the same bytes as
 * publish() gives, and handed back; while it holds one, the next is skipped and counted. */
TEST(Preview, TheWorkerPublishesOffTheFrameThreadAndHandsTheFrameBack)
{
	WedgeScene scene;
	const CameraIntrinsics &camera = scene.camera;
	const Image &image = scene.image;
	Pipeline &pipeline = scene.pipeline;
	const PoseResult &result = *scene.result;
	ASSERT_TRUE(result.found) << poseStatusName(result.status);

	const std::string name = uniqueName("worker");
	PreviewWriter writer;
	ASSERT_TRUE(writer.open(name, camera.width, camera.height, 256).isOk());
	PreviewReader reader;
	ASSERT_TRUE(reader.open(name).isOk());
	PreviewWorker worker;
	hal::Frame back;
	EXPECT_FALSE(worker.submit(hal::Frame{}, pipeline, &result, {})) << "not started";
	EXPECT_EQ(worker.skipped(), 1u);
	ASSERT_TRUE(worker.start(&writer, pipeline).isOk());

	hal::Frame frame;
	frame.image = image.view();
	frame.sequence = 77;
	frame.timestamp_ns = 99;
	frame.slot = 2;
	ASSERT_TRUE(worker.submit(frame, pipeline, &result, { 3, 0x01 }));
	/* Busy or done but not reclaimed: the next one is skipped, never waited for. */
	EXPECT_FALSE(worker.submit(frame, pipeline, &result, { 3, 0x01 }));
	EXPECT_EQ(worker.skipped(), 2u);
	ASSERT_TRUE(worker.drain(&back));
	EXPECT_FALSE(worker.pending()) << "drained: taken up and done";
	EXPECT_EQ(back.slot, 2) << "the held frame comes back to be released";
	EXPECT_EQ(back.sequence, 77u);
	EXPECT_FALSE(worker.reclaim(&back)) << "handed back once";
	EXPECT_EQ(worker.handed(), 1u);

	auto got = std::make_unique<PreviewFrame>();
	ASSERT_EQ(reader.latest(got.get()), 1u);
	EXPECT_EQ(got->frame_counter, 77u);
	EXPECT_EQ(got->timestamp_ns, 99);
	EXPECT_EQ(got->state, 3);
	EXPECT_EQ(got->faults, 0x01);
	EXPECT_EQ(got->found, 1);
	EXPECT_EQ(got->leds_used, result.leds_used);
	EXPECT_EQ(got->blob_count, pipeline.blobs().size());
	/* The same pixels and findings as publish() in the caller's thread. */
	const std::string inline_name = uniqueName("worker-inline");
	PreviewWriter inline_writer;
	ASSERT_TRUE(inline_writer.open(inline_name, camera.width, camera.height, 256).isOk());
	inline_writer.publish(image.view(), 77, 99, pipeline, &result, { 3, 0x01 });
	PreviewReader inline_reader;
	ASSERT_TRUE(inline_reader.open(inline_name).isOk());
	auto want = std::make_unique<PreviewFrame>();
	ASSERT_EQ(inline_reader.latest(want.get()), 1u);
	ASSERT_EQ(got->width, want->width);
	ASSERT_EQ(got->height, want->height);
	EXPECT_TRUE(std::equal(want->pixels,
			       want->pixels + static_cast<std::size_t>(want->width) * want->height,
			       got->pixels));
	for (std::uint32_t i = 0; i < got->led_count; ++i) {
		EXPECT_EQ(got->leds[i].u_px, want->leds[i].u_px);
		EXPECT_EQ(got->leds[i].matched, want->leds[i].matched);
	}

	/* Many frames in a row, reclaimed as they come back: each one is published. */
	int handed = 1;
	for (int i = 0; i < 50; ++i) {
		frame.sequence = 100 + static_cast<std::uint64_t>(i);
		if (!worker.submit(frame, pipeline, &result, {}))
			continue;
		++handed;
		while (!worker.reclaim(&back))
			std::this_thread::yield();
	}
	worker.stop();
	EXPECT_EQ(handed, 51);
	EXPECT_EQ(writer.published(), 51u);
	EXPECT_FALSE(worker.drain(&back)) << "nothing left in hand after the last reclaim";
}

/* A publish in steps (the worker's, paused while the frame loop works): nothing of it reaches a
 * reader before its last row, however long it stops between steps; then the same frame as
 * publish() gives. */
TEST(Preview, APublishInStepsIsInvisibleUntilItsLastRow)
{
	WedgeScene scene;
	const TargetModel &target = scene.target;
	const CameraIntrinsics &camera = scene.camera;
	const Image &image = scene.image;
	Pipeline &pipeline = scene.pipeline;
	const PoseResult &result = *scene.result;
	ASSERT_TRUE(result.found) << poseStatusName(result.status);
	PreviewSnapshot snapshot;
	previewSnapshot(&snapshot, 41, 42, image.width(), image.height(), pipeline, &result,
			{ 2, 0 });

	const std::string name = uniqueName("steps");
	PreviewWriter writer;
	ASSERT_TRUE(writer.open(name, camera.width, camera.height, 256).isOk());
	PreviewReader reader;
	ASSERT_TRUE(reader.open(name).isOk());
	const int rows = writer.rowsPerBlock();
	EXPECT_GE(rows, 1);
	EXPECT_LT(rows, writer.height()) << "a step is part of the frame";

	writer.publish(image.view(), 40, 0, pipeline, &result, { 2, 0 }); /* the frame before */
	auto got = std::make_unique<PreviewFrame>();
	ASSERT_EQ(reader.latest(got.get()), 1u);
	EXPECT_FALSE(writer.beginPublish(snapshot, ImageView{}, target, pipeline.camera()))
		<< "no image: nothing begun";
	ASSERT_TRUE(writer.beginPublish(snapshot, image.view(), target, pipeline.camera()));
	int steps = 0;
	for (bool done = false; !done; ++steps) {
		/* Between steps: the frame before is still the latest, whole. */
		EXPECT_EQ(writer.published(), 1u);
		ASSERT_EQ(reader.latest(got.get()), 1u);
		EXPECT_EQ(got->frame_counter, 40u);
		done = writer.publishRows(rows);
	}
	EXPECT_EQ(steps, (writer.height() + rows - 1) / rows);
	ASSERT_EQ(reader.latest(got.get(), 1), 2u);
	EXPECT_EQ(got->frame_counter, 41u);
	EXPECT_EQ(got->timestamp_ns, 42);

	/* The same pixels and findings as publish() in one go. */
	writer.publish(image.view(), 41, 42, pipeline, &result, { 2, 0 });
	auto want = std::make_unique<PreviewFrame>();
	ASSERT_EQ(reader.latest(want.get(), 2), 3u);
	EXPECT_TRUE(std::equal(want->pixels,
			       want->pixels + static_cast<std::size_t>(want->width) * want->height,
			       got->pixels));
	EXPECT_EQ(got->led_count, want->led_count);
	for (std::uint32_t i = 0; i < got->led_count; ++i)
		EXPECT_EQ(got->leds[i].matched, want->leds[i].matched);
}

/* The worker does its pixel work only while the frame loop is idle: a frame handed over while
 * the loop is busy is not published, however long the loop stays busy, and comes out once the
 * loop goes idle; drain() (the frame thread waiting) lets it finish. Behaviour, not timing: the
 * waits are bounded only to fail rather than hang. */
TEST(Preview, TheWorkerPublishesOnlyWhileTheFrameLoopIsIdle)
{
	WedgeScene scene;
	const CameraIntrinsics &camera = scene.camera;
	const Image &image = scene.image;
	Pipeline &pipeline = scene.pipeline;
	const PoseResult &result = *scene.result;
	ASSERT_TRUE(result.found) << poseStatusName(result.status);

	const std::string name = uniqueName("idle");
	PreviewWriter writer;
	ASSERT_TRUE(writer.open(name, camera.width, camera.height, 256).isOk());
	PreviewReader reader;
	ASSERT_TRUE(reader.open(name).isOk());
	PreviewWorker worker;
	ASSERT_TRUE(worker.start(&writer, pipeline).isOk());
	hal::Frame frame;
	frame.image = image.view();
	frame.slot = 1;
	hal::Frame back;
	/* done() true once (it may consume: reclaim()), or false after a minute. */
	const auto eventually = [](auto done) {
		const auto give_up = std::chrono::steady_clock::now() + 60s;
		for (;;) {
			if (done())
				return true;
			if (std::chrono::steady_clock::now() >= give_up)
				return false;
			std::this_thread::sleep_for(1ms);
		}
	};

	/* Busy: handed over and taken up, but nothing published and nothing to reclaim. */
	worker.setLoopBusy(true);
	frame.sequence = 10;
	ASSERT_TRUE(worker.submit(frame, pipeline, &result, {}));
	ASSERT_TRUE(eventually([&] { return !worker.pending(); })) << "the worker never polled";
	for (int poll = 0; poll < 10; ++poll) {
		std::this_thread::sleep_for(std::chrono::nanoseconds(kPreviewPollNs));
		EXPECT_EQ(writer.published(), 0u) << "published while the loop was busy";
		EXPECT_FALSE(worker.reclaim(&back)) << "done while the loop was busy";
	}
	EXPECT_FALSE(worker.submit(frame, pipeline, &result, {})) << "still in hand: skipped";

	/* Idle: it comes out, and the frame comes back. */
	worker.setLoopBusy(false);
	ASSERT_TRUE(eventually([&] { return worker.reclaim(&back); })) << "never published";
	EXPECT_EQ(back.sequence, 10u);
	EXPECT_EQ(back.slot, 1);
	EXPECT_EQ(writer.published(), 1u);
	auto got = std::make_unique<PreviewFrame>();
	ASSERT_EQ(reader.latest(got.get()), 1u);
	EXPECT_EQ(got->frame_counter, 10u);
	EXPECT_EQ(got->found, 1);

	/* Busy again, then the frame thread drains (as before the camera stops): drain() marks
	 * the loop idle (its caller waits) and the frame is finished and given back. */
	worker.setLoopBusy(true);
	frame.sequence = 11;
	ASSERT_TRUE(worker.submit(frame, pipeline, &result, {}));
	ASSERT_TRUE(worker.drain(&back));
	EXPECT_EQ(back.sequence, 11u);
	EXPECT_EQ(writer.published(), 2u);
	worker.stop();
	EXPECT_EQ(worker.handed(), 2u);
	EXPECT_EQ(worker.skipped(), 1u);
}

/* The writer flat out, each frame's pixels all equal to its counter's low byte: every frame
 * the reader gets is whole (its pixels agree with its counter), and the writer never waited. */
TEST(Preview, TheSeqlockNeverHandsOutATornFrame)
{
	const std::string data = DOCKPOSE_TEST_DATA;
	const TargetModel target = loadTargetModel(data + "/wedge.json").value();
	const CameraIntrinsics camera = loadCameraIntrinsics(data + "/cam512.json").value();
	Pipeline pipeline(target, camera);
	std::vector<Image> frames;
	for (int v = 0; v < 256; ++v) {
		Image img(camera.width, camera.height);
		std::fill(img.data(), img.data() + img.view().stride_bytes * img.view().height,
			  static_cast<std::uint8_t>(v));
		frames.push_back(std::move(img));
	}
	const std::string name = uniqueName("seqlock");
	PreviewWriter writer;
	ASSERT_TRUE(writer.open(name, camera.width, camera.height, 640).isOk());
	PreviewReader reader;
	ASSERT_TRUE(reader.open(name).isOk());

	std::atomic<bool> stop{ false };
	std::thread write([&] {
		for (std::uint64_t c = 0; !stop; ++c)
			writer.publish(frames[c & 0xff].view(), c, 0, pipeline, nullptr, {});
	});
	auto got = std::make_unique<PreviewFrame>();
	int reads = 0, torn = 0;
	std::uint64_t last = 0;
	const auto end = std::chrono::steady_clock::now() + 1500ms;
	while (std::chrono::steady_clock::now() < end && reads < 20000) {
		const std::uint64_t n = reader.latest(got.get(), last);
		if (n == 0)
			continue;
		++reads;
		last = n;
		const auto v = static_cast<std::uint8_t>(got->frame_counter & 0xff);
		const std::size_t pixels = std::size_t{ got->width } * got->height;
		for (std::size_t i = 0; i < pixels; i += 97)
			if (got->pixels[i] != v) {
				++torn;
				break;
			}
	}
	stop = true;
	write.join();
	EXPECT_GT(reads, 100) << "the reader never got a frame";
	EXPECT_EQ(torn, 0) << torn << " torn frames of " << reads;
	EXPECT_GT(writer.published(), static_cast<std::uint64_t>(reads));
}

TEST(Preview, ReadersGetClearErrors)
{
	PreviewReader reader;
	const hal::Status missing = reader.open(uniqueName("absent"));
	ASSERT_FALSE(missing.isOk());
	EXPECT_NE(missing.message().find("is dockposed running with preview.enabled?"),
		  std::string::npos)
		<< missing.message();

	PreviewWriter writer;
	const hal::Status wide = writer.open(uniqueName("tall"), 640, 4000, 640);
	ASSERT_FALSE(wide.isOk());
	EXPECT_NE(wide.message().find("does not fit"), std::string::npos) << wide.message();
	EXPECT_FALSE(writer.open(uniqueName("narrow"), 640, 480, 8).isOk());
}

/* preview.enabled on the sim board at 60 frames/s, 10 Hz: a reader sees the frames at that rate
 * with the pose found in them, and the segment is gone after the daemon stops. */
TEST(Preview, TheDaemonPublishesAtItsRate)
{
	ConfigResult loaded =
		loadBoardConfig(std::string(DOCKPOSE_SOURCE_DIR) + "/board/sim/board.json");
	ASSERT_TRUE(loaded.ok());
	BoardConfig config = loaded.config;
	config.systemd.notify = false;
	config.camera.frame_rate_hz = 60.0;
	config.camera.synthetic.loop = true;
	config.preview.enabled = true;
	config.preview.name = uniqueName("daemon");
	config.preview.rate_hz = 10.0;

	auto hub = std::make_shared<hal::LoopbackHub>();
	board::Backends b;
	ASSERT_TRUE(board::wireSimulated(config,
					 std::make_unique<hal::LoopbackCanBus>(hub, "sensor"), &b)
			    .isOk());
	std::FILE *log = std::tmpfile();
	{
		Daemon daemon(config, std::move(b), log);
		ASSERT_TRUE(daemon.start().isOk());
		PreviewReader reader;
		ASSERT_TRUE(reader.open(config.preview.name).isOk());
		std::atomic<bool> stop{ false };
		std::thread loop([&] { daemon.run(stop); });
		/* Until the camera delivered 60 frames (1 s at 60 frames/s here; far longer under
		 * qemu, where the sim camera renders slowly): the rate is checked against the
		 * frames delivered, not against the clock. */
		const auto give_up = std::chrono::steady_clock::now() + 120s;
		while (daemon.stats().frames < 60 && std::chrono::steady_clock::now() < give_up)
			std::this_thread::sleep_for(20ms);
		auto got = std::make_unique<PreviewFrame>();
		const std::uint64_t before = daemon.stats().frames;
		const std::uint64_t n = reader.latest(got.get());
		const std::uint64_t after = daemon.stats().frames;
		stop = true;
		loop.join();
		ASSERT_GE(before, 60u) << "the camera delivered too few frames in 120 s";
		/* Every 6th frame at 60 frames/s and 10 Hz, the first one included; stats() is
		 * published every 50 ms, so it may trail the loop by a few frames. */
		/* The worker busy: a preview frame skipped, and counted. */
		const std::uint64_t skipped = daemon.stats().preview_skipped;
		EXPECT_GE(static_cast<double>(n + skipped),
			  static_cast<double>(before) / 6.0 - 2.0);
		EXPECT_LE(static_cast<double>(n), static_cast<double>(after) / 6.0 + 4.0);
		EXPECT_EQ(got->found, 1);
		EXPECT_EQ(got->width, 320);
		EXPECT_EQ(got->height, 240);
		EXPECT_GT(got->leds_used, 3);
	}
	std::fclose(log);
	PreviewReader after;
	EXPECT_FALSE(after.open(config.preview.name).isOk()) << "the daemon unlinks its segment";
}

} /* namespace */
} /* namespace dockpose::firmware */

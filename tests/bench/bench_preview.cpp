/* SPDX-License-Identifier: MIT */
/*
 * The operator preview's cost in the frame loop (host-release): the sim
 * board's frames (640x480, the wedge approaching, noise and reflections)
 * through the frame loop's per-frame work — Pipeline::process and the report's
 * encoding — with preview.enabled off, and on at its defaults (every 6th frame
 * at 60 frames/s, 320 px wide: a 2x2 box downscale, the blobs, the LEDs
 * projected), published into a real shared-memory ring.
 * Median of repetitions; the ratio is printed at the end.
 * Goal: per-frame time with the preview on within 5 % of it off.
 */
#include <unistd.h>

#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "algo/io/model_json.h"
#include "algo/pipeline.h"
#include "algo/synth/renderer.h"
#include "firmware/preview.h"
#include "firmware/protocol/dockpose_can.h"
#include "tests/bench/ratio_reporter.h"

using namespace dockpose;

namespace {

constexpr int kFrames = 60; /* one second at 60 frames/s */
constexpr int kPreviewEvery = 6; /* 60 frames/s at preview.rate_hz 10 */
constexpr int kPreviewWidth = 320;

struct Fixture {
	TargetModel target;
	CameraIntrinsics camera;
	std::vector<Image> frames;
};

const Fixture &fixture()
{
	static Fixture f = [] {
		Fixture x;
		const std::string board = std::string(DOCKPOSE_SOURCE_DIR) + "/board/sim";
		x.target = loadTargetModel(board + "/target.json").value();
		x.camera = loadCameraIntrinsics(board + "/camera.json").value();
		FrameRenderer renderer(x.target, x.camera);
		for (int i = 0; i < kFrames; ++i) {
			RenderOptions o;
			o.reflections = 4;
			o.noise_sigma = 2.0;
			o.clutter_seed = 5;
			Image img;
			renderer.render(poseAt(x.camera, x.target, 900.0 - 5.0 * i,
					       { 3.0, 8.0 - 0.1 * i, -2.0 }, 0.48 + 0.001 * i, 0.5),
					o, 100 + static_cast<std::uint64_t>(i), &img);
			x.frames.push_back(std::move(img));
		}
		return x;
	}();
	return f;
}

/* One frame of the loop's work: pixels -> pose -> the report's frames. */
void frameWork(Pipeline &pipeline, can::Encoder &encoder, const Image &frame,
	       firmware::PreviewWriter *preview, int i)
{
	const PoseResult &r = pipeline.process(frame.view());
	can::StatusData status;
	status.pose_valid = r.found;
	can::PoseData pose;
	for (int k = 0; k < 3; ++k)
		pose.t_mm[k] = r.t_mm[k];
	can::RawFrame out[can::kMaxReportFrames];
	benchmark::DoNotOptimize(encoder.encodeReport(status, &pose, out));
	if (preview && i % kPreviewEvery == 0)
		preview->publish(frame.view(), static_cast<std::uint64_t>(i), 0, pipeline, &r,
				 { 2, 0 });
	benchmark::DoNotOptimize(out);
}

void frameLoop(benchmark::State &state, bool with_preview)
{
	const Fixture &f = fixture();
	Pipeline pipeline(f.target, f.camera);
	can::Encoder encoder;
	firmware::PreviewWriter preview;
	if (with_preview) {
		const std::string name = "dockpose-bench-" + std::to_string(getpid());
		if (auto s = preview.open(name, f.camera.width, f.camera.height, kPreviewWidth);
		    !s) {
			state.SkipWithError(s.message().c_str());
			return;
		}
	}
	int i = 0;
	for (auto _ : state) {
		frameWork(pipeline, encoder, f.frames[static_cast<std::size_t>(i % kFrames)],
			  with_preview ? &preview : nullptr, i);
		++i;
	}
}

void frameLoopPreviewOff(benchmark::State &state)
{
	frameLoop(state, false);
}

void frameLoopPreviewOn(benchmark::State &state)
{
	frameLoop(state, true);
}

} /* namespace */

BENCHMARK(frameLoopPreviewOff)
	->Repetitions(9)
	->ReportAggregatesOnly(true)
	->Unit(benchmark::kMicrosecond);
BENCHMARK(frameLoopPreviewOn)
	->Repetitions(9)
	->ReportAggregatesOnly(true)
	->Unit(benchmark::kMicrosecond);

int main(int argc, char **argv)
{
	benchmark::Initialize(&argc, argv);
	bench::RatioReporter reporter;
	benchmark::RunSpecifiedBenchmarks(&reporter);
	auto &m = reporter.median_us;
	if (m.count("frameLoopPreviewOff") && m.count("frameLoopPreviewOn")) {
		const double off = m["frameLoopPreviewOff"], on = m["frameLoopPreviewOn"];
		std::printf("\nmedian per 640x480 frame: preview off %.2f us, on (every %d frames, "
			    "%d px) %.2f us\n",
			    off, kPreviewEvery, kPreviewWidth, on);
		std::printf("ratio preview on/off: %.3f (goal <= 1.05)\n", on / off);
	}
	benchmark::Shutdown();
	return 0;
}

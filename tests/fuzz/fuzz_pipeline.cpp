/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: Pipeline::process (algo/pipeline.h) on arbitrary frames of a
 * fixed camera (160 x 120 pixels, fx = fy = 130 px: a 63 degree field of view)
 * and the wedge target (tests/data/wedge.json, six LEDs, two faces), with the
 * default configuration.
 *
 * Input: mode (u8), background (u8), then
 *  - mode bit 0 clear ("pixels"): the frame's pixels, row by row; pixels the
 *    input does not reach take the background;
 *  - mode bit 0 set ("spots"): up to kMaxSpots spots on the uniform
 *    background, 6 bytes each: x, y (u16, in quarter pixels, modulo the frame),
 *    radius (u8: 0.5 + r / 16 px), peak (u8). A spot's profile is
 *    background + (peak - background) (1 - (d / radius)^2) within its radius,
 *    overlapping spots take the brighter; a spot no brighter than the
 *    background is not drawn. The fuzzer places light sources directly.
 *
 * The oracle has to hold for any frame, since a fuzzer could draw the target:
 *  1. any reported pose is consistent with what the pipeline says it rests on:
 *     log10 NFA within the configured bound, rms reprojection error within
 *     max_rms_px, at least min_leds_search LEDs (led_mask has leds_used bits,
 *     at most the blobs found), a proper rotation with q = R (w >= 0), the
 *     target in front of the camera, and each matched LED's projection near a
 *     detected blob (within sqrt(leds_used) * rms_px, which an rms over
 *     leds_used residuals allows), no two LEDs on the same blob;
 *  2. no pose from a frame that cannot hold the target: in spots mode, a
 *     frame with fewer drawn spots than min_leds_search is a uniform
 *     background with at most three light sources, each of them radially
 *     non-increasing (every level set of the frame is a union of at most three
 *     discs). The target needs four LEDs on four distinct blobs, so any pose
 *     reported from such a frame is a false pose, whatever the thresholds did
 *     (a spot cut into pieces by tile levels is still one source);
 *  3. the frame processed a second time while tracking (regions of interest)
 *     satisfies 1 and 2 as well; and after a pose, the frame processed again
 *     after reset() gives the same result, bit for bit (determinism).
 */
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "algo/io/model_json.h"
#include "algo/pipeline.h"
#include "tests/fuzz/fuzz_check.h"

using namespace dockpose;
using namespace dockpose::fuzz;

namespace {

constexpr int kWidth = 160;
constexpr int kHeight = 120;
constexpr int kMaxSpots = 16;

CameraIntrinsics fuzzCamera()
{
	CameraIntrinsics k;
	k.width = kWidth;
	k.height = kHeight;
	k.fx = k.fy = 130.0;
	k.cx = (kWidth - 1) / 2.0;
	k.cy = (kHeight - 1) / 2.0;
	return k;
}

struct Frame {
	std::vector<std::uint8_t> pixels = std::vector<std::uint8_t>(kWidth * kHeight);
	int spots = -1; /* drawn spots; -1: pixels mode */
};

void drawFrame(FuzzInput &in, Frame *frame)
{
	const std::uint8_t mode = in.u8();
	const std::uint8_t background = in.u8();
	std::fill(frame->pixels.begin(), frame->pixels.end(), background);
	frame->spots = -1;
	if (!(mode & 0x01)) {
		for (std::uint8_t &p : frame->pixels) {
			if (in.empty())
				break;
			p = in.u8();
		}
		return;
	}
	frame->spots = 0;
	for (int s = 0; s < kMaxSpots && in.remaining() >= 6; ++s) {
		const double x = (in.u16() % (4 * kWidth)) / 4.0;
		const double y = (in.u16() % (4 * kHeight)) / 4.0;
		const double r = 0.5 + in.u8() / 16.0;
		const int peak = in.u8();
		if (peak <= background)
			continue;
		++frame->spots;
		const int x0 = std::max(0, static_cast<int>(std::floor(x - r)));
		const int x1 = std::min(kWidth - 1, static_cast<int>(std::ceil(x + r)));
		const int y0 = std::max(0, static_cast<int>(std::floor(y - r)));
		const int y1 = std::min(kHeight - 1, static_cast<int>(std::ceil(y + r)));
		for (int py = y0; py <= y1; ++py) {
			for (int px = x0; px <= x1; ++px) {
				const double d2 =
					((px - x) * (px - x) + (py - y) * (py - y)) / (r * r);
				if (d2 >= 1.0)
					continue;
				const double v = background + (peak - background) * (1.0 - d2);
				std::uint8_t &p =
					frame->pixels[static_cast<std::size_t>(py) * kWidth + px];
				p = std::max(p, static_cast<std::uint8_t>(std::lround(v)));
			}
		}
	}
}

void checkResult(const Pipeline &pipeline, const PipelineConfig &config, const Frame &frame,
		 const PoseResult &r)
{
	FUZZ_CHECK(r.found == (r.status == PoseStatus::Found), "found is status Found");
	if (!r.found)
		return;
	FUZZ_CHECK(frame.spots < 0 || frame.spots >= config.correspondence.min_leds_search,
		   "no pose from a frame of fewer light sources than the LEDs a pose needs");

	const CorrespondenceConfig &cc = config.correspondence;
	FUZZ_CHECK(std::isfinite(r.log10_nfa) && r.log10_nfa <= cc.max_log10_nfa,
		   "a pose's log10 NFA is within the configured bound");
	FUZZ_CHECK(std::isfinite(r.rms_px) && r.rms_px >= 0 && r.rms_px <= cc.max_rms_px,
		   "a pose's rms reprojection error is within max_rms_px");
	FUZZ_CHECK(r.leds_used >= cc.min_leds_search && r.leds_used == std::popcount(r.led_mask) &&
			   r.led_mask < (1u << pipeline.target().points_mm.size()),
		   "a pose rests on min_leds_search LEDs of the target, as led_mask says");
	FUZZ_CHECK(r.leds_used <= static_cast<int>(pipeline.blobs().size()),
		   "a pose uses no more LEDs than blobs found");
	FUZZ_CHECK(r.R.allFinite() && r.t_mm.allFinite() && r.covariance.allFinite(),
		   "a pose is finite");
	FUZZ_CHECK((r.R.transpose() * r.R - Eigen::Matrix3d::Identity()).norm() < 1e-6 &&
			   std::abs(r.R.determinant() - 1.0) < 1e-6,
		   "a pose's R is a rotation");
	FUZZ_CHECK(r.q.w() >= 0 && (r.q.toRotationMatrix() - r.R).norm() < 1e-6,
		   "a pose's quaternion is its R, w >= 0");

	const double gate_px = std::sqrt(static_cast<double>(r.leds_used)) * r.rms_px + 1e-3;
	std::uint64_t blobs_taken = 0;
	for (std::size_t i = 0; i < pipeline.target().points_mm.size(); ++i) {
		if (!(r.led_mask & (1u << i)))
			continue;
		const Eigen::Vector3d X_c = r.R * pipeline.target().points_mm[i] + r.t_mm;
		Eigen::Vector2d uv;
		FUZZ_CHECK(pipeline.camera().project(X_c, &uv),
			   "a matched LED is in front of the camera");
		double best = std::numeric_limits<double>::infinity();
		std::size_t best_j = 0;
		for (std::size_t j = 0; j < pipeline.blobs().size(); ++j) {
			const Blob &b = pipeline.blobs()[j];
			const double d = std::hypot(b.u_px - uv.x(), b.v_px - uv.y());
			if (d < best) {
				best = d;
				best_j = j;
			}
		}
		FUZZ_CHECK(best <= gate_px, "a matched LED projects onto a blob (rms-consistent)");
		FUZZ_CHECK(!(blobs_taken & (std::uint64_t{ 1 } << best_j)),
			   "no two matched LEDs on one blob");
		blobs_taken |= std::uint64_t{ 1 } << best_j;
	}
}

bool sameResult(const PoseResult &a, const PoseResult &b)
{
	return a.found == b.found && a.status == b.status && a.R == b.R && a.t_mm == b.t_mm &&
	       a.led_mask == b.led_mask && a.blobs == b.blobs && a.hypotheses == b.hypotheses &&
	       (a.log10_nfa == b.log10_nfa || (std::isnan(a.log10_nfa) && std::isnan(b.log10_nfa)));
}

} /* namespace */

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	static const PipelineConfig config;
	static Pipeline pipeline = [] {
		Result<TargetModel> target =
			loadTargetModel(DOCKPOSE_SOURCE_DIR "/tests/data/wedge.json");
		FUZZ_CHECK(target.isOk(), "tests/data/wedge.json loads");
		return Pipeline(target.value(), fuzzCamera(), config);
	}();
	static Frame frame;

	FuzzInput in(data, size);
	drawFrame(in, &frame);
	const ImageView view{ frame.pixels.data(), kWidth, kHeight, kWidth };

	pipeline.reset();
	const PoseResult first = pipeline.process(view);
	checkResult(pipeline, config, frame, first);
	/* Tracking from the pose just found: the same frame again, through windows. */
	checkResult(pipeline, config, frame, pipeline.process(view));
	/* Only after a pose (a cold search of a cluttered frame is the slow part). */
	if (first.found) {
		pipeline.reset();
		FUZZ_CHECK(sameResult(pipeline.process(view), first),
			   "the same frame from a reset pipeline gives the same result");
	}
	return 0;
}

/* SPDX-License-Identifier: MIT */
/*
 * What the model harnesses (target, camera, board file) check of a model
 * the readers accepted: that it is what algo's own validation accepts, that
 * writing it out as JSON and reading it again gives the same model, and that
 * a Pipeline built on it runs a frame. Allocates: freely (harnesses only).
 */
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "algo/camera_model.h"
#include "algo/io/model_json.h"
#include "algo/pipeline.h"
#include "algo/target_model.h"
#include "tests/fuzz/fuzz_check.h"

namespace dockpose::fuzz {

/* The largest frame a model harness builds a Pipeline for (pixels): bigger ones cost time
 * and memory per input, not coverage. */
constexpr long kMaxPipelineFramePixels = 512L * 512L;

inline nlohmann::json targetJson(const TargetModel &m)
{
	nlohmann::json j;
	j["name"] = m.name;
	j["units"] = "mm";
	j["points"] = nlohmann::json::array();
	for (const Eigen::Vector3d &p : m.points_mm)
		j["points"].push_back({ p.x(), p.y(), p.z() });
	j["faces"] = nlohmann::json::array();
	for (const std::array<int, 4> &f : m.faces)
		j["faces"].push_back({ f[0], f[1], f[2], f[3] });
	j["led_sigma_mm"] = m.led_sigma_mm;
	if (m.approach.set)
		j["approach"] = { { "axis",
				    { m.approach.axis.x(), m.approach.axis.y(),
				      m.approach.axis.z() } },
				  { "max_deg", m.approach.max_deg } };
	return j;
}

inline nlohmann::json cameraJson(const CameraIntrinsics &k)
{
	const CameraIntrinsics::Sigma &s = k.sigma;
	return { { "width", k.width },
		 { "height", k.height },
		 { "fx", k.fx },
		 { "fy", k.fy },
		 { "cx", k.cx },
		 { "cy", k.cy },
		 { "k1", k.k1 },
		 { "k2", k.k2 },
		 { "p1", k.p1 },
		 { "p2", k.p2 },
		 { "sigma",
		   { { "fx", s.fx },
		     { "fy", s.fy },
		     { "cx", s.cx },
		     { "cy", s.cy },
		     { "k1", s.k1 },
		     { "k2", s.k2 },
		     { "p1", s.p1 },
		     { "p2", s.p2 } } } };
}

inline bool near(double a, double b, double tolerance)
{
	return std::abs(a - b) <= tolerance * (1.0 + std::abs(a) + std::abs(b));
}

/* An accepted target model: valid, finite, and the same after a JSON round trip. */
inline void checkTarget(const TargetModel &m)
{
	FUZZ_CHECK(m.validate().isOk(), "an accepted target passes TargetModel::validate");
	FUZZ_CHECK(m.points_mm.size() >= 4 && !m.faces.empty(), "an accepted target has a face");
	for (const Eigen::Vector3d &p : m.points_mm)
		FUZZ_CHECK(p.allFinite(), "an accepted target's LEDs are finite");
	const double d = m.diameterMm();
	FUZZ_CHECK(d >= TargetModel::kMinDiameterMm && d <= TargetModel::kMaxDiameterMm,
		   "an accepted target's size is within the plausibility bounds");
	StaticVector<Eigen::Vector3d, kMaxFaces> normals;
	m.frontNormals(&normals);
	FUZZ_CHECK(normals.size() == m.faces.size(), "a front normal per face");
	for (const Eigen::Vector3d &n : normals)
		FUZZ_CHECK(n.allFinite() && std::abs(n.norm() - 1.0) < 1e-9,
			   "front normals are unit");

	const Result<TargetModel> again = parseTargetModel(targetJson(m).dump(), "<round trip>");
	FUZZ_CHECK(again.isOk(), "an accepted target, written out, is accepted again");
	FUZZ_CHECK(again->name == m.name && again->points_mm.size() == m.points_mm.size() &&
			   again->faces.size() == m.faces.size() &&
			   again->led_sigma_mm == m.led_sigma_mm &&
			   again->approach.set == m.approach.set,
		   "the round trip keeps the target");
	for (std::size_t i = 0; i < m.points_mm.size(); ++i)
		FUZZ_CHECK(again->points_mm[i] == m.points_mm[i], "the round trip keeps every LED");
	for (std::size_t i = 0; i < m.faces.size(); ++i)
		FUZZ_CHECK(again->faces[i] == m.faces[i], "the round trip keeps every face");
	if (m.approach.set)
		FUZZ_CHECK((again->approach.axis - m.approach.axis).norm() < 1e-12 &&
				   again->approach.max_deg == m.approach.max_deg,
			   "the round trip keeps the approach");
}

/* An accepted camera: valid, the same after a JSON round trip, and its model maps pixels
 * to rays and back. */
inline void checkCamera(const CameraIntrinsics &k)
{
	FUZZ_CHECK(k.validate().isOk(), "an accepted camera passes CameraIntrinsics::validate");
	FUZZ_CHECK(k.width > 0 && k.height > 0 && std::isfinite(k.fx) && std::isfinite(k.fy) &&
			   std::isfinite(k.cx) && std::isfinite(k.cy),
		   "an accepted camera has a size and finite intrinsics");

	const Result<CameraIntrinsics> again =
		parseCameraIntrinsics(cameraJson(k).dump(), "<round trip>");
	FUZZ_CHECK(again.isOk(), "an accepted camera, written out, is accepted again");
	FUZZ_CHECK(again->width == k.width && again->height == k.height && again->fx == k.fx &&
			   again->fy == k.fy && again->cx == k.cx && again->cy == k.cy &&
			   again->k1 == k.k1 && again->k2 == k.k2 && again->p1 == k.p1 &&
			   again->p2 == k.p2 && again->sigma.fx == k.sigma.fx &&
			   again->sigma.k1 == k.sigma.k1 && again->sigma.p2 == k.sigma.p2,
		   "the round trip keeps the camera");

	/* Pixels to normalised rays and back: where undistortion converges (it may say
	 * it does not), the pixel comes back. */
	const CameraModel model(k);
	const double w = k.width, h = k.height;
	const Eigen::Vector2d pixels[] = { { k.cx, k.cy }, { 0.0, 0.0 }, { w, 0.0 },
					   { 0.0, h },	   { w, h },	 { w / 3, h / 2 } };
	for (const Eigen::Vector2d &uv : pixels) {
		Eigen::Vector2d xy;
		if (!model.pixelToNormalized(uv, &xy))
			continue;
		FUZZ_CHECK(xy.allFinite(), "a converged ray is finite");
		const Eigen::Vector2d back = model.normalizedToPixel(xy);
		FUZZ_CHECK((back - uv).norm() <= 1e-3,
			   "a pixel mapped to its ray and back is the same pixel");
	}
}

/* A Pipeline on the pair runs a dark frame and a frame of one bright spot: it finds no pose
 * in either (neither holds four LEDs). */
inline void checkPipeline(const TargetModel &target, const CameraIntrinsics &camera)
{
	if (static_cast<long>(camera.width) * camera.height > kMaxPipelineFramePixels)
		return;
	Pipeline pipeline(target, camera);
	std::vector<std::uint8_t> pixels(static_cast<std::size_t>(camera.width) *
						 static_cast<std::size_t>(camera.height),
					 10);
	const ImageView view{ pixels.data(), camera.width, camera.height, camera.width };
	FUZZ_CHECK(!pipeline.process(view).found, "no pose in a dark frame");
	const int cx = camera.width / 2, cy = camera.height / 2;
	for (int y = std::max(0, cy - 2); y < std::min(camera.height, cy + 3); ++y)
		for (int x = std::max(0, cx - 2); x < std::min(camera.width, cx + 3); ++x)
			pixels[static_cast<std::size_t>(y) * camera.width + x] = 250;
	FUZZ_CHECK(!pipeline.process(view).found, "no pose from one spot");
}

} /* namespace dockpose::fuzz */

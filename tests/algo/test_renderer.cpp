/* SPDX-License-Identifier: MIT */
/*
 * The synthetic renderer against independent references:
 *  - the intensity centroid of every noise-free LED spot (computed here, no
 *    threshold) is the LED centre projected by CameraModel, within 0.03 px;
 *  - the spot's second moments are those of the disc projected point by point
 *    through the exact camera model, plus the blur and the pixel's box;
 *  - brightness follows 1/range^2 and cos(view angle), floored and saturated;
 *  - back-facing, out-of-frame and occluded LEDs are not drawn;
 *  - clutter appears in the requested numbers and kinds;
 *  - frames are deterministic for a seed; noise and gradient have the asked
 *    statistics; render() does not allocate.
 * The harder scenes, each against what it promises:
 *  - blooming clips the spot at 255 and its halo's radius is `bloom` spot radii;
 *  - motion blur adds L^2/12 of variance along its direction only, keeps the
 *    centroid and the energy;
 *  - dimmed LEDs peak at the asked fraction, the others unchanged;
 *  - one-face occlusion leaves exactly one face's LEDs; target-free frames
 *    draw no LED; reflections near the target stay separate blobs;
 *  - sunlit patches are large, smooth and may saturate; LEDs lost in them are
 *    not counted as drawn;
 *  - the any-side pose sampler keeps the chosen face's angle inside the cone,
 *    the range, and the whole target inside the frame;
 *  - the new targets and the wide-angle camera are valid files.
 */
/* The replacement operator delete frees what the replacement operator new took from malloc. */
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "algo/io/model_json.h"
#include "algo/pose.h"
#include "algo/synth/evaluation.h"
#include "algo/synth/renderer.h"

/* Count heap allocations (for the no-allocation test). */
namespace {
std::atomic<long> g_allocations{ 0 };
}

void *operator new(std::size_t n)
{
	g_allocations.fetch_add(1, std::memory_order_relaxed);
	if (void *p = std::malloc(n ? n : 1))
		return p;
	throw std::bad_alloc();
}
void operator delete(void *p) noexcept
{
	std::free(p);
}
void operator delete(void *p, std::size_t) noexcept
{
	std::free(p);
}

using namespace dockpose;

namespace {

const std::string kData = DOCKPOSE_TEST_DATA;
constexpr double kPi = 3.14159265358979323846;

TargetModel loadTarget(const char *name)
{
	auto r = loadTargetModel(kData + "/" + name);
	EXPECT_TRUE(r.isOk()) << r.message();
	return r.value();
}

CameraIntrinsics loadCamera(const char *name)
{
	auto r = loadCameraIntrinsics(kData + "/" + name);
	EXPECT_TRUE(r.isOk()) << r.message();
	return r.value();
}

/* A flat square board: four LEDs, one face, 200 mm side. */
TargetModel board()
{
	TargetModel m;
	m.name = "board";
	m.points_mm.push_back({ -100, -100, 0 });
	m.points_mm.push_back({ 100, -100, 0 });
	m.points_mm.push_back({ 100, 100, 0 });
	m.points_mm.push_back({ -100, 100, 0 });
	m.faces.push_back({ 0, 1, 2, 3 });
	return m;
}

RenderOptions quiet()
{
	RenderOptions o;
	o.background = 0.0;
	o.gradient = 0.0;
	o.noise_sigma = 0.0;
	return o;
}

/* Intensity moments of (I - background) over a square window. */
struct Moments {
	double sum = 0.0;
	Eigen::Vector2d mean = Eigen::Vector2d::Zero();
	Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
	int max = 0;
	int saturated = 0;
};

Moments moments(const Image &img, const Eigen::Vector2d &c, int half, double background = 0.0)
{
	Moments m;
	double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
	const int x0 = std::max(0, static_cast<int>(std::lround(c.x())) - half);
	const int x1 = std::min(img.width() - 1, static_cast<int>(std::lround(c.x())) + half);
	const int y0 = std::max(0, static_cast<int>(std::lround(c.y())) - half);
	const int y1 = std::min(img.height() - 1, static_cast<int>(std::lround(c.y())) + half);
	for (int y = y0; y <= y1; ++y)
		for (int x = x0; x <= x1; ++x) {
			const double w = img.at(x, y) - background;
			m.sum += w;
			sx += w * x;
			sy += w * y;
			sxx += w * x * x;
			syy += w * y * y;
			sxy += w * x * y;
			m.max = std::max<int>(m.max, img.at(x, y));
			m.saturated += img.at(x, y) == 255;
		}
	if (m.sum > 0) {
		m.mean = { sx / m.sum, sy / m.sum };
		m.cov(0, 0) = sxx / m.sum - m.mean.x() * m.mean.x();
		m.cov(1, 1) = syy / m.sum - m.mean.y() * m.mean.y();
		m.cov(0, 1) = m.cov(1, 0) = sxy / m.sum - m.mean.x() * m.mean.y();
	}
	return m;
}

/* The LED normal as the renderer defines it: mean of its faces' outward normals. */
Eigen::Vector3d outwardNormal(const TargetModel &m, int f)
{
	const auto &face = m.faces[f];
	Eigen::Vector3d n = (m.points_mm[face[2]] - m.points_mm[face[0]])
				    .cross(m.points_mm[face[3]] - m.points_mm[face[1]])
				    .normalized();
	Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
	for (const auto &p : m.points_mm)
		centroid += p;
	centroid /= static_cast<double>(m.points_mm.size());
	const Eigen::Vector3d centre = (m.points_mm[face[0]] + m.points_mm[face[1]] +
					m.points_mm[face[2]] + m.points_mm[face[3]]) /
				       4.0;
	const double side = n.dot(centre - centroid);
	if (side < -1e-9 || (std::abs(side) <= 1e-9 && n.z() > 0))
		n = -n;
	return n;
}

/*
 * Second moments of the disc of radius r (normal n_c, centre p_c, camera
 * frame) projected point by point: a 720-gon through CameraModel::project,
 * moments by Green's theorem. Returns the covariance of the uniform region.
 */
Eigen::Matrix2d projectedDiscCovariance(const CameraModel &cam, const Eigen::Vector3d &p_c,
					const Eigen::Vector3d &n_c, double r,
					Eigen::Vector2d *centroid)
{
	const Eigen::Vector3d e1 = n_c.unitOrthogonal(), e2 = n_c.cross(e1);
	const int n = 720;
	std::vector<Eigen::Vector2d> poly(n);
	for (int i = 0; i < n; ++i) {
		const double a = 2.0 * kPi * i / n;
		EXPECT_TRUE(cam.project(p_c + r * (std::cos(a) * e1 + std::sin(a) * e2), &poly[i]));
	}
	double A = 0, cx = 0, cy = 0, ixx = 0, iyy = 0, ixy = 0;
	for (int i = 0; i < n; ++i) {
		const Eigen::Vector2d &p = poly[i], &q = poly[(i + 1) % n];
		const double c = p.x() * q.y() - q.x() * p.y();
		A += c;
		cx += (p.x() + q.x()) * c;
		cy += (p.y() + q.y()) * c;
		ixx += (p.x() * p.x() + p.x() * q.x() + q.x() * q.x()) * c;
		iyy += (p.y() * p.y() + p.y() * q.y() + q.y() * q.y()) * c;
		ixy += (p.x() * q.y() + 2 * p.x() * p.y() + 2 * q.x() * q.y() + q.x() * p.y()) * c;
	}
	A *= 0.5;
	cx /= 6 * A;
	cy /= 6 * A;
	ixx /= 12 * A;
	iyy /= 12 * A;
	ixy /= 24 * A;
	*centroid = { cx, cy };
	Eigen::Matrix2d cov;
	cov << ixx - cx * cx, ixy - cx * cy, ixy - cx * cy, iyy - cy * cy;
	return cov;
}

} /* namespace */

TEST(Renderer, SpotCentroidIsTheProjectedLedCentre)
{
	struct Case {
		const char *target, *camera;
		double range, roll, pan, tilt, u, v, blur;
	};
	const Case cases[] = {
		{ "wedge.json", "cam1456.json", 800, 0, 0, 0, 0.5, 0.5, 0.8 },
		{ "wedge.json", "cam1456.json", 500, 10, 25, -5, 0.3, 0.6, 0.8 },
		{ "wedge.json", "cam1456.json", 1200, -15, -20, 30, 0.15, 0.2,
		  1.2 }, /* strong distortion */
		{ "wedge.json", "cam1456.json", 650, 5, 40, 90, 0.8, 0.8, 0.6 },
		{ "corner.json", "cam1456.json", 700, 8, -12, 20, 0.6, 0.4, 0.8 },
		{ "corner.json", "cam512.json", 900, 0, 10, 0, 0.5, 0.5, 0.8 },
		{ "wedge.json", "cam512.json", 1400, 20, 0, 45, 0.4, 0.55, 1.0 },
	};
	double worst = 0.0;
	int checked = 0;
	for (const Case &c : cases) {
		const TargetModel target = loadTarget(c.target);
		const CameraIntrinsics k = loadCamera(c.camera);
		const CameraModel cam(k);
		FrameRenderer renderer(target, k);
		RenderOptions o = quiet();
		o.blur_sigma_px = c.blur;
		const Pose pose = poseAt(k, target, c.range, { c.roll, c.pan, c.tilt }, c.u, c.v);
		Image img;
		RenderTruth truth;
		renderer.render(pose, o, 11, &img, &truth);
		ASSERT_EQ(img.width(), k.width);
		ASSERT_EQ(img.height(), k.height);
		ASSERT_EQ(truth.led_px.size(), target.points_mm.size());
		ASSERT_NE(truth.visible_mask, 0u);

		for (std::size_t i = 0; i < target.points_mm.size(); ++i) {
			Eigen::Vector2d uv;
			const Eigen::Vector3d p = pose.apply(target.points_mm[i]);
			ASSERT_TRUE(cam.project(p, &uv));
			EXPECT_NEAR((truth.led_px[i] - uv).norm(), 0.0, 1e-9);
			if (!(truth.visible_mask & (1u << i)))
				continue;
			const double rho = k.fx * o.led_radius_mm / p.norm();
			const int half =
				static_cast<int>(std::ceil(1.3 * rho + 5.0 * c.blur + 2.0));
			/* Only spots whose window holds no other LED. */
			bool alone = true;
			for (std::size_t j = 0; j < target.points_mm.size(); ++j)
				if (j != i &&
				    (truth.led_px[j] - uv).lpNorm<Eigen::Infinity>() < 2 * half + 2)
					alone = false;
			if (!alone)
				continue;
			const Moments m = moments(img, uv, half);
			const Moments wide = moments(img, uv, half + 6);
			ASSERT_GT(m.sum, 100.0);
			EXPECT_NEAR(wide.sum, m.sum, 1e-3 * m.sum) << "window too small";
			const double err = (m.mean - uv).norm();
			worst = std::max(worst, err);
			EXPECT_LT(err, 0.03)
				<< c.target << " " << c.camera << " range " << c.range << " LED "
				<< i << " at (" << uv.x() << ", " << uv.y() << ")";
			++checked;
		}
	}
	EXPECT_GE(checked, 25);
	RecordProperty("worst_centroid_error_px", std::to_string(worst));
	std::printf("worst centroid error %.4f px over %d spots\n", worst, checked);
}

TEST(Renderer, SpotShapeIsTheProjectedDiscBlurred)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const CameraModel cam(k);
	const TargetModel target = board();
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.led_radius_mm = 4.0;
	o.led_peak = 120.0; /* no saturation: clipping would change the moments */
	const double box = 1.0 / 12.0;
	const Eigen::Vector3d n_t = outwardNormal(target, 0);
	EXPECT_NEAR(n_t.z(), -1.0, 1e-12); /* a flat board faces a camera at the identity pose */

	struct Case {
		double range, roll, pan, tilt;
	};
	for (const Case &c : { Case{ 700, 0, 0, 0 }, Case{ 700, 0, 60, 0 }, Case{ 900, 50, 0, 30 },
			       Case{ 500, 30, -45, 10 } }) {
		const Pose pose = poseAt(k, target, c.range, { c.roll, c.pan, c.tilt });
		Image img;
		RenderTruth truth;
		renderer.render(pose, o, 3, &img, &truth);
		ASSERT_EQ(truth.visible_mask, 0xfu) << "pan " << c.pan;
		for (int i = 0; i < 4; ++i) {
			const Eigen::Vector3d p = pose.apply(target.points_mm[i]);
			const Eigen::Vector3d n = pose.R * n_t;
			Eigen::Vector2d poly_centroid;
			const Eigen::Matrix2d disc =
				projectedDiscCovariance(cam, p, n, o.led_radius_mm, &poly_centroid);
			const Eigen::Matrix2d expected = disc + (o.blur_sigma_px * o.blur_sigma_px +
								 box) * Eigen::Matrix2d::Identity();
			const int half = static_cast<int>(std::ceil(std::sqrt(disc.trace() * 4.0) +
								    6.0 * o.blur_sigma_px + 3));
			const Moments m = moments(img, truth.led_px[i], half);
			ASSERT_EQ(m.saturated, 0);
			const double tol = 0.01 * expected.trace() + 0.02;
			EXPECT_NEAR(m.cov(0, 0), expected(0, 0), tol)
				<< "pan " << c.pan << " LED " << i;
			EXPECT_NEAR(m.cov(1, 1), expected(1, 1), tol)
				<< "pan " << c.pan << " LED " << i;
			EXPECT_NEAR(m.cov(0, 1), expected(0, 1), tol)
				<< "pan " << c.pan << " LED " << i;

			/* Peak: led_peak (ref/range)^2 cos(view), the pixel's value at the flat top. */
			const double cos_view = n.dot(-p.normalized());
			const double ratio = o.reference_range_mm / p.norm();
			const double peak =
				std::max(o.min_led_peak, o.led_peak * ratio * ratio * cos_view);
			const double minor_px =
				2.0 * std::sqrt(disc.eigenvalues().real().minCoeff());
			ASSERT_GT(minor_px,
				  3.0 * o.blur_sigma_px); /* a flat top: its pixels read the peak */
			EXPECT_NEAR(m.max, std::min(255.0, peak), 0.03 * peak + 1.0)
				<< "pan " << c.pan;
		}
	}

	/* Foreshortening: at pan 60 the spots are about half as wide as they are high. */
	const Pose pose = poseAt(k, target, 700, { 0, 60, 0 });
	Image img;
	RenderTruth truth;
	renderer.render(pose, o, 3, &img, &truth);
	const Moments m = moments(img, truth.led_px[0], 20);
	const double blur2 = o.blur_sigma_px * o.blur_sigma_px + box;
	const double ratio = std::sqrt((m.cov(0, 0) - blur2) / (m.cov(1, 1) - blur2));
	EXPECT_NEAR(ratio, 0.5, 0.08);
}

TEST(Renderer, SpotsShrinkAndDimWithRange)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = board();
	FrameRenderer renderer(target, k);
	const RenderOptions o = quiet();
	Image img;
	RenderTruth truth;
	double last_sum = 1e30, last_size = 1e30;
	int last_max = 256;
	for (double range : { 650.0, 800.0, 950.0, 1100.0 }) {
		renderer.render(poseAt(k, target, range, { 0, 0, 0 }), o, 5, &img, &truth);
		ASSERT_EQ(truth.visible_mask, 0xfu);
		const Moments m = moments(img, truth.led_px[0], 20);
		const double size = m.cov.trace();
		EXPECT_LT(m.sum, last_sum) << range;
		EXPECT_LT(size, last_size) << range;
		EXPECT_LT(m.max, last_max) << range;
		/* The peak follows 1/range^2 (cos ~ 1 for a board on the axis). */
		const Eigen::Vector3d p = truth.pose.apply(target.points_mm[0]);
		const double cos_view = p.normalized().z(); /* LED normal -z, camera towards -p */
		const double expected =
			o.led_peak * std::pow(o.reference_range_mm / p.norm(), 2) * cos_view;
		EXPECT_NEAR(m.max, expected, 0.03 * expected + 1.0) << range;
		last_sum = m.sum;
		last_size = size;
		last_max = m.max;
	}

	/* Far away: floored at min_led_peak (the pixel integral lowers it a little). */
	renderer.render(poseAt(k, target, 4000, { 0, 0, 0 }), o, 5, &img, &truth);
	const Moments far = moments(img, truth.led_px[0], 8);
	EXPECT_LE(far.max, static_cast<int>(o.min_led_peak) + 1);
	EXPECT_GE(far.max, static_cast<int>(0.75 * o.min_led_peak));

	/* Close: saturated at 255 over the disc. */
	renderer.render(poseAt(k, target, 350, { 0, 0, 0 }), o, 5, &img, &truth);
	ASSERT_EQ(truth.visible_mask, 0xfu);
	const Moments near = moments(img, truth.led_px[0], 30);
	EXPECT_EQ(near.max, 255);
	EXPECT_GT(near.saturated, 50);
}

TEST(Renderer, BackFacingAndOutOfFrameLedsAreNotDrawn)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const CameraModel cam(k);
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.background = 12.0;
	Image img;
	RenderTruth truth;

	/* Seen from behind: nothing at all. */
	const Pose behind = poseAt(k, target, 800, { 0, 180, 0 });
	for (int i = 0; i < 6; ++i)
		EXPECT_FALSE(renderer.ledVisible(behind, i, o.max_view_angle_deg));
	renderer.render(behind, o, 9, &img, &truth);
	EXPECT_EQ(truth.visible_mask, 0u);
	EXPECT_EQ(truth.clutter_blobs, 0);
	EXPECT_EQ(*std::min_element(img.data(), img.data() + k.width * k.height), 12);
	EXPECT_EQ(*std::max_element(img.data(), img.data() + k.width * k.height), 12);

	/* Turned so one face is seen beyond 75 degrees: only the other face's LEDs. */
	for (double pan : { 55.0, -55.0, 62.0 }) {
		const Pose pose = poseAt(k, target, 800, { 0, pan, 0 });
		std::uint32_t expected = 0;
		for (int i = 0; i < 6; ++i) {
			const Eigen::Vector3d p = pose.apply(target.points_mm[i]);
			for (int f = 0; f < 2; ++f) {
				const auto &face = target.faces[f];
				if (std::find(face.begin(), face.end(), i) == face.end())
					continue;
				const double angle = std::acos((pose.R * outwardNormal(target, f))
								       .dot(-p.normalized())) *
						     180.0 / kPi;
				if (angle < o.max_view_angle_deg)
					expected |= 1u << i;
			}
			EXPECT_EQ(renderer.ledVisible(pose, i, o.max_view_angle_deg),
				  ((expected >> i) & 1u) != 0);
		}
		ASSERT_EQ(std::popcount(expected), 4)
			<< "pan " << pan; /* the test needs a mixed case */
		renderer.render(pose, o, 9, &img, &truth);
		EXPECT_EQ(truth.visible_mask, expected) << "pan " << pan;
		for (int i = 0; i < 6; ++i) {
			const Eigen::Vector2d uv = truth.led_px[i];
			const int x = static_cast<int>(std::lround(uv.x())),
				  y = static_cast<int>(std::lround(uv.y()));
			if (expected & (1u << i))
				EXPECT_GT(img.at(x, y), 40) << "pan " << pan << " LED " << i;
			else
				EXPECT_EQ(img.at(x, y), 12) << "pan " << pan << " LED " << i;
		}
	}

	/* Half out of the frame: LEDs projecting outside are not drawn (nor counted). */
	const Pose edge = poseAt(k, target, 600, { 0, 0, 0 }, 0.01, 0.5);
	renderer.render(edge, o, 9, &img, &truth);
	std::uint32_t inside = 0;
	for (int i = 0; i < 6; ++i)
		if (cam.inImage(truth.led_px[i]))
			inside |= 1u << i;
	EXPECT_NE(inside, 0u);
	EXPECT_NE(inside, 0x3fu);
	EXPECT_EQ(truth.visible_mask, inside);
}

namespace {

struct Component {
	int area = 0;
	int max = 0;
	int x0 = 1 << 30, x1 = -1, y0 = 1 << 30, y1 = -1;
	double elongation = 1.0;
};

/* 8-connected components of pixels >= level (a plain flood fill). */
std::vector<Component> components(const Image &img, int level)
{
	const int w = img.width(), h = img.height();
	std::vector<int> label(static_cast<std::size_t>(w) * h, -1);
	std::vector<Component> out;
	std::vector<std::pair<int, int>> stack;
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x) {
			if (img.at(x, y) < level || label[y * w + x] >= 0)
				continue;
			Component c;
			double s = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
			stack.push_back({ x, y });
			label[y * w + x] = static_cast<int>(out.size());
			while (!stack.empty()) {
				const auto [px, py] = stack.back();
				stack.pop_back();
				++c.area;
				c.max = std::max<int>(c.max, img.at(px, py));
				c.x0 = std::min(c.x0, px);
				c.x1 = std::max(c.x1, px);
				c.y0 = std::min(c.y0, py);
				c.y1 = std::max(c.y1, py);
				s += 1;
				sx += px;
				sy += py;
				sxx += px * px;
				syy += py * py;
				sxy += px * py;
				for (int dy = -1; dy <= 1; ++dy)
					for (int dx = -1; dx <= 1; ++dx) {
						const int qx = px + dx, qy = py + dy;
						if (qx < 0 || qy < 0 || qx >= w || qy >= h ||
						    img.at(qx, qy) < level ||
						    label[qy * w + qx] >= 0)
							continue;
						label[qy * w + qx] = static_cast<int>(out.size());
						stack.push_back({ qx, qy });
					}
			}
			Eigen::Matrix2d cov;
			const double mx = sx / s, my = sy / s;
			cov << sxx / s - mx * mx, sxy / s - mx * my, sxy / s - mx * my,
				syy / s - my * my;
			const Eigen::Vector2d ev =
				Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues();
			c.elongation = std::sqrt(std::max(ev(1), 1e-9) / std::max(ev(0), 1e-9));
			out.push_back(c);
		}
	return out;
}

} /* namespace */

TEST(Renderer, ClutterAppearsInTheRequestedNumbersAndKinds)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.background = 12.0;
	o.reflections = 5;
	o.glints = 4;
	o.hot_pixels = 30;
	for (std::uint64_t seed : { 1u, 2u, 3u, 4u }) {
		Image img;
		RenderTruth truth;
		renderer.render(poseAt(k, target, 800, { 5, 10, 0 }), o, seed, &img, &truth);
		ASSERT_EQ(truth.visible_mask, 0x3fu);
		EXPECT_EQ(truth.clutter_blobs, 9) << "seed " << seed;
		int hot = 0, glints = 0, round = 0, leds = 0;
		for (const Component &c : components(img, 27)) {
			if (c.area == 1) {
				EXPECT_EQ(c.max, 255);
				++hot;
				continue;
			}
			int contains = 0;
			for (const auto &uv : truth.led_px)
				contains += uv.x() >= c.x0 && uv.x() <= c.x1 && uv.y() >= c.y0 &&
					    uv.y() <= c.y1;
			if (contains > 1)
				ADD_FAILURE() << "one blob holds " << contains << " LEDs";
			if (contains == 1)
				++leds;
			else if (c.elongation > 4.0)
				++glints;
			else if (c.elongation < 1.5)
				++round;
			else
				ADD_FAILURE()
					<< "blob of unexpected shape, elongation " << c.elongation;
		}
		EXPECT_EQ(hot, 30) << "seed " << seed;
		EXPECT_EQ(leds, 6) << "seed " << seed;
		EXPECT_EQ(glints, 4) << "seed " << seed;
		EXPECT_EQ(round, 5) << "seed " << seed;
	}

	/* No clutter asked, none drawn: exactly the LED blobs. */
	Image img;
	RenderTruth truth;
	renderer.render(poseAt(k, target, 800, { 5, 10, 0 }), quiet(), 1, &img, &truth);
	EXPECT_EQ(truth.clutter_blobs, 0);
	EXPECT_EQ(components(img, 15).size(), 6u);
}

TEST(Renderer, OcclusionHidesLeds)
{
	const CameraIntrinsics k = loadCamera("cam512.json");
	const TargetModel target = loadTarget("corner.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.background = 12.0;
	const Pose pose = poseAt(k, target, 900, { 0, 0, 0 });
	Image img;
	RenderTruth truth;
	renderer.render(pose, o, 1, &img, &truth);
	ASSERT_EQ(truth.visible_mask, 0x7fu);
	EXPECT_EQ(truth.occluded_mask, 0u);

	std::vector<std::uint32_t> seen;
	for (std::uint64_t seed = 1; seed <= 8; ++seed) {
		o.occluded_leds = 2;
		o.occlusion_mask = 0;
		renderer.render(pose, o, seed, &img, &truth);
		EXPECT_EQ(std::popcount(truth.occluded_mask), 2);
		EXPECT_EQ(truth.visible_mask, 0x7fu & ~truth.occluded_mask);
		for (int i = 0; i < 7; ++i) {
			const int x = static_cast<int>(std::lround(truth.led_px[i].x()));
			const int y = static_cast<int>(std::lround(truth.led_px[i].y()));
			if (truth.occluded_mask & (1u << i))
				EXPECT_EQ(img.at(x, y), 12);
			else
				EXPECT_GT(img.at(x, y), 40);
		}
		seen.push_back(truth.occluded_mask);
	}
	std::sort(seen.begin(), seen.end());
	EXPECT_GE(std::unique(seen.begin(), seen.end()) - seen.begin(),
		  3); /* the choice is random */

	o.occluded_leds = 0;
	o.occlusion_mask = 0x1u | 0x20u;
	renderer.render(pose, o, 1, &img, &truth);
	EXPECT_EQ(truth.occluded_mask, 0x21u);
	EXPECT_EQ(truth.visible_mask, 0x7fu & ~0x21u);
}

TEST(Renderer, DeterministicNoiseAndGradient)
{
	const CameraIntrinsics k = loadCamera("cam512.json");
	const TargetModel target = loadTarget("wedge.json");
	RenderOptions o;
	o.noise_sigma = 3.0;
	o.reflections = 3;
	o.glints = 2;
	o.hot_pixels = 10;
	o.occluded_leds = 1;
	const Pose pose = poseAt(k, target, 1500, { 3, -8, 2 });
	Image a, b, c;
	RenderTruth ta, tb;
	FrameRenderer(target, k).render(pose, o, 42, &a, &ta);
	FrameRenderer(target, k).render(pose, o, 42, &b, &tb);
	EXPECT_TRUE(std::equal(a.data(), a.data() + 512 * 512, b.data()));
	EXPECT_EQ(ta.occluded_mask, tb.occluded_mask);
	FrameRenderer(target, k).render(pose, o, 43, &c);
	int differ = 0;
	for (int i = 0; i < 512 * 512; ++i)
		differ += a.data()[i] != c.data()[i];
	EXPECT_GT(differ, 512 * 512 / 2);

	/* Noise only (target seen from behind): mean and sigma as asked. */
	RenderOptions n = quiet();
	n.background = 100.0;
	n.noise_sigma = 5.0;
	FrameRenderer(target, k).render(poseAt(k, target, 800, { 0, 180, 0 }), n, 7, &a);
	double s = 0, ss = 0;
	for (int i = 0; i < 512 * 512; ++i) {
		s += a.data()[i];
		ss += a.data()[i] * a.data()[i];
	}
	const double mean = s / (512 * 512), var = ss / (512 * 512) - mean * mean;
	EXPECT_NEAR(mean, 100.0, 0.05);
	EXPECT_NEAR(std::sqrt(var), std::sqrt(25.0 + 1.0 / 12.0), 0.05);
	/* Neighbouring pixels are independent. */
	double cxy = 0;
	for (int y = 0; y < 512; ++y)
		for (int x = 0; x + 1 < 512; ++x)
			cxy += (a.at(x, y) - mean) * (a.at(x + 1, y) - mean);
	EXPECT_NEAR(cxy / (511.0 * 512.0) / var, 0.0, 0.01);

	/* Gradient only: `gradient` levels from one side of the frame to the other, linear. */
	RenderOptions g = quiet();
	g.background = 100.0;
	g.gradient = 40.0;
	for (std::uint64_t seed : { 1u, 2u, 3u }) {
		FrameRenderer(target, k).render(poseAt(k, target, 800, { 0, 180, 0 }), g, seed, &a);
		const auto [lo, hi] = std::minmax_element(a.data(), a.data() + 512 * 512);
		EXPECT_NEAR(*hi - *lo, 40, 1);
		EXPECT_NEAR(
			0.25 * (a.at(255, 255) + a.at(256, 255) + a.at(255, 256) + a.at(256, 256)),
			100.0, 1.0);
		/* Linear: the centre is the mean of opposite corners. */
		EXPECT_NEAR(0.5 * (a.at(0, 0) + a.at(511, 511)), a.at(256, 256), 1.2);
		EXPECT_NEAR(0.5 * (a.at(511, 0) + a.at(0, 511)), a.at(256, 256), 1.2);
	}
}

TEST(Renderer, PoseAtPlacesTheTargetCentre)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const CameraModel cam(k);
	for (const char *name : { "wedge.json", "corner.json" }) {
		const TargetModel target = loadTarget(name);
		Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
		for (const auto &p : target.points_mm)
			centroid += p;
		centroid /= static_cast<double>(target.points_mm.size());
		const Eigen::Vector3d rpy(12, -30, 75);
		const Pose pose = poseAt(k, target, 950, rpy, 0.2, 0.7);
		EXPECT_LT(rotationAngleDeg(pose.R, rotationFromRollPanTiltDeg(rpy)), 1e-9);
		const Eigen::Matrix3d rx =
			Eigen::AngleAxisd(rpy.x() * kPi / 180, Eigen::Vector3d::UnitX())
				.toRotationMatrix();
		const Eigen::Matrix3d ry =
			Eigen::AngleAxisd(rpy.y() * kPi / 180, Eigen::Vector3d::UnitY())
				.toRotationMatrix();
		const Eigen::Matrix3d rz =
			Eigen::AngleAxisd(rpy.z() * kPi / 180, Eigen::Vector3d::UnitZ())
				.toRotationMatrix();
		EXPECT_LT((pose.R - rx * ry * rz).norm(), 1e-12);
		const Eigen::Vector3d c = pose.apply(centroid);
		EXPECT_NEAR(c.z(), 950.0, 1e-9);
		Eigen::Vector2d uv;
		ASSERT_TRUE(cam.project(c, &uv));
		EXPECT_NEAR(uv.x(), 0.2 * 1456 - 0.5, 1e-6);
		EXPECT_NEAR(uv.y(), 0.7 * 1088 - 0.5, 1e-6);
	}
}

TEST(Renderer, RenderDoesNotAllocate)
{
	const CameraIntrinsics k = loadCamera("cam512.json");
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o;
	o.reflections = 4;
	o.glints = 3;
	o.hot_pixels = 20;
	o.occluded_leds = 1;
	Image img(k.width, k.height);
	RenderTruth truth;
	const Pose pose = poseAt(k, target, 700, { 5, 5, 5 });
	const long before = g_allocations.load();
	renderer.render(pose, o, 1, &img, &truth);
	renderer.render(pose, o, 2, &img, &truth);
	EXPECT_EQ(g_allocations.load() - before, 0);
	/* The counter does count (the test can fail). */
	Image wrong(10, 10);
	const long before2 = g_allocations.load();
	renderer.render(pose, o, 1, &wrong, nullptr);
	EXPECT_GT(g_allocations.load() - before2, 0);
	EXPECT_EQ(wrong.width(), k.width);
}

/* ---- The harder scenes. ---- */

namespace {

/* Mean level on the ring |p - c| in [r - 0.5, r + 0.5). */
double ringMean(const Image &img, const Eigen::Vector2d &c, double r)
{
	double sum = 0.0;
	int n = 0;
	const int reach = static_cast<int>(std::ceil(r + 1.0));
	for (int y = static_cast<int>(c.y()) - reach; y <= static_cast<int>(c.y()) + reach; ++y)
		for (int x = static_cast<int>(c.x()) - reach; x <= static_cast<int>(c.x()) + reach;
		     ++x) {
			if (x < 0 || y < 0 || x >= img.width() || y >= img.height())
				continue;
			const double d = (Eigen::Vector2d(x, y) - c).norm();
			if (d >= r - 0.5 && d < r + 0.5) {
				sum += img.at(x, y);
				++n;
			}
		}
	return n > 0 ? sum / n : 0.0;
}

/* The smallest radius beyond which the ring mean stays below level. */
double radiusBelow(const Image &img, const Eigen::Vector2d &c, double level, double max_r)
{
	double r_out = 0.0;
	for (double r = 0.0; r <= max_r; r += 0.25)
		if (ringMean(img, c, r) >= level)
			r_out = r;
	return r_out;
}

std::uint32_t faceMaskOf(const TargetModel &m, std::size_t f)
{
	std::uint32_t mask = 0;
	for (int v : m.faces[f])
		mask |= 1u << v;
	return mask;
}

} /* namespace */

TEST(RendererHard, BloomClipsAt255AndItsHaloScalesWithTheOption)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = board();
	FrameRenderer renderer(target, k);
	const Pose pose = poseAt(k, target, 800, { 0, 0, 0 });
	const double halo_peak = 80.0;
	Image img;
	RenderTruth truth;

	/* Without bloom: not saturated, and dark at twice the spot's radius. */
	RenderOptions o = quiet();
	renderer.render(pose, o, 1, &img, &truth);
	const Eigen::Vector2d c = truth.led_px[0];
	const Eigen::Vector3d p = pose.apply(target.points_mm[0]);
	const double r_spot = k.fx * o.led_radius_mm / p.norm(); /* head on: nearly round */
	ASSERT_GT(r_spot, 4.0);
	EXPECT_LT(moments(img, c, 30).max, 200);
	EXPECT_LT(ringMean(img, c, 2.0 * r_spot), 2.0);

	double radius_at[2] = { 0.0, 0.0 };
	const double blooms[2] = { 2.0, 3.0 };
	for (int b = 0; b < 2; ++b) {
		o.bloom = blooms[b];
		o.bloom_halo_peak = halo_peak;
		renderer.render(pose, o, 1, &img, &truth);
		ASSERT_EQ(truth.visible_mask, 0xfu);
		const Moments m = moments(img, c, 40);
		EXPECT_EQ(m.max, 255);
		/* The core is clipped: the whole emitting disc reads 255. */
		EXPECT_GT(m.saturated, static_cast<int>(0.8 * kPi * r_spot * r_spot));
		EXPECT_EQ(img.at(static_cast<int>(std::lround(c.x())),
				 static_cast<int>(std::lround(c.y()))),
			  255);
		/* The halo: half its level at `bloom` spot radii (within the blur of its edge). */
		radius_at[b] = radiusBelow(img, c, 0.5 * halo_peak, 50.0);
		EXPECT_NEAR(radius_at[b], blooms[b] * r_spot, 0.15 * blooms[b] * r_spot)
			<< "bloom " << blooms[b];
		/* Beyond the halo the frame is dark again. */
		EXPECT_LT(ringMean(img, c, 2.0 * blooms[b] * r_spot), 3.0);
		/* The centroid stays on the LED (everything is symmetric about it). */
		EXPECT_LT(
			(moments(img, c, static_cast<int>(3 * blooms[b] * r_spot)).mean - c).norm(),
			0.05);
	}
	EXPECT_NEAR(radius_at[1] / radius_at[0], 1.5, 0.12);
}

TEST(RendererHard, MotionBlurElongatesTheSpotAlongItsDirection)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = board();
	FrameRenderer renderer(target, k);
	const Pose pose = poseAt(k, target, 900, { 0, 0, 0 });
	RenderOptions o = quiet();
	o.led_peak = 400.0; /* bright (little quantisation), not saturated */
	o.min_led_peak = 0.0; /* energy kept exactly (no floor) */
	Image img;
	RenderTruth truth;
	renderer.render(pose, o, 1, &img, &truth);
	const Eigen::Vector2d c = truth.led_px[2];
	const Moments still = moments(img, c, 30);
	ASSERT_EQ(still.saturated, 0);

	for (const double length : { 3.0, 7.0, 12.0 })
		for (const double angle_deg : { 0.0, 30.0, 115.0 }) {
			o.motion_blur_px = length;
			o.motion_blur_angle_deg = angle_deg;
			renderer.render(pose, o, 1, &img, &truth);
			EXPECT_NEAR(truth.motion_blur_angle_deg, angle_deg, 1e-9);
			const Moments m = moments(img, c, 30);
			const Eigen::Vector2d d(std::cos(angle_deg * kPi / 180.0),
						std::sin(angle_deg * kPi / 180.0));
			const Eigen::Vector2d n(-d.y(), d.x());
			/* A uniform streak of length L adds L^2/12 along it, nothing across. */
			const double along = d.dot((m.cov - still.cov) * d);
			const double across = n.dot((m.cov - still.cov) * n);
			EXPECT_NEAR(along, length * length / 12.0,
				    0.03 * length * length / 12.0 + 0.03)
				<< "L " << length << " angle " << angle_deg;
			EXPECT_NEAR(across, 0.0, 0.04) << "L " << length << " angle " << angle_deg;
			EXPECT_LT((m.mean - c).norm(), 0.03);
			EXPECT_NEAR(m.sum, still.sum,
				    0.01 * still.sum); /* the energy is spread, not lost */
			/* So the peak falls once the streak is longer than the flat top is wide. */
			EXPECT_LE(m.max, still.max);
			if (length > 2.0 * k.fx * o.led_radius_mm / 900.0) {
				EXPECT_LT(m.max, 0.8 * still.max) << "L " << length;
			}
		}

	/* The gain floor holds for a streak too: a dim LED does not vanish. */
	o = quiet();
	o.motion_blur_px = 12.0;
	o.motion_blur_angle_deg = 45.0;
	renderer.render(poseAt(k, target, 3000, { 0, 0, 0 }), o, 1, &img, &truth);
	EXPECT_GE(moments(img, truth.led_px[0], 15).max, static_cast<int>(0.85 * o.min_led_peak));

	/* A random direction per frame seed. */
	o.motion_blur_angle_deg = std::numeric_limits<double>::quiet_NaN();
	std::vector<double> angles;
	for (std::uint64_t seed = 1; seed <= 5; ++seed) {
		renderer.render(pose, o, seed, &img, &truth);
		angles.push_back(truth.motion_blur_angle_deg);
	}
	std::sort(angles.begin(), angles.end());
	EXPECT_EQ(std::unique(angles.begin(), angles.end()) - angles.begin(), 5);
}

TEST(RendererHard, DimmedLedsPeakAtTheAskedFraction)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = board();
	FrameRenderer renderer(target, k);
	const Pose pose = poseAt(k, target, 700, { 0, 0, 0 });
	RenderOptions o = quiet();
	o.led_peak = 200.0;
	Image plain, img;
	RenderTruth truth;
	renderer.render(pose, o, 1, &plain, &truth);
	int plain_max[4];
	for (int i = 0; i < 4; ++i) {
		plain_max[i] = moments(plain, truth.led_px[i], 20).max;
		ASSERT_LT(plain_max[i], 255);
		ASSERT_GT(plain_max[i], 100);
	}

	o.dim_mask = 0x2u;
	o.dim_min = o.dim_max = 0.3;
	renderer.render(pose, o, 1, &img, &truth);
	EXPECT_EQ(truth.dimmed_mask, 0x2u);
	for (int i = 0; i < 4; ++i) {
		const int m = moments(img, truth.led_px[i], 20).max;
		if (i == 1)
			EXPECT_NEAR(m, 0.3 * plain_max[i], 1.5);
		else
			EXPECT_EQ(m, plain_max[i]);
	}

	/* Random LEDs, factors drawn in [0.25, 0.40]. */
	o.dim_mask = 0;
	o.dimmed_leds = 2;
	o.dim_min = 0.25;
	o.dim_max = 0.40;
	std::vector<std::uint32_t> seen;
	for (std::uint64_t seed = 1; seed <= 8; ++seed) {
		renderer.render(pose, o, seed, &img, &truth);
		ASSERT_EQ(std::popcount(truth.dimmed_mask), 2);
		seen.push_back(truth.dimmed_mask);
		for (int i = 0; i < 4; ++i) {
			const double ratio = moments(img, truth.led_px[i], 20).max /
					     static_cast<double>(plain_max[i]);
			if (truth.dimmed_mask & (1u << i)) {
				EXPECT_GE(ratio, 0.25 - 0.015);
				EXPECT_LE(ratio, 0.40 + 0.015);
			} else {
				EXPECT_EQ(ratio, 1.0);
			}
		}
	}
	std::sort(seen.begin(), seen.end());
	EXPECT_GE(std::unique(seen.begin(), seen.end()) - seen.begin(), 3);
}

TEST(RendererHard, OneFaceOcclusionLeavesExactlyOneFace)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	for (const char *name : { "corner.json", "pyramid.json", "roof.json" }) {
		const TargetModel target = loadTarget(name);
		FrameRenderer renderer(target, k);
		RenderOptions o = quiet();
		o.background = 12.0;
		Image img;
		RenderTruth truth;
		/* A view in which several faces are complete. */
		Pose pose;
		int complete = 0;
		for (const Eigen::Vector3d &rpy :
		     { Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 40, 0),
		       Eigen::Vector3d(40, 0, 0), Eigen::Vector3d(0, -40, 0),
		       Eigen::Vector3d(-40, 0, 0) }) {
			pose = poseAt(k, target, 900, rpy);
			renderer.render(pose, o, 1, &img, &truth);
			complete = 0;
			for (std::size_t f = 0; f < target.faces.size(); ++f)
				complete += (truth.visible_mask & faceMaskOf(target, f)) ==
					    faceMaskOf(target, f);
			if (complete >= 2)
				break;
		}
		ASSERT_GE(complete, 2) << name;

		o.one_face_only = true;
		std::vector<int> kept;
		for (std::uint64_t seed = 1; seed <= 12; ++seed) {
			renderer.render(pose, o, seed, &img, &truth);
			ASSERT_GE(truth.kept_face, 0);
			const std::uint32_t face = faceMaskOf(target, truth.kept_face);
			EXPECT_EQ(truth.visible_mask, face) << name << " seed " << seed;
			for (std::size_t i = 0; i < target.points_mm.size(); ++i) {
				const int x = static_cast<int>(std::lround(truth.led_px[i].x()));
				const int y = static_cast<int>(std::lround(truth.led_px[i].y()));
				if (face & (1u << i))
					EXPECT_GT(img.at(x, y), 40) << name << " LED " << i;
				else
					EXPECT_EQ(img.at(x, y), 12) << name << " LED " << i;
			}
			kept.push_back(truth.kept_face);
		}
		std::sort(kept.begin(), kept.end());
		EXPECT_GE(std::unique(kept.begin(), kept.end()) - kept.begin(), 2) << name;

		/* A chosen face: only its drawable LEDs remain (all four when it is complete). */
		o.one_face_only = false;
		for (std::size_t f = 0; f < target.faces.size(); ++f) {
			o.keep_face = -1;
			renderer.render(pose, o, 1, &img, &truth);
			const std::uint32_t drawable = truth.visible_mask;
			o.keep_face = static_cast<int>(f);
			renderer.render(pose, o, 1, &img, &truth);
			EXPECT_EQ(truth.kept_face, static_cast<int>(f));
			EXPECT_EQ(truth.visible_mask, faceMaskOf(target, f) & drawable) << name;
		}
	}
}

TEST(RendererHard, TargetFreeFramesDrawNoLed)
{
	const CameraIntrinsics k = loadCamera("cam512.json");
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.background = 12.0;
	o.draw_target = false;
	const Pose pose = poseAt(k, target, 800, { 5, 10, 0 });
	Image img;
	RenderTruth truth;
	renderer.render(pose, o, 3, &img, &truth);
	EXPECT_FALSE(truth.target_drawn);
	EXPECT_EQ(truth.visible_mask, 0u);
	EXPECT_EQ(*std::min_element(img.data(), img.data() + 512 * 512), 12);
	EXPECT_EQ(*std::max_element(img.data(), img.data() + 512 * 512), 12);

	/* Clutter is still drawn, in the asked numbers, and may sit where the target would be. */
	o.reflections = 10;
	o.near_reflections = 10;
	o.glints = 2;
	double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
	for (const auto &uv : truth.led_px) {
		x0 = std::min(x0, uv.x());
		x1 = std::max(x1, uv.x());
		y0 = std::min(y0, uv.y());
		y1 = std::max(y1, uv.y());
	}
	int in_place = 0;
	for (std::uint64_t seed = 1; seed <= 10; ++seed) {
		renderer.render(pose, o, seed, &img, &truth);
		EXPECT_EQ(truth.visible_mask, 0u);
		EXPECT_EQ(truth.clutter_blobs, 22);
		const std::vector<Component> blobs = components(img, 20);
		EXPECT_EQ(blobs.size(), 22u) << "seed " << seed;
		for (const Component &c : blobs) {
			const double cx = 0.5 * (c.x0 + c.x1), cy = 0.5 * (c.y0 + c.y1);
			in_place += cx > x0 && cx < x1 && cy > y0 && cy < y1;
		}
	}
	EXPECT_GT(in_place, 3);
}

TEST(RendererHard, ScrambledFramesMoveEveryLedByTheAskedShare)
{
	const CameraIntrinsics k = loadCamera("cam512.json");
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	const Pose pose = poseAt(k, target, 900, { 5, 10, 0 });
	Image img;
	RenderTruth plain, scrambled;
	renderer.render(pose, o, 3, &img, &plain);
	EXPECT_FALSE(plain.scrambled);
	o.scramble = 0.4;
	const double diameter = target.diameterMm();
	double shift_sum = 0.0, scale_sum = 0.0;
	for (std::uint64_t seed = 1; seed <= 20; ++seed) {
		renderer.render(pose, o, seed, &img, &scrambled);
		EXPECT_TRUE(scrambled.scrambled);
		EXPECT_TRUE(scrambled.target_drawn);
		EXPECT_NE(scrambled.visible_mask, 0u) << "seed " << seed;
		for (std::size_t i = 0; i < target.points_mm.size(); ++i) {
			if (!(scrambled.visible_mask & (1u << i)))
				continue;
			/* Displaced 0.2-0.4 diameters in 3-D: at least the perpendicular share moves in the image. */
			const Eigen::Vector2d shift = scrambled.led_px[i] - plain.led_px[i];
			const double z = pose.apply(target.points_mm[i]).z();
			EXPECT_LT(shift.norm(), 0.4 * diameter * k.fx / (z - 0.4 * diameter) + 1e-6)
				<< "seed " << seed;
			shift_sum += shift.norm();
			scale_sum += 0.3 * diameter * k.fx / z; /* the mean displacement, head on */
		}
		/* The LEDs drawn are blobs (two may merge where they land together). */
		const int blobs = static_cast<int>(components(img, 20).size());
		EXPECT_GE(blobs, 1) << "seed " << seed;
		EXPECT_LE(blobs, std::popcount(scrambled.visible_mask)) << "seed " << seed;
	}
	/* A random direction keeps on average pi/4 of a displacement across the line of sight. */
	EXPECT_GT(shift_sum, 0.5 * scale_sum);
	/* The same seed scrambles the same way; another seed differently. */
	RenderTruth again;
	renderer.render(pose, o, 20, &img, &again);
	EXPECT_EQ(again.led_px[0], scrambled.led_px[0]);
	renderer.render(pose, o, 21, &img, &again);
	EXPECT_NE(again.led_px[0], scrambled.led_px[0]);
}

TEST(RendererHard, ReflectionsNearTheTargetStaySeparateBlobs)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.background = 12.0;
	o.reflections = 6;
	o.near_reflections = 24;
	o.reflection_squash = 0.5;
	int inside_box = 0, elongated = 0;
	for (std::uint64_t seed : { 1u, 2u, 3u }) {
		Image img;
		RenderTruth truth;
		renderer.render(poseAt(k, target, 900, { 5, 10, 0 }), o, seed, &img, &truth);
		ASSERT_EQ(truth.visible_mask, 0x3fu);
		EXPECT_EQ(truth.clutter_blobs, 30) << "seed " << seed;
		double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
		for (const auto &uv : truth.led_px) {
			x0 = std::min(x0, uv.x());
			x1 = std::max(x1, uv.x());
			y0 = std::min(y0, uv.y());
			y1 = std::max(y1, uv.y());
		}
		int leds = 0, others = 0;
		for (const Component &c : components(img, 20)) {
			int contains = 0;
			for (const auto &uv : truth.led_px)
				contains += uv.x() >= c.x0 && uv.x() <= c.x1 && uv.y() >= c.y0 &&
					    uv.y() <= c.y1;
			EXPECT_LE(contains, 1) << "a reflection merged with an LED, seed " << seed;
			if (contains == 1) {
				++leds;
				continue;
			}
			++others;
			const double cx = 0.5 * (c.x0 + c.x1), cy = 0.5 * (c.y0 + c.y1);
			inside_box += cx > x0 && cx < x1 && cy > y0 && cy < y1;
			elongated += c.elongation > 1.3;
		}
		EXPECT_EQ(leds, 6) << "seed " << seed;
		EXPECT_EQ(others, 30) << "seed " << seed;
	}
	EXPECT_GE(inside_box, 6); /* among the LEDs, not only around them */
	EXPECT_GE(elongated, 10); /* squashed like foreshortened LEDs */
}

TEST(RendererHard, SunlitPatchesAreLargeSmoothAndMaySaturate)
{
	const CameraIntrinsics k = loadCamera("cam1456.json");
	const TargetModel target = loadTarget("wedge.json");
	FrameRenderer renderer(target, k);
	RenderOptions o = quiet();
	o.background = 20.0;
	o.sun_patches = 2;
	o.sun_peak_min = o.sun_peak_max = 320.0;
	const Pose behind = poseAt(k, target, 800, { 0, 180, 0 }); /* no LED: the patches alone */
	Image img;
	RenderTruth truth;
	int saturated_frames = 0;
	for (std::uint64_t seed = 1; seed <= 4; ++seed) {
		renderer.render(behind, o, seed, &img, &truth);
		EXPECT_EQ(truth.sun_patches, 2);
		int saturated = 0, bright = 0, steepest = 0;
		for (int y = 0; y < k.height; ++y)
			for (int x = 0; x < k.width; ++x) {
				saturated += img.at(x, y) == 255;
				bright += img.at(x, y) > 120;
				if (x + 1 < k.width)
					steepest = std::max(steepest, std::abs(img.at(x + 1, y) -
									       img.at(x, y)));
				if (y + 1 < k.height)
					steepest = std::max(steepest, std::abs(img.at(x, y + 1) -
									       img.at(x, y)));
			}
		saturated_frames += saturated > 2000;
		/* Large: each semi-axis at least 6% of 1456 px, partly outside the frame at worst. */
		EXPECT_GT(bright, 3000) << "seed " << seed;
		/* Smooth: the edge ramps over at least 30 px (smoothstep slope <= 1.5 peak / 30 px). */
		EXPECT_LE(steepest, static_cast<int>(std::ceil(1.5 * 320.0 / 30.0)) + 1);
	}
	EXPECT_GE(saturated_frames, 3);

	/* Over the target: LEDs on a saturated patch are not counted as drawn. */
	o.sun_patches = 12;
	o.sun_peak_min = o.sun_peak_max = 400.0;
	const Pose front = poseAt(k, target, 800, { 5, 10, 0 });
	int washed = 0;
	for (std::uint64_t seed = 1; seed <= 20; ++seed) {
		renderer.render(front, o, seed, &img, &truth);
		EXPECT_EQ(truth.visible_mask & truth.washed_out_mask, 0u);
		EXPECT_EQ(truth.visible_mask | truth.washed_out_mask, 0x3fu);
		for (int i = 0; i < 6; ++i)
			if (truth.washed_out_mask & (1u << i)) {
				++washed;
				EXPECT_EQ(
					img.at(static_cast<int>(std::lround(truth.led_px[i].x())),
					       static_cast<int>(std::lround(truth.led_px[i].y()))),
					255);
			}
	}
	EXPECT_GT(washed, 0);
}

TEST(RendererHard, SideViewsStayInsideTheConeAndTheFrame)
{
	for (const char *cam_name : { "cam-wide.json", "cam1456.json", "cam512.json" })
		for (const char *name :
		     { "wedge.json", "corner.json", "pyramid.json", "roof.json" }) {
			const TargetModel target = loadTarget(name);
			const CameraIntrinsics k = loadCamera(cam_name);
			const CameraModel cam(k);
			FrameRenderer renderer(target, k);
			StaticVector<Eigen::Vector3d, kMaxFaces> normals;
			target.frontNormals(&normals);
			Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
			for (const auto &p : target.points_mm)
				centroid += p;
			centroid /= static_cast<double>(target.points_mm.size());
			const double max_angle = 60.0;
			double widest = 0.0;
			int fitted = 0, quadrant[4] = { 0, 0, 0, 0 };
			for (std::uint64_t seed = 1; seed <= 120; ++seed) {
				const int face = static_cast<int>(seed % target.faces.size());
				const double range = 700.0 + 10.0 * seed;
				Pose pose;
				SideView view;
				const bool fits = sampleSideView(k, target, face, range, max_angle,
								 seed, &pose, &view);
				ASSERT_TRUE(fits) << name << " " << cam_name << " seed " << seed;
				++fitted;
				EXPECT_EQ(view.face, face);
				EXPECT_NEAR(
					(pose.R.transpose() * pose.R - Eigen::Matrix3d::Identity())
						.norm(),
					0.0, 1e-12);
				EXPECT_NEAR(pose.R.determinant(), 1.0, 1e-12);
				/* The face's centre at the range, its normal within the cone. */
				Eigen::Vector3d centre = Eigen::Vector3d::Zero();
				for (int v : target.faces[face])
					centre += target.points_mm[v];
				centre = pose.apply(centre / 4.0);
				EXPECT_NEAR(centre.norm(), range, 1e-6);
				const double angle =
					std::acos(std::clamp(
						(pose.R * normals[face]).dot(-centre.normalized()),
						-1.0, 1.0)) *
					180.0 / kPi;
				EXPECT_LE(angle, max_angle + 1e-6) << name << " seed " << seed;
				EXPECT_NEAR(angle, view.angle_deg, 1e-6);
				widest = std::max(widest, angle);
				/* The whole target inside the frame, so its centroid too. */
				EXPECT_TRUE(targetInFrame(cam, target, pose, 4.0));
				Eigen::Vector2d uv;
				ASSERT_TRUE(cam.project(pose.apply(centroid), &uv));
				EXPECT_TRUE(cam.inImage(uv, 4.0));
				quadrant[(uv.x() > 0.5 * k.width) + 2 * (uv.y() > 0.5 * k.height)]++;
				/* Inside the emission cone, the chosen face is drawn whole. */
				for (int v : target.faces[face])
					EXPECT_TRUE(renderer.ledVisible(pose, v, 75.0))
						<< name << " " << cam_name << " seed " << seed
						<< " LED " << v;
			}
			EXPECT_GT(widest, 0.8 * max_angle) << name;
			EXPECT_EQ(fitted, 120);
			for (int q = 0; q < 4; ++q)
				EXPECT_GT(quadrant[q], 10)
					<< name << " " << cam_name << " quadrant " << q;
		}

	/* Too close to fit: reported, and the pose falls back to the frame's centre. */
	const TargetModel wedge = loadTarget("wedge.json");
	const CameraIntrinsics k = loadCamera("cam512.json");
	Pose pose;
	SideView view;
	EXPECT_FALSE(sampleSideView(k, wedge, 0, 60.0, 30.0, 1, &pose, &view));
	EXPECT_EQ(view.u_frac, 0.5);
	EXPECT_EQ(view.v_frac, 0.5);
}

TEST(RendererHard, NewTargetsAndTheWideCameraAreValid)
{
	struct Expect {
		const char *name;
		std::size_t leds, faces;
	};
	for (const Expect &e : { Expect{ "pyramid.json", 8, 5 }, Expect{ "roof.json", 8, 3 } }) {
		const TargetModel m = loadTarget(e.name);
		EXPECT_EQ(m.validate().message(), "") << e.name;
		EXPECT_EQ(m.points_mm.size(), e.leds);
		EXPECT_EQ(m.faces.size(), e.faces);
		EXPECT_GE(m.diameterMm(), 150.0);
		EXPECT_LE(m.diameterMm(), 250.0);
		/* Every face shares an edge (two LEDs) with another. */
		for (std::size_t f = 0; f < m.faces.size(); ++f) {
			bool adjacent = false;
			for (std::size_t g = 0; g < m.faces.size(); ++g)
				if (g != f &&
				    std::popcount(faceMaskOf(m, f) & faceMaskOf(m, g)) == 2)
					adjacent = true;
			EXPECT_TRUE(adjacent) << e.name << " face " << f;
		}
		/* Asymmetric: no two LED pairs are the same distance apart (no isometry permutes the LEDs). */
		std::vector<double> d;
		for (std::size_t i = 0; i < m.points_mm.size(); ++i)
			for (std::size_t j = i + 1; j < m.points_mm.size(); ++j)
				d.push_back((m.points_mm[i] - m.points_mm[j]).norm());
		std::sort(d.begin(), d.end());
		for (std::size_t i = 1; i < d.size(); ++i)
			EXPECT_GT(d[i] - d[i - 1], 0.1) << e.name;
		/* The fronts point out of the model. */
		StaticVector<Eigen::Vector3d, kMaxFaces> normals;
		m.frontNormals(&normals);
		Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
		for (const auto &p : m.points_mm)
			centroid += p;
		centroid /= static_cast<double>(m.points_mm.size());
		for (std::size_t f = 0; f < m.faces.size(); ++f) {
			Eigen::Vector3d centre = Eigen::Vector3d::Zero();
			for (int v : m.faces[f])
				centre += m.points_mm[v];
			EXPECT_GT(normals[f].dot(centre / 4.0 - centroid), 0.0)
				<< e.name << " face " << f;
		}
	}
	/* The pyramid's top and one side are rendered whole from inside both their cones. */
	const CameraIntrinsics wide = loadCamera("cam-wide.json");
	EXPECT_NEAR(wide.k1, -0.30, 0.02);
	EXPECT_GT(wide.k2, 0.0);
	/* The distortion is monotonic over the frame (no fold-back): corners round-trip. */
	const CameraModel cam(wide);
	for (const Eigen::Vector2d &uv :
	     { Eigen::Vector2d(0, 0), Eigen::Vector2d(wide.width - 1, 0),
	       Eigen::Vector2d(0, wide.height - 1),
	       Eigen::Vector2d(wide.width - 1, wide.height - 1) }) {
		Eigen::Vector2d xy;
		ASSERT_TRUE(cam.pixelToNormalized(uv, &xy));
		EXPECT_LT((cam.normalizedToPixel(xy) - uv).norm(), 1e-6);
		EXPECT_GT(xy.norm(), 1.2); /* wide: more than 50° off axis in the corners */
	}
}

TEST(RendererHard, EveryEffectAtOnceDoesNotAllocateAndIsDeterministic)
{
	const CameraIntrinsics k = loadCamera("cam512.json");
	const TargetModel target = loadTarget("pyramid.json");
	FrameRenderer renderer(target, k);
	RenderOptions o;
	o.reflections = 10;
	o.near_reflections = 12;
	o.reflection_squash = 0.5;
	o.glints = 3;
	o.hot_pixels = 20;
	o.bloom = 2.5;
	o.motion_blur_px = 9.0;
	o.dimmed_leds = 2;
	o.sun_patches = 2;
	o.one_face_only = true;
	o.fast_noise = true;
	Image a(k.width, k.height), b(k.width, k.height);
	RenderTruth ta, tb;
	const Pose pose = poseAt(k, target, 900, { 5, 5, 5 });
	const long before = g_allocations.load();
	renderer.render(pose, o, 7, &a, &ta);
	renderer.render(pose, o, 7, &b, &tb);
	EXPECT_EQ(g_allocations.load() - before, 0);
	EXPECT_TRUE(std::equal(a.data(), a.data() + k.width * k.height, b.data()));
	EXPECT_EQ(ta.visible_mask, tb.visible_mask);
	EXPECT_EQ(ta.dimmed_mask, tb.dimmed_mask);
	EXPECT_EQ(ta.clutter_blobs, tb.clutter_blobs);
	EXPECT_GE(ta.kept_face, 0);
	EXPECT_EQ(ta.sun_patches, 2);

	/* Fast noise: the asked sigma, no correlation between neighbours. */
	RenderOptions n = quiet();
	n.background = 100.0;
	n.noise_sigma = 5.0;
	n.fast_noise = true;
	renderer.render(poseAt(k, target, 800, { 0, 180, 0 }), n, 7, &a);
	double s = 0, ss = 0, cxy = 0;
	for (int i = 0; i < 512 * 512; ++i) {
		s += a.data()[i];
		ss += a.data()[i] * a.data()[i];
	}
	const double mean = s / (512 * 512), var = ss / (512 * 512) - mean * mean;
	for (int y = 0; y < 512; ++y)
		for (int x = 0; x + 1 < 512; ++x)
			cxy += (a.at(x, y) - mean) * (a.at(x + 1, y) - mean);
	EXPECT_NEAR(mean, 100.0, 0.05);
	EXPECT_NEAR(std::sqrt(var), std::sqrt(25.0 + 1.0 / 12.0), 0.05);
	EXPECT_NEAR(cxy / (511.0 * 512.0) / var, 0.0, 0.01);
}

TEST(Evaluation, ScenariosTallyFaceCompleteAndTargetFreeFrames)
{
	const TargetModel target = loadTarget("pyramid.json");
	const CameraIntrinsics k = loadCamera("cam512.json");
	EvaluationConfig e;
	e.frames = 12;
	e.seed = 3;
	e.min_range_mm = 900.0;
	e.max_range_mm = 1800.0;
	e.any_side = true;

	e.scenario = Scenario::TargetFree;
	EvaluationTally t =
		evaluate(target, k, PipelineConfig{}, e, [&](const FrameOutcome &f, const Image &) {
			EXPECT_TRUE(f.target_free);
			EXPECT_FALSE(f.face_complete);
			EXPECT_EQ(f.render.visible_mask, 0u);
			EXPECT_EQ(f.wrong, f.result->found);
		});
	EXPECT_EQ(t.target_free, 12);
	EXPECT_EQ(t.scenarios[static_cast<int>(Scenario::TargetFree)].frames, 12);
	EXPECT_EQ(t.face_complete, 0);
	EXPECT_EQ(t.correct, 0);
	EXPECT_EQ(t.total.target_free_wrong, t.wrong);

	/* One face: every frame where the target fits is face-complete, exactly one face drawn. */
	e.scenario = Scenario::OneFace;
	int complete = 0;
	t = evaluate(target, k, PipelineConfig{}, e, [&](const FrameOutcome &f, const Image &) {
		EXPECT_FALSE(f.target_free);
		EXPECT_GE(f.view_face, 0);
		EXPECT_LE(f.view_angle_deg, 60.0 + 1e-9);
		if (f.face_complete) {
			++complete;
			EXPECT_EQ(std::popcount(f.render.visible_mask), 4);
		}
	});
	EXPECT_EQ(t.face_complete, complete);
	EXPECT_GE(complete, 9);
	const ScenarioTally &st = t.scenarios[static_cast<int>(Scenario::OneFace)];
	int misses = st.face_complete_wrong;
	for (int m : st.misses)
		misses += m;
	EXPECT_EQ(st.face_complete_correct + misses, st.face_complete);

	/* Mix: every scenario but legacy and scrambled comes up. */
	e.scenario = Scenario::Mix;
	e.frames = 120;
	e.min_range_mm = 1200.0; /* small, quick frames */
	e.max_range_mm = 2000.0;
	t = evaluate(target, k, PipelineConfig{}, e);
	EXPECT_EQ(t.scenarios[static_cast<int>(Scenario::Legacy)].frames, 0);
	EXPECT_EQ(t.scenarios[static_cast<int>(Scenario::Scrambled)].frames, 0);
	for (int s = 1; s < kScenarioCount; ++s) {
		if (static_cast<Scenario>(s) != Scenario::Scrambled) {
			EXPECT_GT(t.scenarios[s].frames, 3)
				<< scenarioName(static_cast<Scenario>(s));
		}
	}
	EXPECT_EQ(t.total.frames, 120);
	EXPECT_EQ(t.target_free, t.scenarios[static_cast<int>(Scenario::TargetFree)].frames);

	/* Names round-trip. */
	for (int s = 0; s <= kScenarioCount; ++s) {
		Scenario parsed;
		ASSERT_TRUE(parseScenario(scenarioName(static_cast<Scenario>(s)), &parsed));
		EXPECT_EQ(static_cast<int>(parsed), s);
	}
	Scenario unused;
	EXPECT_FALSE(parseScenario("sunny", &unused));
}

/* SPDX-License-Identifier: MIT */
/*
 * The synthetic frame renderer (see renderer.h).
 *
 * Optics of one LED: a uniformly emitting disc of radius led_radius_mm whose
 * normal is the mean of its faces' outward normals. Its image is the ellipse
 * obtained by mapping the disc through the local (affine) projection at the
 * LED centre, lens distortion included, so the ellipse is centred exactly on
 * the projected LED centre; the ellipse is convolved with an isotropic
 * Gaussian blur of blur_sigma_px and integrated over each pixel's area.
 *
 * The pixel integral is exact along x: over a horizontal chord [l, r] of the
 * ellipse, the pixel-box-integrated Gaussian integrates in closed form through
 * Psi(z) = z Phi(z) + phi(z), the antiderivative of the normal CDF Phi. Along
 * y the chords are summed with the midpoint rule in theta (delta = H sin
 * theta), which takes the square-root ends of the ellipse smoothly; the nodes
 * are symmetric about the centre, so the emitter's discretised centroid is
 * exactly the projected LED centre and its area exactly the ellipse's.
 *
 * Brightness: the peak of the continuous spot above background is
 * led_peak (reference_range_mm / range)^2 cos(view angle), floored at
 * min_led_peak, times led_gain; the frame saturates at 255.
 *
 * The harder scenes reuse the same spot: a blooming LED is its spot
 * overexposed plus a second, round and softer spot (the halo); a motion-blurred
 * spot is the spot summed at evenly spaced positions along the streak (spacing
 * at most half the blur sigma, so the sum is smooth), each with its share of
 * the amplitude; a sunlit patch is a soft-edged ellipse (a cubic smoothstep
 * across its edge) added to the background.
 *
 * Frame assembly is tiled (64 x 64 pixels): per tile, every spot and glint
 * touching the tile is accumulated into a stack buffer of doubles, the
 * background (level + linear gradient) and the read noise are added, and the
 * tile is quantised to 8 bits. The noise of pixel (x, y) is a counter-based
 * hash of (seed, x, y) through Box-Muller, so it does not depend on the tile
 * order or on the clutter. Clutter placement uses std::mt19937_64 (its output
 * sequence is fixed by the C++ standard) with our own uniform and normal
 * transforms, one stream per kind of clutter, so a frame is the same for a
 * seed on every standard library.
 *
 * Allocates: never (fixed-capacity containers and stack buffers only), except
 * when *out has the wrong size.
 */
#include "algo/synth/renderer.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <limits>
#include <random>

#include <Eigen/Geometry>

#include "algo/synth/rng.h"

namespace dockpose {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kInvSqrt2 = 0.70710678118654752440;
constexpr double kInvSqrt2Pi = 0.39894228040143267794;
constexpr double kSqrt3 = 1.73205080756887729353;

/* Reflections and glints beyond these counts are not drawn (truth says how many were). */
constexpr std::size_t kMaxReflections = 64;
constexpr std::size_t kMaxGlints = 64;
constexpr std::size_t kMaxSpots = kMaxLeds + kMaxReflections;
constexpr std::size_t kMaxSunPatches = 16;
/* Samples along a motion-blur streak, at most. */
constexpr int kMaxStreakSamples = 256;
constexpr int kTile = 64;
/* Place attempts per clutter item before it is given up. */
constexpr int kPlaceAttempts = 200;
/* Spots are foreshortened no further than this viewing angle (an LED sitting on an edge). */
constexpr double kMaxShapeAngleDeg = 85.0;

using synth::Rng;
using synth::splitmix64;

/* Standard normal CDF and the antiderivative of it. */
double normalCdf(double z)
{
	return 0.5 * std::erfc(-z * kInvSqrt2);
}

double normalCdfIntegral(double z)
{
	return z * normalCdf(z) + kInvSqrt2Pi * std::exp(-0.5 * z * z);
}

/* One elliptical spot: a uniform ellipse convolved with the blur. */
struct Spot {
	double cu = 0.0, cv = 0.0; /* centre, px */
	double half_height = 0.0; /* H = sqrt(M_yy), px */
	double inv_sqrt_a = 0.0; /* chord half-width at delta = 0, px */
	double slope = 0.0; /* chord centre shift per px of delta */
	double amplitude = 0.0; /* levels per px^2 of emitter */
	double extent_px = 0.0; /* radius that holds the spot (for clutter placement) */
	double sigma_px = 0.8; /* its blur */
	/* Motion blur: the spot summed at centre + ((k + 0.5) / n - 0.5) (du, dv), k < n. */
	double streak_du = 0.0, streak_dv = 0.0;
	int streak_n = 1;
	int n_theta = 0;
	int x0 = 0, x1 = -1, y0 = 0, y1 = -1; /* bounding box, inclusive */
};

/* A glint: a thin streak along a segment, Gaussian across it. */
struct Glint {
	Eigen::Vector2d p0 = Eigen::Vector2d::Zero(), p1 = Eigen::Vector2d::Zero();
	double sigma_px = 0.7;
	double peak = 200.0;
	int x0 = 0, x1 = -1, y0 = 0, y1 = -1;
};

/* A sunlit patch: a soft-edged bright ellipse. */
struct SunPatch {
	double cu = 0.0, cv = 0.0;
	double cos_a = 1.0, sin_a = 0.0; /* orientation of the first semi-axis */
	double inv_a = 1.0, inv_b = 1.0; /* 1 / semi-axes, px */
	double r_min = 1.0; /* min(a, b): the edge is nowhere steeper than edge_px says */
	double edge_px = 10.0; /* the edge ramps from 0 to peak over 2 edge_px */
	double peak = 100.0;
	int x0 = 0, x1 = -1, y0 = 0, y1 = -1;

	double level(double x, double y) const
	{
		const double dx = x - cu, dy = y - cv;
		const double p = (cos_a * dx + sin_a * dy) * inv_a;
		const double q = (-sin_a * dx + cos_a * dy) * inv_b;
		const double d = (std::sqrt(p * p + q * q) - 1.0) * r_min; /* px outside, at most */
		const double t = std::clamp((edge_px - d) / (2.0 * edge_px), 0.0, 1.0);
		return peak * t * t * (3.0 - 2.0 * t);
	}
};

/*
 * Build a spot from its centre, its shape matrix M = A A^T (the ellipse is
 * {c + A s : |s| <= 1}) and its continuous peak level above background.
 */
Spot makeSpot(const Eigen::Vector2d &c, const Eigen::Matrix2d &M_in, double peak, double sigma_px)
{
	Spot s;
	s.cu = c.x();
	s.cv = c.y();
	s.sigma_px = sigma_px;
	/* Keep the ellipse from collapsing entirely (edge-on); 0.01 px is far below the blur. */
	Eigen::Matrix2d M = M_in;
	M(0, 0) += 1e-4;
	M(1, 1) += 1e-4;
	const double det = M.determinant();
	const double a = M(1, 1) / det; /* (M^-1)_xx */
	const double b = -M(0, 1) / det; /* (M^-1)_xy */
	s.half_height = std::sqrt(M(1, 1));
	s.inv_sqrt_a = 1.0 / std::sqrt(a);
	s.slope = -b / a;
	/* Chord spacing well below the blur; capped for absurdly close LEDs (spots > ~400 px). */
	const double step = std::min(0.3, 0.5 * sigma_px);
	s.n_theta = std::clamp(static_cast<int>(std::ceil(kPi * s.half_height / step)), 4, 4096);

	/* Peak of the continuous profile at the centre, per unit amplitude. */
	const double dtheta = kPi / s.n_theta;
	double p0 = 0.0;
	for (int k = 0; k < s.n_theta; ++k) {
		const double theta = -0.5 * kPi + (k + 0.5) * dtheta;
		const double delta = s.half_height * std::sin(theta);
		const double w = s.half_height * std::cos(theta) * dtheta;
		const double half = std::cos(theta) * s.inv_sqrt_a;
		const double mid = s.slope * delta;
		const double gy = kInvSqrt2Pi / sigma_px *
				  std::exp(-0.5 * delta * delta / (sigma_px * sigma_px));
		p0 += w * gy *
		      (normalCdf((mid + half) / sigma_px) - normalCdf((mid - half) / sigma_px));
	}
	s.amplitude = p0 > 0.0 ? peak / p0 : 0.0;

	const double reach = 4.5 * sigma_px + 1.0;
	/* Bounding box; never beyond kMaxFrameSide around the centre (which is inside the frame). */
	const double hx = std::min(std::sqrt(M(0, 0)), 1.0 * kMaxFrameSide);
	const double hy = std::min(s.half_height, 1.0 * kMaxFrameSide);
	s.extent_px = std::max(hx, hy) + 3.0 * sigma_px;
	s.x0 = static_cast<int>(std::floor(c.x() - hx - reach));
	s.x1 = static_cast<int>(std::ceil(c.x() + hx + reach));
	s.y0 = static_cast<int>(std::floor(c.y() - hy - reach));
	s.y1 = static_cast<int>(std::ceil(c.y() + hy + reach));
	return s;
}

/*
 * The continuous value of spot s per unit amplitude (before the pixel
 * integral, one streak position) at (du, dv) from its centre.
 */
double spotValue(const Spot &s, double du, double dv)
{
	const double sigma_px = s.sigma_px;
	const double dtheta = kPi / s.n_theta;
	double v = 0.0;
	for (int k = 0; k < s.n_theta; ++k) {
		const double theta = -0.5 * kPi + (k + 0.5) * dtheta;
		const double delta = s.half_height * std::sin(theta);
		const double w = s.half_height * std::cos(theta) * dtheta;
		const double half = std::cos(theta) * s.inv_sqrt_a;
		const double mid = s.slope * delta - du;
		const double ey = (delta - dv) / sigma_px;
		const double gy = kInvSqrt2Pi / sigma_px * std::exp(-0.5 * ey * ey);
		v += w * gy *
		     (normalCdf((mid + half) / sigma_px) - normalCdf((mid - half) / sigma_px));
	}
	return v;
}

/*
 * Smear spot s along the streak (du, dv) (its length in px): samples spaced at
 * most half the blur sigma. The amplitude is left as it is (so the energy is
 * kept); returns the streak's continuous value at its centre per unit
 * amplitude, for the caller to set the brightness.
 */
double makeStreak(Spot *s, double du, double dv)
{
	const double length = std::hypot(du, dv);
	if (!(length > 0.0))
		return spotValue(*s, 0.0, 0.0);
	const double step = std::min(0.5, 0.5 * s->sigma_px);
	s->streak_n =
		std::clamp(static_cast<int>(std::ceil(length / step)) + 1, 2, kMaxStreakSamples);
	s->streak_du = du;
	s->streak_dv = dv;
	s->x0 = static_cast<int>(std::floor(s->x0 - 0.5 * std::abs(du)));
	s->x1 = static_cast<int>(std::ceil(s->x1 + 0.5 * std::abs(du)));
	s->y0 = static_cast<int>(std::floor(s->y0 - 0.5 * std::abs(dv)));
	s->y1 = static_cast<int>(std::ceil(s->y1 + 0.5 * std::abs(dv)));
	s->extent_px += 0.5 * length;
	double centre = 0.0;
	for (int k = 0; k < s->streak_n; ++k) {
		const double o = (k + 0.5) / s->streak_n - 0.5;
		centre += spotValue(*s, -o * du, -o * dv);
	}
	return centre / s->streak_n;
}

/*
 * Add the pixel integrals of one streak position of spot s (centre cu, cv,
 * amplitude) over the tile [tx0, tx0 + tw) x [ty0, ty0 + th) into acc (row
 * stride kTile).
 */
void accumulateSpotAt(const Spot &s, double cu, double cv, double amplitude, int tx0, int ty0,
		      int tw, int th, double *acc)
{
	const double sigma_px = s.sigma_px;
	const int cx0 = std::max(s.x0, tx0), cx1 = std::min(s.x1, tx0 + tw - 1);
	const int cy0 = std::max(s.y0, ty0), cy1 = std::min(s.y1, ty0 + th - 1);
	if (cx0 > cx1 || cy0 > cy1)
		return;
	const int nc = cx1 - cx0 + 1, nr = cy1 - cy0 + 1;
	std::array<double, kTile + 1> edge_l, edge_r; /* Psi at the column edges */
	std::array<double, kTile + 1> cdf_y; /* Phi at the row edges */
	std::array<double, kTile> fx, by;
	const double inv_sigma = 1.0 / sigma_px;
	const double dtheta = kPi / s.n_theta;

	for (int k = 0; k < s.n_theta; ++k) {
		const double theta = -0.5 * kPi + (k + 0.5) * dtheta;
		const double ct = std::cos(theta);
		const double delta = s.half_height * std::sin(theta);
		const double w = amplitude * s.half_height * ct * dtheta;
		const double half = ct * s.inv_sqrt_a;
		const double l = cu + s.slope * delta - half; /* chord, absolute px */
		const double r = cu + s.slope * delta + half;
		const double yc = cv + delta;

		/* Rows: the pixel-box integral of the Gaussian about yc. */
		for (int j = 0; j <= nr; ++j)
			cdf_y[j] = normalCdf((cy0 + j - 0.5 - yc) * inv_sigma);
		bool any = false;
		for (int j = 0; j < nr; ++j) {
			by[j] = cdf_y[j + 1] - cdf_y[j];
			any = any || by[j] > 1e-12;
		}
		if (!any)
			continue;
		/* Columns: integral over the chord of the pixel-box Gaussian. */
		for (int i = 0; i <= nc; ++i) {
			const double e = cx0 + i - 0.5;
			edge_l[i] = normalCdfIntegral((e - l) * inv_sigma);
			edge_r[i] = normalCdfIntegral((e - r) * inv_sigma);
		}
		for (int i = 0; i < nc; ++i)
			fx[i] = sigma_px *
				((edge_l[i + 1] - edge_l[i]) - (edge_r[i + 1] - edge_r[i]));

		for (int j = 0; j < nr; ++j) {
			const double wy = w * by[j];
			if (wy == 0.0)
				continue;
			double *row = acc + static_cast<std::ptrdiff_t>(cy0 - ty0 + j) * kTile +
				      (cx0 - tx0);
			for (int i = 0; i < nc; ++i)
				row[i] += wy * fx[i];
		}
	}
}

/* Add spot s, every position of its streak, over the tile into acc. */
void accumulateSpot(const Spot &s, int tx0, int ty0, int tw, int th, double *acc)
{
	if (s.streak_n <= 1) {
		accumulateSpotAt(s, s.cu, s.cv, s.amplitude, tx0, ty0, tw, th, acc);
		return;
	}
	const double amplitude = s.amplitude / s.streak_n;
	for (int k = 0; k < s.streak_n; ++k) {
		const double o = (k + 0.5) / s.streak_n - 0.5;
		accumulateSpotAt(s, s.cu + o * s.streak_du, s.cv + o * s.streak_dv, amplitude, tx0,
				 ty0, tw, th, acc);
	}
}

void accumulateGlint(const Glint &g, int tx0, int ty0, int tw, int th, double *acc)
{
	const int cx0 = std::max(g.x0, tx0), cx1 = std::min(g.x1, tx0 + tw - 1);
	const int cy0 = std::max(g.y0, ty0), cy1 = std::min(g.y1, ty0 + th - 1);
	const Eigen::Vector2d d = g.p1 - g.p0;
	const double len2 = d.squaredNorm();
	const double inv2s2 = 0.5 / (g.sigma_px * g.sigma_px);
	for (int y = cy0; y <= cy1; ++y)
		for (int x = cx0; x <= cx1; ++x) {
			const Eigen::Vector2d p(x, y);
			const double t = len2 > 0.0 ? std::clamp((p - g.p0).dot(d) / len2, 0.0, 1.0)
						    : 0.0;
			const double dist2 = (p - (g.p0 + t * d)).squaredNorm();
			acc[(y - ty0) * kTile + (x - tx0)] += g.peak * std::exp(-dist2 * inv2s2);
		}
}

/* Distance from p to the segment [a, b]. */
double pointSegmentDistance(const Eigen::Vector2d &p, const Eigen::Vector2d &a,
			    const Eigen::Vector2d &b)
{
	const Eigen::Vector2d d = b - a;
	const double len2 = d.squaredNorm();
	const double t = len2 > 0.0 ? std::clamp((p - a).dot(d) / len2, 0.0, 1.0) : 0.0;
	return (p - (a + t * d)).norm();
}

double cross2(const Eigen::Vector2d &a, const Eigen::Vector2d &b)
{
	return a.x() * b.y() - a.y() * b.x();
}

double segmentDistance(const Eigen::Vector2d &a0, const Eigen::Vector2d &a1,
		       const Eigen::Vector2d &b0, const Eigen::Vector2d &b1)
{
	const double d1 = cross2(a1 - a0, b0 - a0), d2 = cross2(a1 - a0, b1 - a0);
	const double d3 = cross2(b1 - b0, a0 - b0), d4 = cross2(b1 - b0, a1 - b0);
	if (((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0)))
		return 0.0; /* they cross */
	return std::min({ pointSegmentDistance(a0, b0, b1), pointSegmentDistance(a1, b0, b1),
			  pointSegmentDistance(b0, a0, a1), pointSegmentDistance(b1, a0, a1) });
}

/* Rx(roll) Ry(pan) Rz(tilt), degrees. */
Eigen::Matrix3d rotationRpy(const Eigen::Vector3d &rpy_deg)
{
	const double k = kPi / 180.0;
	return (Eigen::AngleAxisd(rpy_deg.x() * k, Eigen::Vector3d::UnitX()) *
		Eigen::AngleAxisd(rpy_deg.y() * k, Eigen::Vector3d::UnitY()) *
		Eigen::AngleAxisd(rpy_deg.z() * k, Eigen::Vector3d::UnitZ()))
		.toRotationMatrix();
}

Eigen::Vector3d centroidOf(const TargetModel &target)
{
	Eigen::Vector3d c = Eigen::Vector3d::Zero();
	for (const auto &p : target.points_mm)
		c += p;
	return target.points_mm.empty()
		       ? c
		       : Eigen::Vector3d(c / static_cast<double>(target.points_mm.size()));
}

} /* namespace */

/*
 * Face fronts: the same definition the solver uses (TargetModel::frontNormals),
 * so the truth and the correspondence agree on which LEDs can be seen.
 */
/* NOLINTNEXTLINE(modernize-pass-by-value): the header's signature, kept as it is */
FrameRenderer::FrameRenderer(const TargetModel &target, const CameraIntrinsics &camera)
	: target_(target),
	  camera_(camera)
{
	target_.frontNormals(&normals_);
}

bool FrameRenderer::ledVisible(const Pose &pose, int led, double max_view_angle_deg) const
{
	if (led < 0 || led >= static_cast<int>(target_.points_mm.size()))
		return false;
	const Eigen::Vector3d p = pose.apply(target_.points_mm[led]);
	const double dist = p.norm();
	if (!(p.z() > 1e-6) || !(dist > 0.0))
		return false;
	const Eigen::Vector3d to_camera = -p / dist;
	const double cos_max = std::cos(max_view_angle_deg * kPi / 180.0);
	bool on_face = false;
	for (std::size_t f = 0; f < target_.faces.size(); ++f) {
		const auto &face = target_.faces[f];
		if (std::find(face.begin(), face.end(), led) == face.end())
			continue;
		on_face = true;
		if ((pose.R * normals_[f]).dot(to_camera) > cos_max)
			return true;
	}
	if (on_face)
		return false;
	/* An LED on no face shines away from the centroid (or towards -z on a flat target). */
	Eigen::Vector3d n = target_.points_mm[led] - centroidOf(target_);
	n = n.norm() > 1e-9 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d(0.0, 0.0, -1.0);
	return (pose.R * n).dot(to_camera) > cos_max;
}

namespace {

/* The frame's random streams, one per kind of choice, from the scene's seed or the frame's. */
struct FrameStreams {
	FrameStreams(std::uint64_t seed, std::uint64_t scene_seed)
		: gradient(splitmix64(scene_seed ^ 0x67726164ULL)),
		  occlusion(splitmix64(seed ^ 0x6f63636cULL)),
		  reflections(splitmix64(scene_seed ^ 0x7265666cULL)),
		  glints(splitmix64(scene_seed ^ 0x676c6e74ULL)),
		  hot(splitmix64(scene_seed ^ 0x686f7470ULL)),
		  noise_key(splitmix64(seed ^ 0x6e6f6973ULL)),
		  near(splitmix64(scene_seed ^ 0x6e656172ULL)),
		  shape(splitmix64(scene_seed ^ 0x73686170ULL)),
		  sun(splitmix64(scene_seed ^ 0x73756e70ULL)),
		  face(splitmix64(seed ^ 0x66616365ULL)),
		  dim(splitmix64(seed ^ 0x64696d6dULL)),
		  motion(splitmix64(seed ^ 0x6d6f746eULL)),
		  scramble(splitmix64(seed ^ 0x7363726dULL))
	{
	}

	Rng gradient, occlusion, reflections, glints, hot;
	std::uint64_t noise_key;
	/* The harder scenes have streams of their own, so turning one on leaves the rest alone. */
	Rng near, shape, sun, face, dim, motion, scramble;
};

/* A box in the image, px. */
struct Box {
	double x0, x1, y0, y1;
};

/*
 * One frame being rendered: its inputs, then what the steps below work out in
 * turn (the LEDs, their spots, the clutter, the background).
 */
struct FrameState {
	FrameState(const TargetModel &target_model, const CameraModel &camera_model,
		   const StaticVector<Eigen::Vector3d, kMaxFaces> &face_normals,
		   const Pose &frame_pose, const RenderOptions &render_options)
		: target(target_model),
		  camera(camera_model),
		  normals(face_normals),
		  pose(frame_pose),
		  options(render_options),
		  width(camera_model.intrinsics().width),
		  height(camera_model.intrinsics().height),
		  sigma(std::max(0.3, render_options.blur_sigma_px)),
		  n_leds(static_cast<int>(target_model.points_mm.size())),
		  centroid(centroidOf(target_model))
	{
	}

	const TargetModel &target;
	const CameraModel &camera;
	const StaticVector<Eigen::Vector3d, kMaxFaces> &normals; /* the faces' fronts */
	const Pose &pose;
	const RenderOptions &options;
	const int width, height;
	const double sigma; /* the spots' blur */
	const int n_leds;
	const Eigen::Vector3d centroid;

	/* The LEDs drawn (displaced on a scrambled frame), where they land, which are shown. */
	std::array<Eigen::Vector3d, kMaxLeds> led_mm;
	bool scrambled = false;
	std::array<Eigen::Vector2d, kMaxLeds> led_px;
	std::uint32_t drawable = 0, occluded = 0, visible = 0, dimmed = 0, washed_out = 0;
	int kept_face = -1;
	std::array<double, kMaxLeds> brightness;

	/* Motion blur (one streak for the frame) and blooming. */
	bool streaked = false, blooming = false;
	double streak_angle = 0.0, streak_du = 0.0, streak_dv = 0.0;

	/* The LED spots (the first n_led_spots), then the reflections; the halos apart. */
	StaticVector<Spot, kMaxSpots> spots, halos;
	std::array<double, kMaxSpots> outer_extent{}; /* spot and its halo */
	std::array<double, kMaxLeds> led_peak_level{}; /* contrast of LED spot s */
	std::array<int, kMaxLeds> spot_led{}; /* LED of spot s (for the first n_led_spots) */
	std::size_t n_led_spots = 0;

	/* Clutter: a typical LED spot, the clearance kept from each LED, glints, sunlit patches. */
	double typical_radius_px = 0.0, typical_peak = 0.0;
	std::array<double, kMaxLeds> led_clearance;
	bool avoid_leds = true, bloom_clutter = false, streak_clutter = false;
	StaticVector<Glint, kMaxGlints> glints;
	StaticVector<SunPatch, kMaxSunPatches> patches;

	/* Background: a gradient of gscale levels per px along (gdx, gdy) from the middle. */
	double gdx = 0.0, gdy = 0.0, gscale = 0.0, mid_x = 0.0, mid_y = 0.0;
};

/* Place the LEDs: the model's, or displaced ones on a scrambled frame. */
void placeLeds(FrameState *f, Rng *rng_scramble)
{
	const RenderOptions &options = f->options;
	f->scrambled = options.scramble > 0.0 && options.draw_target;
	const double scramble_mm = options.scramble * f->target.diameterMm();
	for (int i = 0; i < f->n_leds; ++i) {
		f->led_mm[i] = f->target.points_mm[i];
		if (!f->scrambled)
			continue;
		Eigen::Vector3d dir(rng_scramble->normal(), rng_scramble->normal(),
				    rng_scramble->normal());
		if (dir.norm() < 1e-9)
			dir = Eigen::Vector3d::UnitX();
		f->led_mm[i] += dir.normalized() * rng_scramble->uniform(0.5, 1.0) * scramble_mm;
	}
}

/* Project every LED, and mark drawable those in the frame that shine towards the camera. */
void projectLeds(const FrameRenderer &renderer, FrameState *f)
{
	f->drawable = 0;
	for (int i = 0; i < f->n_leds; ++i) {
		const Eigen::Vector3d p = f->pose.apply(f->led_mm[i]);
		Eigen::Vector2d uv;
		f->led_px[i] = Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
		if (!f->camera.project(p, &uv))
			continue;
		f->led_px[i] = uv;
		/* In the frame and the lens's valid field (no fold-back of the distortion). */
		Eigen::Vector2d xy;
		const Eigen::Vector2d ideal(p.x() / p.z(), p.y() / p.z());
		if (!f->camera.inImage(uv) || !f->camera.pixelToNormalized(uv, &xy) ||
		    (xy - ideal).norm() > 1e-6)
			continue;
		if (renderer.ledVisible(f->pose, i, f->options.max_view_angle_deg))
			f->drawable |= 1u << i;
	}
	if (!f->options.draw_target)
		f->drawable = 0;
}

/* The LEDs of face f, as a mask. */
std::uint32_t faceMask(const TargetModel &target, std::size_t f)
{
	std::uint32_t m = 0;
	for (int v : target.faces[f])
		m |= 1u << v;
	return m;
}

/* One-face occlusion: hide every drawable LED off the kept face (keep_face, or a random one). */
void occludeAllButOneFace(FrameState *f, Rng *rng_face)
{
	const RenderOptions &options = f->options;
	const TargetModel &target = f->target;
	if (f->drawable == 0 || (options.keep_face < 0 && !options.one_face_only))
		return;
	if (options.keep_face >= 0 && options.keep_face < static_cast<int>(target.faces.size())) {
		f->kept_face = options.keep_face;
	} else if (options.keep_face < 0) {
		/* A random complete face, else one with the most drawable LEDs. */
		std::array<int, kMaxFaces> best{};
		int n_best = 0, best_count = 0;
		for (std::size_t face = 0; face < target.faces.size(); ++face) {
			const int count = std::popcount(faceMask(target, face) & f->drawable);
			if (count > best_count) {
				best_count = count;
				n_best = 0;
			}
			if (count == best_count && count > 0)
				best[n_best++] = static_cast<int>(face);
		}
		if (n_best > 0)
			f->kept_face = best[rng_face->index(n_best)];
	}
	if (f->kept_face >= 0)
		f->occluded |= f->drawable & ~faceMask(target, f->kept_face);
}

/* Random occlusion: hide occluded_leds of the drawable LEDs not hidden yet. */
void occludeRandomLeds(FrameState *f, Rng *rng_occlusion)
{
	std::array<int, kMaxLeds> pool{};
	int n_pool = 0;
	for (int i = 0; i < f->n_leds; ++i)
		if ((f->drawable & ~f->occluded) & (1u << i))
			pool[n_pool++] = i;
	for (int n = 0; n < f->options.occluded_leds && n_pool > 0; ++n) {
		const int pick = rng_occlusion->index(n_pool);
		f->occluded |= 1u << pool[pick];
		pool[pick] = pool[--n_pool];
	}
}

/* Dim LEDs: the mask, then random ones; a brightness factor per LED in LED order. */
void dimLeds(FrameState *f, Rng *rng_dim)
{
	const RenderOptions &options = f->options;
	f->brightness.fill(1.0);
	f->dimmed = options.dim_mask & f->visible;
	std::array<int, kMaxLeds> pool{};
	int n_pool = 0;
	for (int i = 0; i < f->n_leds; ++i)
		if ((f->visible & ~f->dimmed) & (1u << i))
			pool[n_pool++] = i;
	for (int n = 0; n < options.dimmed_leds && n_pool > 0; ++n) {
		const int pick = rng_dim->index(n_pool);
		f->dimmed |= 1u << pool[pick];
		pool[pick] = pool[--n_pool];
	}
	for (int i = 0; i < f->n_leds; ++i)
		if (f->dimmed & (1u << i))
			f->brightness[i] = rng_dim->uniform(options.dim_min, options.dim_max);
}

/* Choose the frame's motion-blur streak (its direction drawn when not given) and blooming. */
void chooseStreak(FrameState *f, Rng *rng_motion)
{
	const RenderOptions &options = f->options;
	f->streaked = options.motion_blur_px > 0.0;
	f->streak_angle = 0.0;
	if (f->streaked)
		f->streak_angle = std::isnan(options.motion_blur_angle_deg)
					  ? rng_motion->uniform(0.0, 2.0 * kPi)
					  : options.motion_blur_angle_deg * kPi / 180.0;
	f->streak_du = options.motion_blur_px * std::cos(f->streak_angle);
	f->streak_dv = options.motion_blur_px * std::sin(f->streak_angle);
	f->blooming = options.bloom > 0.0;
}

/*
 * Blooming and motion blur of a spot: overexposure and halo, streak and
 * brightness; the halo goes to f->halos, and the radius that holds both is
 * returned. floor_peak: the streak's peak is not lowered below it.
 */
double hardenSpot(FrameState *f, Spot *spot, const Eigen::Matrix2d &M, double peak,
		  double floor_peak, double halo_peak, bool bloom_it, bool streak_it)
{
	const double sigma = f->sigma;
	double outer = spot->extent_px;
	if (bloom_it) {
		const double r_spot = std::max(
			std::sqrt(std::max(
				0.0, 0.5 * (M.trace() +
					    std::sqrt(std::max(
						    0.0, (M(0, 0) - M(1, 1)) * (M(0, 0) - M(1, 1)) +
								 4.0 * M(0, 1) * M(0, 1)))))),
			sigma);
		const double r_halo = f->options.bloom * r_spot;
		const double sigma_halo = std::max(sigma, 0.25 * r_halo);
		Spot h = makeSpot(Eigen::Vector2d(spot->cu, spot->cv),
				  Eigen::Matrix2d::Identity() * r_halo * r_halo, halo_peak,
				  sigma_halo);
		if (streak_it)
			h.amplitude = halo_peak / makeStreak(&h, f->streak_du, f->streak_dv);
		outer = std::max(outer, h.extent_px);
		f->halos.push_back(h);
	}
	if (streak_it) {
		const double per_amplitude = makeStreak(spot, f->streak_du, f->streak_dv);
		const double kept = spot->amplitude * per_amplitude; /* energy kept */
		const double target = std::min(peak, std::max(kept, floor_peak));
		spot->amplitude = per_amplitude > 0.0 ? target / per_amplitude : 0.0;
		outer = std::max(outer, spot->extent_px);
	}
	return outer;
}

/* The normal of LED i in the target frame: the mean of its faces' fronts. */
Eigen::Vector3d ledNormal(const FrameState &f, int i)
{
	Eigen::Vector3d n_t = Eigen::Vector3d::Zero();
	for (std::size_t face = 0; face < f.target.faces.size(); ++face) {
		const auto &leds = f.target.faces[face];
		if (std::find(leds.begin(), leds.end(), i) != leds.end())
			n_t += f.normals[face];
	}
	if (n_t.norm() < 1e-9)
		n_t = f.target.points_mm[i] - f.centroid;
	if (n_t.norm() < 1e-9)
		n_t = Eigen::Vector3d(0.0, 0.0, -1.0);
	return n_t;
}

/* Add the spot of visible LED i: its disc's image, brightness, blooming and streak. */
void addLedSpot(FrameState *f, int i)
{
	const RenderOptions &options = f->options;
	const double cos_shape_min = std::cos(kMaxShapeAngleDeg * kPi / 180.0);
	const Eigen::Vector3d p = f->pose.apply(f->led_mm[i]);
	const double range = p.norm();
	const Eigen::Vector3d to_camera = -p / range;
	Eigen::Vector3d n = (f->pose.R * ledNormal(*f, i)).normalized();
	double cos_view = n.dot(to_camera);
	if (cos_view < cos_shape_min) {
		/* Tilt the disc towards the camera so it is not seen edge-on. */
		Eigen::Vector3d side = n - cos_view * to_camera;
		side = side.norm() > 1e-9 ? Eigen::Vector3d(side.normalized())
					  : to_camera.unitOrthogonal();
		cos_view = cos_shape_min;
		n = cos_view * to_camera + std::sqrt(1.0 - cos_view * cos_view) * side;
	}
	/* The disc's image through the local projection. */
	Eigen::Vector2d uv;
	Eigen::Matrix<double, 2, 3> J;
	f->camera.project(p, &uv, &J);
	const Eigen::Vector3d e1 = n.unitOrthogonal();
	const Eigen::Vector3d e2 = n.cross(e1);
	Eigen::Matrix<double, 3, 2> E;
	E.col(0) = e1;
	E.col(1) = e2;
	const Eigen::Matrix2d A = options.led_radius_mm * (J * E);
	const double ratio = options.reference_range_mm / range;
	double base = std::max(options.min_led_peak, options.led_peak * ratio * ratio * cos_view);
	if (f->blooming)
		base = std::max(base * options.bloom_overexposure, 1.5 * 255.0);
	double peak = base * options.led_gain;
	if (f->dimmed & (1u << i))
		peak *= f->brightness[i];
	const Eigen::Matrix2d M = A * A.transpose();
	const std::size_t s = f->spots.size();
	f->spot_led[s] = i;
	f->led_peak_level[s] = peak;
	Spot spot = makeSpot(uv, M, peak, f->sigma);
	f->outer_extent[s] = spot.extent_px;
	if (f->blooming || f->streaked)
		f->outer_extent[s] =
			hardenSpot(f, &spot, M, peak,
				   options.min_led_peak * options.led_gain * f->brightness[i],
				   options.bloom_halo_peak * options.led_gain * f->brightness[i],
				   f->blooming, f->streaked);
	f->spots.push_back(spot);
}

/* Work out a typical LED spot at this range and how far clutter keeps clear of each LED. */
void prepareClutter(FrameState *f)
{
	const RenderOptions &options = f->options;
	/* A typical LED spot at this range, for LED-like reflections. */
	const Eigen::Vector3d centre_c = f->pose.apply(f->centroid);
	const double centre_range = std::max(1.0, centre_c.norm());
	f->typical_radius_px =
		std::max(0.5, f->camera.intrinsics().fx * options.led_radius_mm / centre_range);
	const double typical_ratio = options.reference_range_mm / centre_range;
	f->typical_peak =
		std::min(255.0, std::max(options.min_led_peak,
					 options.led_peak * typical_ratio * typical_ratio));

	/* Clutter keeps clear of every LED that projects into the frame, drawn or not. */
	f->led_clearance.fill(f->typical_radius_px + 3.0 * f->sigma);
	for (std::size_t s = 0; s < f->n_led_spots; ++s)
		f->led_clearance[f->spot_led[s]] =
			std::max(f->led_clearance[f->spot_led[s]], f->outer_extent[s]);
	/* On a target-free frame clutter may be anywhere. */
	f->avoid_leds = options.draw_target;
	f->bloom_clutter = f->blooming && options.bloom_reflections;
	f->streak_clutter = f->streaked && options.motion_blur_reflections;
}

/* Add a reflection of radius r at c, shaped, bloomed and streaked like the LEDs. */
void addReflection(FrameState *f, Rng *rng_shape, const Eigen::Vector2d &c, double radius,
		   double peak)
{
	const RenderOptions &options = f->options;
	Eigen::Matrix2d M = Eigen::Matrix2d::Identity() * radius * radius;
	if (options.reflection_squash > 0.0) {
		const double q =
			rng_shape->uniform(1.0 - std::min(options.reflection_squash, 0.9), 1.0);
		const double a = rng_shape->uniform(0.0, kPi);
		Eigen::Matrix2d rot;
		rot << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
		M = rot * Eigen::Vector2d(radius * radius, q * q * radius * radius).asDiagonal() *
		    rot.transpose();
	}
	if (f->bloom_clutter)
		peak = std::max(peak * options.bloom_overexposure, 1.5 * 255.0);
	Spot spot = makeSpot(c, M, peak, f->sigma);
	const std::size_t s = f->spots.size();
	f->outer_extent[s] = spot.extent_px;
	if (f->bloom_clutter || f->streak_clutter)
		f->outer_extent[s] = hardenSpot(f, &spot, M, peak, options.min_led_peak,
						options.bloom_halo_peak, f->bloom_clutter,
						f->streak_clutter);
	f->spots.push_back(spot);
}

/* The radius that a reflection of radius r will hold once bloomed and streaked. */
double reflectionExtent(const FrameState &f, double radius)
{
	const double sigma = f.sigma;
	double extent = radius + 3.0 * sigma;
	if (f.bloom_clutter) {
		const double r_halo = f.options.bloom * std::max(radius, sigma);
		extent = std::max(extent, r_halo + 3.0 * std::max(sigma, 0.25 * r_halo));
	}
	if (f.streak_clutter)
		extent += 0.5 * f.options.motion_blur_px;
	return extent;
}

/* Whether a reflection of that extent at c keeps gap px clear of the LEDs and reflections. */
bool reflectionClear(const FrameState &f, const Eigen::Vector2d &c, double extent, double gap)
{
	bool clear = true;
	for (int i = 0; i < f.n_leds && clear && f.avoid_leds; ++i)
		if (f.led_px[i].allFinite() &&
		    (c - f.led_px[i]).norm() < extent + f.led_clearance[i] + gap)
			clear = false;
	for (std::size_t s = f.n_led_spots; s < f.spots.size() && clear; ++s)
		if ((c - Eigen::Vector2d(f.spots[s].cu, f.spots[s].cv)).norm() <
		    extent + f.outer_extent[s] + gap)
			clear = false;
	return clear;
}

/* Add the LED-like reflections anywhere in the frame, clear of the LEDs and each other. */
void addReflections(FrameState *f, Rng *rng_reflections, Rng *rng_shape)
{
	const int width = f->width, height = f->height;
	const int n_reflections =
		std::clamp(f->options.reflections, 0, static_cast<int>(kMaxReflections));
	for (int n = 0; n < n_reflections; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			const double radius =
				f->typical_radius_px * rng_reflections->uniform(0.7, 1.3);
			const double peak = f->typical_peak * rng_reflections->uniform(0.6, 1.0);
			const double margin = radius + 3.0 * f->sigma;
			if (2.0 * margin >= width || 2.0 * margin >= height)
				break;
			const Eigen::Vector2d c(
				rng_reflections->uniform(margin, width - 1 - margin),
				rng_reflections->uniform(margin, height - 1 - margin));
			const double extent = reflectionExtent(*f, radius);
			if (!reflectionClear(*f, c, extent, 3.0))
				continue;
			addReflection(f, rng_shape, c, radius, peak);
			break;
		}
	}
}

/*
 * The box of the near reflections: the bounding box of the LEDs that project
 * into the frame, grown by half its size on each side (the whole frame when
 * none does).
 */
Box nearReflectionBox(const FrameState &f)
{
	Box b{ static_cast<double>(f.width), -1.0, static_cast<double>(f.height), -1.0 };
	for (int i = 0; i < f.n_leds; ++i)
		if (f.led_px[i].allFinite() && f.camera.inImage(f.led_px[i])) {
			b.x0 = std::min(b.x0, f.led_px[i].x());
			b.x1 = std::max(b.x1, f.led_px[i].x());
			b.y0 = std::min(b.y0, f.led_px[i].y());
			b.y1 = std::max(b.y1, f.led_px[i].y());
		}
	if (b.x1 < b.x0) {
		b.x0 = 0.0;
		b.x1 = f.width - 1.0;
		b.y0 = 0.0;
		b.y1 = f.height - 1.0;
	} else {
		const double grow =
			0.5 * std::max(b.x1 - b.x0, b.y1 - b.y0) + 4.0 * f.typical_radius_px;
		b.x0 -= grow;
		b.x1 += grow;
		b.y0 -= grow;
		b.y1 += grow;
	}
	return b;
}

/*
 * Add the reflections near the target: inside nearReflectionBox(), clear of
 * the LED spots and of each other by near_clearance_px only.
 */
void addNearReflections(FrameState *f, Rng *rng_near, Rng *rng_shape)
{
	const int width = f->width, height = f->height;
	const int n_near = std::clamp(f->options.near_reflections, 0,
				      static_cast<int>(kMaxReflections) -
					      static_cast<int>(f->spots.size() - f->n_led_spots));
	if (n_near <= 0)
		return;
	const Box b = nearReflectionBox(*f);
	const double gap = std::max(0.0, f->options.near_clearance_px);
	for (int n = 0; n < n_near; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			const double radius = f->typical_radius_px * rng_near->uniform(0.7, 1.3);
			const double peak = f->typical_peak * rng_near->uniform(0.6, 1.0);
			const double margin = radius + 3.0 * f->sigma;
			const double x0 = std::max(margin, b.x0),
				     x1 = std::min(width - 1 - margin, b.x1);
			const double y0 = std::max(margin, b.y0),
				     y1 = std::min(height - 1 - margin, b.y1);
			if (x1 <= x0 || y1 <= y0)
				break;
			const Eigen::Vector2d c(rng_near->uniform(x0, x1),
						rng_near->uniform(y0, y1));
			const double extent = reflectionExtent(*f, radius);
			if (!reflectionClear(*f, c, extent, gap))
				continue;
			addReflection(f, rng_shape, c, radius, peak);
			break;
		}
	}
}

/* Whether glint g keeps clear of the LEDs, the reflections and the other glints. */
bool glintClear(const FrameState &f, const Glint &g)
{
	const double clear_px = 3.0 * g.sigma_px + 3.0;
	bool clear = true;
	for (int i = 0; i < f.n_leds && clear && f.avoid_leds; ++i)
		if (f.led_px[i].allFinite() &&
		    pointSegmentDistance(f.led_px[i], g.p0, g.p1) < f.led_clearance[i] + clear_px)
			clear = false;
	for (std::size_t s = f.n_led_spots; s < f.spots.size() && clear; ++s)
		if (pointSegmentDistance(Eigen::Vector2d(f.spots[s].cu, f.spots[s].cv), g.p0,
					 g.p1) < f.outer_extent[s] + clear_px)
			clear = false;
	for (std::size_t q = 0; q < f.glints.size() && clear; ++q)
		if (segmentDistance(g.p0, g.p1, f.glints[q].p0, f.glints[q].p1) < 2.0 * clear_px)
			clear = false;
	return clear;
}

/* Add the glints: long thin streaks wholly in the frame, clear of everything else. */
void addGlints(FrameState *f, Rng *rng_glints)
{
	const int width = f->width, height = f->height;
	const int n_glints = std::clamp(f->options.glints, 0, static_cast<int>(kMaxGlints));
	for (int n = 0; n < n_glints; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			Glint g;
			const double length = rng_glints->uniform(30.0, 200.0);
			const double angle = rng_glints->uniform(0.0, kPi);
			g.sigma_px = rng_glints->uniform(0.5, 0.9);
			g.peak = rng_glints->uniform(150.0, 255.0);
			const Eigen::Vector2d c(rng_glints->uniform(0.0, width - 1.0),
						rng_glints->uniform(0.0, height - 1.0));
			const Eigen::Vector2d d =
				0.5 * length * Eigen::Vector2d(std::cos(angle), std::sin(angle));
			g.p0 = c - d;
			g.p1 = c + d;
			/* The whole streak lies in the frame. */
			if (std::min(g.p0.x(), g.p1.x()) < 0.0 ||
			    std::max(g.p0.x(), g.p1.x()) > width - 1.0 ||
			    std::min(g.p0.y(), g.p1.y()) < 0.0 ||
			    std::max(g.p0.y(), g.p1.y()) > height - 1.0)
				continue;
			if (!glintClear(*f, g))
				continue;
			const double reach = 4.0 * g.sigma_px + 1.0;
			g.x0 = static_cast<int>(std::floor(std::min(g.p0.x(), g.p1.x()) - reach));
			g.x1 = static_cast<int>(std::ceil(std::max(g.p0.x(), g.p1.x()) + reach));
			g.y0 = static_cast<int>(std::floor(std::min(g.p0.y(), g.p1.y()) - reach));
			g.y1 = static_cast<int>(std::ceil(std::max(g.p0.y(), g.p1.y()) + reach));
			f->glints.push_back(g);
			break;
		}
	}
}

/* Add the sunlit patches: anywhere, over the target too. */
void addSunPatches(FrameState *f, Rng *rng_sun)
{
	const RenderOptions &options = f->options;
	const int width = f->width, height = f->height;
	const int n_patches = std::clamp(options.sun_patches, 0, static_cast<int>(kMaxSunPatches));
	for (int n = 0; n < n_patches; ++n) {
		const double side = std::max(width, height);
		const double a = side * rng_sun->uniform(0.06, 0.25);
		const double b = side * rng_sun->uniform(0.06, 0.25);
		const double angle = rng_sun->uniform(0.0, kPi);
		SunPatch p;
		p.cu = rng_sun->uniform(0.0, width - 1.0);
		p.cv = rng_sun->uniform(0.0, height - 1.0);
		p.cos_a = std::cos(angle);
		p.sin_a = std::sin(angle);
		p.inv_a = 1.0 / a;
		p.inv_b = 1.0 / b;
		p.r_min = std::min(a, b);
		p.edge_px = rng_sun->uniform(15.0, std::max(15.0, 0.5 * std::min(a, b)));
		p.peak = rng_sun->uniform(options.sun_peak_min, options.sun_peak_max);
		const double reach = std::max(a, b) * (1.0 + p.edge_px / p.r_min) + 1.0;
		p.x0 = std::max(0, static_cast<int>(std::floor(p.cu - reach)));
		p.x1 = std::min(width - 1, static_cast<int>(std::ceil(p.cu + reach)));
		p.y0 = std::max(0, static_cast<int>(std::floor(p.cv - reach)));
		p.y1 = std::min(height - 1, static_cast<int>(std::ceil(p.cv + reach)));
		f->patches.push_back(p);
	}
}

/* Choose the background: a gradient of `gradient` levels across the frame, random direction. */
void chooseGradient(FrameState *f, Rng *rng_gradient)
{
	const int width = f->width, height = f->height;
	const double gradient_angle = rng_gradient->uniform(0.0, 2.0 * kPi);
	f->gdx = std::cos(gradient_angle);
	f->gdy = std::sin(gradient_angle);
	const double span = std::abs(f->gdx) * (width - 1) + std::abs(f->gdy) * (height - 1);
	f->gscale = span > 0.0 ? f->options.gradient / span : 0.0;
	f->mid_x = 0.5 * (width - 1);
	f->mid_y = 0.5 * (height - 1);
}

/* Add every spot, halo, glint and sunlit patch touching the tile into acc (row stride kTile). */
void accumulateTile(const FrameState &f, int tx0, int ty0, int tw, int th, double *acc)
{
	for (const Spot &s : f.spots)
		if (s.x1 >= tx0 && s.x0 < tx0 + tw && s.y1 >= ty0 && s.y0 < ty0 + th)
			accumulateSpot(s, tx0, ty0, tw, th, acc);
	for (const Spot &s : f.halos)
		if (s.x1 >= tx0 && s.x0 < tx0 + tw && s.y1 >= ty0 && s.y0 < ty0 + th)
			accumulateSpot(s, tx0, ty0, tw, th, acc);
	for (const Glint &g : f.glints)
		if (g.x1 >= tx0 && g.x0 < tx0 + tw && g.y1 >= ty0 && g.y0 < ty0 + th)
			accumulateGlint(g, tx0, ty0, tw, th, acc);
	for (const SunPatch &p : f.patches) {
		const int cx0 = std::max(p.x0, tx0), cx1 = std::min(p.x1, tx0 + tw - 1);
		const int cy0 = std::max(p.y0, ty0), cy1 = std::min(p.y1, ty0 + th - 1);
		for (int y = cy0; y <= cy1; ++y)
			for (int x = cx0; x <= cx1; ++x)
				acc[(y - ty0) * kTile + (x - tx0)] += p.level(x, y);
	}
}

/* The noise of a pixel whose noise-free level is v: read noise and shot noise. */
double pixelSigma(const RenderOptions &o, double v)
{
	if (o.shot_gain <= 0.0)
		return o.noise_sigma;
	return std::sqrt(o.noise_sigma * o.noise_sigma + o.shot_gain * std::max(v, 0.0));
}

/*
 * Quantise one tile row (pixels tx0 .. tx0 + tw - 1 of row y, levels acc_row
 * above background bg_row) with the fast read noise: four uniforms per pixel.
 */
void quantiseRowFastNoise(const FrameState &f, std::uint64_t noise_key, const double *acc_row,
			  int tx0, int tw, int y, double bg_row, std::uint8_t *row)
{
	for (int i = 0; i < tw; ++i) {
		const int x = tx0 + i;
		const std::uint64_t h =
			splitmix64(noise_key + static_cast<std::uint64_t>(y) * f.width +
				   static_cast<std::uint64_t>(x));
		const double sum = static_cast<double>((h & 0xffff) + ((h >> 16) & 0xffff) +
						       ((h >> 32) & 0xffff) + (h >> 48)) +
				   2.0;
		/* Four uniforms in (0, 1): mean 2, variance 1/3. */
		const double z = (sum * 0x1.0p-16 - 2.0) * kSqrt3;
		const double clean = bg_row + f.gscale * (x - f.mid_x) * f.gdx + acc_row[i];
		const double v = clean + pixelSigma(f.options, clean) * z;
		row[x] = static_cast<std::uint8_t>(std::clamp(std::floor(v + 0.5), 0.0, 255.0));
	}
}

/*
 * Quantise one tile row, as above, with the Gaussian read noise (if any):
 * Box-Muller on a hash of the pixel pair (x even, x + 1), cos for the even
 * pixel, sin for the odd one. Tiles start at even x, so a pair never
 * straddles two tiles.
 */
void quantiseRowGaussianNoise(const FrameState &f, std::uint64_t noise_key, const double *acc_row,
			      int tx0, int tw, int y, double bg_row, std::uint8_t *row)
{
	const bool noisy = f.options.noise_sigma > 0.0 || f.options.shot_gain > 0.0;
	const std::uint64_t pairs_per_row = (static_cast<std::uint64_t>(f.width) + 1) / 2;
	for (int i = 0; i < tw; i += 2) {
		const int x = tx0 + i;
		double z_even = 0.0, z_odd = 0.0;
		if (noisy) {
			const std::uint64_t h = splitmix64(
				noise_key + static_cast<std::uint64_t>(y) * pairs_per_row +
				static_cast<std::uint64_t>(x / 2));
			const double u1 = (static_cast<double>(h >> 32) + 0.5) * 0x1.0p-32;
			const double u2 =
				(static_cast<double>(h & 0xffffffffULL) + 0.5) * 0x1.0p-32;
			const double r = std::sqrt(-2.0 * std::log(u1));
			z_even = r * std::cos(2.0 * kPi * u2);
			z_odd = r * std::sin(2.0 * kPi * u2);
		}
		for (int q = 0; q < 2 && i + q < tw; ++q) {
			double v = bg_row + f.gscale * (x + q - f.mid_x) * f.gdx + acc_row[i + q];
			if (noisy)
				v += pixelSigma(f.options, v) * (q ? z_odd : z_even);
			row[x + q] = static_cast<std::uint8_t>(
				std::clamp(std::floor(v + 0.5), 0.0, 255.0));
		}
	}
}

/*
 * Quantise one tile (acc: its levels above background, row stride kTile) into
 * *out, with the background and the read noise.
 */
void quantiseTile(const FrameState &f, std::uint64_t noise_key, const double *acc, int tx0, int ty0,
		  int tw, int th, Image *out)
{
	const RenderOptions &options = f.options;
	const bool fast_noise = (options.noise_sigma > 0.0 || options.shot_gain > 0.0) &&
				options.fast_noise;
	for (int j = 0; j < th; ++j) {
		const int y = ty0 + j;
		std::uint8_t *row = out->data() + static_cast<std::size_t>(y) * f.width;
		const double bg_row = options.background + f.gscale * (y - f.mid_y) * f.gdy;
		const double *acc_row = acc + static_cast<std::ptrdiff_t>(j) * kTile;
		if (fast_noise) {
			quantiseRowFastNoise(f, noise_key, acc_row, tx0, tw, y, bg_row, row);
			continue;
		}
		quantiseRowGaussianNoise(f, noise_key, acc_row, tx0, tw, y, bg_row, row);
	}
}

/* Draw the frame tile by tile: spots and clutter, background and read noise, quantised. */
void drawTiles(const FrameState &f, std::uint64_t noise_key, Image *out)
{
	std::array<double, static_cast<std::size_t>(kTile) * kTile> acc;
	for (int ty0 = 0; ty0 < f.height; ty0 += kTile) {
		const int th = std::min(kTile, f.height - ty0);
		for (int tx0 = 0; tx0 < f.width; tx0 += kTile) {
			const int tw = std::min(kTile, f.width - tx0);
			std::fill(acc.begin(), acc.end(), 0.0);
			accumulateTile(f, tx0, ty0, tw, th, acc.data());
			quantiseTile(f, noise_key, acc.data(), tx0, ty0, tw, th, out);
		}
	}
}

/* Whether a hot pixel at (x, y) keeps clear of the spots, glints and other hot pixels. */
bool hotPixelClear(const FrameState &f, int x, int y, const Image &out)
{
	bool clear = true;
	for (std::size_t s = 0; s < f.spots.size() && clear; ++s)
		if (x >= f.spots[s].x0 && x <= f.spots[s].x1 && y >= f.spots[s].y0 &&
		    y <= f.spots[s].y1)
			clear = false;
	for (std::size_t s = 0; s < f.halos.size() && clear; ++s)
		if (x >= f.halos[s].x0 && x <= f.halos[s].x1 && y >= f.halos[s].y0 &&
		    y <= f.halos[s].y1)
			clear = false;
	for (std::size_t q = 0; q < f.glints.size() && clear; ++q)
		if (pointSegmentDistance(Eigen::Vector2d(x, y), f.glints[q].p0, f.glints[q].p1) <
		    4.0 * f.glints[q].sigma_px + 2.0)
			clear = false;
	for (int dy = -1; dy <= 1 && clear; ++dy)
		for (int dx = -1; dx <= 1 && clear; ++dx) {
			const int xx = x + dx, yy = y + dy;
			if (xx >= 0 && yy >= 0 && xx < f.width && yy < f.height &&
			    out.at(xx, yy) == 255)
				clear = false;
		}
	return clear;
}

/*
 * Draw the hot pixels: isolated saturated pixels, clear of the spots and glints
 * (so that every clutter item stays a separate blob of known kind).
 */
void drawHotPixels(const FrameState &f, Rng *rng_hot, Image *out)
{
	for (int n = 0; n < f.options.hot_pixels; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			const int x = rng_hot->index(f.width), y = rng_hot->index(f.height);
			if (!hotPixelClear(f, x, y, *out))
				continue;
			out->at(x, y) = 255;
			break;
		}
	}
}

/*
 * Find the LEDs lost in a sunlit patch (less than half the contrast they would
 * have on the plain background is left below 255) and take them off the visible.
 */
void washOutLeds(FrameState *f)
{
	if (f->patches.empty())
		return;
	const RenderOptions &options = f->options;
	for (std::size_t s = 0; s < f->n_led_spots; ++s) {
		const double x = f->spots[s].cu, y = f->spots[s].cv;
		double bg = options.background + f->gscale * (y - f->mid_y) * f->gdy +
			    f->gscale * (x - f->mid_x) * f->gdx;
		for (const SunPatch &p : f->patches)
			bg += p.level(x, y);
		const double peak = f->led_peak_level[s];
		const double full =
			std::min(peak, 255.0 - std::clamp(options.background, 0.0, 254.0));
		const double left = std::min(peak, 255.0 - bg);
		if (left < 0.5 * full)
			f->washed_out |= 1u << f->spot_led[s];
	}
	f->visible &= ~f->washed_out;
}

/* Fill in the frame's truth. */
void fillTruth(const FrameState &f, RenderTruth *truth)
{
	truth->pose = f.pose;
	truth->led_px.clear();
	for (int i = 0; i < f.n_leds; ++i)
		truth->led_px.push_back(f.led_px[i]);
	truth->visible_mask = f.visible;
	truth->occluded_mask = f.occluded;
	truth->clutter_blobs = static_cast<int>(f.spots.size() - f.n_led_spots + f.glints.size());
	truth->dimmed_mask = f.dimmed;
	truth->washed_out_mask = f.washed_out;
	truth->kept_face = f.kept_face;
	truth->motion_blur_angle_deg = f.streaked ? f.streak_angle * 180.0 / kPi : 0.0;
	truth->sun_patches = static_cast<int>(f.patches.size());
	truth->target_drawn = f.options.draw_target;
	truth->scrambled = f.scrambled;
}

} /* namespace */

void FrameRenderer::render(const Pose &pose, const RenderOptions &options, std::uint64_t seed,
			   Image *out, RenderTruth *truth) const
{
	FrameState f(target_, camera_, normals_, pose, options);
	if (out->width() != f.width || out->height() != f.height)
		*out = Image(f.width, f.height);

	/* The scene (gradient, clutter) may have its own seed; noise and occlusion: per frame. */
	FrameStreams rng(seed, options.clutter_seed != 0 ? options.clutter_seed : seed);

	/* The LEDs: where they land, which are hidden, which are dimmed. */
	placeLeds(&f, &rng.scramble);
	projectLeds(*this, &f);
	/* Occlusion: all but one face, the mask, then random drawable LEDs. */
	f.occluded = options.occlusion_mask & f.drawable;
	occludeAllButOneFace(&f, &rng.face);
	occludeRandomLeds(&f, &rng.occlusion);
	f.visible = f.drawable & ~f.occluded;
	dimLeds(&f, &rng.dim);

	/* The LED spots, then the clutter around them. */
	chooseStreak(&f, &rng.motion);
	for (int i = 0; i < f.n_leds; ++i)
		if (f.visible & (1u << i))
			addLedSpot(&f, i);
	f.n_led_spots = f.spots.size();
	prepareClutter(&f);
	addReflections(&f, &rng.reflections, &rng.shape);
	addNearReflections(&f, &rng.near, &rng.shape);
	addGlints(&f, &rng.glints);
	addSunPatches(&f, &rng.sun);

	/* The pixels, then what is drawn over them or lost in them. */
	chooseGradient(&f, &rng.gradient);
	drawTiles(f, rng.noise_key, out);
	drawHotPixels(f, &rng.hot, out);
	washOutLeds(&f);

	if (truth)
		fillTruth(f, truth);
}

Pose poseAt(const CameraIntrinsics &camera, const TargetModel &target, double range_mm,
	    const Eigen::Vector3d &rpy_deg, double u_frac, double v_frac)
{
	const CameraModel model(camera);
	Pose pose;
	pose.R = rotationRpy(rpy_deg);
	const Eigen::Vector2d uv(u_frac * camera.width - 0.5, v_frac * camera.height - 0.5);
	Eigen::Vector2d xy;
	if (!model.pixelToNormalized(uv, &xy))
		xy = Eigen::Vector2d((uv.x() - camera.cx) / camera.fx,
				     (uv.y() - camera.cy) / camera.fy);
	const Eigen::Vector3d centre_c = range_mm * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
	pose.t_mm = centre_c - pose.R * centroidOf(target);
	return pose;
}

} /* namespace dockpose */

namespace dockpose {

bool targetInFrame(const CameraModel &camera, const TargetModel &target, const Pose &pose,
		   double margin_px)
{
	for (const auto &point : target.points_mm) {
		const Eigen::Vector3d p = pose.apply(point);
		Eigen::Vector2d uv, xy;
		if (!(p.z() > 1e-6) || !camera.project(p, &uv) || !camera.inImage(uv, margin_px))
			return false;
		const Eigen::Vector2d ideal(p.x() / p.z(), p.y() / p.z());
		if (!camera.pixelToNormalized(uv, &xy) || (xy - ideal).norm() > 1e-6)
			return false;
	}
	return true;
}

Pose poseFromSide(const CameraIntrinsics &camera, const TargetModel &target, double range_mm,
		  const SideView &view)
{
	Pose pose;
	if (view.face < 0 || view.face >= static_cast<int>(target.faces.size()))
		return pose;
	StaticVector<Eigen::Vector3d, kMaxFaces> normals;
	target.frontNormals(&normals);
	const Eigen::Vector3d n = normals[view.face];
	Eigen::Vector3d centre = Eigen::Vector3d::Zero();
	for (int v : target.faces[view.face])
		centre += target.points_mm[v];
	centre /= 4.0;

	/* From the face's centre towards the camera, target frame. */
	const double k = kPi / 180.0;
	const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
	const Eigen::Vector3d d =
		std::cos(view.angle_deg * k) * n +
		std::sin(view.angle_deg * k) *
			(std::cos(view.azimuth_deg * k) * e1 + std::sin(view.azimuth_deg * k) * e2);

	/* The line of sight to the face's centre, camera frame. */
	const CameraModel model(camera);
	const Eigen::Vector2d uv(view.u_frac * camera.width - 0.5,
				 view.v_frac * camera.height - 0.5);
	Eigen::Vector2d xy;
	if (!model.pixelToNormalized(uv, &xy))
		xy = Eigen::Vector2d((uv.x() - camera.cx) / camera.fx,
				     (uv.y() - camera.cy) / camera.fy);
	const Eigen::Vector3d ray = Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();

	/* R d = -ray (the camera is along d from the face), then the roll about the ray. */
	const Eigen::Matrix3d R0 = Eigen::Quaterniond::FromTwoVectors(d, -ray).toRotationMatrix();
	pose.R = Eigen::AngleAxisd(view.roll_deg * k, ray).toRotationMatrix() * R0;
	pose.t_mm = range_mm * ray - pose.R * centre;
	return pose;
}

bool sampleSideView(const CameraIntrinsics &camera, const TargetModel &target, int face,
		    double range_mm, double max_angle_deg, std::uint64_t seed, Pose *pose,
		    SideView *view, double margin_px)
{
	SideView v;
	v.face = face;
	Rng rng(splitmix64(seed ^ 0x73696465ULL));
	const double cos_max = std::cos(std::clamp(max_angle_deg, 0.0, 180.0) * kPi / 180.0);
	v.angle_deg = std::acos(std::clamp(rng.uniform(cos_max, 1.0), -1.0, 1.0)) * 180.0 / kPi;
	v.azimuth_deg = rng.uniform(0.0, 360.0);
	v.roll_deg = rng.uniform(0.0, 360.0);
	if (view)
		*view = v;
	*pose = Pose();
	if (face < 0 || face >= static_cast<int>(target.faces.size()))
		return false;

	/* Anywhere in the frame first; then ever nearer the centre; last the centre itself. */
	const CameraModel model(camera);
	constexpr int kUniform = 48, kShrinking = 16;
	for (int attempt = 0; attempt <= kUniform + kShrinking; ++attempt) {
		double spread = 0.5;
		if (attempt >= kUniform)
			spread = 0.5 * (kUniform + kShrinking - attempt) / (kShrinking + 1.0);
		v.u_frac = 0.5 + rng.uniform(-spread, spread);
		v.v_frac = 0.5 + rng.uniform(-spread, spread);
		if (attempt == kUniform + kShrinking)
			v.u_frac = v.v_frac = 0.5;
		*pose = poseFromSide(camera, target, range_mm, v);
		if (targetInFrame(model, target, *pose, margin_px)) {
			if (view)
				*view = v;
			return true;
		}
	}
	if (view)
		*view = v;
	return false;
}

} /* namespace dockpose */

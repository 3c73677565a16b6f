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
#include <cmath>
#include <limits>
#include <random>

#include <Eigen/Geometry>

namespace dockpose {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kInvSqrt2 = 0.70710678118654752440;
constexpr double kInvSqrt2Pi = 0.39894228040143267794;

/* Reflections and glints beyond these counts are not drawn (truth says how many were). */
constexpr std::size_t kMaxReflections = 64;
constexpr std::size_t kMaxGlints = 64;
constexpr std::size_t kMaxSpots = kMaxLeds + kMaxReflections;
constexpr int kTile = 64;
/* Place attempts per clutter item before it is given up. */
constexpr int kPlaceAttempts = 200;
/* Spots are foreshortened no further than this viewing angle (an LED sitting on an edge). */
constexpr double kMaxShapeAngleDeg = 85.0;

std::uint64_t splitmix64(std::uint64_t x)
{
	x += 0x9e3779b97f4a7c15ULL;
	x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
	x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
	return x ^ (x >> 31);
}

/* A deterministic random stream: mt19937_64 with our own transforms. */
class Rng
{
public:
	explicit Rng(std::uint64_t seed)
		: engine_(seed)
	{
	}

	/* Uniform in [0, 1) with 53 bits. */
	double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
	double uniform(double a, double b) { return a + (b - a) * uniform(); }
	/* Uniform integer in [0, n), n > 0. */
	int index(int n) { return std::min(n - 1, static_cast<int>(uniform() * n)); }

private:
	std::mt19937_64 engine_;
};

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

/*
 * Build a spot from its centre, its shape matrix M = A A^T (the ellipse is
 * {c + A s : |s| <= 1}) and its continuous peak level above background.
 */
Spot makeSpot(const Eigen::Vector2d &c, const Eigen::Matrix2d &M_in, double peak, double sigma_px)
{
	Spot s;
	s.cu = c.x();
	s.cv = c.y();
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
 * Add the pixel integrals of spot s over the tile [tx0, tx0 + tw) x
 * [ty0, ty0 + th) into acc (row stride kTile).
 */
void accumulateSpot(const Spot &s, double sigma_px, int tx0, int ty0, int tw, int th, double *acc)
{
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
		const double w = s.amplitude * s.half_height * ct * dtheta;
		const double half = ct * s.inv_sqrt_a;
		const double l = s.cu + s.slope * delta - half; /* chord, absolute px */
		const double r = s.cu + s.slope * delta + half;
		const double yc = s.cv + delta;

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
			double *row = acc + (cy0 - ty0 + j) * kTile + (cx0 - tx0);
			for (int i = 0; i < nc; ++i)
				row[i] += wy * fx[i];
		}
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

void FrameRenderer::render(const Pose &pose, const RenderOptions &options, std::uint64_t seed,
			   Image *out, RenderTruth *truth) const
{
	const CameraIntrinsics &k = camera_.intrinsics();
	const int width = k.width, height = k.height;
	if (out->width() != width || out->height() != height)
		*out = Image(width, height);

	const double sigma = std::max(0.3, options.blur_sigma_px);
	const int n_leds = static_cast<int>(target_.points_mm.size());
	const Eigen::Vector3d centroid = centroidOf(target_);

	/* The scene (gradient and clutter) may have its own seed; noise and occlusion are per frame. */
	const std::uint64_t scene_seed = options.clutter_seed != 0 ? options.clutter_seed : seed;
	Rng rng_gradient(splitmix64(scene_seed ^ 0x67726164ULL));
	Rng rng_occlusion(splitmix64(seed ^ 0x6f63636cULL));
	Rng rng_reflections(splitmix64(scene_seed ^ 0x7265666cULL));
	Rng rng_glints(splitmix64(scene_seed ^ 0x676c6e74ULL));
	Rng rng_hot(splitmix64(scene_seed ^ 0x686f7470ULL));
	const std::uint64_t noise_key = splitmix64(seed ^ 0x6e6f6973ULL);

	/* Where every LED lands, and which ones shine towards the camera. */
	std::array<Eigen::Vector2d, kMaxLeds> led_px;
	std::uint32_t drawable = 0;
	for (int i = 0; i < n_leds; ++i) {
		const Eigen::Vector3d p = pose.apply(target_.points_mm[i]);
		Eigen::Vector2d uv;
		led_px[i] = Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
		if (!camera_.project(p, &uv))
			continue;
		led_px[i] = uv;
		/* Inside the frame, and inside the lens's valid field (no fold-back of the distortion). */
		Eigen::Vector2d xy;
		const Eigen::Vector2d ideal(p.x() / p.z(), p.y() / p.z());
		if (!camera_.inImage(uv) || !camera_.pixelToNormalized(uv, &xy) ||
		    (xy - ideal).norm() > 1e-6)
			continue;
		if (ledVisible(pose, i, options.max_view_angle_deg))
			drawable |= 1u << i;
	}

	/* Occlusion: random drawable LEDs, plus the mask. */
	std::uint32_t occluded = options.occlusion_mask & drawable;
	{
		std::array<int, kMaxLeds> pool{};
		int n_pool = 0;
		for (int i = 0; i < n_leds; ++i)
			if ((drawable & ~occluded) & (1u << i))
				pool[n_pool++] = i;
		for (int n = 0; n < options.occluded_leds && n_pool > 0; ++n) {
			const int pick = rng_occlusion.index(n_pool);
			occluded |= 1u << pool[pick];
			pool[pick] = pool[--n_pool];
		}
	}
	const std::uint32_t visible = drawable & ~occluded;

	/* LED spots. */
	StaticVector<Spot, kMaxSpots> spots;
	std::array<int, kMaxLeds> spot_led{}; /* LED of spot s (for the first n_led_spots) */
	const double cos_shape_min = std::cos(kMaxShapeAngleDeg * kPi / 180.0);
	for (int i = 0; i < n_leds; ++i) {
		if (!(visible & (1u << i)))
			continue;
		const Eigen::Vector3d p = pose.apply(target_.points_mm[i]);
		const double range = p.norm();
		const Eigen::Vector3d to_camera = -p / range;
		/* The LED's normal: the mean of its faces' fronts. */
		Eigen::Vector3d n_t = Eigen::Vector3d::Zero();
		for (std::size_t f = 0; f < target_.faces.size(); ++f) {
			const auto &face = target_.faces[f];
			if (std::find(face.begin(), face.end(), i) != face.end())
				n_t += normals_[f];
		}
		if (n_t.norm() < 1e-9)
			n_t = target_.points_mm[i] - centroid;
		if (n_t.norm() < 1e-9)
			n_t = Eigen::Vector3d(0.0, 0.0, -1.0);
		Eigen::Vector3d n = (pose.R * n_t).normalized();
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
		camera_.project(p, &uv, &J);
		const Eigen::Vector3d e1 = n.unitOrthogonal();
		const Eigen::Vector3d e2 = n.cross(e1);
		Eigen::Matrix<double, 3, 2> E;
		E.col(0) = e1;
		E.col(1) = e2;
		const Eigen::Matrix2d A = options.led_radius_mm * (J * E);
		const double ratio = options.reference_range_mm / range;
		const double peak = std::max(options.min_led_peak,
					     options.led_peak * ratio * ratio * cos_view) *
				    options.led_gain;
		spot_led[spots.size()] = i;
		spots.push_back(makeSpot(uv, A * A.transpose(), peak, sigma));
	}
	const std::size_t n_led_spots = spots.size();

	/* A typical LED spot at this range, for LED-like reflections. */
	const Eigen::Vector3d centre_c = pose.apply(centroid);
	const double centre_range = std::max(1.0, centre_c.norm());
	const double typical_radius_px = std::max(0.5, k.fx * options.led_radius_mm / centre_range);
	const double typical_ratio = options.reference_range_mm / centre_range;
	const double typical_peak =
		std::min(255.0, std::max(options.min_led_peak,
					 options.led_peak * typical_ratio * typical_ratio));

	/* Clutter keeps clear of every LED that projects into the frame, drawn or not. */
	std::array<double, kMaxLeds> led_clearance;
	led_clearance.fill(typical_radius_px + 3.0 * sigma);
	for (std::size_t s = 0; s < n_led_spots; ++s)
		led_clearance[spot_led[s]] =
			std::max(led_clearance[spot_led[s]], spots[s].extent_px);
	auto ledClearance = [&](int i) {
		return led_clearance[i];
	};

	const int n_reflections =
		std::clamp(options.reflections, 0, static_cast<int>(kMaxReflections));
	for (int n = 0; n < n_reflections; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			const double radius = typical_radius_px * rng_reflections.uniform(0.7, 1.3);
			const double peak = typical_peak * rng_reflections.uniform(0.6, 1.0);
			const double margin = radius + 3.0 * sigma;
			if (2.0 * margin >= width || 2.0 * margin >= height)
				break;
			const Eigen::Vector2d c(rng_reflections.uniform(margin, width - 1 - margin),
						rng_reflections.uniform(margin,
									height - 1 - margin));
			const double extent = radius + 3.0 * sigma;
			bool clear = true;
			for (int i = 0; i < n_leds && clear; ++i)
				if (led_px[i].allFinite() &&
				    (c - led_px[i]).norm() < extent + ledClearance(i) + 3.0)
					clear = false;
			for (std::size_t s = n_led_spots; s < spots.size() && clear; ++s)
				if ((c - Eigen::Vector2d(spots[s].cu, spots[s].cv)).norm() <
				    extent + spots[s].extent_px + 3.0)
					clear = false;
			if (!clear)
				continue;
			spots.push_back(makeSpot(c, Eigen::Matrix2d::Identity() * radius * radius,
						 peak, sigma));
			break;
		}
	}

	StaticVector<Glint, kMaxGlints> glints;
	const int n_glints = std::clamp(options.glints, 0, static_cast<int>(kMaxGlints));
	for (int n = 0; n < n_glints; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			Glint g;
			const double length = rng_glints.uniform(30.0, 200.0);
			const double angle = rng_glints.uniform(0.0, kPi);
			g.sigma_px = rng_glints.uniform(0.5, 0.9);
			g.peak = rng_glints.uniform(150.0, 255.0);
			const Eigen::Vector2d c(rng_glints.uniform(0.0, width - 1.0),
						rng_glints.uniform(0.0, height - 1.0));
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
			const double reach = 4.0 * g.sigma_px + 1.0;
			const double clear_px = 3.0 * g.sigma_px + 3.0;
			bool clear = true;
			for (int i = 0; i < n_leds && clear; ++i)
				if (led_px[i].allFinite() &&
				    pointSegmentDistance(led_px[i], g.p0, g.p1) <
					    ledClearance(i) + clear_px)
					clear = false;
			for (std::size_t s = n_led_spots; s < spots.size() && clear; ++s)
				if (pointSegmentDistance(Eigen::Vector2d(spots[s].cu, spots[s].cv),
							 g.p0,
							 g.p1) < spots[s].extent_px + clear_px)
					clear = false;
			for (std::size_t q = 0; q < glints.size() && clear; ++q)
				if (segmentDistance(g.p0, g.p1, glints[q].p0, glints[q].p1) <
				    2.0 * clear_px)
					clear = false;
			if (!clear)
				continue;
			g.x0 = static_cast<int>(std::floor(std::min(g.p0.x(), g.p1.x()) - reach));
			g.x1 = static_cast<int>(std::ceil(std::max(g.p0.x(), g.p1.x()) + reach));
			g.y0 = static_cast<int>(std::floor(std::min(g.p0.y(), g.p1.y()) - reach));
			g.y1 = static_cast<int>(std::ceil(std::max(g.p0.y(), g.p1.y()) + reach));
			glints.push_back(g);
			break;
		}
	}

	/* Background: a linear gradient of `gradient` levels across the frame, random direction. */
	const double gradient_angle = rng_gradient.uniform(0.0, 2.0 * kPi);
	const double gdx = std::cos(gradient_angle), gdy = std::sin(gradient_angle);
	const double span = std::abs(gdx) * (width - 1) + std::abs(gdy) * (height - 1);
	const double gscale = span > 0.0 ? options.gradient / span : 0.0;
	const double mid_x = 0.5 * (width - 1), mid_y = 0.5 * (height - 1);
	const bool noisy = options.noise_sigma > 0.0;
	const std::uint64_t pairs_per_row = (static_cast<std::uint64_t>(width) + 1) / 2;

	std::array<double, kTile * kTile> acc;
	for (int ty0 = 0; ty0 < height; ty0 += kTile) {
		const int th = std::min(kTile, height - ty0);
		for (int tx0 = 0; tx0 < width; tx0 += kTile) {
			const int tw = std::min(kTile, width - tx0);
			std::fill(acc.begin(), acc.end(), 0.0);
			for (const Spot &s : spots)
				if (s.x1 >= tx0 && s.x0 < tx0 + tw && s.y1 >= ty0 &&
				    s.y0 < ty0 + th)
					accumulateSpot(s, sigma, tx0, ty0, tw, th, acc.data());
			for (const Glint &g : glints)
				if (g.x1 >= tx0 && g.x0 < tx0 + tw && g.y1 >= ty0 &&
				    g.y0 < ty0 + th)
					accumulateGlint(g, tx0, ty0, tw, th, acc.data());

			for (int j = 0; j < th; ++j) {
				const int y = ty0 + j;
				std::uint8_t *row =
					out->data() + static_cast<std::size_t>(y) * width;
				const double bg_row =
					options.background + gscale * (y - mid_y) * gdy;
				for (int i = 0; i < tw; ++i) {
					const int x = tx0 + i;
					double v = bg_row + gscale * (x - mid_x) * gdx +
						   acc[j * kTile + i];
					if (noisy) {
						/* Box-Muller on a hash of the pixel pair: cos for even x, sin for odd. */
						const std::uint64_t h = splitmix64(
							noise_key +
							static_cast<std::uint64_t>(y) *
								pairs_per_row +
							static_cast<std::uint64_t>(x / 2));
						const double u1 =
							(static_cast<double>(h >> 32) + 0.5) *
							0x1.0p-32;
						const double u2 =
							(static_cast<double>(h & 0xffffffffULL) +
							 0.5) *
							0x1.0p-32;
						const double r = std::sqrt(-2.0 * std::log(u1));
						const double z =
							(x & 1) ? r * std::sin(2.0 * kPi * u2)
								: r * std::cos(2.0 * kPi * u2);
						v += options.noise_sigma * z;
					}
					row[x] = static_cast<std::uint8_t>(
						std::clamp(std::floor(v + 0.5), 0.0, 255.0));
				}
			}
		}
	}

	/*
	 * Hot pixels: isolated saturated pixels, clear of the spots and glints
	 * (so that every clutter item stays a separate blob of known kind).
	 */
	for (int n = 0; n < options.hot_pixels; ++n) {
		for (int attempt = 0; attempt < kPlaceAttempts; ++attempt) {
			const int x = rng_hot.index(width), y = rng_hot.index(height);
			bool clear = true;
			for (std::size_t s = 0; s < spots.size() && clear; ++s)
				if (x >= spots[s].x0 && x <= spots[s].x1 && y >= spots[s].y0 &&
				    y <= spots[s].y1)
					clear = false;
			for (std::size_t q = 0; q < glints.size() && clear; ++q)
				if (pointSegmentDistance(Eigen::Vector2d(x, y), glints[q].p0,
							 glints[q].p1) <
				    4.0 * glints[q].sigma_px + 2.0)
					clear = false;
			for (int dy = -1; dy <= 1 && clear; ++dy)
				for (int dx = -1; dx <= 1 && clear; ++dx) {
					const int xx = x + dx, yy = y + dy;
					if (xx >= 0 && yy >= 0 && xx < width && yy < height &&
					    out->at(xx, yy) == 255)
						clear = false;
				}
			if (!clear)
				continue;
			out->at(x, y) = 255;
			break;
		}
	}

	if (truth) {
		truth->pose = pose;
		truth->led_px.clear();
		for (int i = 0; i < n_leds; ++i)
			truth->led_px.push_back(led_px[i]);
		truth->visible_mask = visible;
		truth->occluded_mask = occluded;
		truth->clutter_blobs = static_cast<int>(spots.size() - n_led_spots + glints.size());
	}
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

/* SPDX-License-Identifier: MIT */
#include "algo/correspondence.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <utility>

#include <Eigen/Geometry>

#include "algo/p3p.h"

namespace dockpose {

namespace {

constexpr double kPi = 3.14159265358979323846;

double cross2(const Eigen::Vector2d &a, const Eigen::Vector2d &b)
{
	return a.x() * b.y() - a.y() * b.x();
}

/*
 * Order four points counter-clockwise around their centroid and check that
 * they are in strictly convex position. Returns false for a point inside the
 * triangle of the other three, or for (near-)collinear triples.
 */
bool convexOrder(const Eigen::Vector2d *p, const int idx[4], int order[4])
{
	Eigen::Vector2d c = Eigen::Vector2d::Zero();
	for (int k = 0; k < 4; ++k)
		c += p[idx[k]];
	c *= 0.25;
	/*
	 * By angle about the centroid, as atan2 orders them (from -pi to pi),
	 * without atan2: the half-plane first (y < 0, then the positive x axis,
	 * y > 0, the negative x axis), then the turn between the two.
	 */
	Eigen::Vector2d d[4];
	int half[4];
	for (int k = 0; k < 4; ++k) {
		d[k] = p[idx[k]] - c;
		order[k] = idx[k];
		const double x = d[k].x(), y = d[k].y();
		half[k] = y < 0.0 ? 0 : y > 0.0 ? 2 : x < 0.0 ? (std::signbit(y) ? -1 : 3) : 1;
	}
	auto after = [&](int a, int b) {
		return half[a] > half[b] || (half[a] == half[b] && cross2(d[a], d[b]) < 0.0);
	};
	/* Insertion sort of four by angle. */
	for (int i = 1; i < 4; ++i)
		for (int j = i; j > 0 && after(j - 1, j); --j) {
			std::swap(d[j - 1], d[j]);
			std::swap(half[j - 1], half[j]);
			std::swap(order[j - 1], order[j]);
		}
	double scale2 = 0.0;
	for (int k = 0; k < 4; ++k)
		scale2 = std::max(scale2, (p[order[k]] - c).squaredNorm());
	for (int k = 0; k < 4; ++k) {
		const Eigen::Vector2d e0 = p[order[(k + 1) % 4]] - p[order[k]];
		const Eigen::Vector2d e1 = p[order[(k + 2) % 4]] - p[order[(k + 1) % 4]];
		/* Every turn must be left and not degenerate (area > 1% of the extent). */
		if (cross2(e0, e1) <= 1e-2 * scale2)
			return false;
	}
	return true;
}

/*
 * Where the diagonals p0-p2 and p1-p3 of a quadrilateral cross: p0 + s (p2 -
 * p0) = p1 + t (p3 - p1). False when they are parallel.
 */
bool diagonalCross(const Eigen::Vector2d &p0, const Eigen::Vector2d &p1, const Eigen::Vector2d &p2,
		   const Eigen::Vector2d &p3, double *s, double *t)
{
	const Eigen::Vector2d d0 = p2 - p0, d1 = p3 - p1, w = p1 - p0;
	const double den = cross2(d0, d1);
	if (!(std::abs(den) > 1e-300))
		return false;
	*s = cross2(w, d1) / den;
	*t = cross2(w, d0) / den;
	return true;
}

/* Remove match->pairs[k], and its LED's bit. */
void removePair(Match *match, std::size_t k)
{
	match->led_mask &= ~(1u << match->pairs[k][0]);
	for (std::size_t l = k; l + 1 < match->pairs.size(); ++l)
		match->pairs[l] = match->pairs[l + 1];
	match->pairs.pop_back();
}

/* log10 of the binomial coefficient C(n, k). */
double log10Choose(int n, int k)
{
	if (k < 0 || k > n)
		return -std::numeric_limits<double>::infinity();
	return (std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0)) /
	       std::log(10.0);
}

} /* namespace */

double bestSubsetLog10Nfa(const double *tol2_sorted, int k, int n, double rho, double log10_tests)
{
	double best = std::numeric_limits<double>::max();
	for (int m = 4; m <= k; ++m) {
		const double p = -std::expm1(-rho * kPi * tol2_sorted[m - 1]);
		const double choose = n < 0 ? 0.0 : log10Choose(n - 3, m - 3);
		best = std::min(best,
				log10_tests + choose + (m - 3) * std::log10(std::max(p, 1e-300)));
	}
	return best;
}

Correspondence::Correspondence(TargetModel target, const CameraModel &camera,
			       const CorrespondenceConfig &config)
	: target_(std::move(target)),
	  camera_(camera),
	  config_(config)
{
	diameter_mm_ = target_.diameterMm();
	cos_view_max_ = std::cos(config_.max_view_angle_deg * kPi / 180.0);
	tan_view_max_ = std::tan(std::min(config_.max_view_angle_deg, 89.0) * kPi / 180.0);
	/*
	 * A stopped search leaves rivals unsought: any rival within the ambiguity
	 * margin of a pose that stops it must itself be a false alarm the bound
	 * admits, whatever the configured stop.
	 */
	early_exit_log10_nfa_ =
		std::min(config_.early_exit_log10_nfa,
			 config_.max_log10_nfa - std::max(config_.ambiguity_margin, 0.0));
	for (const auto &p : target_.points_mm)
		centroid_mm_ += p;
	if (!target_.points_mm.empty())
		centroid_mm_ /= static_cast<double>(target_.points_mm.size());

	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		for (int k = 0; k < 4; ++k) {
			led_faces_[target_.faces[f][k]] |= 1u << f;
			led_faces_mask_[f] |= 1u << target_.faces[f][k];
		}

	orientFaces();
	findSymmetries();
	findCongruences();
	findTriangleModels();
	findQuadAssignments();
}

/*
 * The model triangles the hidden-vertex search tries: each face with one
 * vertex missing (a hidden LED of only one face leaves the other faces
 * complete for the quadrilateral search, so only shared vertices, or any
 * vertex of a lone face), its other three in cyclic order, the one direction
 * round in which a face seen from its front keeps its orientation in the
 * image (tryAssignment's sign rule: det[q_i q_j q_k] / A < 0): the image
 * triangle is counter-clockwise, so the model's must be clockwise about the
 * front normal; the other direction's poses all see the face from behind.
 * Triangles with equal sides share their P3P depths (sides_class).
 */
void Correspondence::findTriangleModels()
{
	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		for (int missing = 0; missing < 4; ++missing) {
			if (target_.faces.size() > 1 &&
			    __builtin_popcount(led_faces_[target_.faces[f][missing]]) < 2)
				continue;
			for (int dir = -1; dir <= 1; dir += 2) {
				TriangleModel tm;
				tm.face = f;
				for (int k = 0; k < 3; ++k)
					tm.vertex[k] = ((missing + dir * (k + 1)) % 4 + 4) % 4;
				const auto &plane = face_plane_[f];
				if (!(cross2(plane[tm.vertex[1]] - plane[tm.vertex[0]],
					     plane[tm.vertex[2]] - plane[tm.vertex[0]]) < 0.0))
					continue;
				Eigen::Vector3d model_mm[3];
				for (int k = 0; k < 3; ++k) {
					const int led = target_.faces[f][tm.vertex[k]];
					tm.leds |= 1u << led;
					model_mm[k] = target_.points_mm[led];
				}
				p3pSides(model_mm, tm.sides_mm2.data());
				tm.p3p = p3pModel(model_mm);
				tm.sides_class = static_cast<int>(triangle_models_.size());
				for (const TriangleModel &other : triangle_models_) {
					bool same = true;
					for (int k = 0; k < 3; ++k)
						same = same && std::abs(other.sides_mm2[k] -
									tm.sides_mm2[k]) <=
								       1e-12 * tm.sides_mm2[k];
					if (same) {
						tm.sides_class = other.sides_class;
						break;
					}
				}
				if (!triangle_models_.full())
					triangle_models_.push_back(tm);
			}
		}
}

/* Front normals, face centres and in-plane vertex coordinates of every face. */
void Correspondence::orientFaces()
{
	target_.frontNormals(&normals_);
	face_centres_.clear();
	face_plane_.clear();
	for (std::size_t f = 0; f < target_.faces.size(); ++f) {
		const auto &face = target_.faces[f];
		Eigen::Vector3d centre = Eigen::Vector3d::Zero();
		for (int k = 0; k < 4; ++k)
			centre += target_.points_mm[face[k]] / 4.0;
		face_centres_.push_back(centre);
		const Eigen::Vector3d e0 =
			(target_.points_mm[face[1]] - target_.points_mm[face[0]]).normalized();
		const Eigen::Vector3d e1 = normals_[f].cross(e0);
		std::array<Eigen::Vector2d, 4> plane;
		for (int k = 0; k < 4; ++k) {
			const Eigen::Vector3d d = target_.points_mm[face[k]] - centre;
			plane[k] = { d.dot(e0), d.dot(e1) };
		}
		face_plane_.push_back(plane);
		std::array<double, 4> frac{};
		for (int a = 0; a < 4; ++a) {
			double t = 0.0;
			diagonalCross(plane[a], plane[(a + 1) % 4], plane[(a + 2) % 4],
				      plane[(a + 3) % 4], &frac[a], &t);
		}
		diagonal_frac_.push_back(frac);
	}
}

/*
 * Rigid symmetries: transforms that map the LED set and the faces onto
 * themselves. Found by fitting face 0 onto every face in every cyclic
 * assignment and checking that all LEDs and faces land on LEDs and faces.
 */
void Correspondence::findSymmetries()
{
	symmetries_.clear();
	Symmetry identity;
	for (std::size_t i = 0; i < kMaxLeds; ++i)
		identity.perm[i] = static_cast<std::int8_t>(i);
	symmetries_.push_back(identity);

	const double tol = 1e-3 * std::max(diameter_mm_, 1e-9);
	const std::size_t nl = target_.points_mm.size();
	const auto &face0 = target_.faces[0];
	for (const auto &face : target_.faces) {
		for (int dir = -1; dir <= 1; dir += 2)
			for (int rot = 0; rot < 4; ++rot) {
				Eigen::Vector3d src[4], dst[4];
				for (int k = 0; k < 4; ++k) {
					src[k] = target_.points_mm[face0[k]];
					dst[k] = target_.points_mm[face[((rot + dir * k) % 4 + 4) %
									4]];
				}
				Pose t;
				double sse = 0.0;
				if (!hornFit(src, dst, 4, &t, false, nullptr, &sse) ||
				    sse > 4.0 * tol * tol)
					continue;
				Symmetry s;
				bool ok = true;
				std::uint32_t used = 0;
				for (std::size_t i = 0; i < nl && ok; ++i) {
					const Eigen::Vector3d q = t.apply(target_.points_mm[i]);
					int hit = -1;
					for (std::size_t j = 0; j < nl; ++j)
						if ((q - target_.points_mm[j]).norm() < tol)
							hit = static_cast<int>(j);
					if (hit < 0 || (used & (1u << hit))) {
						ok = false;
						break;
					}
					used |= 1u << hit;
					s.perm[i] = static_cast<std::int8_t>(hit);
				}
				/* Faces must map onto faces. */
				for (std::size_t f = 0; f < target_.faces.size() && ok; ++f) {
					std::uint32_t image = 0;
					for (int k = 0; k < 4; ++k)
						image |= 1u << s.perm[target_.faces[f][k]];
					bool found = false;
					for (const auto &other : target_.faces) {
						std::uint32_t m = 0;
						for (int k = 0; k < 4; ++k)
							m |= 1u << other[k];
						found = found || m == image;
					}
					ok = found;
				}
				if (!ok)
					continue;
				bool duplicate = false;
				for (const auto &known : symmetries_)
					duplicate = duplicate || std::equal(known.perm.begin(),
									    known.perm.begin() + nl,
									    s.perm.begin());
				if (duplicate)
					continue;
				for (std::size_t i = nl; i < kMaxLeds; ++i)
					s.perm[i] = static_cast<std::int8_t>(i);
				s.transform = t;
				symmetries_.push_back(s);
			}
	}
}

/*
 * Near-congruences of faces: face f fitted onto face g in each cyclic
 * assignment that keeps the front (a rigid turn); kept when the fit is within
 * 10% of the face's size and the transform is no symmetry of the whole model
 * (those are folded by canonicalise()).
 */
void Correspondence::findCongruences()
{
	congruences_.clear();
	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		for (std::size_t g = 0; g < target_.faces.size(); ++g)
			for (int dir = -1; dir <= 1; dir += 2)
				for (int rot = 0; rot < 4; ++rot) {
					Eigen::Vector3d src[4], dst[4];
					double size2 = 0.0;
					for (int k = 0; k < 4; ++k) {
						src[k] = target_.points_mm[target_.faces[f][k]];
						dst[k] =
							target_.points_mm
								[target_.faces[g][((rot + dir * k) %
											   4 +
										   4) %
										  4]];
					}
					size2 = std::max((src[0] - src[2]).squaredNorm(),
							 (src[1] - src[3]).squaredNorm());
					Pose t;
					double sse = 0.0;
					if (!hornFit(src, dst, 4, &t, false, nullptr, &sse) ||
					    sse > 4.0 * 0.01 * size2)
						continue;
					/* Fronts must map onto fronts. */
					if (normals_[g].dot(t.R * normals_[f]) < 0.5)
						continue;
					bool known = false;
					for (const auto &sym : symmetries_)
						known = known || samePose(t, sym.transform);
					for (const auto &c : congruences_)
						known = known || samePose(t, c);
					if (!known)
						congruences_.push_back(t);
				}
}

/* Is face f seen from its front, within the view angle, from this pose? */
bool Correspondence::faceVisible(const Pose &pose, std::size_t f) const
{
	return faceVisibleFrom(-pose.R.transpose() * pose.t_mm, f);
}

/* The same from camera_t, the camera centre in the target frame (mm). */
bool Correspondence::faceVisibleFrom(const Eigen::Vector3d &camera_t, std::size_t f) const
{
	const Eigen::Vector3d view = camera_t - face_centres_[f];
	/* From behind (or edge-on): no square root needed to say so. */
	if (cos_view_max_ >= 0.0 && !(normals_[f].dot(view) > 0.0))
		return false;
	return normals_[f].dot(view.normalized()) > cos_view_max_;
}

/*
 * Is the target in front of the camera, and (with the target file's approach
 * prior) the camera within approach.max_deg of its approach axis?
 */
bool Correspondence::plausible(const Pose &pose) const
{
	if (!(pose.apply(centroid_mm_).z() > 0.0))
		return false;
	if (!target_.approach.set)
		return true;
	const Eigen::Vector3d camera_t = -pose.R.transpose() * pose.t_mm;
	const Eigen::Vector3d d = camera_t - centroid_mm_;
	return target_.approach.axis.dot(d) >=
	       std::cos(target_.approach.max_deg * kPi / 180.0) * d.norm();
}

/*
 * LEDs that may be seen (bit mask): an LED shines only out of the faces it
 * sits on, and one of them must be seen from its front within the view angle
 * (faceVisible()). The LEDs a pose predicts and the LEDs it may match are the
 * same set: a pose that explains a spot with an LED seen edge-on (a wrong box
 * corner pose put one at 89 degrees, where the true pose saw every matched
 * LED within 57) would claim a spot the LED cannot make.
 */
std::uint32_t Correspondence::frontLeds(const Pose &pose) const
{
	const Eigen::Vector3d camera_t = -pose.R.transpose() * pose.t_mm;
	std::uint32_t front = 0;
	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		if (faceVisibleFrom(camera_t, f))
			front |= led_faces_mask_[f];
	return front;
}

/* frontLeds() projecting inside the frame, margin_px from its edge. */
std::uint32_t Correspondence::predictedLeds(const Pose &pose, double margin_px) const
{
	const std::uint32_t front = frontLeds(pose);
	std::uint32_t inside = 0;
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i) {
		if (!(front & (1u << i)))
			continue;
		Eigen::Vector2d uv;
		if (camera_.project(pose.apply(target_.points_mm[i]), &uv) &&
		    camera_.inImage(uv, margin_px))
			inside |= 1u << i;
	}
	return inside;
}

double Correspondence::sizePx(const Pose &pose) const
{
	const double z = std::max(pose.apply(centroid_mm_).z(), 1.0);
	return camera_.intrinsics().fx * diameter_mm_ / z;
}

double Correspondence::gatePx(const Pose &pose) const
{
	return std::clamp(config_.gate_frac * sizePx(pose), config_.gate_px,
			  std::max(config_.gate_px, 30.0));
}

/*
 * Project every model LED in front of the camera and take the nearest usable
 * candidate within the gate; a candidate claimed twice goes to the nearer LED.
 */
int Correspondence::matchPredicted(const Pose &pose, double gate_px, Match *match) const
{
	std::array<int, kMaxCandidates> owner;
	std::array<double, kMaxCandidates> owner_d2;
	owner.fill(-1);
	owner_d2.fill(0.0);
	std::array<int, kMaxLeds> choice;
	choice.fill(-1);
	const double gate2 = gate_px * gate_px;
	const std::uint32_t front = frontLeds(pose);
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i) {
		Eigen::Vector2d uv;
		if (!(front & (1u << i)))
			continue;
		if (!camera_.project(pose.apply(target_.points_mm[i]), &uv) ||
		    !camera_.inImage(uv, -gate_px))
			continue;
		int best = -1;
		double best_d2 = gate2;
		forCandidatesNear(uv.x(), gate_px, [&](int j) {
			const double d2 = (px_[j] - uv).squaredNorm();
			/* The nearest; of equals the first candidate, as in index order. */
			if (d2 < best_d2 || (d2 == best_d2 && best >= 0 && j < best)) {
				best_d2 = d2;
				best = j;
			}
			return false;
		});
		if (best < 0)
			continue;
		if (owner[best] >= 0) {
			if (owner_d2[best] <= best_d2)
				continue;
			choice[owner[best]] = -1;
		}
		owner[best] = static_cast<int>(i);
		owner_d2[best] = best_d2;
		choice[i] = best;
	}
	match->pairs.clear();
	match->led_mask = 0;
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i)
		if (choice[i] >= 0) {
			match->pairs.push_back({ static_cast<std::int8_t>(i),
						 static_cast<std::int8_t>(choice[i]) });
			match->led_mask |= 1u << i;
		}
	return static_cast<int>(match->pairs.size());
}

/*
 * The LEDs other than own_leds, predicted by the pose on a face that faces
 * the camera and inside the frame, that have a usable candidate other than
 * own_candidates within gate_px: how many, and for each the smallest
 * centroid variance (major axis, px^2) among its candidates there, appended
 * to var_px2. An upper bound of what matchPredicted() adds to a P3P pose's
 * three points (two LEDs may claim one candidate here): the screen before a
 * triangle's pose is verified.
 */
int Correspondence::moreLedsOnCandidates(const Pose &pose, double gate_px, std::uint32_t own_leds,
					 std::uint64_t own_candidates,
					 StaticVector<double, kMaxLeds> *var_px2) const
{
	const std::uint32_t front = frontLeds(pose) & ~own_leds;
	const double gate2 = gate_px * gate_px;
	int found = 0;
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i) {
		if (!(front & (1u << i)))
			continue;
		Eigen::Vector2d uv;
		if (!camera_.project(pose.apply(target_.points_mm[i]), &uv) ||
		    !camera_.inImage(uv, -gate_px))
			continue;
		double var = std::numeric_limits<double>::max();
		forCandidatesNear(uv.x(), gate_px, [&](int j) {
			if (!(own_candidates & (std::uint64_t{ 1 } << j)) &&
			    (px_[j] - uv).squaredNorm() < gate2)
				var = std::min(var, var_[j]);
			return false;
		});
		if (var == std::numeric_limits<double>::max())
			continue;
		++found;
		if (!var_px2->full())
			var_px2->push_back(var);
	}
	return found;
}

/*
 * The smallest log10 NFA (log10Nfa()) a triangle's pose could reach with
 * the LEDs whose candidates have these centroid variances: every tolerance
 * at its floor (twice the centroid's sigma), the density the frame's
 * candidates alone give, every combinatorial factor at 1. Allocates: never.
 */
double Correspondence::log10NfaFloor(StaticVector<double, kMaxLeds> var_px2) const
{
	const int k = static_cast<int>(var_px2.size());
	if (k < 4)
		return 0.0;
	std::sort(var_px2.begin(), var_px2.end());
	std::array<double, kMaxLeds> tol2{};
	for (int i = 0; i < k; ++i)
		tol2[static_cast<std::size_t>(i)] = 4.0 * var_px2[static_cast<std::size_t>(i)];
	const CameraIntrinsics &intr = camera_.intrinsics();
	const double rho = n_cand_ / (static_cast<double>(intr.width) * intr.height);
	return bestSubsetLog10Nfa(tol2.data(), k, -1, rho, log10_triangle_tests_);
}

/* Refine over the hypothesis's current matches (the covariance only when asked for). */
bool Correspondence::refineMatched(const Pose &initial, Hypothesis *h, bool covariance) const
{
	const int n = static_cast<int>(h->match.pairs.size());
	if (n < 3)
		return false;
	std::array<Eigen::Vector3d, kMaxLeds> model;
	std::array<Eigen::Vector2d, kMaxLeds> pixels;
	std::array<Eigen::Matrix2d, kMaxLeds> cov;
	for (int k = 0; k < n; ++k) {
		model[k] = target_.points_mm[h->match.pairs[k][0]];
		pixels[k] = px_[h->match.pairs[k][1]];
		cov[k] = cov_[h->match.pairs[k][1]];
	}
	RefineOptions options = config_.refine;
	options.covariance = covariance;
	options.led_sigma_mm = target_.led_sigma_mm;
	/* A copy: initial may alias h->refined.pose, which refinePose() resets. */
	const Pose start = initial; // NOLINT(performance-unnecessary-copy-initialization)
	return refinePose(camera_, model.data(), pixels.data(), n, start, options, &h->refined,
			  cov.data());
}

/*
 * From an initial pose: match with a first (wider) gate, refine, match again
 * with the normal gate, refine; then count what the pose predicts. Fails as
 * soon as fewer than min_matches LEDs match. With covariance, every
 * refinement gives the pose's covariance too (and fails where it is not
 * determined): the tracked match, usually refined once, needs no second run.
 */
bool Correspondence::refineMatch(const Pose &initial, double first_gate_px, int min_matches,
				 Hypothesis *h, bool covariance) const
{
	if (matchPredicted(initial, first_gate_px, &h->match) < min_matches)
		return false;
	if (!refineMatched(initial, h, covariance))
		return false;
	Pose pose = h->refined.pose;
	for (int round = 0; round < 2; ++round) {
		Match again;
		if (matchPredicted(pose, gatePx(pose), &again) < min_matches)
			return false;
		const bool changed =
			again.led_mask != h->match.led_mask ||
			!std::equal(again.pairs.begin(), again.pairs.end(), h->match.pairs.begin());
		if (!changed)
			break;
		h->match = again;
		if (!refineMatched(pose, h, covariance))
			return false;
		pose = h->refined.pose;
	}
	/*
	 * A clutter blob next to an LED's prediction can take its place and
	 * pull the fit into a wrong minimum: while the error is too large, drop
	 * the worst match, refine, and match again.
	 */
	for (int drop = 0; drop < 3 && h->refined.rms_px > config_.max_rms_px &&
			   static_cast<int>(h->match.pairs.size()) > min_matches;
	     ++drop) {
		std::size_t worst = 0;
		double worst_d2 = -1.0;
		for (std::size_t k = 0; k < h->match.pairs.size(); ++k) {
			Eigen::Vector2d uv;
			if (!camera_.project(pose.apply(target_.points_mm[h->match.pairs[k][0]]),
					     &uv))
				return false;
			const double d2 = (uv - px_[h->match.pairs[k][1]]).squaredNorm();
			if (d2 > worst_d2) {
				worst_d2 = d2;
				worst = k;
			}
		}
		Hypothesis trial = *h;
		const auto dropped = trial.match.pairs[worst];
		removePair(&trial.match, worst);
		if (!refineMatched(pose, &trial, covariance))
			break;
		/*
		 * Re-match from the cleaner pose: the LED may find its own blob now.
		 * Not the blob it was dropped from: within the gate, the nearest
		 * one comes straight back (an LED merged with a reflection, a spot
		 * pulled off its LED), and the trial would only repeat the fit.
		 */
		Match again;
		if (matchPredicted(trial.refined.pose, gatePx(trial.refined.pose), &again) >=
		    min_matches) {
			for (std::size_t k = 0; k < again.pairs.size(); ++k)
				if (again.pairs[k] == dropped) {
					removePair(&again, k);
					break;
				}
		}
		if (static_cast<int>(again.pairs.size()) >= min_matches) {
			trial.match = again;
			if (!refineMatched(trial.refined.pose, &trial, covariance))
				break;
		}
		/*
		 * Better in pixels; and a fit that its centroids' covariance
		 * explains keeps its LEDs (the drop is for an error too large).
		 */
		if (trial.refined.rms_px >= h->refined.rms_px ||
		    (trial.match.pairs.size() < h->match.pairs.size() && errorExplained(*h, 1.0)))
			break;
		*h = trial;
		pose = h->refined.pose;
	}
	const std::uint32_t predicted = predictedLeds(h->refined.pose, 0.0);
	h->expected = __builtin_popcount(predicted);
	h->missing = __builtin_popcount(predicted & ~h->match.led_mask);
	h->log10_nfa = log10Nfa(*h);
	return true;
}

/*
 * log10 of the number of hypotheses one family of the full search can form
 * from this frame's candidates: every candidate anchors the quadrilaterals of
 * three of its neighbours (4 assignments to each face: of the 8, the 4 that go
 * round the other way would see the face from behind and are never formed),
 * once among every candidate and once among the clipped spots alone
 * (searchQuads()), or the triangles of two, as well once among each
 * (searchTriangles(); for each face, 4 hidden vertices;
 * 3 assignments, the one direction round that sees the face from its front;
 * 2 starts; and 2 poses per assignment, P3P's mean number of solutions on the
 * cold-search benchmark's frames, of up to 4). Duplicates are counted, so
 * this bounds the search from above, as does C(candidates, 4) for the
 * quadrilaterals, each set of four formed at most once; the factor 2 shares
 * the false-alarm budget between the two families.
 */
double Correspondence::log10Tests(bool triangles) const
{
	const int candidates = std::max(n_cand_, context_.frame_candidates);
	const double faces = static_cast<double>(target_.faces.size());
	auto quads = [&](int members) {
		const double m = members;
		const double k = std::min(config_.neighbours, std::max(members - 1, 0));
		return m * k * (k - 1.0) * (k - 2.0) / 6.0 * faces * 4.0;
	};
	auto triangles_of = [&](int members) {
		const double m = members;
		const double k = std::min(config_.triangle_neighbours, std::max(members - 1, 0));
		return m * 0.5 * k * (k - 1.0) * faces * 48.0;
	};
	/*
	 * The clipped spots' pass of either family counts as a second one over
	 * every candidate where they are not known (windows: the last whole
	 * frame's candidates are counted, not its clipped ones).
	 */
	auto with_second = [&](auto &&family, bool clipped_runs) {
		double second = 0.0;
		if (candidates > n_cand_)
			second = family(candidates);
		else if (clipped_runs)
			second = family(std::popcount(clipped_bits_));
		return family(candidates) + second;
	};
	/* Each set of four is formed once, in one pass or the other. */
	const double n =
		triangles ? with_second(triangles_of, clippedTriangles())
			  : std::min(with_second(quads, clippedPass()),
				     std::pow(10.0, log10Choose(candidates, 4)) * faces * 4.0);
	return std::log10(2.0 * std::max(n, 1.0));
}

/*
 * The a-contrario number of false alarms of a verified hypothesis (see the
 * header): how many of the hypotheses this frame allows would, by chance,
 * be explained as well by candidates scattered at this frame's density.
 */
double Correspondence::log10Nfa(const Hypothesis &h) const
{
	const int k = static_cast<int>(h.match.pairs.size());
	if (k < 4)
		return 0.0;
	const int n = std::max(h.expected, k);
	const CameraIntrinsics &intr = camera_.intrinsics();
	const double frame_area = static_cast<double>(intr.width) * intr.height;

	/*
	 * Each matched LED's tolerance: its residual (inflated: the fit absorbs 6
	 * of the 2k coordinates), never below twice its centroid's sigma; and the
	 * matched blobs' extent.
	 */
	const double inflate2 = 2.0 * k / (2.0 * k - 6.0);
	std::array<double, kMaxLeds> tol2{};
	Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::max());
	Eigen::Vector2d hi = -lo;
	std::uint64_t matched = 0;
	for (std::size_t i = 0; i < h.match.pairs.size(); ++i) {
		const auto &pair = h.match.pairs[i];
		Eigen::Vector2d uv;
		if (!camera_.project(h.refined.pose.apply(target_.points_mm[pair[0]]), &uv))
			return 0.0;
		const int j = static_cast<std::uint8_t>(pair[1]); /* a candidate index, 0..63 */
		tol2[i] = std::max((uv - px_[j]).squaredNorm() * inflate2, 4.0 * var_[j]);
		lo = lo.cwiseMin(px_[j]);
		hi = hi.cwiseMax(px_[j]);
		matched |= std::uint64_t{ 1 } << j;
	}
	std::sort(tol2.begin(), tol2.begin() + k);

	/*
	 * Density: the frame's candidates, or the unmatched ones in a window of
	 * three times the target's extent around it, whichever is denser. When
	 * only windows were read (context_), the unmatched blobs in them over
	 * their area, or the last whole frame's candidates.
	 */
	const bool windows = context_.window_area_px2 > 0.0;
	const double extent = std::max({ hi.x() - lo.x(), hi.y() - lo.y(), 1.0 });
	const double x0 = std::max(lo.x() - extent, -0.5),
		     x1 = std::min(hi.x() + extent, intr.width - 0.5);
	const double y0 = std::max(lo.y() - extent, -0.5),
		     y1 = std::min(hi.y() + extent, intr.height - 0.5);
	int local = 0;
	for (std::size_t j = 0; j < px_.size(); ++j)
		if (usable_[j] && !(matched & (std::uint64_t{ 1 } << j)) &&
		    (windows || (px_[j].x() >= x0 && px_[j].x() <= x1 && px_[j].y() >= y0 &&
				 px_[j].y() <= y1)))
			++local;
	const double local_area = windows ? context_.window_area_px2
					  : std::max((x1 - x0) * (y1 - y0), 1.0);
	const double frame_count = windows ? context_.frame_candidates : n_cand_;
	const double rho = std::max(frame_count / frame_area, local / local_area);

	/*
	 * The evidence of the best m of the k matched LEDs (m >= 4), as
	 * a-contrario RANSAC counts it: a tolerance common to the m tightest
	 * LEDs, each further one a chance hit within it with probability p, and
	 * the choice of m one more factor (k - 3). One imprecise LED (a bloomed,
	 * clipped spot with a sigma of pixels) then weakens only its own share of
	 * the evidence: with a single tolerance for all k, it made the true box
	 * corner's six-LED pose (log10 NFA +1.5) lose to a half-turned five-LED one
	 * that left that spot out (-9.1).
	 */
	const double tests = (h.from_triangle ? log10_triangle_tests_ : log10_quad_tests_) +
			     std::log10(static_cast<double>(k - 3));
	const double search = bestSubsetLog10Nfa(tol2.data(), k, n, rho, tests);
	if (!h.tracked)
		return search;
	/* The prediction's window: one test, every matched LED a chance hit in it. */
	const double pw = -std::expm1(-rho * kPi * h.track_gate_px * h.track_gate_px);
	const double window = log10Choose(n, k) + k * std::log10(std::max(pw, 1e-300));
	return std::log10(2.0) + std::min(search, window);
}

/*
 * LEDs a pose needs: min_leds_search for the full search (never more than the
 * model has), min_leds_track when the tracked prediction supports it.
 */
int Correspondence::minLeds(bool tracking) const
{
	const int total = static_cast<int>(target_.points_mm.size());
	return std::max(4, std::min(tracking ? config_.min_leds_track : config_.min_leds_search,
				    total));
}

/* The 99.9 % point of chi2 for a fit's 2k - 6 degrees of freedom, k points (Wilson-Hilferty). */
double Correspondence::chi2Bound(int points)
{
	const double dof = std::max(2.0 * static_cast<double>(points) - 6.0, 1.0);
	const double c = 2.0 / (9.0 * dof);
	return dof * std::pow(1.0 - c + 3.09 * std::sqrt(c), 3.0);
}

/*
 * A fit accepted on max_rms_px whose chi2 lies beyond its 99.9 % point has
 * residuals its centroids' covariance does not explain: its own covariance
 * is scaled by what the residuals say (chi2 / dof, the Birge ratio), so that
 * the precision limit and the reported sigmas see that error too. Within
 * the point it is left as propagated (a right fit's chi2 / dof scatters
 * about 1).
 */
void Correspondence::scaleUnexplained(int points, RefineResult *refined)
{
	if (!(refined->chi2 > chi2Bound(points)))
		return;
	const double dof = std::max(2.0 * static_cast<double>(points) - 6.0, 1.0);
	refined->covariance *= refined->chi2 / dof;
}

/* The residuals are what the centroids' covariance predicts (chi2 within its 99.9 % point, x slack^2). */
bool Correspondence::fitStatistical(const Hypothesis &h, double slack) const
{
	return h.refined.chi2 <= slack * slack * chi2Bound(static_cast<int>(h.match.pairs.size()));
}

/*
 * The error measure (method.md section 6): the residuals must be what the
 * centroids' noise explains. Small in pixels (max_rms_px), or within the
 * 99.9% point of chi^2 under the points' covariances, scaled by `slack`.
 */
bool Correspondence::errorExplained(const Hypothesis &h, double slack) const
{
	return h.refined.rms_px <= slack * config_.max_rms_px || fitStatistical(h, slack);
}

bool Correspondence::acceptable(const Hypothesis &h) const
{
	return static_cast<int>(h.match.pairs.size()) >= minLeds(h.tracked) &&
	       h.missing <= config_.max_missing && errorExplained(h, 1.0) && h.refined.converged &&
	       plausible(h.refined.pose) && h.log10_nfa <= config_.max_log10_nfa;
}

/*
 * Can `other` stand beside `chosen`? Acceptable but for the false-alarm
 * bound, which is relaxed to ambiguity_margin decades above the chosen
 * pose's, and the error, within the bound or twice the chosen pose's (four
 * times the bound for a pose that explains more LEDs than the chosen one):
 * two explanations that close cannot be told apart, wherever the bounds
 * happen to fall between them.
 */
bool Correspondence::rival(const Hypothesis &other, const Hypothesis &chosen) const
{
	/*
	 * When the chosen pose fits as its centroids' covariance predicts, a
	 * competitor must fit comparably: chi2 within the bound or 4x the chosen
	 * pose's (2x its error). The px floor (max_rms_px) stands in for the
	 * covariance only when the chosen pose does not fit it either (blooms,
	 * a lens model off): a 0.6 px residual is 40 sigma for a sharp spot.
	 */
	const bool comparable = fitStatistical(chosen, 1.0)
					? fitStatistical(other, 1.0) ||
						  other.refined.chi2 <= 4.0 * chosen.refined.chi2
					: errorExplained(other, 1.0) ||
						  other.refined.rms_px <=
							  2.0 * chosen.refined.rms_px;
	return static_cast<int>(other.match.pairs.size()) >= minLeds(other.tracked) &&
	       other.missing <= config_.max_missing &&
	       (other.match.pairs.size() > chosen.match.pairs.size() ? errorExplained(other, 4.0)
								     : comparable) &&
	       other.refined.converged && plausible(other.refined.pose) &&
	       other.log10_nfa <=
		       std::max(config_.max_log10_nfa, chosen.log10_nfa + config_.ambiguity_margin);
}

/*
 * The largest log10 NFA of a hypothesis that can still matter: acceptable,
 * or a rival of an accepted pose (rival(): within ambiguity_margin of it).
 */
double Correspondence::rivalLog10Nfa() const
{
	return config_.max_log10_nfa + std::max(config_.ambiguity_margin, 0.0);
}

/* Acceptable first; then more LEDs explained; then fewer false alarms; then lower error. */
bool Correspondence::better(const Hypothesis &a, const Hypothesis &b) const
{
	const bool aa = acceptable(a), ab = acceptable(b);
	if (aa != ab)
		return aa;
	const int na = static_cast<int>(a.match.pairs.size()),
		  nb = static_cast<int>(b.match.pairs.size());
	if (na != nb)
		return na > nb;
	if (a.log10_nfa != b.log10_nfa)
		return a.log10_nfa < b.log10_nfa;
	return a.refined.rms_px < b.refined.rms_px;
}

bool Correspondence::samePose(const Pose &a, const Pose &b) const
{
	const double range = std::max(a.t_mm.norm(), 1.0);
	return rotationAngleDeg(a.R, b.R) < 1.0 && (a.t_mm - b.t_mm).norm() < 0.01 * range + 0.5;
}

/* All matched LEDs on one face's plane? (Then a mirror pose may fit as well.) */
bool Correspondence::planarMatch(const Match &match) const
{
	if (match.pairs.size() < 3)
		return true;
	const double tol = 1e-3 * diameter_mm_;
	/* Plane through the first three non-collinear matched LEDs. */
	const Eigen::Vector3d a = target_.points_mm[match.pairs[0][0]];
	for (std::size_t i = 1; i < match.pairs.size(); ++i)
		for (std::size_t j = i + 1; j < match.pairs.size(); ++j) {
			const Eigen::Vector3d n =
				(target_.points_mm[match.pairs[i][0]] - a)
					.cross(target_.points_mm[match.pairs[j][0]] - a);
			if (n.norm() < tol * diameter_mm_)
				continue;
			const Eigen::Vector3d u = n.normalized();
			for (const auto &pair : match.pairs)
				if (std::abs(u.dot(target_.points_mm[pair[0]] - a)) > tol)
					return false;
			return true;
		}
	return true;
}

/*
 * A planar set of points seen in perspective has, beside the true pose, a
 * second local minimum: the plane tilted the other way about the line of
 * sight. When every matched LED lies in one plane, start a refinement from
 * that mirror and see whether it explains the same points as well; if it
 * does, the pose is ambiguous and must not be reported.
 */
bool Correspondence::planarFlipExplains(const Hypothesis &h) const
{
	const Pose &pose = h.refined.pose;
	Eigen::Vector3d centre = Eigen::Vector3d::Zero();
	for (const auto &pair : h.match.pairs)
		centre += target_.points_mm[pair[0]];
	centre /= static_cast<double>(h.match.pairs.size());
	const Eigen::Vector3d a = target_.points_mm[h.match.pairs[0][0]];
	Eigen::Vector3d n = Eigen::Vector3d::Zero();
	for (std::size_t i = 1; i + 1 < h.match.pairs.size() && n.norm() < 1e-9; ++i)
		n = (target_.points_mm[h.match.pairs[i][0]] - a)
			    .cross(target_.points_mm[h.match.pairs[i + 1][0]] - a);
	if (n.norm() < 1e-9)
		return true;
	const Eigen::Vector3d v = pose.apply(centre).normalized();
	const Eigen::Vector3d nc = (pose.R * n).normalized();
	if (std::abs(nc.dot(v)) >
	    std::cos(0.25 * kPi / 180.0)) /* head-on: the two minima coincide */
		return false;
	const Pose start = mirrorPose(pose, centre, n.normalized());
	Hypothesis other;
	other.match = h.match;
	if (!refineMatched(start, &other, false))
		return false;
	if (samePose(other.refined.pose, pose))
		return false;
	return other.refined.converged &&
	       other.refined.rms_px <= std::max(config_.max_rms_px, 1.5 * h.refined.rms_px);
}

/*
 * Among the poses equivalent under the target's symmetries, take the one
 * closest in rotation to the reference (the tracked pose), else to the
 * model's own orientation; permute the matches accordingly and refine again
 * so the covariance belongs to the reported pose.
 */
bool Correspondence::canonicalise(const Pose *reference, Hypothesis *h) const
{
	if (symmetries_.size() < 2)
		return false;
	const Eigen::Matrix3d ref = reference ? reference->R : Eigen::Matrix3d::Identity();
	std::size_t best = 0;
	double best_angle = std::numeric_limits<double>::max();
	for (std::size_t k = 0; k < symmetries_.size(); ++k) {
		const Eigen::Matrix3d R = h->refined.pose.R * symmetries_[k].transform.R;
		const double angle = rotationAngleDeg(R, ref);
		if (angle < best_angle - 1e-9) {
			best_angle = angle;
			best = k;
		}
	}
	if (best == 0)
		return false;
	const Symmetry &s = symmetries_[best];
	/* P' = P o S: LED i of P' sits where LED perm[i] sits for P. */
	std::array<int, kMaxLeds> inverse;
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i)
		inverse[s.perm[i]] = static_cast<int>(i);
	Pose start;
	start.R = h->refined.pose.R * s.transform.R;
	start.t_mm = h->refined.pose.R * s.transform.t_mm + h->refined.pose.t_mm;
	Match permuted;
	for (const auto &pair : h->match.pairs) {
		const int led = inverse[pair[0]];
		permuted.pairs.push_back({ static_cast<std::int8_t>(led), pair[1] });
		permuted.led_mask |= 1u << led;
	}
	/* By LED, as matchPredicted() lists them (insertion: at most kMaxLeds). */
	for (std::size_t i = 1; i < permuted.pairs.size(); ++i)
		for (std::size_t j = i; j > 0 && permuted.pairs[j - 1][0] > permuted.pairs[j][0];
		     --j)
			std::swap(permuted.pairs[j - 1], permuted.pairs[j]);
	Hypothesis moved = *h;
	moved.match = permuted;
	if (!refineMatched(start, &moved, false))
		return false;
	h->match = moved.match;
	h->refined = moved.refined;
	return true;
}

/* Keep the best few distinct hypotheses (for the ambiguity test). */
void Correspondence::keep(const Hypothesis &h)
{
	for (auto &k : kept_)
		if (k.match.led_mask == h.match.led_mask &&
		    std::equal(k.match.pairs.begin(), k.match.pairs.end(), h.match.pairs.begin())) {
			if (better(h, k))
				k = h;
			return;
		}
	if (!kept_.full()) {
		kept_.push_back(h);
		return;
	}
	std::size_t worst = 0;
	for (std::size_t i = 1; i < kept_.size(); ++i)
		if (better(kept_[worst], kept_[i]))
			worst = i;
	if (better(h, kept_[worst]))
		kept_[worst] = h;
}

/*
 * The shape screen of one assignment of four image points (normalised q, their
 * quadDeterminants() D) to the vertices of face f (quad_assignments_),
 * exact under perspective: the depths the image implies, and the six side
 * lengths they give. True when the face could be seen so.
 */
bool Correspondence::quadShape(const Eigen::Vector2d q[4], const double D[4], std::size_t f,
			       int assignment) const
{
	const QuadAssignment &qa = quad_assignments_[f][static_cast<std::size_t>(assignment)];
	/*
	 * The depths Z_m ∝ D_(m)/A_(m). With A signed about the face's front
	 * normal, det[P_i P_j P_k] = 2 A (n . P_i) and n . P_i < 0 when the
	 * camera sees the front: so D/A < 0 for all four exactly when the face
	 * is seen from its front. Any other sign pattern is rejected here.
	 */
	double Z[4];
	for (int m = 0; m < 4; ++m) {
		Z[m] = -D[m] / qa.area[m];
		if (!(Z[m] > 0.0) || !std::isfinite(Z[m]))
			return false;
	}
	/* ... and reproduce the face's six side lengths up to one scale. */
	double sdl = 0.0, sdd = 0.0, d_ij[6];
	int e = 0;
	for (int i = 0; i < 4; ++i)
		for (int j = i + 1; j < 4; ++j, ++e) {
			const Eigen::Vector3d pi{ q[i].x() * Z[i], q[i].y() * Z[i], Z[i] };
			const Eigen::Vector3d pj{ q[j].x() * Z[j], q[j].y() * Z[j], Z[j] };
			d_ij[e] = (pi - pj).norm();
			sdl += d_ij[e] * qa.side[e];
			sdd += d_ij[e] * d_ij[e];
		}
	const double scale = sdl / sdd;
	double res = 0.0;
	for (int k = 0; k < 6; ++k)
		res += (scale * d_ij[k] - qa.side[k]) * (scale * d_ij[k] - qa.side[k]);
	return res <= 0.04 * qa.sides2;
}

/* The determinants quadShape() divides, of a quadrilateral's image points: det[q_i q_j q_l]. */
void Correspondence::quadDeterminants(const Eigen::Vector2d q[4], double D[4])
{
	for (int m = 0; m < 4; ++m) {
		const int i = (m + 1) % 4, j = (m + 2) % 4, l = (m + 3) % 4;
		D[m] = cross2(q[j] - q[i], q[l] - q[i]); /* with unit third row */
	}
}

/* Assignment a = 4 (dir + 1) / 2 + rot: image point k on face-local vertex (rot + dir k) mod 4. */
void Correspondence::findQuadAssignments()
{
	for (std::size_t f = 0; f < target_.faces.size(); ++f) {
		std::array<QuadAssignment, 8> table{};
		for (int dir = -1; dir <= 1; dir += 2)
			for (int rot = 0; rot < 4; ++rot) {
				const int assignment = 4 * (dir + 1) / 2 + rot;
				QuadAssignment &qa = table[static_cast<std::size_t>(assignment)];
				Eigen::Vector2d plane[4];
				for (int k = 0; k < 4; ++k) {
					qa.vertex[k] = ((rot + dir * k) % 4 + 4) % 4;
					plane[k] = face_plane_[f][qa.vertex[k]];
				}
				for (int m = 0; m < 4; ++m) {
					const int i = (m + 1) % 4, j = (m + 2) % 4, l = (m + 3) % 4;
					qa.area[m] =
						cross2(plane[j] - plane[i], plane[l] - plane[i]);
				}
				int e = 0;
				qa.sides2 = 0.0;
				for (int i = 0; i < 4; ++i)
					for (int j = i + 1; j < 4; ++j, ++e) {
						qa.side[e] = (plane[i] - plane[j]).norm();
						qa.sides2 += qa.side[e] * qa.side[e];
					}
			}
		quad_assignments_.push_back(table);
	}
}

/*
 * One assignment that passed quadShape() (image point k: candidate
 * candidate[k] on face-local vertex[k]): the closed-form pose, then
 * verification; true when it is good enough to stop the search.
 */
bool Correspondence::tryAssignment(const int candidate[4], std::size_t f, const int vertex[4])
{
	Eigen::Vector2d q[4], uv[4];
	Eigen::Matrix2d cov[4];
	Eigen::Vector3d model[4];
	for (int k = 0; k < 4; ++k) {
		const int c = candidate[k];
		q[k] = xy_[c];
		uv[k] = px_[c];
		cov[k] = cov_[c];
		model[k] = target_.points_mm[target_.faces[f][vertex[k]]];
	}
	Pose pose;
	if (!solveFourCoplanar(model, q, &pose))
		return false;
	return verify(pose, f, model, uv, cov);
}

/*
 * The mirror of a pose about the line of sight to a plane through centre_t
 * with normal normal_t (target frame): the plane tilted the other way, the
 * second minimum of a planar set seen in perspective.
 */
Pose Correspondence::mirrorPose(const Pose &pose, const Eigen::Vector3d &centre_t,
				const Eigen::Vector3d &normal_t)
{
	const Eigen::Vector3d c = pose.apply(centre_t);
	const Eigen::Vector3d v = c.normalized();
	const Eigen::Vector3d nc = (pose.R * normal_t).normalized();
	const Eigen::Vector3d mirrored = 2.0 * nc.dot(v) * v - nc;
	const Eigen::Matrix3d flip =
		Eigen::Quaterniond::FromTwoVectors(nc, mirrored).toRotationMatrix();
	Pose out;
	out.R = flip * pose.R;
	out.t_mm = c - flip * (c - pose.t_mm);
	return out;
}

/* The checks every hypothesis pose goes through, then verification; true: stop the search. */
bool Correspondence::verify(const Pose &pose, std::size_t f, const Eigen::Vector3d model[4],
			    const Eigen::Vector2d uv[4], const Eigen::Matrix2d cov[4])
{
	if (!faceVisible(pose, f) || !plausible(pose))
		return false;
	/* The pose must reproject its own points. */
	const double gate = gatePx(pose);
	for (int k = 0; k < 4; ++k) {
		Eigen::Vector2d p;
		if (!camera_.project(pose.apply(model[k]), &p) ||
		    (p - uv[k]).squaredNorm() > 4.0 * gate * gate)
			return false;
	}

	if (verified_ >= config_.max_verifications)
		return false;
	/*
	 * The face's own four points first: a closed-form pose may be too rough
	 * for the normal gate far from the face, so it is matched with a wider
	 * one; but a wide gate also takes a clutter blob near a predicted LED (47
	 * px off a wedge's far LED at 372 mm), and the fit it pulls can settle in
	 * the face's other minimum, leaving the field to its in-plane half turn.
	 * Refined on its own points and fitting them, the pose gets the normal gate.
	 *
	 * Four points that are this face fit it as their centroids' noise (or the
	 * px floor) allows. When the fit converged and its error is beyond the
	 * loosest bound any kept hypothesis is held to (a rival with more LEDs:
	 * 4 max_rms_px, or chi2 16 times its 99.9 % point), the quadrilateral is
	 * not the face and is not verified: most chance quadrilaterals that pass
	 * the invariant screen end here, before matching and refinement.
	 */
	Pose start = pose;
	double first_gate = 2.0 * gate;
	RefineOptions own_options = config_.refine;
	own_options.covariance = false;
	own_options.led_sigma_mm = target_.led_sigma_mm;
	RefineResult own;
	if (refinePose(camera_, model, uv, 4, pose, own_options, &own, cov) && own.converged) {
		constexpr double kLoosest = 4.0; /* rival()'s slack for a pose with more LEDs */
		if (own.rms_px > kLoosest * config_.max_rms_px &&
		    own.chi2 > kLoosest * kLoosest * chi2Bound(4))
			return false;
		if (own.rms_px <= config_.max_rms_px) {
			start = own.pose;
			first_gate = gatePx(start);
		}
	}
	++verified_;
	Hypothesis h;
	if (!refineMatch(start, first_gate, minLeds(false), &h))
		return false;
	keep(h);
	return earlyExit(h);
}

/*
 * Stop early once a pose is so certain that no chance competitor can come
 * close, and it fits as its centroids' covariance predicts: a pose that fits
 * only within the px floor may be a near-congruent copy of the true one (a
 * box corner half-turned fits six LEDs within 0.6 px at 30 px across), which
 * the competitors generated afterwards (near-congruences, the planar mirror)
 * do not always reach from there.
 *
 * Such a pose that leaves a candidate unexplained near the target
 * (nearTarget()) may still be a near-congruent copy of a pose that explains
 * it as well: on a far box corner, five of six spots fit a wrong pose as
 * their covariance predicts (log10 NFA -8.3) two hypotheses before the true
 * pose explains all six (-15). Then the search goes on, but only over the
 * hypotheses formed from candidates near the target (focus_): the true pose's
 * spots lie there, which is what the test assumed, and a rival elsewhere is a
 * chance match the bound below the margin already answers. A pose on every
 * LED of the model stops the search whatever lies near it: no competitor can
 * explain more, and its near-congruent copies on the same spots are
 * generated afterwards (addCompetitors()). In clutter this skips most of the
 * budget a frame with its pose found would have spent.
 */
bool Correspondence::earlyExit(const Hypothesis &h)
{
	if (!acceptable(h) || !fitStatistical(h, 1.0) || h.log10_nfa > early_exit_log10_nfa_)
		return false;
	if (h.match.pairs.size() == target_.points_mm.size())
		return true;
	std::uint64_t used = 0;
	for (const auto &pair : h.match.pairs)
		used |= std::uint64_t{ 1 } << static_cast<std::uint8_t>(pair[1]);
	const std::uint64_t near = nearTarget(h);
	if ((near & ~used) == 0)
		return true;
	focus_ = focused_ ? (focus_ | near) : near;
	focused_ = true;
	return false;
}

/*
 * The candidates near the target in the image (bits: candidate indices):
 * inside the bounding box of the hypothesis's matched spots and of every
 * model LED projected, widened by half its size on each side (by the gate
 * at least).
 */
std::uint64_t Correspondence::nearTarget(const Hypothesis &h) const
{
	if (h.match.pairs.empty())
		return 0;
	const double gate = gatePx(h.refined.pose);
	Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::max());
	Eigen::Vector2d hi = -lo;
	for (const auto &pair : h.match.pairs) {
		const std::size_t j =
			static_cast<std::uint8_t>(pair[1]); /* a candidate index, 0..63 */
		lo = lo.cwiseMin(px_[j]);
		hi = hi.cwiseMax(px_[j]);
	}
	for (const Eigen::Vector3d &point : target_.points_mm) {
		Eigen::Vector2d uv;
		if (camera_.project(h.refined.pose.apply(point), &uv)) {
			lo = lo.cwiseMin(uv);
			hi = hi.cwiseMax(uv);
		}
	}
	const Eigen::Vector2d margin = (0.5 * (hi - lo)).cwiseMax(Eigen::Vector2d::Constant(gate));
	lo -= margin;
	hi += margin;
	std::uint64_t near = 0;
	forCandidatesNear(0.5 * (lo.x() + hi.x()), 0.5 * (hi.x() - lo.x()), [&](int j) {
		if (px_[j].y() >= lo.y() && px_[j].y() <= hi.y())
			near |= std::uint64_t{ 1 } << j;
		return false;
	});
	return near;
}

/*
 * Each usable candidate's nearest neighbours in undistorted image
 * coordinates (positions in cand_), nearest first, among the candidates of
 * `among` (bits of cand_ positions; candidates outside it get none).
 */
void Correspondence::findNeighbours(std::uint64_t among, NeighbourTable *table) const
{
	table->among = among;
	const int members = std::popcount(among);
	const int k = std::min(config_.neighbours, members - 1);
	for (int a = 0; a < n_cand_; ++a) {
		table->n[a] = 0;
		table->bits[a] = 0;
		if (!(among & (std::uint64_t{ 1 } << a)))
			continue;
		auto &list = table->list[a];
		std::array<double, kMaxCandidates> best_d2;
		int n = 0;
		for (std::uint64_t others = among & ~(std::uint64_t{ 1 } << a); others != 0;
		     others &= others - 1) {
			const int b = std::countr_zero(others);
			const double d2 = (xy_[cand_[a]] - xy_[cand_[b]]).squaredNorm();
			if (n == k && d2 >= best_d2[n - 1])
				continue;
			/* Insert into the sorted list of the k nearest. */
			int pos = n < k ? n++ : n - 1;
			while (pos > 0 && best_d2[pos - 1] > d2) {
				best_d2[pos] = best_d2[pos - 1];
				list[pos] = list[pos - 1];
				--pos;
			}
			best_d2[pos] = d2;
			list[pos] = static_cast<std::int8_t>(b);
		}
		table->n[a] = n;
		for (int i = 0; i < n; ++i)
			table->bits[a] |= std::uint64_t{ 1 } << list[i];
	}
}

/* Does the clipped spots' own pass run: four of them at least, and not every candidate? */
bool Correspondence::clippedPass() const
{
	const int clipped = std::popcount(clipped_bits_);
	return clipped >= 4 && clipped < n_cand_;
}

/*
 * Do the clipped spots' triangles run first: three of them at least, and
 * fewer than the spots that do not clip? Where most spots clip (a sunlit
 * patch, blooms) the clipped ones are no likelier the target's than any
 * others, and their triangles would only take the budget of the search over
 * every candidate.
 */
bool Correspondence::clippedTriangles() const
{
	const int clipped = std::popcount(clipped_bits_);
	return clipped >= 3 && 2 * clipped < n_cand_;
}

/* The first `first` of candidate a's neighbours in `table`, as bits. */
std::uint64_t Correspondence::neighbourBits(const NeighbourTable &table, int a, int first)
{
	if (first >= table.n[a])
		return table.bits[a];
	std::uint64_t bits = 0;
	for (int i = 0; i < first; ++i)
		bits |= std::uint64_t{ 1 } << table.list[a][i];
	return bits;
}

/*
 * Was the candidate set `set` formed over `table` by a search that joins a
 * candidate to its first `first` neighbours (searchQuads(): sets of four,
 * config_.neighbours; searchTriangles(): sets of three,
 * config_.triangle_neighbours)?
 */
bool Correspondence::formedIn(const NeighbourTable &table, std::uint64_t set, int first)
{
	if ((set & table.among) != set)
		return false;
	for (std::uint64_t members = set; members != 0; members &= members - 1) {
		const int x = std::countr_zero(members);
		const std::uint64_t others = set & ~(std::uint64_t{ 1 } << x);
		if ((neighbourBits(table, x, first) & others) == others)
			return true;
	}
	return false;
}

/*
 * The perspective invariant of a quadrilateral in convex order q[0..3]
 * (normalised coordinates): the fractions at which its diagonals cross equal
 * the face's own in an affine view; perspective moves a fraction s along a
 * diagonal whose ends differ in depth by dZ by s (1 - s) dZ / Z <= dZ / 4Z, and
 * dZ / Z <= l tan(theta) for a diagonal of image length l tilted by at most the
 * largest view angle theta. Centroid noise adds about sigma / l. Computed once
 * per quadrilateral; screenQuad() compares it with each face and assignment.
 */
bool Correspondence::quadInvariant(const Eigen::Vector2d q[4], QuadInvariant *inv) const
{
	if (!diagonalCross(q[0], q[1], q[2], q[3], &inv->s, &inv->t))
		return false;
	const double tan_max = tan_view_max_;
	const double sigma = config_.screen_sigma_px / camera_.intrinsics().fx;
	auto tolerance = [&](double l) {
		const double x = l * tan_max;
		if (x >= 1.5)
			return 1.0;
		return 1.25 * 0.25 * x / (1.0 - 0.5 * x) + 4.0 * sigma / std::max(l, 1e-12);
	};
	inv->tol_s = tolerance((q[2] - q[0]).norm());
	inv->tol_t = tolerance((q[3] - q[1]).norm());
	return true;
}

/* The invariant against face f in the assignment vertex[]. */
bool Correspondence::screenQuad(const QuadInvariant &inv, std::size_t f, const int vertex[4]) const
{
	return std::abs(inv.s - diagonal_frac_[f][vertex[0]]) <= inv.tol_s &&
	       std::abs(inv.t - diagonal_frac_[f][vertex[1]]) <= inv.tol_t;
}

/*
 * One candidate set of four (positions in cand_): in convex position,
 * screened against every face in its 8 assignments, the survivors solved and
 * verified. Found: a pose stopped the search; Budget: a budget ran out first.
 */
Correspondence::SetOutcome Correspondence::tryQuadSet(const int members[4])
{
	/* The triangles' share stays theirs (searchTriangles()). */
	const int quad_budget = config_.max_hypotheses - std::min(config_.max_triangle_hypotheses,
								  config_.max_hypotheses / 2);
	if (hypotheses_ >= quad_budget || verified_ >= config_.max_verifications) {
		budget_hit_ = true;
		return SetOutcome::Budget;
	}
	const int idx[4] = { cand_[members[0]], cand_[members[1]], cand_[members[2]],
			     cand_[members[3]] };
	if (!inFocus(idx, 4))
		return SetOutcome::Tried;
	int order[4];
	if (!convexOrder(xy_.data(), idx, order))
		return SetOutcome::Tried;
	Eigen::Vector2d q[4];
	for (int k = 0; k < 4; ++k)
		q[k] = xy_[order[k]];
	QuadInvariant inv;
	if (!quadInvariant(q, &inv))
		return SetOutcome::Tried;
	double D[4];
	quadDeterminants(q, D);
	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		for (int as = 0; as < 8; ++as) {
			const QuadAssignment &qa =
				quad_assignments_[f][static_cast<std::size_t>(as)];
			/*
			 * Seen from the front in one direction round only
			 * (quadShape()'s sign rule, D/A < 0): the other four
			 * assignments are no hypotheses.
			 */
			if (!(D[0] * qa.area[0] < 0.0) || !screenQuad(inv, f, qa.vertex.data()))
				continue;
			++hypotheses_;
			if (quadShape(q, D, f, as) && tryAssignment(order, f, qa.vertex.data()))
				return SetOutcome::Found;
		}
	return SetOutcome::Tried;
}

/*
 * The quadrilaterals among the `pool` strongest candidates first, in the
 * order of their weakest member (PROSAC's): every set of four of them that a
 * pass of searchQuads() forms, no other (strongestTried()), and those passes
 * skip them. The same hypotheses in another order: a target whose LEDs are
 * among the strongest spots is found before every neighbour set of a strong
 * reflection is tried.
 */
bool Correspondence::searchStrongestQuads(int pool)
{
	for (int w = 3; w < pool; ++w)
		for (int a = 0; a < w; ++a)
			for (int b = a + 1; b < w; ++b)
				for (int c = b + 1; c < w; ++c) {
					const std::uint64_t set = (std::uint64_t{ 1 } << a) |
								  (std::uint64_t{ 1 } << b) |
								  (std::uint64_t{ 1 } << c) |
								  (std::uint64_t{ 1 } << w);
					if (!strongestTried(set))
						continue;
					const int members[4] = { a, b, c, w };
					const SetOutcome outcome = tryQuadSet(members);
					if (outcome != SetOutcome::Tried)
						return outcome == SetOutcome::Found;
				}
	return false;
}

/*
 * Is the set one searchStrongestQuads() tries: among the strongest_
 * candidates, and formed by the search over every candidate or by the
 * clipped spots' own pass (when it runs)?
 */
bool Correspondence::strongestTried(std::uint64_t set) const
{
	return (set & ~strongest_) == 0 &&
	       (formedIn(neighbours_, set, config_.neighbours) ||
		(clipped_pass_ && formedIn(clipped_neighbours_, set, config_.neighbours)));
}

/*
 * Quadrilaterals of each candidate and three of its neighbours in `table`,
 * strongest anchors first, each set once (at the strongest member whose
 * neighbours hold the other three; sets `before`'s pass formed are skipped,
 * and those searchStrongestQuads() tried), through tryQuadSet().
 */
bool Correspondence::searchQuads(const NeighbourTable &table, const NeighbourTable *before)
{
	for (int a = 0; a < n_cand_; ++a) {
		const int na = table.n[a];
		const auto &nb = table.list[a];
		for (int i = 0; i < na; ++i)
			for (int j = i + 1; j < na; ++j)
				for (int l = j + 1; l < na; ++l) {
					const int m[3] = { nb[i], nb[j], nb[l] };
					const std::uint64_t set = (std::uint64_t{ 1 } << a) |
								  (std::uint64_t{ 1 } << m[0]) |
								  (std::uint64_t{ 1 } << m[1]) |
								  (std::uint64_t{ 1 } << m[2]);
					bool earlier = false;
					for (int e = 0; e < 3 && !earlier; ++e) {
						const std::uint64_t others =
							set & ~(std::uint64_t{ 1 } << m[e]);
						earlier = m[e] < a &&
							  (table.bits[m[e]] & others) == others;
					}
					if (earlier ||
					    (before &&
					     formedIn(*before, set, config_.neighbours)) ||
					    strongestTried(set))
						continue;
					const int members[4] = { a, m[0], m[1], m[2] };
					const SetOutcome outcome = tryQuadSet(members);
					if (outcome != SetOutcome::Tried)
						return outcome == SetOutcome::Found;
				}
	}
	return false;
}

/*
 * The LEDs a triangle's pose must put on candidates to matter: a pose counts
 * only when it is acceptable and explains more LEDs than every acceptable
 * pose kept so far (better()), or as many (a rival: ambiguity); with none
 * kept, the floor min_leds_search. (Counted at P3P's pose within the normal
 * gate, as the first extra LED always was.) Kept in triangle_leds_ while the
 * search runs: the best acceptable pose is never evicted, so it only grows.
 */
int Correspondence::triangleLeds() const
{
	int leds = minLeds(false);
	for (const auto &h : kept_)
		if (acceptable(h))
			leds = std::max(leds, static_cast<int>(h.match.pairs.size()));
	return leds;
}

/*
 * Three image points (normalised) on three vertices of face f: the poses of
 * P3P, each seen from the face's front, must put one more LED on a candidate
 * before it is verified. True: stop the search.
 */
bool Correspondence::tryTriangle(const TriangleModel &triangle, const Eigen::Vector2d q[3],
				 const P3pDepths &depths, std::uint64_t own_candidates)
{
	++hypotheses_;
	const std::size_t f = triangle.face;
	const std::uint32_t own_leds = triangle.leds;
	Pose poses[4];
	const int n = p3pPoses(triangle.p3p, q, depths, poses);
	StaticVector<double, kMaxLeds> own_var_px2;
	for (std::uint64_t bits = own_candidates; bits != 0; bits &= bits - 1)
		own_var_px2.push_back(var_[static_cast<std::size_t>(std::countr_zero(bits))]);
	for (int k = 0; k < n; ++k) {
		const Pose &pose = poses[k];
		if (!faceVisible(pose, f) || !plausible(pose))
			continue;
		/*
		 * The normal gate: P3P fits its three points exactly, as a refined
		 * pose does (the doubled gate is for the quadrilaterals' rough
		 * closed form); a wider one lets a reflection near a prediction
		 * pull the refinement off the target.
		 */
		const double gate = gatePx(pose);
		StaticVector<double, kMaxLeds> var_px2 = own_var_px2;
		if (moreLedsOnCandidates(pose, gate, own_leds, own_candidates, &var_px2) <
			    triangle_leds_ - 3 ||
		    log10NfaFloor(var_px2) > rivalLog10Nfa() ||
		    verified_ >= config_.max_verifications)
			continue;
		++verified_;
		Hypothesis h;
		h.from_triangle = true;
		if (!refineMatch(pose, gate, minLeds(false), &h))
			continue;
		keep(h);
		if (acceptable(h))
			triangle_leds_ =
				std::max(triangle_leds_, static_cast<int>(h.match.pairs.size()));
		if (earlyExit(h))
			return true;
	}
	return false;
}

/*
 * Faces with one vertex hidden (an occluded LED shared by two faces leaves no
 * face complete): every image triangle of a candidate and two of its
 * neighbours, against every face with each shared vertex missing in turn.
 * Each assignment of the three points to three vertices of the face gives up
 * to four poses (P3P); each is verified like a quadrilateral's.
 */
bool Correspondence::searchTriangles(const NeighbourTable &table, const NeighbourTable *before)
{
	triangle_leds_ = triangleLeds();
	const int budget =
		std::min(config_.max_hypotheses, hypotheses_ + config_.max_triangle_hypotheses);
	for (int a0 = 0; a0 < n_cand_; ++a0) {
		const int na = std::min(table.n[a0], config_.triangle_neighbours);
		const auto &nb = table.list[a0];
		for (int i = 0; i < na; ++i)
			for (int j = i + 1; j < na; ++j) {
				const int m[2] = { nb[i], nb[j] };
				const std::uint64_t set = (std::uint64_t{ 1 } << a0) |
							  (std::uint64_t{ 1 } << m[0]) |
							  (std::uint64_t{ 1 } << m[1]);
				bool earlier = false;
				for (int e = 0; e < 2 && !earlier; ++e) {
					const std::uint64_t others = set &
								     ~(std::uint64_t{ 1 } << m[e]);
					earlier = m[e] < a0 &&
						  (neighbourBits(table, m[e],
								 config_.triangle_neighbours) &
						   others) == others;
				}
				if (earlier ||
				    (before && formedIn(*before, set, config_.triangle_neighbours)))
					continue;
				if (hypotheses_ >= budget ||
				    verified_ >= config_.max_verifications) {
					budget_hit_ = true;
					return false;
				}
				int ti[3] = { cand_[a0], cand_[m[0]], cand_[m[1]] };
				if (!inFocus(ti, 3))
					continue;
				Eigen::Vector2d t[3] = { xy_[ti[0]], xy_[ti[1]], xy_[ti[2]] };
				/* Counter-clockwise, and not collinear. */
				double area = cross2(t[1] - t[0], t[2] - t[0]);
				if (area < 0.0) {
					std::swap(t[1], t[2]);
					std::swap(ti[1], ti[2]);
					area = -area;
				}
				const double extent2 = std::max({ (t[1] - t[0]).squaredNorm(),
								  (t[2] - t[1]).squaredNorm(),
								  (t[0] - t[2]).squaredNorm() });
				if (area < 0.05 * extent2)
					continue;
				/*
				 * Each model triangle in each of the three ways round; the
				 * depths once per ray order and side lengths.
				 */
				if (++depth_stamp_ == 0) { /* wrapped: forget every stamp */
					for (auto &row : depth_stamps_)
						row.fill(0);
					depth_stamp_ = 1;
				}
				const std::uint64_t cands = (std::uint64_t{ 1 } << ti[0]) |
							    (std::uint64_t{ 1 } << ti[1]) |
							    (std::uint64_t{ 1 } << ti[2]);
				for (const TriangleModel &triangle : triangle_models_)
					for (int rot = 0; rot < 3; ++rot) {
						Eigen::Vector2d q[3];
						for (int k = 0; k < 3; ++k)
							q[k] = t[(k + rot) % 3];
						const std::size_t c = static_cast<std::size_t>(
							triangle.sides_class);
						if (depth_stamps_[rot][c] != depth_stamp_) {
							solveP3pDepths(q, triangle.sides_mm2.data(),
								       &depths_[rot][c]);
							depth_stamps_[rot][c] = depth_stamp_;
						}
						if (tryTriangle(triangle, q, depths_[rot][c],
								cands))
							return true;
					}
			}
	}
	return false;
}

/*
 * The structural competitors of a chosen pose: each near-congruence of the
 * model applied to it (the same image points explained by other LEDs),
 * verified like any hypothesis and kept beside it for the ambiguity test.
 */
void Correspondence::addCompetitors(const Hypothesis &chosen)
{
	const Pose &pose = chosen.refined.pose;
	for (const Pose &c : congruences_) {
		/* C(T(X)) = P(X): C = P o T^-1. */
		Pose start;
		start.R = pose.R * c.R.transpose();
		start.t_mm = pose.t_mm - start.R * c.t_mm;
		if (!plausible(start))
			continue;
		Hypothesis h;
		if (refineMatch(start, 2.0 * gatePx(start), minLeds(false), &h))
			keep(h);
	}
}

bool Correspondence::fullSearch(const Pose *reference, CorrespondenceResult *result)
{
	/*
	 * Clipped spots first, among themselves: at close range a target's
	 * LEDs are far apart in the image and every reflection between them
	 * pushes them out of each other's nearest neighbours, but its LEDs,
	 * driven to be the brightest things in view, reach the clip level
	 * where most reflections do not. Then every candidate.
	 */
	const std::uint64_t all = n_cand_ >= 64 ? ~std::uint64_t{ 0 }
						: (std::uint64_t{ 1 } << n_cand_) - 1;
	findNeighbours(all, &neighbours_);
	const bool clipped_pass = clippedPass();
	clipped_pass_ = clipped_pass;
	const bool clipped_triangles = clippedTriangles();
	if (clipped_pass || clipped_triangles)
		findNeighbours(clipped_bits_, &clipped_neighbours_);

	/*
	 * Unless a quadrilateral gave a complete explanation (every predicted LED
	 * found), also try faces with a hidden vertex: when a shared LED is
	 * hidden no face is complete, and the true pose comes only from there,
	 * while a wrong, incomplete one may have come from the quadrilaterals.
	 */
	const int pool = std::min(n_cand_, config_.strongest_first);
	strongest_ = pool >= 64	 ? ~std::uint64_t{ 0 }
		     : pool >= 4 ? (std::uint64_t{ 1 } << pool) - 1
				 : 0;
	bool complete = pool >= 4 && searchStrongestQuads(pool);
	complete = complete || (clipped_pass && searchQuads(clipped_neighbours_, nullptr));
	complete = complete ||
		   searchQuads(neighbours_, clipped_pass ? &clipped_neighbours_ : nullptr);
	for (const auto &h : kept_)
		complete = complete || (acceptable(h) && h.missing == 0);
	/*
	 * The triangles, the clipped spots' first: three clipped LEDs of a face
	 * whose fourth is too dim to clip (seen obliquely, or off its emission
	 * axis) put it, and every further LED, on its spot through P3P, where
	 * among thirty reflections at close range the face's four spots are
	 * rarely each other's nearest neighbours and the quadrilaterals run out
	 * of budget before they meet them.
	 */
	if (!complete && clipped_triangles)
		complete = searchTriangles(clipped_neighbours_, nullptr);
	if (!complete)
		searchTriangles(neighbours_, clipped_triangles ? &clipped_neighbours_ : nullptr);

	result->budget_exhausted = budget_hit_;
	if (kept_.empty())
		return false;
	auto best_kept = [this] {
		std::size_t best = 0;
		for (std::size_t i = 1; i < kept_.size(); ++i)
			if (better(kept_[i], kept_[best]))
				best = i;
		return best;
	};
	std::size_t best = best_kept();
	if (acceptable(kept_[best])) {
		const Hypothesis first = kept_[best];
		addCompetitors(first);
		best = best_kept();
	}
	Hypothesis chosen = kept_[best];
	result->log10_nfa = chosen.log10_nfa;
	if (!acceptable(chosen)) {
		result->error_too_large = !errorExplained(chosen, 1.0) &&
					  static_cast<int>(chosen.match.pairs.size()) >=
						  minLeds(false);
		return false;
	}
	/*
	 * Another acceptable, different pose that explains as many LEDs:
	 * ambiguous, whatever each predicts to be missing (an LED can be missed
	 * by the detector, so that count alone must not decide).
	 */
	for (std::size_t i = 0; i < kept_.size(); ++i) {
		if (i == best || !rival(kept_[i], chosen))
			continue;
		const Hypothesis &other = kept_[i];
		/*
		 * One that explains fewer LEDs stands aside, unless it fits as its
		 * centroids' covariance predicts and the chosen pose clearly does not
		 * (an error beyond twice what the covariance predicts, fitting only
		 * within the px floor): then the extra LEDs are no evidence for the
		 * chosen pose. A true pose just past the 99.9 % point keeps its extra
		 * LEDs' evidence (a box corner at 488 mm: six LEDs at chi2 33
		 * against 22.7, beside a four-LED pose that left two of the spots
		 * unexplained).
		 */
		if (other.match.pairs.size() < chosen.match.pairs.size() &&
		    !(fitStatistical(other, 1.0) && !fitStatistical(chosen, 2.0)))
			continue;
		bool symmetric = false;
		for (const auto &s : symmetries_) {
			Pose equivalent;
			equivalent.R = other.refined.pose.R * s.transform.R;
			equivalent.t_mm =
				other.refined.pose.R * s.transform.t_mm + other.refined.pose.t_mm;
			symmetric = symmetric || samePose(equivalent, chosen.refined.pose);
		}
		if (!symmetric) {
			result->ambiguous = true;
			return false;
		}
	}
	if (planarMatch(chosen.match) && planarFlipExplains(chosen)) {
		result->ambiguous = true;
		return false;
	}
	canonicalise(reference, &chosen);
	if (!refineMatched(chosen.refined.pose, &chosen, true))
		return false;
	result->refined = chosen.refined;
	result->match = chosen.match;
	scaleUnexplained(static_cast<int>(chosen.match.pairs.size()), &result->refined);
	return true;
}

double Correspondence::trackGatePx(const Pose &prediction) const
{
	return std::max(config_.track_gate_px, 0.15 * sizePx(prediction));
}

bool Correspondence::solve(const StaticVector<Blob, kMaxCandidates> &blobs, const Pose *prediction,
			   CorrespondenceResult *result, const SolveContext &context)
{
	*result = CorrespondenceResult{};
	context_ = context;
	hypotheses_ = 0;
	verified_ = 0;
	budget_hit_ = false;
	focus_ = ~std::uint64_t{ 0 };
	focused_ = false;
	kept_.clear();
	px_.clear();
	xy_.clear();
	usable_.clear();
	clipped_bits_ = 0;
	var_.clear();
	cov_.clear();
	n_cand_ = 0;
	const double floor2 = config_.refine.sigma_px * config_.refine.sigma_px;
	for (const auto &blob : blobs) {
		const Eigen::Vector2d uv{ blob.u_px, blob.v_px };
		Eigen::Vector2d xy = Eigen::Vector2d::Zero();
		const bool ok = camera_.pixelToNormalized(uv, &xy);
		if (ok) {
			if (blob.saturated_px > 0)
				clipped_bits_ |= std::uint64_t{ 1 } << n_cand_;
			cand_[n_cand_++] = static_cast<int>(px_.size());
		}
		px_.push_back(uv);
		xy_.push_back(xy);
		usable_.push_back(ok ? 1 : 0);
		Eigen::Matrix2d cov;
		cov << blob.cov_uu_px2, blob.cov_uv_px2, blob.cov_uv_px2, blob.cov_vv_px2;
		const bool known = blob.cov_uu_px2 > 0.0 && blob.cov_vv_px2 > 0.0;
		if (!known)
			cov = floor2 * Eigen::Matrix2d::Identity();
		/* A spot cut by the frame's edge: its centroid is uncertain by up to its radius. */
		const CameraIntrinsics &intr = camera_.intrinsics();
		const bool measured = blob.area_px >
				      0.0; /* (blobs made by hand may carry no extent) */
		if (measured && (blob.x_min == 0 || blob.y_min == 0 ||
				 blob.x_max + 1 >= intr.width || blob.y_max + 1 >= intr.height)) {
			const double r = 0.5 * std::max(blob.x_max - blob.x_min + 1,
							blob.y_max - blob.y_min + 1);
			cov += r * r * Eigen::Matrix2d::Identity();
		}
		cov_.push_back(cov);
		/* The larger eigenvalue of the 2x2 covariance. */
		const double half_tr = 0.5 * (cov(0, 0) + cov(1, 1));
		const double det = cov(0, 0) * cov(1, 1) - cov(0, 1) * cov(0, 1);
		var_.push_back(half_tr + std::sqrt(std::max(half_tr * half_tr - det, 0.0)));
	}
	/* Usable candidates by column, for the gated look-ups. */
	by_u_.clear();
	for (std::size_t j = 0; j < px_.size(); ++j)
		if (usable_[j])
			by_u_.push_back(static_cast<std::int8_t>(j));
	std::sort(by_u_.begin(), by_u_.end(), [this](std::int8_t a, std::int8_t b) {
		return px_[a].x() < px_[b].x() || (px_[a].x() == px_[b].x() && a < b);
	});
	u_sorted_.clear();
	for (const std::int8_t j : by_u_)
		u_sorted_.push_back(px_[j].x());
	log10_quad_tests_ = log10Tests(false);
	log10_triangle_tests_ = log10Tests(true);
	if (n_cand_ < minLeds(true))
		return false;

	if (prediction) {
		Hypothesis h;
		h.tracked = true;
		const double gate = trackGatePx(*prediction);
		h.track_gate_px = gate;
		if (refineMatch(*prediction, gate, minLeds(true), &h, true) && acceptable(h) &&
		    !(planarMatch(h.match) && planarFlipExplains(h))) {
			if (canonicalise(prediction, &h) &&
			    !refineMatched(h.refined.pose, &h, true))
				return false;
			result->found = true;
			result->tracked = true;
			result->refined = h.refined;
			result->match = h.match;
			scaleUnexplained(static_cast<int>(h.match.pairs.size()), &result->refined);
			result->log10_nfa = h.log10_nfa;
			result->verified = 1;
			return true;
		}
	}

	if (context_.window_area_px2 > 0.0)
		return false;
	result->found = fullSearch(prediction, result);
	result->hypotheses = hypotheses_;
	result->verified = verified_;
	return result->found;
}

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
#include "algo/correspondence.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

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
	double angle[4];
	for (int k = 0; k < 4; ++k) {
		const Eigen::Vector2d d = p[idx[k]] - c;
		angle[k] = std::atan2(d.y(), d.x());
		order[k] = idx[k];
	}
	/* Insertion sort of four by angle. */
	for (int i = 1; i < 4; ++i)
		for (int j = i; j > 0 && angle[j - 1] > angle[j]; --j) {
			std::swap(angle[j - 1], angle[j]);
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

} /* namespace */

Correspondence::Correspondence(const TargetModel &target, const CameraModel &camera,
			       const CorrespondenceConfig &config)
	: target_(target), camera_(camera), config_(config)
{
	diameter_mm_ = target_.diameterMm();
	for (const auto &p : target_.points_mm)
		centroid_mm_ += p;
	if (!target_.points_mm.empty())
		centroid_mm_ /= static_cast<double>(target_.points_mm.size());

	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		for (int k = 0; k < 4; ++k)
			led_faces_[target_.faces[f][k]] |= 1u << f;

	orientFaces();
	findSymmetries();
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
		const Eigen::Vector3d e0 = (target_.points_mm[face[1]] - target_.points_mm[face[0]]).normalized();
		const Eigen::Vector3d e1 = normals_[f].cross(e0);
		std::array<Eigen::Vector2d, 4> plane;
		for (int k = 0; k < 4; ++k) {
			const Eigen::Vector3d d = target_.points_mm[face[k]] - centre;
			plane[k] = { d.dot(e0), d.dot(e1) };
		}
		face_plane_.push_back(plane);
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
	for (std::size_t g = 0; g < target_.faces.size(); ++g) {
		const auto &face = target_.faces[g];
		for (int dir = -1; dir <= 1; dir += 2)
			for (int rot = 0; rot < 4; ++rot) {
				Eigen::Vector3d src[4], dst[4];
				for (int k = 0; k < 4; ++k) {
					src[k] = target_.points_mm[face0[k]];
					dst[k] = target_.points_mm[face[((rot + dir * k) % 4 + 4) % 4]];
				}
				Pose t;
				double sse = 0.0;
				if (!hornFit(src, dst, 4, &t, false, nullptr, &sse) || sse > 4.0 * tol * tol)
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
					for (std::size_t h = 0; h < target_.faces.size(); ++h) {
						std::uint32_t m = 0;
						for (int k = 0; k < 4; ++k)
							m |= 1u << target_.faces[h][k];
						found = found || m == image;
					}
					ok = found;
				}
				if (!ok)
					continue;
				bool duplicate = false;
				for (const auto &known : symmetries_)
					duplicate = duplicate ||
						    std::equal(known.perm.begin(), known.perm.begin() + nl, s.perm.begin());
				if (duplicate)
					continue;
				for (std::size_t i = nl; i < kMaxLeds; ++i)
					s.perm[i] = static_cast<std::int8_t>(i);
				s.transform = t;
				symmetries_.push_back(s);
			}
	}
}

/* Is face f seen from its front, within the view angle, from this pose? */
bool Correspondence::faceVisible(const Pose &pose, std::size_t f) const
{
	const Eigen::Vector3d camera_t = -pose.R.transpose() * pose.t_mm; /* camera centre, target frame */
	const Eigen::Vector3d view = (camera_t - face_centres_[f]).normalized();
	return normals_[f].dot(view) > std::cos(config_.max_view_angle_deg * kPi / 180.0);
}

/* Is the camera within max_off_axis_deg of the target's approach axis (-z)? */
bool Correspondence::plausible(const Pose &pose) const
{
	const Eigen::Vector3d camera_t = -pose.R.transpose() * pose.t_mm;
	const Eigen::Vector3d d = camera_t - centroid_mm_;
	return -d.z() >= std::cos(config_.max_off_axis_deg * kPi / 180.0) * d.norm() && pose.apply(centroid_mm_).z() > 0.0;
}

/* LEDs on faces seen from the front, projecting inside the frame. */
std::uint32_t Correspondence::predictedLeds(const Pose &pose, double margin_px) const
{
	std::uint32_t front = 0;
	for (std::size_t f = 0; f < target_.faces.size(); ++f)
		if (faceVisible(pose, f))
			for (int k = 0; k < 4; ++k)
				front |= 1u << target_.faces[f][k];
	std::uint32_t inside = 0;
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i) {
		if (!(front & (1u << i)))
			continue;
		Eigen::Vector2d uv;
		if (camera_.project(pose.apply(target_.points_mm[i]), &uv) && camera_.inImage(uv, margin_px))
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
	return std::clamp(config_.gate_frac * sizePx(pose), config_.gate_px, std::max(config_.gate_px, 30.0));
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
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i) {
		Eigen::Vector2d uv;
		if (!camera_.project(pose.apply(target_.points_mm[i]), &uv) || !camera_.inImage(uv, -gate_px))
			continue;
		int best = -1;
		double best_d2 = gate2;
		for (std::size_t j = 0; j < px_.size(); ++j) {
			if (!usable_[j])
				continue;
			const double d2 = (px_[j] - uv).squaredNorm();
			if (d2 < best_d2) {
				best_d2 = d2;
				best = static_cast<int>(j);
			}
		}
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
			match->pairs.push_back({ static_cast<std::int8_t>(i), static_cast<std::int8_t>(choice[i]) });
			match->led_mask |= 1u << i;
		}
	return static_cast<int>(match->pairs.size());
}

/* Refine over the hypothesis's current matches (the covariance only when asked for). */
bool Correspondence::refineMatched(const Pose &initial, Hypothesis *h, bool covariance) const
{
	const int n = static_cast<int>(h->match.pairs.size());
	if (n < 3)
		return false;
	std::array<Eigen::Vector3d, kMaxLeds> model;
	std::array<Eigen::Vector2d, kMaxLeds> pixels;
	for (int k = 0; k < n; ++k) {
		model[k] = target_.points_mm[h->match.pairs[k][0]];
		pixels[k] = px_[h->match.pairs[k][1]];
	}
	RefineOptions options = config_.refine;
	options.covariance = covariance;
	const Pose start = initial; /* initial may alias h->refined.pose, which refinePose() resets */
	return refinePose(camera_, model.data(), pixels.data(), n, start, options, &h->refined);
}

/*
 * From an initial pose: match with a first (wider) gate, refine, match again
 * with the normal gate, refine; then count what the pose predicts. Fails as
 * soon as fewer than min_matches LEDs match.
 */
bool Correspondence::refineMatch(const Pose &initial, double first_gate_px, int min_matches, Hypothesis *h) const
{
	if (matchPredicted(initial, first_gate_px, &h->match) < min_matches)
		return false;
	if (!refineMatched(initial, h, false))
		return false;
	Pose pose = h->refined.pose;
	for (int round = 0; round < 2; ++round) {
		Match again;
		if (matchPredicted(pose, gatePx(pose), &again) < min_matches)
			return false;
		const bool changed = again.led_mask != h->match.led_mask ||
				     !std::equal(again.pairs.begin(), again.pairs.end(), h->match.pairs.begin());
		if (!changed)
			break;
		h->match = again;
		if (!refineMatched(pose, h, false))
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
			if (!camera_.project(pose.apply(target_.points_mm[h->match.pairs[k][0]]), &uv))
				return false;
			const double d2 = (uv - px_[h->match.pairs[k][1]]).squaredNorm();
			if (d2 > worst_d2) {
				worst_d2 = d2;
				worst = k;
			}
		}
		Hypothesis trial = *h;
		trial.match.led_mask &= ~(1u << trial.match.pairs[worst][0]);
		for (std::size_t k = worst; k + 1 < trial.match.pairs.size(); ++k)
			trial.match.pairs[k] = trial.match.pairs[k + 1];
		trial.match.pairs.pop_back();
		if (!refineMatched(pose, &trial, false))
			break;
		/* Re-match from the cleaner pose: the LED may find its own blob now. */
		Match again;
		if (matchPredicted(trial.refined.pose, gatePx(trial.refined.pose), &again) >= min_matches) {
			trial.match = again;
			if (!refineMatched(trial.refined.pose, &trial, false))
				break;
		}
		if (trial.refined.rms_px >= h->refined.rms_px)
			break;
		*h = trial;
		pose = h->refined.pose;
	}
	const std::uint32_t predicted = predictedLeds(h->refined.pose, 0.0);
	h->expected = __builtin_popcount(predicted);
	h->missing = __builtin_popcount(predicted & ~h->match.led_mask);
	return true;
}

/*
 * LEDs a pose needs: min_leds_search for the full search (never more than the
 * model has), min_leds_track when the tracked prediction supports it.
 */
int Correspondence::minLeds(bool tracking) const
{
	const int total = static_cast<int>(target_.points_mm.size());
	return std::min(tracking ? config_.min_leds_track : config_.min_leds_search, total);
}

bool Correspondence::acceptable(const Hypothesis &h) const
{
	return static_cast<int>(h.match.pairs.size()) >= minLeds(h.tracked) && h.missing <= config_.max_missing &&
	       h.refined.rms_px <= config_.max_rms_px && h.refined.converged && plausible(h.refined.pose);
}

/* Acceptable first; then more LEDs explained; then fewer predicted-but-missing; then lower error. */
bool Correspondence::better(const Hypothesis &a, const Hypothesis &b) const
{
	const bool aa = acceptable(a), ab = acceptable(b);
	if (aa != ab)
		return aa;
	const int na = static_cast<int>(a.match.pairs.size()), nb = static_cast<int>(b.match.pairs.size());
	if (na != nb)
		return na > nb;
	if (a.missing != b.missing)
		return a.missing < b.missing;
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
			const Eigen::Vector3d n = (target_.points_mm[match.pairs[i][0]] - a)
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
		n = (target_.points_mm[h.match.pairs[i][0]] - a).cross(target_.points_mm[h.match.pairs[i + 1][0]] - a);
	if (n.norm() < 1e-9)
		return true;
	const Eigen::Vector3d v = pose.apply(centre).normalized();
	const Eigen::Vector3d nc = (pose.R * n).normalized();
	if (std::abs(nc.dot(v)) > std::cos(0.25 * kPi / 180.0)) /* head-on: the two minima coincide */
		return false;
	const Pose start = mirrorPose(pose, centre, n.normalized());
	Hypothesis other;
	other.match = h.match;
	if (!refineMatched(start, &other, false))
		return false;
	if (samePose(other.refined.pose, pose))
		return false;
	return other.refined.converged && other.refined.rms_px <= std::max(config_.max_rms_px, 1.5 * h.refined.rms_px);
}

/*
 * Among the poses equivalent under the target's symmetries, take the one
 * closest in rotation to the reference (the tracked pose), else to the
 * model's own orientation; permute the matches accordingly and refine again
 * so the covariance belongs to the reported pose.
 */
void Correspondence::canonicalise(const Pose *reference, Hypothesis *h) const
{
	if (symmetries_.size() < 2)
		return;
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
		return;
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
	std::sort(permuted.pairs.begin(), permuted.pairs.end(),
		  [](const auto &x, const auto &y) { return x[0] < y[0]; });
	Hypothesis moved = *h;
	moved.match = permuted;
	if (refineMatched(start, &moved, false)) {
		h->match = moved.match;
		h->refined = moved.refined;
	}
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
 * One assignment of four image points (normalised q, pixels uv) to the
 * vertices of face f (vertex[k] is the face-local index for image point k).
 * Point `virtual_k` (or -1) is not a blob but the affine prediction of a
 * hidden vertex. Screens, solves, verifies and keeps the hypothesis; returns
 * true when it is good enough to stop the search.
 */
bool Correspondence::tryAssignment(const Eigen::Vector2d q[4], const Eigen::Vector2d uv[4], std::size_t f,
				   const int vertex[4], int virtual_k)
{
	++hypotheses_;
	Eigen::Vector2d plane[4];
	Eigen::Vector3d model[4];
	for (int k = 0; k < 4; ++k) {
		plane[k] = face_plane_[f][vertex[k]];
		model[k] = target_.points_mm[target_.faces[f][vertex[k]]];
	}

	/*
	 * Screen: the depths Z_m ∝ D_(m)/A_(m). With A signed about the face's
	 * front normal, det[P_i P_j P_k] = 2 A (n . P_i) and n . P_i < 0 when the
	 * camera sees the front: so D/A < 0 for all four exactly when the face
	 * is seen from its front. Any other sign pattern is rejected here.
	 */
	double Z[4];
	for (int m = 0; m < 4; ++m) {
		const int i = (m + 1) % 4, j = (m + 2) % 4, l = (m + 3) % 4;
		const double D = cross2(q[j] - q[i], q[l] - q[i]); /* det[q_i q_j q_l] with unit third row */
		const double A = cross2(plane[j] - plane[i], plane[l] - plane[i]);
		Z[m] = -D / A;
		/* (Not for an affine guess of a hidden vertex: strong perspective can flip it.) */
		if (virtual_k < 0 && (!(Z[m] > 0.0) || !std::isfinite(Z[m])))
			return false;
	}
	if (virtual_k < 0) {
		/* ... and reproduce the face's six side lengths up to one scale. */
		double sdl = 0.0, sdd = 0.0, sll = 0.0, d_ij[6], l_ij[6];
		int e = 0;
		for (int i = 0; i < 4; ++i)
			for (int j = i + 1; j < 4; ++j, ++e) {
				const Eigen::Vector3d pi{ q[i].x() * Z[i], q[i].y() * Z[i], Z[i] };
				const Eigen::Vector3d pj{ q[j].x() * Z[j], q[j].y() * Z[j], Z[j] };
				d_ij[e] = (pi - pj).norm();
				l_ij[e] = (plane[i] - plane[j]).norm();
				sdl += d_ij[e] * l_ij[e];
				sdd += d_ij[e] * d_ij[e];
				sll += l_ij[e] * l_ij[e];
			}
		const double scale = sdl / sdd;
		double res = 0.0;
		for (int k = 0; k < 6; ++k)
			res += (scale * d_ij[k] - l_ij[k]) * (scale * d_ij[k] - l_ij[k]);
		if (!(res <= 0.04 * sll))
			return false;
	}

	Pose pose;
	if (!solveFourCoplanar(model, q, &pose))
		return false;
	if (virtual_k < 0)
		return verify(pose, f, model, uv, virtual_k);

	/*
	 * Cheap test first: the rough pose must already put at least one other
	 * LED near a blob (within half the face's size).
	 */
	if (!plausible(pose))
		return false;
	Match rough;
	const double face_px = camera_.intrinsics().fx * (model[0] - model[2]).norm() /
			       std::max(pose.apply(model[0]).z(), 1.0);
	if (matchPredicted(pose, std::max(gatePx(pose), 0.5 * face_px), &rough) < minLeds(false) - 1)
		return false;
	/*
	 * The affine guess of the hidden vertex is only approximate under
	 * perspective: fit the three real points exactly (three points, six
	 * unknowns). Three points have up to four such poses; start from the
	 * closed form's pose and from its mirror about the line of sight, the
	 * two a small face is most often confused between.
	 */
	Eigen::Vector3d model3[3];
	Eigen::Vector2d px3[3];
	for (int k = 0, n = 0; k < 4; ++k)
		if (k != virtual_k) {
			model3[n] = model[k];
			px3[n++] = uv[k];
		}
	RefineOptions quick = config_.refine;
	quick.max_iterations = 8;
	quick.covariance = false;
	const Pose starts[2] = { pose, mirrorPose(pose, face_centres_[f], normals_[f]) };
	for (const Pose &start : starts) {
		RefineResult exact;
		if (refinePose(camera_, model3, px3, 3, start, quick, &exact) &&
		    verify(exact.pose, f, model, uv, virtual_k))
			return true;
	}
	return false;
}

/*
 * The mirror of a pose about the line of sight to a plane through centre_t
 * with normal normal_t (target frame): the plane tilted the other way, the
 * second minimum of a planar set seen in perspective.
 */
Pose Correspondence::mirrorPose(const Pose &pose, const Eigen::Vector3d &centre_t, const Eigen::Vector3d &normal_t)
{
	const Eigen::Vector3d c = pose.apply(centre_t);
	const Eigen::Vector3d v = c.normalized();
	const Eigen::Vector3d nc = (pose.R * normal_t).normalized();
	const Eigen::Vector3d mirrored = 2.0 * nc.dot(v) * v - nc;
	const Eigen::Matrix3d flip = Eigen::Quaterniond::FromTwoVectors(nc, mirrored).toRotationMatrix();
	Pose out;
	out.R = flip * pose.R;
	out.t_mm = c - flip * (c - pose.t_mm);
	return out;
}

/* The checks every hypothesis pose goes through, then verification; true: stop the search. */
bool Correspondence::verify(const Pose &pose, std::size_t f, const Eigen::Vector3d model[4],
			    const Eigen::Vector2d uv[4], int virtual_k)
{
	if (!faceVisible(pose, f) || !plausible(pose))
		return false;
	/* The pose must reproject its own (real) points. */
	const double gate = gatePx(pose);
	for (int k = 0; k < 4; ++k) {
		if (k == virtual_k)
			continue;
		Eigen::Vector2d p;
		if (!camera_.project(pose.apply(model[k]), &p) || (p - uv[k]).squaredNorm() > 4.0 * gate * gate)
			return false;
	}

	++verified_;
	Hypothesis h;
	if (!refineMatch(pose, 2.0 * gate, minLeds(false), &h))
		return false;
	keep(h);
	/*
	 * Stop early only when every LED of the model is explained with a small
	 * error. A pose that explains all it predicts but not every LED may be a
	 * partial symmetry of the target (7 corners of a box: a half turn of
	 * the box maps 6 of them onto others); then the search goes on so the
	 * ambiguity test can see the competitor.
	 */
	return acceptable(h) && h.missing == 0 && h.refined.rms_px <= 0.5 * config_.max_rms_px &&
	       h.match.pairs.size() == target_.points_mm.size() && !planarMatch(h.match);
}

/*
 * Every 4-subset in convex position against every face, 4 rotations, both
 * windings. Subsets are visited strongest first (by their weakest member), so
 * with a hypothesis budget the likeliest sets are tried before it runs out.
 */
bool Correspondence::searchQuads(const int *cand, int nc)
{
	for (int d = 3; d < nc; ++d)
		for (int c = 2; c < d; ++c)
			for (int b = 1; b < c; ++b)
				for (int a = 0; a < b; ++a) {
					if (hypotheses_ >= config_.max_hypotheses)
						return false;
					const int idx[4] = { cand[a], cand[b], cand[c], cand[d] };
					int order[4];
					if (!convexOrder(xy_.data(), idx, order))
						continue;
					Eigen::Vector2d q[4], uv[4];
					for (int k = 0; k < 4; ++k) {
						q[k] = xy_[order[k]];
						uv[k] = px_[order[k]];
					}
					for (std::size_t f = 0; f < target_.faces.size(); ++f)
						for (int dir = -1; dir <= 1; dir += 2)
							for (int rot = 0; rot < 4; ++rot) {
								int vertex[4];
								for (int k = 0; k < 4; ++k)
									vertex[k] = ((rot + dir * k) % 4 + 4) % 4;
								if (tryAssignment(q, uv, f, vertex, -1))
									return true;
							}
				}
	return false;
}

/*
 * Faces with one vertex hidden (an occluded LED shared by two faces leaves no
 * face complete): every image triangle against every face with each vertex
 * missing in turn. The hidden vertex's image is predicted with the affine
 * coordinates it has in the face's plane; the closed form then runs on the
 * four points and the refinement uses only real blobs.
 */
bool Correspondence::searchTriangles(const int *cand, int nc)
{
	for (int c = 2; c < nc; ++c)
		for (int b = 1; b < c; ++b)
			for (int a = 0; a < b; ++a) {
				if (hypotheses_ >= config_.max_hypotheses)
					return false;
				Eigen::Vector2d t[3] = { xy_[cand[a]], xy_[cand[b]], xy_[cand[c]] };
				int ti[3] = { cand[a], cand[b], cand[c] };
				/* Counter-clockwise, and not collinear. */
				double area = cross2(t[1] - t[0], t[2] - t[0]);
				if (area < 0.0) {
					std::swap(t[1], t[2]);
					std::swap(ti[1], ti[2]);
					area = -area;
				}
				const double extent2 = std::max({ (t[1] - t[0]).squaredNorm(), (t[2] - t[1]).squaredNorm(),
								  (t[0] - t[2]).squaredNorm() });
				if (area < 0.05 * extent2)
					continue;
				for (std::size_t f = 0; f < target_.faces.size(); ++f)
					for (int missing = 0; missing < 4; ++missing) {
						/*
						 * A hidden LED of only one face leaves the other faces
						 * complete for the quadrilateral search: only shared
						 * vertices need trying (any vertex for a lone face).
						 */
						if (target_.faces.size() > 1 &&
						    __builtin_popcount(led_faces_[target_.faces[f][missing]]) < 2)
							continue;
						for (int dir = -1; dir <= 1; dir += 2)
							for (int rot = 0; rot < 3; ++rot) {
								/* Face vertices in cyclic order (direction dir) starting after `missing`. */
								int vertex[4];
								for (int k = 0; k < 4; ++k)
									vertex[k] = ((missing + dir * (k + 1)) % 4 + 4) % 4;
								/* vertex[3] == missing; image points for vertex[0..2], rotated. */
								Eigen::Vector2d q[4], uv[4];
								for (int k = 0; k < 3; ++k) {
									q[k] = t[(k + rot) % 3];
									uv[k] = px_[ti[(k + rot) % 3]];
								}
								/* Affine coordinates of the hidden vertex in the face plane. */
								const Eigen::Vector2d p0 = face_plane_[f][vertex[0]];
								Eigen::Matrix2d basis;
								basis.col(0) = face_plane_[f][vertex[1]] - p0;
								basis.col(1) = face_plane_[f][vertex[2]] - p0;
								const Eigen::Vector2d ab =
									basis.inverse() * (face_plane_[f][vertex[3]] - p0);
								q[3] = q[0] + ab.x() * (q[1] - q[0]) + ab.y() * (q[2] - q[0]);
								uv[3] = camera_.normalizedToPixel(q[3]);
								if (tryAssignment(q, uv, f, vertex, 3))
									return true;
							}
					}
			}
	return false;
}

bool Correspondence::fullSearch(const Pose *reference, CorrespondenceResult *result)
{
	/* The strongest usable candidates take part in the search. */
	std::array<int, kMaxCandidates> cand;
	int nc = 0;
	for (std::size_t j = 0; j < px_.size() && nc < config_.max_search_candidates; ++j)
		if (usable_[j])
			cand[nc++] = static_cast<int>(j);

	/*
	 * Unless a quadrilateral gave a complete explanation (every predicted LED
	 * found), also try faces with a hidden vertex: when a shared LED is
	 * hidden no face is complete, and the true pose comes only from there,
	 * while a wrong, incomplete one may have come from the quadrilaterals.
	 */
	bool complete = searchQuads(cand.data(), nc);
	for (const auto &h : kept_)
		complete = complete || (acceptable(h) && h.missing == 0);
	if (!complete)
		searchTriangles(cand.data(), nc);

	result->budget_exhausted = hypotheses_ >= config_.max_hypotheses;
	if (kept_.empty())
		return false;
	std::size_t best = 0;
	for (std::size_t i = 1; i < kept_.size(); ++i)
		if (better(kept_[i], kept_[best]))
			best = i;
	Hypothesis chosen = kept_[best];
	/*
	 * A search cut short by the budget may not have met the competitor that
	 * makes a pose ambiguous: then only a pose that explains every LED of
	 * the model is trusted.
	 */
	if (result->budget_exhausted && chosen.match.pairs.size() < target_.points_mm.size())
		return false;
	if (!acceptable(chosen)) {
		result->error_too_large = chosen.refined.rms_px > config_.max_rms_px &&
					  static_cast<int>(chosen.match.pairs.size()) >= minLeds(false);
		return false;
	}
	/*
	 * Another acceptable, different pose that explains as many LEDs:
	 * ambiguous, whatever each predicts to be missing (an LED can be missed
	 * by the detector, so that count alone must not decide).
	 */
	for (std::size_t i = 0; i < kept_.size(); ++i) {
		if (i == best || !acceptable(kept_[i]))
			continue;
		const Hypothesis &other = kept_[i];
		if (other.match.pairs.size() < chosen.match.pairs.size())
			continue;
		bool symmetric = false;
		for (const auto &s : symmetries_) {
			Pose equivalent;
			equivalent.R = other.refined.pose.R * s.transform.R;
			equivalent.t_mm = other.refined.pose.R * s.transform.t_mm + other.refined.pose.t_mm;
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
	result->expected_visible = chosen.expected;
	return true;
}

bool Correspondence::solve(const StaticVector<Blob, kMaxCandidates> &blobs, const Pose *prediction,
			   CorrespondenceResult *result)
{
	*result = CorrespondenceResult{};
	hypotheses_ = 0;
	verified_ = 0;
	kept_.clear();
	px_.clear();
	xy_.clear();
	usable_.clear();
	int usable = 0;
	for (const auto &blob : blobs) {
		const Eigen::Vector2d uv{ blob.u_px, blob.v_px };
		Eigen::Vector2d xy = Eigen::Vector2d::Zero();
		const bool ok = camera_.pixelToNormalized(uv, &xy);
		px_.push_back(uv);
		xy_.push_back(xy);
		usable_.push_back(ok ? 1 : 0);
		usable += ok ? 1 : 0;
	}
	if (usable < minLeds(true))
		return false;

	if (prediction) {
		Hypothesis h;
		h.tracked = true;
		const double gate = std::max(config_.track_gate_px, 0.15 * sizePx(*prediction));
		if (refineMatch(*prediction, gate, minLeds(true), &h) && acceptable(h) &&
		    !(planarMatch(h.match) && planarFlipExplains(h))) {
			canonicalise(prediction, &h);
			if (!refineMatched(h.refined.pose, &h, true))
				return false;
			result->found = true;
			result->tracked = true;
			result->refined = h.refined;
			result->match = h.match;
			result->expected_visible = h.expected;
			result->verified = 1;
			return true;
		}
	}

	result->found = fullSearch(prediction, result);
	result->hypotheses = hypotheses_;
	result->verified = verified_;
	return result->found;
}

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
/*
 * Correspondence: which blob is which model LED (method.md section 4), and the
 * pose that follows.
 *
 * Full search: every 4-subset of candidates in convex position is tried
 * against every model face in its 4 cyclic rotations, in both windings. Each
 * (subset, face, rotation) is screened by the depth ratios and side lengths
 * of section 5, then by the closed-form pose: the face must be seen from its
 * front, the camera within max_off_axis_deg of the target's approach axis,
 * and the four points must reproject; then it is verified by projecting every model LED that the hypothesis
 * says is visible and counting the candidates that agree; the best few are
 * refined over all their matches. A pose is accepted only when
 *  - it explains at least min_leds_search LEDs (min_leds_track when tracking)
 *    and misses at most max_missing of the
 *    LEDs it predicts to be visible inside the frame,
 *  - the refined rms reprojection error is within max_rms_px, and
 *  - no other, different pose explains the image as well (else Ambiguous).
 * Poses that differ only by a symmetry of the target (e.g. the wedge's 180°
 * turn about its axis) are one pose: the one closest to the tracked pose,
 * else to the model's own orientation, is reported.
 *
 * When no face is complete (a hidden LED shared by two faces), image
 * triangles are tried against faces with one vertex hidden, the hidden
 * vertex predicted from its affine coordinates in the face.
 *
 * Tracking: with a previous pose, predicted LED positions are matched first;
 * the full search runs only when that fails.
 *
 * Allocates: in the constructor only.
 */
#pragma once

#include <array>
#include <cstdint>

#include <Eigen/Core>

#include "algo/blob_detector.h"
#include "algo/camera_model.h"
#include "algo/capacities.h"
#include "algo/pose.h"
#include "algo/static_vector.h"
#include "algo/target_model.h"

namespace dockpose {

struct CorrespondenceConfig {
	/* A predicted LED agrees with a blob within max(gate_px, gate_frac * target size in px). */
	double gate_px = 2.5;
	double gate_frac = 0.04;
	/* Tracking: first match within this many pixels (or 15% of target size) of the prediction. */
	double track_gate_px = 12.0;
	/*
	 * Acceptance. Four points of one face fit a random quadrilateral of
	 * clutter too often over thousands of hypotheses, so the full search
	 * needs five LEDs (or all of a smaller model); a tracked pose, supported
	 * by its prediction, may rest on four.
	 */
	int min_leds_search = 5;
	int min_leds_track = 4;
	int max_missing = 2;
	double max_rms_px = 0.6;
	/* Full search considers at most this many candidates (strongest first) ... */
	int max_search_candidates = 24;
	/* ... and screens at most this many (subset, face, rotation) hypotheses per frame. */
	int max_hypotheses = 60000;
	/* Faces seen more obliquely than this (or from behind) are predicted invisible. */
	double max_view_angle_deg = 80.0;
	/*
	 * Poses that put the camera more than this off the target's approach
	 * axis (-z in target coordinates, see TargetModel::frontNormals) are not
	 * considered: a docking target is approached from its front.
	 */
	double max_off_axis_deg = 75.0;
	RefineOptions refine;
};

struct Match {
	StaticVector<std::array<std::int8_t, 2>, kMaxLeds> pairs; /* (led, candidate index) */
	std::uint32_t led_mask = 0;
};

struct CorrespondenceResult {
	bool found = false;
	bool ambiguous = false;	 /* two different poses explain the image equally well */
	bool error_too_large = false; /* the best match left a reprojection error above max_rms_px */
	bool tracked = false;
	bool budget_exhausted = false; /* the search stopped at max_hypotheses */
	RefineResult refined;
	Match match;
	int expected_visible = 0; /* LEDs the accepted pose predicts inside the frame */
	int hypotheses = 0;	  /* closed-form hypotheses screened */
	int verified = 0;	  /* hypotheses verified by projecting all LEDs */
};

class Correspondence
{
public:
	Correspondence(const TargetModel &target, const CameraModel &camera, const CorrespondenceConfig &config);

	/*
	 * Match `blobs` to the model and return the pose. prediction may be null
	 * (no track). Allocates: never.
	 */
	bool solve(const StaticVector<Blob, kMaxCandidates> &blobs, const Pose *prediction,
		   CorrespondenceResult *result);

	/* Rigid symmetries of the model (identity first): LED permutation and transform. */
	struct Symmetry {
		std::array<std::int8_t, kMaxLeds> perm{}; /* model LED i maps onto LED perm[i] */
		Pose transform;				   /* X' = R X + t maps the model onto itself */
	};
	const StaticVector<Symmetry, 2 * 4 * kMaxFaces> &symmetries() const { return symmetries_; }

private:
	/* A verified hypothesis: refined pose, its matches, and what it predicts. */
	struct Hypothesis {
		RefineResult refined;
		Match match;
		int expected = 0;	/* LEDs predicted visible inside the frame */
		int missing = 0;	/* predicted visible but not matched */
		bool tracked = false;	/* found from the tracked prediction */
	};
	static constexpr std::size_t kMaxKept = 8;

	void orientFaces();
	void findSymmetries();
	bool faceVisible(const Pose &pose, std::size_t f) const;
	bool plausible(const Pose &pose) const;
	std::uint32_t predictedLeds(const Pose &pose, double margin_px) const;
	int matchPredicted(const Pose &pose, double gate_px, Match *match) const;
	bool refineMatch(const Pose &initial, double first_gate_px, int min_matches, Hypothesis *hypothesis) const;
	bool refineMatched(const Pose &initial, Hypothesis *hypothesis, bool covariance) const;
	bool acceptable(const Hypothesis &hypothesis) const;
	bool better(const Hypothesis &a, const Hypothesis &b) const;
	bool samePose(const Pose &a, const Pose &b) const;
	double sizePx(const Pose &pose) const;
	double gatePx(const Pose &pose) const;
	bool planarMatch(const Match &match) const;
	bool planarFlipExplains(const Hypothesis &hypothesis) const;
	void canonicalise(const Pose *reference, Hypothesis *hypothesis) const;
	void keep(const Hypothesis &hypothesis);
	int minLeds(bool tracking) const;
	bool tryAssignment(const Eigen::Vector2d q[4], const Eigen::Vector2d uv[4], std::size_t f, const int vertex[4],
			   int virtual_k);
	bool verify(const Pose &pose, std::size_t f, const Eigen::Vector3d model[4], const Eigen::Vector2d uv[4],
		    int virtual_k);
	static Pose mirrorPose(const Pose &pose, const Eigen::Vector3d &centre_t, const Eigen::Vector3d &normal_t);
	bool searchQuads(const int *cand, int nc);
	bool searchTriangles(const int *cand, int nc);
	bool fullSearch(const Pose *reference, CorrespondenceResult *result);

	TargetModel target_;
	CameraModel camera_;
	CorrespondenceConfig config_;
	double diameter_mm_ = 0.0;
	Eigen::Vector3d centroid_mm_ = Eigen::Vector3d::Zero();
	/* Front normals of the faces (TargetModel::frontNormals). */
	StaticVector<Eigen::Vector3d, kMaxFaces> normals_;
	StaticVector<Eigen::Vector3d, kMaxFaces> face_centres_;
	StaticVector<Symmetry, 2 * 4 * kMaxFaces> symmetries_;

	/* Face vertices in 2-D coordinates of the face's own plane (for signed areas). */
	StaticVector<std::array<Eigen::Vector2d, 4>, kMaxFaces> face_plane_;
	/* For each LED, the faces it belongs to (bit mask). */
	std::array<std::uint32_t, kMaxLeds> led_faces_{};

	/* Per-frame scratch (sized here, reused). */
	StaticVector<Eigen::Vector2d, kMaxCandidates> px_;
	StaticVector<Eigen::Vector2d, kMaxCandidates> xy_;
	StaticVector<std::uint8_t, kMaxCandidates> usable_;
	StaticVector<Hypothesis, kMaxKept> kept_;
	int hypotheses_ = 0;
	int verified_ = 0;
};

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
/*
 * Correspondence: which blob is which model LED (method.md section 4), and the
 * pose that follows.
 *
 * Hypotheses. Every usable candidate (up to kMaxCandidates) takes part. Each
 * candidate's k nearest neighbours (in undistorted image coordinates) span
 * the quadrilaterals it anchors, strongest anchors first, each quadrilateral
 * once: first among the clipped spots alone (their own nearest clipped
 * neighbours: close up, reflections between a target's LEDs push them out of
 * each other's nearest candidates, but the LEDs clip where most reflections
 * do not), then among every candidate, skipping the sets already formed; the
 * NFA's count of tests includes both. Before either pass, the sets of four
 * that they would form among the strongest_first strongest candidates come
 * in the order of their weakest member (PROSAC's), and the passes skip them:
 * the same hypotheses, but a target whose LEDs are among the brightest spots
 * is found before every neighbour set of a bright reflection is tried.
 * A quadrilateral in convex position is screened against every face in its
 * 8 cyclic assignments by a perspective invariant: where its diagonals
 * cross, as fractions along each diagonal. Those fractions are the face's own
 * under an affine view and move by at most a quarter of the diagonal's
 * relative depth change under perspective, a bound that follows from the
 * diagonal's image length and the largest view angle. Survivors go through the
 * depth ratios and side lengths of method.md section 5, the closed-form pose
 * (the face seen from its front; the optional approach prior of the target
 * file), reprojection of their own points, and verification: every model LED
 * the pose predicts visible is matched to the nearest candidate, refined over
 * all matches (weighted by each blob's centroid covariance), matched again.
 * When a shared LED is hidden and no face is complete, image triangles are
 * tried against three vertices of each face (P3P, up to four poses each).
 *
 * Acceptance: an a-contrario false-alarm bound, not an LED count. For a
 * verified pose with k of its n predicted LEDs matched, the number of false
 * alarms is
 *     NFA = min over m in 4..k of N_tests * (k - 3) * C(n - 3, m - 3) * p_m^(m - 3),
 *     p_m = 1 - exp(-rho * pi * r_m^2),
 * the expected number of hypotheses, among the N_tests this frame's
 * candidates allow the search to form, that candidates scattered at random at
 * this frame's density rho would explain as well: three points fix a pose,
 * each further LED must land within r_m of its prediction. rho is the larger
 * of the frame's candidate density and that of the unmatched candidates
 * around the target; each LED's tolerance is its residual (inflated for the
 * degrees of freedom the fit absorbed), never below twice its centroid's
 * sigma, and r_m is the m-th smallest: the evidence of the best m LEDs, as
 * a-contrario RANSAC counts it (the choice of m is the factor k - 3). A
 * tracked pose is also tested against its prediction's window (one test,
 * every LED a chance hit within the window), and the smaller of the two,
 * doubled, is its NFA. A pose is accepted when log10 NFA <= max_log10_nfa,
 * it rests on at least min_leds LEDs (a floor), its rms reprojection error is
 * within max_rms_px, and no other, different pose explains the image as well
 * (else Ambiguous; one on fewer LEDs does when it fits the centroids'
 * covariance and the chosen pose misfits it by more than twice, fitting only
 * max_rms_px): the competitors are the other hypotheses kept, the model's
 * near-congruences of faces applied to the chosen pose (a box corner
 * half-turned maps six of its seven LEDs onto others), and, for a planar
 * match, the mirror pose about the line of sight. Poses that differ only by a
 * symmetry of the target (e.g. the wedge's 180 degree turn about its axis)
 * are one pose: the one closest to the tracked pose, else to the model's own
 * orientation, is reported.
 *
 * The search stops early once a verified pose's NFA is below
 * early_exit_log10_nfa and its residuals are what the centroids' covariance
 * predicts, and it leaves no candidate near the target unexplained or
 * explains every LED of the model: no chance competitor can come close, and
 * the structural ones are generated explicitly. (A pose that fits only
 * within max_rms_px does not stop the search: it may be a near-congruent
 * copy of the true pose.) One that leaves a candidate near the target
 * unexplained narrows the rest of the search to the candidates near the
 * target, where a pose explaining that candidate too would rest.
 *
 * Tracking: with a previous pose, predicted LED positions are matched first;
 * the full search runs only when that fails.
 *
 * Allocates: in the constructor only.
 */
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>

#include <Eigen/Core>

#include "algo/blob_detector.h"
#include "algo/camera_model.h"
#include "algo/capacities.h"
#include "algo/p3p.h"
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
	/* Acceptance: log10 of the largest number of false alarms (see above). */
	double max_log10_nfa = -4.0;
	/* A competitor within this many decades of the chosen pose's NFA makes it ambiguous. */
	double ambiguity_margin = 3.0;
	/*
	 * Stop the search once a verified pose is this certain; never above
	 * max_log10_nfa - ambiguity_margin, where a rival the stop leaves unsought
	 * would itself be within the acceptance bound (Correspondence applies it).
	 */
	double early_exit_log10_nfa = -8.0;
	/* Floors: LEDs a pose must rest on, from the full search and from tracking. */
	int min_leds_search = 4;
	int min_leds_track = 4;
	/* Predicted-visible LEDs that may be unmatched (occlusion); the NFA already weighs them. */
	int max_missing = static_cast<int>(kMaxLeds);
	double max_rms_px = 0.6;
	/* Neighbours of each candidate that span its quadrilaterals, and its triangles. */
	int neighbours = 9;
	int triangle_neighbours = 4;
	/*
	 * The quadrilaterals among this many strongest candidates come first
	 * (searchStrongestQuads(): at most C(12, 4) = 495 sets; 0: none).
	 */
	int strongest_first = 12;
	/* Centroid error (px) the invariant screen tolerates beyond the blob's own sigma. */
	double screen_sigma_px = 1.0;
	/*
	 * Screen at most this many (subset, face, assignment seeing the face from
	 * its front) hypotheses per frame, of them this many from triangles: the
	 * quadrilaterals stop that many short (at most half the budget), so the
	 * triangles keep their share when the quadrilaterals run out.
	 */
	int max_hypotheses = 20000;
	int max_triangle_hypotheses = 4000;
	/* ... and verify (refine over all predicted LEDs) at most this many: the search's time bound. */
	int max_verifications = 400;
	/* Faces seen more obliquely than this (or from behind) are predicted invisible, and their LEDs match no spot. */
	double max_view_angle_deg = 80.0;
	RefineOptions refine;
};

struct Match {
	StaticVector<std::array<std::int8_t, 2>, kMaxLeds> pairs; /* (led, candidate index) */
	std::uint32_t led_mask = 0;
};

struct CorrespondenceResult {
	bool found = false;
	bool ambiguous = false; /* two different poses explain the image equally well */
	bool error_too_large =
		false; /* the best match left a reprojection error above max_rms_px */
	bool tracked = false;
	bool budget_exhausted = false; /* the search stopped at max_hypotheses */
	/*
	 * The accepted fit. Its covariance is the centroids' propagated, scaled
	 * by chi2 / dof when the fit was accepted on max_rms_px with chi2 beyond
	 * its 99.9 % point (the residuals say more error than the centroids'
	 * covariance: a spot merged with a reflection, an unmodelled lens).
	 */
	RefineResult refined;
	Match match;
	double log10_nfa = 0.0; /* of the accepted pose (or of the best rejected one) */
	int hypotheses = 0; /* closed-form hypotheses screened */
	int verified = 0; /* hypotheses verified by projecting all LEDs */
};

/*
 * What the caller knows beyond the blobs: with regions of interest
 * (Pipeline's tracking), the blobs come only from windows around the
 * predicted LEDs, not from the whole frame.
 */
struct SolveContext {
	/*
	 * > 0: the blobs come from windows of this many pixels in all. The
	 * density of chance candidates is then the larger of that of the
	 * unmatched blobs in the windows and that of the last whole-frame pass;
	 * the hypotheses a search could form are counted from that pass's
	 * candidates; only the tracked prediction is tried (a full search on a
	 * partial frame would miss what lies outside the windows).
	 */
	double window_area_px2 = 0.0;
	int frame_candidates = 0; /* candidates (blobs) of the last whole-frame pass */
};

/*
 * The NFA's evidence term (see above) for k >= 4 matched LEDs: min over m in
 * 4..k of log10_tests + log10 C(n - 3, m - 3) + (m - 3) log10 p_m, p_m =
 * 1 - exp(-rho pi tol2_sorted[m - 1]), with tol2_sorted the k squared
 * tolerances (px^2) in increasing order and rho a density (px^-2); n < 0
 * leaves out the factor C (as a floor). It grows with every tolerance, rho,
 * log10_tests and n: a search screen that passes it the smallest of each
 * bounds from below the log10 NFA a verified pose can reach. Allocates: never.
 */
double bestSubsetLog10Nfa(const double *tol2_sorted, int k, int n, double rho, double log10_tests);

class Correspondence
{
public:
	Correspondence(TargetModel target, const CameraModel &camera,
		       const CorrespondenceConfig &config);

	/*
	 * Match `blobs` to the model and return the pose. prediction may be null
	 * (no track). Allocates: never.
	 */
	bool solve(const StaticVector<Blob, kMaxCandidates> &blobs, const Pose *prediction,
		   CorrespondenceResult *result, const SolveContext &context = {});

	/*
	 * Where tracking from `prediction` looks: the LEDs predicted visible
	 * (bit mask, as led_mask) and the first match's gate, pixels: a blob
	 * farther than the gate from every predicted LED takes no part in the
	 * tracked match. Allocates: never.
	 */
	std::uint32_t trackedLeds(const Pose &prediction) const
	{
		return predictedLeds(prediction, 0.0);
	}
	double trackGatePx(const Pose &prediction) const;

	/* Rigid symmetries of the model (identity first): LED permutation and transform. */
	struct Symmetry {
		std::array<std::int8_t, kMaxLeds> perm{}; /* model LED i maps onto LED perm[i] */
		Pose transform; /* X' = R X + t maps the model onto itself */
	};
	const StaticVector<Symmetry, kMaxFaces * 8> &symmetries() const { return symmetries_; }

private:
	/* A verified hypothesis: refined pose, its matches, and what it predicts. */
	struct Hypothesis {
		RefineResult refined;
		Match match;
		int expected = 0; /* LEDs predicted visible inside the frame */
		int missing = 0; /* predicted visible but not matched */
		bool tracked = false; /* found from the tracked prediction */
		double track_gate_px = 0.0; /* the prediction's window, when tracked */
		bool from_triangle = false; /* generated by the hidden-vertex search */
		double log10_nfa = 0.0;
	};
	static constexpr std::size_t kMaxKept = 8;

	void orientFaces();
	void findSymmetries();
	bool faceVisible(const Pose &pose, std::size_t f) const;
	bool faceVisibleFrom(const Eigen::Vector3d &camera_t, std::size_t f) const;
	bool plausible(const Pose &pose) const;
	std::uint32_t frontLeds(const Pose &pose) const;
	std::uint32_t predictedLeds(const Pose &pose, double margin_px) const;
	int matchPredicted(const Pose &pose, double gate_px, Match *match) const;
	bool refineMatch(const Pose &initial, double first_gate_px, int min_matches,
			 Hypothesis *hypothesis, bool covariance = false) const;
	bool refineMatched(const Pose &initial, Hypothesis *hypothesis, bool covariance) const;
	bool acceptable(const Hypothesis &hypothesis) const;
	bool better(const Hypothesis &a, const Hypothesis &b) const;
	bool rival(const Hypothesis &other, const Hypothesis &chosen) const;
	bool errorExplained(const Hypothesis &hypothesis, double slack) const;
	static double chi2Bound(int points);
	/* CorrespondenceResult::refined's covariance scaling, for a fit of `points` LEDs. */
	static void scaleUnexplained(int points, RefineResult *refined);
	bool fitStatistical(const Hypothesis &hypothesis, double slack) const;
	bool earlyExit(const Hypothesis &hypothesis);
	std::uint64_t nearTarget(const Hypothesis &hypothesis) const;
	/* Are the candidates idx[0..n) all in focus_ (see earlyExit())? */
	bool inFocus(const int *idx, int n) const
	{
		for (int k = 0; k < n; ++k)
			if (!(focus_ & (std::uint64_t{ 1 } << idx[k])))
				return false;
		return true;
	}
	bool samePose(const Pose &a, const Pose &b) const;
	double sizePx(const Pose &pose) const;
	double gatePx(const Pose &pose) const;
	bool planarMatch(const Match &match) const;
	bool planarFlipExplains(const Hypothesis &hypothesis) const;
	/* True when it moved the pose (refined again, without a covariance). */
	bool canonicalise(const Pose *reference, Hypothesis *hypothesis) const;
	void keep(const Hypothesis &hypothesis);
	int minLeds(bool tracking) const;
	/*
	 * Calls visit(j) for each usable candidate j whose column is within
	 * gate_px of u_px, left to right, until it returns true (then true).
	 */
	template<typename Visit>
	bool forCandidatesNear(double u_px, double gate_px, Visit &&visit) const
	{
		const auto first =
			std::lower_bound(u_sorted_.begin(), u_sorted_.end(), u_px - gate_px);
		for (auto it = first; it != u_sorted_.end() && *it <= u_px + gate_px; ++it)
			if (visit(static_cast<int>(
				    by_u_[static_cast<std::size_t>(it - u_sorted_.begin())])))
				return true;
		return false;
	}
	int triangleLeds() const;
	/* Where a quadrilateral's diagonals cross, and how far perspective may move it. */
	struct QuadInvariant {
		double s = 0.0, t = 0.0;
		double tol_s = 0.0, tol_t = 0.0;
	};
	bool quadInvariant(const Eigen::Vector2d q[4], QuadInvariant *invariant) const;
	bool screenQuad(const QuadInvariant &invariant, std::size_t f, const int vertex[4]) const;
	/* A face's vertices in one of its 8 cyclic assignments, and what quadShape() needs of them. */
	struct QuadAssignment {
		std::array<int, 4> vertex{}; /* image point k on face-local vertex[k] */
		std::array<double, 4> area{}; /* signed areas A_(m) of the other three vertices */
		std::array<double, 6>
			side{}; /* side lengths, pairs (0,1) (0,2) (0,3) (1,2) (1,3) (2,3) */
		double sides2 = 0.0; /* sum of their squares */
	};
	void findQuadAssignments();
	static void quadDeterminants(const Eigen::Vector2d q[4], double D[4]);
	bool quadShape(const Eigen::Vector2d q[4], const double D[4], std::size_t f,
		       int assignment) const;
	bool tryAssignment(const int candidate[4], std::size_t f, const int vertex[4]);
	bool verify(const Pose &pose, std::size_t f, const Eigen::Vector3d model[4],
		    const Eigen::Vector2d uv[4], const Eigen::Matrix2d cov[4]);
	/* Three vertices of a face whose fourth is hidden, as the triangle search tries them. */
	struct TriangleModel {
		std::size_t face = 0;
		std::array<int, 3> vertex{}; /* face-local, in the order of the image points */
		std::uint32_t leds = 0; /* bit mask */
		std::array<double, 3> sides_mm2{}; /* p3pSides() */
		int sides_class = 0; /* index of the first model triangle with these sides */
		P3pModel p3p; /* its three LEDs (mm), prepared for p3pPoses() */
	};
	static constexpr std::size_t kMaxTriangleModels = kMaxFaces * 8;
	void findTriangleModels();
	bool tryTriangle(const TriangleModel &triangle, const Eigen::Vector2d q[3],
			 const P3pDepths &depths, std::uint64_t own_candidates);
	int moreLedsOnCandidates(const Pose &pose, double gate_px, std::uint32_t own_leds,
				 std::uint64_t own_candidates,
				 StaticVector<double, kMaxLeds> *var_px2) const;
	double log10NfaFloor(StaticVector<double, kMaxLeds> var_px2) const;
	double rivalLog10Nfa() const;
	static Pose mirrorPose(const Pose &pose, const Eigen::Vector3d &centre_t,
			       const Eigen::Vector3d &normal_t);
	double log10Nfa(const Hypothesis &hypothesis) const;
	double log10Tests(bool triangles) const;
	void findCongruences();
	void addCompetitors(const Hypothesis &chosen);
	/*
	 * Each candidate's nearest neighbours (positions in cand_, nearest
	 * first, as a list and as bits) among the candidates of `among`.
	 */
	struct NeighbourTable {
		std::uint64_t among = 0; /* bits of cand_ positions */
		std::array<std::uint64_t, kMaxCandidates> bits{};
		std::array<std::array<std::int8_t, kMaxCandidates>, kMaxCandidates> list{};
		std::array<int, kMaxCandidates> n{};
	};
	void findNeighbours(std::uint64_t among, NeighbourTable *table) const;
	static std::uint64_t neighbourBits(const NeighbourTable &table, int a, int first);
	bool clippedPass() const;
	bool clippedTriangles() const;
	static bool formedIn(const NeighbourTable &table, std::uint64_t set, int first);
	/* What tryQuadSet() came to: the set tried, a pose that stops the search, the budget spent. */
	enum class SetOutcome {
		Tried,
		Found,
		Budget
	};
	SetOutcome tryQuadSet(const int members[4]);
	bool searchStrongestQuads(int pool);
	bool strongestTried(std::uint64_t set) const;
	bool searchQuads(const NeighbourTable &table, const NeighbourTable *before);
	bool searchTriangles(const NeighbourTable &table, const NeighbourTable *before);
	bool fullSearch(const Pose *reference, CorrespondenceResult *result);

	TargetModel target_;
	CameraModel camera_;
	CorrespondenceConfig config_;
	double diameter_mm_ = 0.0;
	/* cos and tan of config_.max_view_angle_deg (tan of at most 89 degrees). */
	double cos_view_max_ = 0.0;
	double tan_view_max_ = 0.0;
	/* config_.early_exit_log10_nfa, at most max_log10_nfa - ambiguity_margin. */
	double early_exit_log10_nfa_ = 0.0;
	Eigen::Vector3d centroid_mm_ = Eigen::Vector3d::Zero();
	/* Front normals of the faces (TargetModel::frontNormals). */
	StaticVector<Eigen::Vector3d, kMaxFaces> normals_;
	StaticVector<Eigen::Vector3d, kMaxFaces> face_centres_;
	StaticVector<Symmetry, kMaxFaces * 8> symmetries_; /* 2 directions x 4 turns per face */

	/*
	 * Face vertices in 2-D coordinates of the face's own plane (for signed
	 * areas), in a right-handed frame about the front normal.
	 */
	StaticVector<std::array<Eigen::Vector2d, 4>, kMaxFaces> face_plane_;
	/* For each LED, the faces it belongs to (bit mask). */
	std::array<std::uint32_t, kMaxLeds> led_faces_{};
	/* For each face, its LEDs (bit mask). */
	std::array<std::uint32_t, kMaxFaces> led_faces_mask_{};
	/*
	 * Where the diagonals of face f cross: diagonal_frac_[f][a] is the
	 * fraction along the diagonal from vertex a to vertex a + 2.
	 */
	StaticVector<std::array<double, 4>, kMaxFaces> diagonal_frac_;
	/*
	 * Near-congruences: rigid transforms that map one face onto another (or
	 * onto itself turned) within 10% of its size, but are no symmetry of
	 * the whole model. Applied to a chosen pose they give its structural
	 * competitors.
	 */
	StaticVector<Pose, 8 * kMaxFaces * kMaxFaces> congruences_;
	StaticVector<TriangleModel, kMaxTriangleModels> triangle_models_;
	StaticVector<std::array<QuadAssignment, 8>, kMaxFaces> quad_assignments_;
	/* P3P depths of the current image triangle, per ray order and side class (valid when stamped). */
	std::array<std::array<P3pDepths, kMaxTriangleModels>, 3> depths_{};
	std::array<std::array<std::uint32_t, kMaxTriangleModels>, 3> depth_stamps_{};
	std::uint32_t depth_stamp_ = 0;

	/* Per-frame scratch (sized here, reused). */
	StaticVector<Eigen::Vector2d, kMaxCandidates> px_;
	StaticVector<Eigen::Vector2d, kMaxCandidates> xy_;
	StaticVector<std::uint8_t, kMaxCandidates> usable_;
	StaticVector<double, kMaxCandidates> var_; /* centroid variance along its major axis, px^2 */
	std::uint64_t clipped_bits_ = 0; /* cand_ positions of spots that reach the clip level */
	StaticVector<Eigen::Matrix2d, kMaxCandidates> cov_; /* centroid covariance, px^2 */
	/* Usable candidates, strongest first, and each one's nearest neighbours (as bits and a list). */
	std::array<int, kMaxCandidates> cand_{};
	/* Usable candidates (px_ indices) sorted by column, and their columns. */
	StaticVector<std::int8_t, kMaxCandidates> by_u_;
	StaticVector<double, kMaxCandidates> u_sorted_;
	int n_cand_ = 0;
	/* Among every candidate, and among the clipped spots alone (see searchQuads()). */
	NeighbourTable neighbours_;
	NeighbourTable clipped_neighbours_;
	/* The candidates (bits of cand_ positions) searchStrongestQuads() took: the strongest. */
	std::uint64_t strongest_ = 0;
	/* This frame's clipped spots have their own pass (clippedPass()). */
	bool clipped_pass_ = false;
	SolveContext context_;
	double log10_quad_tests_ = 0.0; /* hypotheses the full search can form on this frame */
	double log10_triangle_tests_ = 0.0;
	StaticVector<Hypothesis, kMaxKept> kept_;
	int hypotheses_ = 0;
	bool budget_hit_ = false;
	/*
	 * The candidates (bits: indices) a search that found a pose still
	 * forms hypotheses from, while focused_ (earlyExit()); all before.
	 */
	std::uint64_t focus_ = ~std::uint64_t{ 0 };
	bool focused_ = false;
	int verified_ = 0;
	int triangle_leds_ = 4; /* triangleLeds(), while the triangle search runs */
};

} /* namespace dockpose */

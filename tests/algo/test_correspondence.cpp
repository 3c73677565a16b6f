/* SPDX-License-Identifier: MIT */
/*
 * Correspondence on synthetic centroids (no rendering): the model's LEDs
 * projected at a known pose, with noise, clutter points and hidden LEDs.
 * Checks that the right pose is found, that symmetries are folded into one
 * reported pose, and that nothing is reported when the image cannot say.
 */
#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "algo/correspondence.h"
#include "algo/pose.h"
#include "fixtures.h"

using namespace dockpose;

namespace {

/* Three faces around a box corner, the corner towards the camera (-z), no symmetry. */
TargetModel corner()
{
	TargetModel m;
	m.name = "corner";
	/* Box corner at c; unit axes rotated so that the corner points along -z. */
	const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.9553166181245093 + 3.14159265358979323846,
						     Eigen::Vector3d(1, -1, 0).normalized()))
					  .toRotationMatrix();
	auto P = [&](double x, double y, double z) {
		return Eigen::Vector3d(R * Eigen::Vector3d(x, y, z));
	};
	/* LED 0 the corner; 1,2,3 along the edges (different lengths); 4,5,6 on the face corners. */
	m.points_mm.push_back(P(0, 0, 0));
	m.points_mm.push_back(P(-80, 0, 0));
	m.points_mm.push_back(P(0, -60, 0));
	m.points_mm.push_back(P(0, 0, -70));
	m.points_mm.push_back(P(-80, -60, 0));
	m.points_mm.push_back(P(0, -60, -70));
	m.points_mm.push_back(P(-80, 0, -70));
	m.faces.push_back({ 0, 1, 4, 2 });
	m.faces.push_back({ 0, 2, 5, 3 });
	m.faces.push_back({ 0, 3, 6, 1 });
	return m;
}

/* The 1456x1088 camera, with its own small tangential terms. */
CameraIntrinsics cam1456()
{
	return test::camera1456(0.0005, -0.0003);
}

Pose makePose(double roll, double pan, double tilt, double x, double y, double z)
{
	Pose p;
	p.R = rotationFromRollPanTiltDeg({ roll, pan, tilt });
	p.t_mm = { x, y, z };
	return p;
}

/*
 * Blobs at the projections of the LEDs the camera can see (on a face seen
 * from its front within 80 degrees, not hidden) plus clutter.
 */
StaticVector<Blob, kMaxCandidates> observe(const TargetModel &m, const CameraModel &cam,
					   const Pose &pose, std::uint32_t hidden, int clutter,
					   double noise_px, std::mt19937 &rng)
{
	StaticVector<Eigen::Vector3d, kMaxFaces> normals;
	m.frontNormals(&normals);
	const Eigen::Vector3d camera_t = -pose.R.transpose() * pose.t_mm;
	std::uint32_t shining = 0;
	for (std::size_t f = 0; f < m.faces.size(); ++f) {
		Eigen::Vector3d centre = Eigen::Vector3d::Zero();
		for (int k = 0; k < 4; ++k)
			centre += m.points_mm[m.faces[f][k]] / 4.0;
		if (normals[f].dot((camera_t - centre).normalized()) >
		    std::cos(80.0 * M_PI / 180.0))
			for (int k = 0; k < 4; ++k)
				shining |= 1u << m.faces[f][k];
	}
	StaticVector<Blob, kMaxCandidates> blobs;
	std::normal_distribution<double> noise(0.0, noise_px);
	for (std::size_t i = 0; i < m.points_mm.size(); ++i) {
		if ((hidden & (1u << i)) || !(shining & (1u << i)))
			continue;
		Eigen::Vector2d uv;
		if (!cam.project(pose.apply(m.points_mm[i]), &uv) || !cam.inImage(uv))
			continue;
		Blob b;
		b.u_px = uv.x() + noise(rng);
		b.v_px = uv.y() + noise(rng);
		b.weight = 1000;
		blobs.push_back(b);
	}
	std::uniform_real_distribution<double> u(0, cam.intrinsics().width - 1),
		v(0, cam.intrinsics().height - 1);
	for (int c = 0; c < clutter; ++c) {
		Blob b;
		b.u_px = u(rng);
		b.v_px = v(rng);
		b.weight = 900;
		blobs.push_back(b);
	}
	std::shuffle(blobs.begin(), blobs.end(), rng);
	return blobs;
}

void expectPose(const Pose &truth, const Pose &found, double rot_deg, double trans_mm)
{
	EXPECT_LT(rotationAngleDeg(truth.R, found.R), rot_deg);
	EXPECT_LT((truth.t_mm - found.t_mm).norm(), trans_mm)
		<< "true " << truth.t_mm.transpose() << " found " << found.t_mm.transpose();
}

} /* namespace */

TEST(Correspondence, WedgeHasItsHalfTurnSymmetry)
{
	const TargetModel m = test::wedgeModel();
	Correspondence c(m, CameraModel(cam1456()), {});
	ASSERT_EQ(c.symmetries().size(), 2u);
	const auto &s = c.symmetries()[1];
	EXPECT_NEAR(rotationAngleDeg(s.transform.R, Eigen::Matrix3d::Identity()), 180.0, 1e-6);
	/* LED 0 (-89,-38) maps onto LED 5 (89,38). */
	EXPECT_EQ(s.perm[0], 5);
	EXPECT_EQ(s.perm[2], 3);
}

TEST(Correspondence, CornerHasNoSymmetry)
{
	Correspondence c(corner(), CameraModel(cam1456()), {});
	EXPECT_EQ(c.symmetries().size(), 1u);
}

TEST(Correspondence, FindsPoseWithClutterAndHiddenLed)
{
	std::mt19937 rng(7);
	const CameraModel cam(cam1456());
	for (const TargetModel &m : { test::wedgeModel(), corner() }) {
		Correspondence c(m, cam, {});
		int found = 0, trials = 0;
		std::uniform_real_distribution<double> ang(-25, 25), range(300, 2000),
			lat(-0.2, 0.2);
		for (int t = 0; t < 60; ++t) {
			const double z = range(rng);
			const Pose truth = makePose(ang(rng), ang(rng), ang(rng), lat(rng) * z,
						    lat(rng) * z, z);
			const std::uint32_t hidden = (t % 3 == 0) ? (1u << (t % m.points_mm.size()))
								  : 0;
			auto blobs = observe(m, cam, truth, hidden, 8, 0.1, rng);
			CorrespondenceResult r;
			++trials;
			if (c.solve(blobs, nullptr, &r)) {
				++found;
				expectPose(truth, r.refined.pose, 1.0, std::max(3.0, 0.01 * z));
				EXPECT_LT(r.refined.rms_px, 0.5);
			}
		}
		EXPECT_GE(found, trials * 95 / 100) << m.name;
	}
}

/*
 * The early exit leaves rivals unsought, so it never sits above
 * max_log10_nfa - ambiguity_margin, whatever is configured: an early exit
 * configured at +5 stops the search exactly where one at that limit does, and
 * a wider ambiguity margin makes the search go on longer, never shorter.
 */
TEST(Correspondence, TheEarlyExitStaysAMarginBelowTheBound)
{
	std::mt19937 rng(19);
	const CameraModel cam(cam1456());
	const TargetModel m = corner();
	int stopped_sooner = 0;
	for (int t = 0; t < 8; ++t) {
		const Pose truth = makePose(6 - 2 * t, 4 + t, 10 * t, 15, -20, 700 + 150 * t);
		auto blobs = observe(m, cam, truth, 0, 16, 0.1, rng);
		CorrespondenceConfig limit, careless, wide;
		limit.early_exit_log10_nfa = limit.max_log10_nfa - limit.ambiguity_margin;
		careless.early_exit_log10_nfa = 5.0;
		wide.early_exit_log10_nfa = 5.0;
		/* An exit at -18: below every pose here (their log10 NFA: -15 to -16.3). */
		wide.ambiguity_margin = 14.0;
		CorrespondenceResult rl, rc, rw;
		const bool fl = Correspondence(m, cam, limit).solve(blobs, nullptr, &rl);
		const bool fc = Correspondence(m, cam, careless).solve(blobs, nullptr, &rc);
		Correspondence(m, cam, wide).solve(blobs, nullptr, &rw);
		ASSERT_TRUE(fl) << "trial " << t;
		EXPECT_EQ(fl, fc) << "trial " << t;
		EXPECT_EQ(rl.hypotheses, rc.hypotheses) << "trial " << t;
		EXPECT_EQ(rl.log10_nfa, rc.log10_nfa) << "trial " << t;
		EXPECT_LE(rl.hypotheses, rw.hypotheses) << "trial " << t;
		stopped_sooner += rl.hypotheses < rw.hypotheses;
	}
	/* The test means something only where the exit did stop the search early. */
	EXPECT_GE(stopped_sooner, 4);
}

/*
 * At close range a target's LEDs lie far apart in the image and reflections
 * between them push each out of the others' nearest neighbours: no face's
 * four LEDs are among one another's 9 nearest, and the quadrilateral search
 * over every candidate cannot form a face. The LEDs reach the clip level and
 * the reflections do not, so the pass among the clipped spots forms them.
 * The same blobs with no spot marked clipped: the face is found less often.
 */
TEST(Correspondence, ClippedSpotsFormTheirFacesAmongReflectionsBetweenThem)
{
	std::mt19937 rng(23);
	const CameraModel cam(cam1456());
	const TargetModel m = test::wedgeModel();
	Correspondence c(m, cam, {});
	std::uniform_real_distribution<double> ang(-10, 10), range(320, 420);
	int found_clipped = 0, found_unmarked = 0, trials = 0;
	for (int t = 0; t < 20; ++t) {
		const Pose truth = makePose(ang(rng), ang(rng), ang(rng), 0, 0, range(rng));
		StaticVector<Blob, kMaxCandidates> blobs = observe(m, cam, truth, 0, 0, 0.05, rng);
		ASSERT_GE(blobs.size(), 6u);
		double u0 = 1e9, u1 = -1e9, v0 = 1e9, v1 = -1e9;
		for (Blob &b : blobs) {
			u0 = std::min(u0, b.u_px);
			u1 = std::max(u1, b.u_px);
			v0 = std::min(v0, b.v_px);
			v1 = std::max(v1, b.v_px);
			b.saturated_px = 400;
			b.cov_uu_px2 = b.cov_vv_px2 = 0.05 * 0.05;
		}
		/* Unclipped reflections among the LEDs, as dense as 30 in the target's extent. */
		std::uniform_real_distribution<double> u(u0, u1), v(v0, v1);
		for (int k = 0; k < 30; ++k) {
			Blob b;
			b.u_px = u(rng);
			b.v_px = v(rng);
			b.weight = 900;
			b.cov_uu_px2 = b.cov_vv_px2 = 0.05 * 0.05;
			blobs.push_back(b);
		}
		std::shuffle(blobs.begin(), blobs.end(), rng);
		++trials;
		CorrespondenceResult r;
		if (c.solve(blobs, nullptr, &r)) {
			++found_clipped;
			expectPose(truth, r.refined.pose, 1.0, 5.0);
		}
		for (Blob &b : blobs)
			b.saturated_px = 0;
		CorrespondenceResult ru;
		if (c.solve(blobs, nullptr, &ru)) {
			++found_unmarked;
			expectPose(truth, ru.refined.pose, 1.0, 5.0);
		}
	}
	EXPECT_GE(found_clipped, trials * 9 / 10);
	EXPECT_LT(found_unmarked, found_clipped);
}

/*
 * The box corner with its corner LED (shared by all three faces) hidden
 * leaves no face complete: only the triangle search can find the pose, and
 * it solves P3P only for the vertex order a face seen from its front shows.
 * Were that orientation rule wrong, nothing would be found here.
 */
TEST(Correspondence, TrianglesFindThePoseWhenNoFaceIsComplete)
{
	std::mt19937 rng(11);
	const CameraModel cam(cam1456());
	const TargetModel m = corner();
	Correspondence c(m, cam, {});
	std::uniform_real_distribution<double> ang(-20, 20), range(400, 1500), lat(-0.15, 0.15);
	int found = 0, trials = 0;
	for (int t = 0; t < 40; ++t) {
		const double z = range(rng);
		const Pose truth =
			makePose(ang(rng), ang(rng), ang(rng), lat(rng) * z, lat(rng) * z, z);
		auto blobs = observe(m, cam, truth, 1u << 0, 4, 0.1, rng);
		CorrespondenceResult r;
		++trials;
		if (c.solve(blobs, nullptr, &r)) {
			++found;
			expectPose(truth, r.refined.pose, 1.0, std::max(3.0, 0.01 * z));
			EXPECT_EQ(r.match.led_mask & 1u, 0u);
		}
	}
	EXPECT_GE(found, trials * 9 / 10);
}

TEST(Correspondence, ReportsTheSymmetricPoseNearestTheModelOrientation)
{
	std::mt19937 rng(3);
	const CameraModel cam(cam1456());
	const TargetModel m = test::wedgeModel();
	Correspondence c(m, cam, {});
	/* Rolled by 150 degrees about the optical axis the wedge looks like it is rolled by -30. */
	const Pose truth = makePose(0, 0, 150, 20, -10, 900);
	auto blobs = observe(m, cam, truth, 0, 0, 0.05, rng);
	CorrespondenceResult r;
	ASSERT_TRUE(c.solve(blobs, nullptr, &r));
	const Eigen::Vector3d rpy = rollPanTiltDegFromRotation(r.refined.pose.R);
	EXPECT_NEAR(rpy.z(), -30.0, 0.5);
	/* ... but when tracking a pose near 150 degrees, the tracked branch is kept. */
	ASSERT_TRUE(c.solve(blobs, &truth, &r));
	EXPECT_TRUE(r.tracked);
	expectPose(truth, r.refined.pose, 0.5, 2.0);
}

TEST(Correspondence, TrackingUsesThePrediction)
{
	std::mt19937 rng(11);
	const CameraModel cam(cam1456());
	const TargetModel m = corner();
	Correspondence c(m, cam, {});
	const Pose truth = makePose(5, -10, 8, 30, 15, 700);
	Pose predicted = truth;
	predicted.t_mm += Eigen::Vector3d(4, -3, 10);
	auto blobs = observe(m, cam, truth, 0, 6, 0.1, rng);
	CorrespondenceResult r;
	ASSERT_TRUE(c.solve(blobs, &predicted, &r));
	EXPECT_TRUE(r.tracked);
	EXPECT_EQ(r.hypotheses, 0);
	expectPose(truth, r.refined.pose, 0.5, 2.0);
	/* A prediction far off falls back to the full search. */
	predicted.t_mm += Eigen::Vector3d(300, 0, 0);
	ASSERT_TRUE(c.solve(blobs, &predicted, &r));
	EXPECT_FALSE(r.tracked);
	EXPECT_GT(r.hypotheses, 0);
	expectPose(truth, r.refined.pose, 0.5, 2.0);
}

TEST(Correspondence, RandomPointsGiveNoPose)
{
	std::mt19937 rng(5);
	const CameraModel cam(cam1456());
	for (const TargetModel &m : { test::wedgeModel(), corner() }) {
		Correspondence c(m, cam, {});
		for (int t = 0; t < 40; ++t) {
			auto blobs =
				observe(m, cam, makePose(0, 0, 0, 0, 0, 1000), 0x7f, 12, 0.0, rng);
			CorrespondenceResult r;
			EXPECT_FALSE(c.solve(blobs, nullptr, &r)) << m.name << " trial " << t;
		}
	}
}

/*
 * The acceptance is the a-contrario bound and nothing else: an accepted pose's
 * log10 NFA is at most max_log10_nfa, and the same frame with the bound set just
 * below that pose's evidence is refused.
 */
TEST(Correspondence, TheNfaBoundDecidesAcceptance)
{
	std::mt19937 rng(11);
	const CameraModel cam(cam1456());
	for (const TargetModel &m : { test::wedgeModel(), corner() }) {
		int checked = 0;
		for (int t = 0; t < 12; ++t) {
			const Pose truth =
				makePose(10 - 2 * t, 5 + t, 3 * t, 20, -30, 600 + 100 * t);
			auto blobs = observe(m, cam, truth, 0, 10, 0.1, rng);
			Correspondence c(m, cam, {});
			CorrespondenceResult r;
			if (!c.solve(blobs, nullptr, &r))
				continue;
			++checked;
			EXPECT_LE(r.log10_nfa, CorrespondenceConfig{}.max_log10_nfa)
				<< m.name << " trial " << t;
			CorrespondenceConfig strict;
			strict.max_log10_nfa = r.log10_nfa - 1.0; /* the early exit follows */
			Correspondence cs(m, cam, strict);
			CorrespondenceResult rs;
			EXPECT_FALSE(cs.solve(blobs, nullptr, &rs))
				<< m.name << " trial " << t << ": accepted at log10 NFA "
				<< rs.log10_nfa << " with the bound at " << strict.max_log10_nfa;
		}
		EXPECT_GE(checked, 10) << m.name;
	}
}

/*
 * The triangle search's screen (log10NfaFloor) passes bestSubsetLog10Nfa()
 * the smallest of everything a verified pose's NFA uses: tolerances at twice
 * the centroids' sigma, the frame's own density, the fewest tests and no
 * factor C(n - 3, m - 3). Whatever a verification then measures at or above
 * those (residuals, a denser neighbourhood, more tests, more predicted LEDs),
 * its NFA is no smaller than the floor: the screen skips no pose that could
 * be accepted or rival one. Random draws, and the floor reached exactly.
 */
TEST(Correspondence, TheNfaFloorBoundsEveryVerifiedNfa)
{
	std::mt19937 rng(17);
	std::uniform_real_distribution<double> unit(0.0, 1.0);
	for (int trial = 0; trial < 2000; ++trial) {
		const int k = 4 + static_cast<int>(unit(rng) * (kMaxLeds - 3));
		std::array<double, kMaxLeds> floor2{}, tol2{};
		for (int i = 0; i < k; ++i) {
			const double sigma_px = 0.02 + 2.0 * unit(rng) * unit(rng);
			floor2[i] = 4.0 * sigma_px * sigma_px;
			tol2[i] = floor2[i] * (1.0 + (unit(rng) < 0.3 ? 0.0 : 50.0 * unit(rng)));
		}
		std::sort(floor2.begin(), floor2.begin() + k);
		std::sort(tol2.begin(), tol2.begin() + k);
		const double rho = (1.0 + 63.0 * unit(rng)) / (1456.0 * 1088.0);
		const double tests = 2.0 + 4.0 * unit(rng);
		const double floor = bestSubsetLog10Nfa(floor2.data(), k, -1, rho, tests);
		const int n = k + static_cast<int>(unit(rng) * 4.0);
		const double nfa = bestSubsetLog10Nfa(tol2.data(), k, n, rho * (1.0 + unit(rng)),
						      tests + std::log10(k - 3.0));
		EXPECT_LE(floor, nfa + 1e-12) << "trial " << trial << ", k " << k;
		/* At the floor's own inputs with n = k (C = 1 for m = k) nothing is lost. */
		EXPECT_LE(bestSubsetLog10Nfa(floor2.data(), k, k, rho, tests),
			  floor + 1e-12 + std::log10(static_cast<double>(1 << (k - 3))));
	}
	/* One term by hand: four LEDs, 0.1 px sigma, 20 candidates in a 1456x1088 frame. */
	const double tol2[4] = { 0.04, 0.04, 0.04, 0.04 };
	const double rho = 20.0 / (1456.0 * 1088.0);
	const double p = 1.0 - std::exp(-rho * 3.14159265358979323846 * 0.04);
	EXPECT_NEAR(bestSubsetLog10Nfa(tol2, 4, -1, rho, 3.0), 3.0 + std::log10(p), 1e-9);
	EXPECT_NEAR(bestSubsetLog10Nfa(tol2, 4, 9, rho, 3.0), 3.0 + std::log10(6.0 * p), 1e-9);
}

/*
 * The same LEDs among more clutter are weaker evidence: the density of unmatched
 * points enters the NFA, so the accepted pose's log10 NFA rises (towards the
 * bound) as clutter is added around it.
 */
TEST(Correspondence, ClutterWeakensTheEvidence)
{
	std::mt19937 rng(13);
	const CameraModel cam(cam1456());
	const TargetModel m = corner();
	const Pose truth = makePose(8, -12, 20, 15, 10, 700);
	auto sparse = observe(m, cam, truth, 0, 0, 0.1, rng);
	auto dense = sparse;
	std::uniform_real_distribution<double> u(0, cam.intrinsics().width - 1),
		v(0, cam.intrinsics().height - 1);
	while (dense.size() < 40) {
		Blob b;
		b.u_px = u(rng);
		b.v_px = v(rng);
		b.weight = 900;
		dense.push_back(b);
	}
	Correspondence c(m, cam, {});
	CorrespondenceResult rs, rd;
	ASSERT_TRUE(c.solve(sparse, nullptr, &rs));
	ASSERT_TRUE(c.solve(dense, nullptr, &rd));
	EXPECT_LT(rs.log10_nfa, rd.log10_nfa);
	expectPose(truth, rd.refined.pose, 1.0, 7.0);
}

/*
 * A frame full of random points (the candidate list's capacity) and no target:
 * the search may test tens of thousands of hypotheses, and none may be accepted.
 */
TEST(Correspondence, DenseRandomPointsGiveNoPose)
{
	std::mt19937 rng(17);
	const CameraModel cam(cam1456());
	std::uniform_real_distribution<double> u(0, cam.intrinsics().width - 1),
		v(0, cam.intrinsics().height - 1);
	for (const TargetModel &m : { test::wedgeModel(), corner() }) {
		Correspondence c(m, cam, {});
		for (int t = 0; t < 15; ++t) {
			StaticVector<Blob, kMaxCandidates> blobs;
			while (blobs.size() < kMaxCandidates) {
				Blob b;
				b.u_px = u(rng);
				b.v_px = v(rng);
				b.weight = 900;
				blobs.push_back(b);
			}
			CorrespondenceResult r;
			EXPECT_FALSE(c.solve(blobs, nullptr, &r))
				<< m.name << " trial " << t << ": log10 NFA " << r.log10_nfa;
		}
	}
}

TEST(Correspondence, TooFewPointsGiveNoPose)
{
	std::mt19937 rng(1);
	const CameraModel cam(cam1456());
	const TargetModel m = test::wedgeModel();
	Correspondence c(m, cam, {});
	/* Only three LEDs visible. */
	auto blobs = observe(m, cam, makePose(0, 0, 0, 0, 0, 800), 0b111000, 0, 0.05, rng);
	CorrespondenceResult r;
	EXPECT_FALSE(c.solve(blobs, nullptr, &r));
}

TEST(Correspondence, SingleFaceFarAndObliqueIsAmbiguousNotWrong)
{
	/* A target of one square face: far away, small and tilted, the two planar
	 * solutions explain the four points equally well. Either the right pose
	 * or nothing may come out — never the mirror. */
	TargetModel m;
	m.name = "square";
	for (const auto &p : { Eigen::Vector3d(-40, -40, 0), Eigen::Vector3d(40, -40, 0),
			       Eigen::Vector3d(40, 40, 0), Eigen::Vector3d(-40, 40, 0) })
		m.points_mm.push_back(p);
	m.faces.push_back({ 0, 1, 2, 3 });
	std::mt19937 rng(9);
	const CameraModel cam(cam1456());
	CorrespondenceConfig cfg;
	cfg.max_missing = 0;
	Correspondence c(m, cam, cfg);
	int wrong = 0, found = 0;
	for (int t = 0; t < 40; ++t) {
		const Pose truth = makePose(20, 15, 10 * t, 0, 0, 2000);
		auto blobs = observe(m, cam, truth, 0, 0, 0.3, rng);
		CorrespondenceResult r;
		if (c.solve(blobs, nullptr, &r)) {
			++found;
			/* Square symmetry: compare up to the model's own symmetries. */
			double best = 1e9;
			for (const auto &s : c.symmetries())
				best = std::min(best,
						rotationAngleDeg(truth.R,
								 r.refined.pose.R * s.transform.R));
			wrong += best > 3.0;
		}
	}
	EXPECT_EQ(wrong, 0) << "found " << found;

	/* Near and clearly tilted, the mirror solution fits far worse: found, and right. */
	int near_found = 0;
	for (int t = 0; t < 20; ++t) {
		const Pose truth = makePose(35, 25, 15 * t, 10, -5, 400);
		auto blobs = observe(m, cam, truth, 0, 0, 0.1, rng);
		CorrespondenceResult r;
		if (c.solve(blobs, nullptr, &r)) {
			++near_found;
			double best = 1e9;
			for (const auto &s : c.symmetries())
				best = std::min(best,
						rotationAngleDeg(truth.R,
								 r.refined.pose.R * s.transform.R));
			EXPECT_LT(best, 1.0);
		}
	}
	EXPECT_GE(near_found, 18);
}

TEST(Correspondence, AReflectionNearAFarLedDoesNotTurnTheFaceOver)
{
	/*
	 * The blobs (centroids, covariances, weights) the pipeline found in a frame of
	 * dockpose-accuracy (wedge, 1456 px, legacy seed 42, frame 1347) that gave a wrong pose:
	 * one face complete at 384 mm, a ridge LED of the other face, its far LED out of sight
	 * and a reflection 47 px from where it would be. The closed-form pose matched with the
	 * wide first gate took the reflection, the fit it pulled fell into the face's other
	 * minimum, and the face turned by half about its normal (48 degrees off) fitted its four
	 * LEDs exactly. The face's own points refine the pose before it is matched now.
	 */
	const CameraModel cam(cam1456());
	const TargetModel m = test::wedgeModel();
	Pose truth;
	truth.R = Eigen::AngleAxisd(
			  0.311398683,
			  Eigen::Vector3d(-0.292763852, 0.944857394, -0.146744105).normalized())
			  .toRotationMatrix();
	truth.t_mm = { -18.588317, -9.944561, 384.391099 };
	const double seen[][6] = {
		{ 1003.280683, 20.598316, 4.392e-06, 2.529e-08, 4.409e-06, 137892.0 },
		{ 1014.916880, 633.123788, 4.955e-06, -1.733e-08, 4.955e-06, 126757.0 },
		{ 580.263460, 667.880826, 8.802e-05, -1.597e-08, 8.815e-05, 122804.0 },
		{ 571.731519, 290.652240, 8.969e-05, -7.264e-08, 8.980e-05, 114116.0 },
		{ 1038.663029, 291.278810, 9.130e-05, 1.053e-07, 9.139e-05, 109232.0 },
		{ 292.413957, 683.856105, 9.815e-05, -3.256e-08, 1.006e-04, 47889.0 },
		{ 290.402402, 366.189934, 8.399e-05, -4.356e-07, 8.694e-05, 44468.0 },
	};
	StaticVector<Blob, kMaxCandidates> blobs;
	for (const auto &s : seen) {
		Blob b;
		b.u_px = s[0];
		b.v_px = s[1];
		b.cov_uu_px2 = s[2];
		b.cov_uv_px2 = s[3];
		b.cov_vv_px2 = s[4];
		b.weight = s[5];
		blobs.push_back(b);
	}
	Correspondence c(m, cam, {});
	CorrespondenceResult r;
	ASSERT_TRUE(c.solve(blobs, nullptr, &r));
	EXPECT_EQ(r.match.pairs.size(), 5u);
	/* The wedge's half turn about its axis is the same pose (a symmetry of the model). */
	const double direct = rotationAngleDeg(truth.R, r.refined.pose.R);
	const double turned =
		rotationAngleDeg(truth.R * c.symmetries().back().transform.R, r.refined.pose.R);
	EXPECT_LT(std::min(direct, turned), 0.5)
		<< "direct " << direct << " deg, half-turned " << turned << " deg";
}

TEST(Correspondence, ASpotPulledOffItsLedIsLeftOutNotMatchedAgain)
{
	/*
	 * One LED's spot merged with a reflection: its centroid sits 3 px off, well
	 * inside the gate. The refinement drops it as the worst match; matching again
	 * from the cleaner pose must not take that same spot back (it is the nearest
	 * within the gate), or the fit only repeats and the pose is refused as an
	 * error too large, though the other six LEDs fit it exactly. (Frames of the
	 * independent renderer, tests/algo/independent_renderer.py, showed it.)
	 */
	const CameraModel cam(cam1456());
	const TargetModel m = corner();
	const Pose truth = makePose(10, -15, 5, 20, -10, 700);
	std::mt19937 rng(3);
	auto blobs = observe(m, cam, truth, 0, 0, 0.0, rng);
	ASSERT_EQ(blobs.size(), m.points_mm.size());
	Eigen::Vector2d led4;
	ASSERT_TRUE(cam.project(truth.apply(m.points_mm[4]), &led4));
	int pulled = -1;
	for (std::size_t j = 0; j < blobs.size(); ++j) {
		Blob &b = blobs[j];
		b.cov_uu_px2 = b.cov_vv_px2 = 0.05 * 0.05;
		if ((Eigen::Vector2d(b.u_px, b.v_px) - led4).norm() < 1e-6) {
			b.u_px += 2.4;
			b.v_px -= 1.8;
			pulled = static_cast<int>(j);
		}
	}
	ASSERT_GE(pulled, 0);
	Correspondence c(m, cam, {});
	CorrespondenceResult r;
	ASSERT_TRUE(c.solve(blobs, nullptr, &r)) << "error too large: " << r.error_too_large;
	EXPECT_EQ(r.match.pairs.size(), m.points_mm.size() - 1);
	for (const auto &pair : r.match.pairs)
		EXPECT_NE(pair[1], pulled);
	expectPose(truth, r.refined.pose, 0.1, 0.5);
}

TEST(Correspondence, AFitAcceptedOnItsPixelErrorCarriesTheErrorItShows)
{
	/*
	 * One LED's spot merged with a reflection 0.8 px off, its covariance
	 * (0.03 px) that of a bright spot: the fit is accepted on max_rms_px
	 * though its chi2 lies far beyond its 99.9 % point. Its covariance must
	 * say the error the residuals show (scaled by chi2 / dof), not the
	 * centroids' alone: on the independent renderer's frames such a pose,
	 * rotated 3.2 deg, carried a sigma of 0.12 deg and passed the precision
	 * limit. A fit within its point keeps the propagated covariance.
	 */
	const CameraModel cam(cam1456());
	const TargetModel m = corner();
	const Pose truth = makePose(10, -15, 5, 20, -10, 1400);
	std::mt19937 rng(3);
	const auto clean = observe(m, cam, truth, 0, 0, 0.0, rng);
	ASSERT_EQ(clean.size(), m.points_mm.size());
	auto pulled = clean;
	for (Blob &b : pulled)
		b.cov_uu_px2 = b.cov_vv_px2 = 0.03 * 0.03;
	auto exact = pulled;
	pulled[2].u_px += 0.6;
	pulled[2].v_px -= 0.5;

	Correspondence c(m, cam, {});
	CorrespondenceResult r;
	ASSERT_TRUE(c.solve(pulled, nullptr, &r)) << "error too large: " << r.error_too_large;
	ASSERT_EQ(r.match.pairs.size(), m.points_mm.size());
	const int n = static_cast<int>(r.match.pairs.size());
	const double dof = 2.0 * n - 6.0;
	ASSERT_GT(r.refined.chi2, 3.0 * dof);
	ASSERT_LT(r.refined.rms_px, CorrespondenceConfig{}.max_rms_px);

	/* The same match refined alone: the centroids' covariance, unscaled. */
	std::array<Eigen::Vector3d, kMaxLeds> model;
	std::array<Eigen::Vector2d, kMaxLeds> px;
	std::array<Eigen::Matrix2d, kMaxLeds> cov;
	for (int i = 0; i < n; ++i) {
		const auto &pair = r.match.pairs[static_cast<std::size_t>(i)];
		const Blob &b = pulled[static_cast<std::size_t>(pair[1])];
		model[static_cast<std::size_t>(i)] = m.points_mm[static_cast<std::size_t>(pair[0])];
		px[static_cast<std::size_t>(i)] = { b.u_px, b.v_px };
		cov[static_cast<std::size_t>(i)] << b.cov_uu_px2, b.cov_uv_px2, b.cov_uv_px2,
			b.cov_vv_px2;
	}
	RefineOptions o;
	o.led_sigma_mm = m.led_sigma_mm;
	RefineResult alone;
	ASSERT_TRUE(
		refinePose(cam, model.data(), px.data(), n, r.refined.pose, o, &alone, cov.data()));
	for (int k = 0; k < 6; ++k)
		EXPECT_NEAR(r.refined.covariance(k, k) / alone.covariance(k, k),
			    r.refined.chi2 / dof, 0.02 * r.refined.chi2 / dof)
			<< "axis " << k;

	/* The exact spots: chi2 within its point, the covariance as propagated. */
	ASSERT_TRUE(c.solve(exact, nullptr, &r));
	ASSERT_LT(r.refined.chi2, dof);
	RefineResult exact_alone;
	for (int i = 0; i < n; ++i) {
		const auto &pair = r.match.pairs[static_cast<std::size_t>(i)];
		const Blob &b = exact[static_cast<std::size_t>(pair[1])];
		px[static_cast<std::size_t>(i)] = { b.u_px, b.v_px };
		model[static_cast<std::size_t>(i)] = m.points_mm[static_cast<std::size_t>(pair[0])];
	}
	ASSERT_TRUE(refinePose(cam, model.data(), px.data(), n, r.refined.pose, o, &exact_alone,
			       cov.data()));
	EXPECT_NEAR(r.refined.covariance(0, 0), exact_alone.covariance(0, 0),
		    1e-6 * exact_alone.covariance(0, 0));
}

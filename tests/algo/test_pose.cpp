/* SPDX-License-Identifier: MIT */
/*
 * Pose math: rotation conventions, the closed form for four coplanar points
 * (method.md section 5), Horn's fit (section 6, against Eigen's Umeyama as
 * an independent reference), and the refinement with its covariance (against
 * the empirical scatter over many noise draws).
 */
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "algo/camera_model.h"
#include "algo/pose.h"
#include "fixtures.h"

using namespace dockpose;

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

/* The elementary rotations written out (the reference for the convention). */
Eigen::Matrix3d Rx(double a)
{
	Eigen::Matrix3d r;
	r << 1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a);
	return r;
}

Eigen::Matrix3d Ry(double a)
{
	Eigen::Matrix3d r;
	r << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
	return r;
}

Eigen::Matrix3d Rz(double a)
{
	Eigen::Matrix3d r;
	r << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
	return r;
}

Eigen::Matrix3d randomRotation(std::mt19937 &rng)
{
	std::normal_distribution<double> g;
	Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
	return q.normalized().toRotationMatrix();
}

Eigen::Vector3d randomUnit(std::mt19937 &rng)
{
	std::normal_distribution<double> g;
	return Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
}

/* Rotation vector w with exp([w]x) = R. */
Eigen::Vector3d logRotation(const Eigen::Matrix3d &R)
{
	const Eigen::AngleAxisd aa(R);
	return aa.angle() * aa.axis();
}

double angleRad(const Eigen::Matrix3d &a, const Eigen::Matrix3d &b)
{
	return Eigen::AngleAxisd(a.transpose() * b).angle();
}

using test::distortedCamera;

/* The wedge of method.md section 3. */
const TargetModel kWedge = test::wedgeModel();

/*
 * A random convex quadrilateral: four points on an ellipse at increasing
 * angles (at least 35 deg apart), in a random plane of the model frame.
 */
void randomConvexQuad(std::mt19937 &rng, Eigen::Vector3d quad[4])
{
	std::uniform_real_distribution<double> axis(30.0, 150.0);
	std::uniform_real_distribution<double> angle(0.0, 2.0 * kPi);
	std::uniform_real_distribution<double> offset(-300.0, 300.0);
	const double a = axis(rng), b = axis(rng);
	double th[4];
	for (;;) {
		for (double &t : th)
			t = angle(rng);
		std::sort(th, th + 4);
		bool ok = th[0] + 2.0 * kPi - th[3] > 35.0 * kDeg;
		for (int i = 0; i < 3; ++i)
			ok = ok && th[i + 1] - th[i] > 35.0 * kDeg;
		if (ok)
			break;
	}
	const Eigen::Matrix3d Rm = randomRotation(rng);
	const Eigen::Vector3d o{ offset(rng), offset(rng), offset(rng) };
	for (int i = 0; i < 4; ++i)
		quad[i] = Rm * Eigen::Vector3d(a * std::cos(th[i]), b * std::sin(th[i]), 0.0) + o;
}

/*
 * A random pose that puts the quad's centroid at range 300..2000 mm within
 * 15 deg of the optical axis, with the face seen from the requested side
 * (sign of the face normal (M1 - M0) x (M2 - M0) along the viewing ray) and
 * no more obliquely than max_oblique_deg.
 */
Pose randomPoseFacing(std::mt19937 &rng, const Eigen::Vector3d quad[4], bool front,
		      double max_oblique_deg)
{
	std::uniform_real_distribution<double> range(300.0, 2000.0);
	std::uniform_real_distribution<double> off(-0.27, 0.27);
	const Eigen::Vector3d centroid = (quad[0] + quad[1] + quad[2] + quad[3]) / 4.0;
	const Eigen::Vector3d n_model = (quad[1] - quad[0]).cross(quad[2] - quad[0]).normalized();
	for (;;) {
		const double z = range(rng);
		const Eigen::Vector3d c{ off(rng) * z, off(rng) * z, z };
		Eigen::Matrix3d R = randomRotation(rng);
		Eigen::Vector3d n = R * n_model;
		const Eigen::Vector3d ray = c.normalized();
		if ((n.dot(ray) < 0.0) != front) {
			/* Turn the face over: a half turn about an axis in its plane. */
			const Eigen::Vector3d u = n.cross(randomUnit(rng)).normalized();
			R = Eigen::AngleAxisd(kPi, u).toRotationMatrix() * R;
			n = R * n_model;
		}
		if (std::acos(std::abs(n.dot(ray))) > max_oblique_deg * kDeg)
			continue;
		Pose pose;
		pose.R = R;
		pose.t_mm = c - R * centroid;
		bool in_front = true;
		for (int i = 0; i < 4; ++i)
			in_front = in_front && pose.apply(quad[i]).z() > 50.0;
		if (in_front)
			return pose;
	}
}

void projectIdeal(const Pose &pose, const Eigen::Vector3d *model, int n, Eigen::Vector2d *xy)
{
	for (int i = 0; i < n; ++i) {
		const Eigen::Vector3d p = pose.apply(model[i]);
		xy[i] = { p.x() / p.z(), p.y() / p.z() };
	}
}

} /* namespace */

/* ---------------------------------------------------------------- conventions */

TEST(Rotation, RollPanTiltIsRxRyRz)
{
	std::mt19937 rng(1);
	std::uniform_real_distribution<double> u(-180.0, 180.0);
	for (int i = 0; i < 200; ++i) {
		const Eigen::Vector3d rpy{ u(rng), u(rng) / 2.0, u(rng) };
		const Eigen::Matrix3d expected =
			Rx(rpy.x() * kDeg) * Ry(rpy.y() * kDeg) * Rz(rpy.z() * kDeg);
		EXPECT_LT((rotationFromRollPanTiltDeg(rpy) - expected).norm(), 1e-14);
	}
	/* Roll alone turns about camera x: +90 deg takes y (down) to z (forward). */
	EXPECT_LT((rotationFromRollPanTiltDeg({ 90, 0, 0 }) * Eigen::Vector3d::UnitY() -
		   Eigen::Vector3d::UnitZ())
			  .norm(),
		  1e-15);
	/* Pan alone turns about y: +90 deg takes z to x. */
	EXPECT_LT((rotationFromRollPanTiltDeg({ 0, 90, 0 }) * Eigen::Vector3d::UnitZ() -
		   Eigen::Vector3d::UnitX())
			  .norm(),
		  1e-15);
	/* Tilt alone turns about z: +90 deg takes x to y. */
	EXPECT_LT((rotationFromRollPanTiltDeg({ 0, 0, 90 }) * Eigen::Vector3d::UnitX() -
		   Eigen::Vector3d::UnitY())
			  .norm(),
		  1e-15);
	/* The order: roll applied last (outermost), tilt first. */
	const Eigen::Matrix3d R = rotationFromRollPanTiltDeg({ 90, 90, 0 });
	EXPECT_LT((R * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitX()).norm(), 1e-15);
	EXPECT_LT((R * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 1e-15);
}

TEST(Rotation, RollPanTiltRoundTrip)
{
	std::mt19937 rng(2);
	std::uniform_real_distribution<double> u(-179.9, 179.9);
	std::uniform_real_distribution<double> p(-89.9, 89.9);
	for (int i = 0; i < 1000; ++i) {
		const Eigen::Vector3d rpy{ u(rng), p(rng), u(rng) };
		const Eigen::Vector3d back =
			rollPanTiltDegFromRotation(rotationFromRollPanTiltDeg(rpy));
		EXPECT_LT((back - rpy).norm(), 1e-9)
			<< rpy.transpose() << " -> " << back.transpose();
	}
	for (int i = 0; i < 1000; ++i) {
		const Eigen::Matrix3d R = randomRotation(rng);
		const Eigen::Vector3d rpy = rollPanTiltDegFromRotation(R);
		EXPECT_LE(std::abs(rpy.y()), 90.0);
		EXPECT_LT((rotationFromRollPanTiltDeg(rpy) - R).norm(), 1e-12);
	}
}

TEST(Rotation, GimbalLockIsGraceful)
{
	std::mt19937 rng(3);
	std::uniform_real_distribution<double> u(-179.0, 179.0);
	for (double pan : { 90.0, -90.0, 90.0 - 1e-6, -90.0 + 1e-9, 90.0 - 1e-12, 89.99 }) {
		for (int i = 0; i < 50; ++i) {
			const Eigen::Matrix3d R =
				rotationFromRollPanTiltDeg({ u(rng), pan, u(rng) });
			const Eigen::Vector3d rpy = rollPanTiltDegFromRotation(R);
			ASSERT_TRUE(rpy.allFinite());
			EXPECT_LE(std::abs(rpy.y()), 90.0);
			EXPECT_NEAR(rpy.y(), pan, 1e-5);
			EXPECT_LT((rotationFromRollPanTiltDeg(rpy) - R).norm(), 1e-12) << pan;
		}
	}
}

TEST(Rotation, QuaternionHasNonNegativeW)
{
	std::mt19937 rng(4);
	for (int i = 0; i < 2000; ++i) {
		Eigen::Matrix3d R = randomRotation(rng);
		if (i % 10 == 0) /* half turns: w = 0 up to rounding */
			R = Eigen::AngleAxisd(kPi, randomUnit(rng)).toRotationMatrix();
		const Eigen::Quaterniond q = quaternionFromRotation(R);
		EXPECT_GE(q.w(), 0.0);
		EXPECT_NEAR(q.norm(), 1.0, 1e-15);
		EXPECT_LT((q.toRotationMatrix() - R).norm(), 1e-14);
	}
	/* A quarter turn about z. */
	const Eigen::Quaterniond q = quaternionFromRotation(Rz(kPi / 2));
	EXPECT_NEAR(q.w(), std::sqrt(0.5), 1e-15);
	EXPECT_NEAR(q.z(), std::sqrt(0.5), 1e-15);
	EXPECT_NEAR(q.x(), 0.0, 1e-15);
	EXPECT_NEAR(q.y(), 0.0, 1e-15);
	/* Three quarters about z is a quarter the other way, with w >= 0. */
	const Eigen::Quaterniond q3 = quaternionFromRotation(Rz(1.5 * kPi));
	EXPECT_NEAR(q3.w(), std::sqrt(0.5), 1e-15);
	EXPECT_NEAR(q3.z(), -std::sqrt(0.5), 1e-15);
}

TEST(Rotation, AngleBetweenRotations)
{
	std::mt19937 rng(5);
	for (double deg : { 0.0, 1e-7, 1e-3, 0.5, 30.0, 90.0, 170.0, 179.999, 180.0 }) {
		const Eigen::Matrix3d a = randomRotation(rng);
		const Eigen::Matrix3d b =
			a * Eigen::AngleAxisd(deg * kDeg, randomUnit(rng)).toRotationMatrix();
		EXPECT_NEAR(rotationAngleDeg(a, b), deg, 1e-9 * std::max(1.0, deg)) << deg;
		EXPECT_NEAR(rotationAngleDeg(b, a), deg, 1e-9 * std::max(1.0, deg)) << deg;
	}
}

/* ---------------------------------------------------------- four coplanar points */

TEST(SolveFourCoplanar, ExactOnNoiseFreeProjectionsFromBothSides)
{
	std::mt19937 rng(10);
	int solved[2] = { 0, 0 };
	for (int trial = 0; trial < 600; ++trial) {
		const bool front = trial % 2 == 0;
		Eigen::Vector3d quad[4];
		randomConvexQuad(rng, quad);
		const Pose truth = randomPoseFacing(rng, quad, front, 70.0);
		Eigen::Vector2d xy[4];
		projectIdeal(truth, quad, 4, xy);

		const double size = (quad[0] - quad[2]).norm() + (quad[1] - quad[3]).norm();
		const double tol_t = 1e-9 * truth.t_mm.norm();
		const double tol_rad = 1e-9;

		Pose pose;
		double rms = -1.0;
		ASSERT_TRUE(solveFourCoplanar(quad, xy, &pose, &rms)) << "trial " << trial;
		EXPECT_LT(angleRad(pose.R, truth.R), tol_rad) << "trial " << trial;
		EXPECT_LT((pose.t_mm - truth.t_mm).norm(), tol_t) << "trial " << trial;
		EXPECT_LT(rms, 1e-9 * size);
		EXPECT_NEAR(pose.R.determinant(), 1.0, 1e-12);
		solved[front]++;

		/* The same correspondences listed in reverse order, and cyclically shifted. */
		Eigen::Vector3d quad_r[4], quad_s[4];
		Eigen::Vector2d xy_r[4], xy_s[4];
		for (int i = 0; i < 4; ++i) {
			quad_r[i] = quad[3 - i];
			xy_r[i] = xy[3 - i];
			quad_s[i] = quad[(i + 1) % 4];
			xy_s[i] = xy[(i + 1) % 4];
		}
		ASSERT_TRUE(solveFourCoplanar(quad_r, xy_r, &pose));
		EXPECT_LT(angleRad(pose.R, truth.R), tol_rad);
		EXPECT_LT((pose.t_mm - truth.t_mm).norm(), tol_t);
		ASSERT_TRUE(solveFourCoplanar(quad_s, xy_s, &pose));
		EXPECT_LT(angleRad(pose.R, truth.R), tol_rad);
		EXPECT_LT((pose.t_mm - truth.t_mm).norm(), tol_t);
	}
	EXPECT_EQ(solved[0], 300);
	EXPECT_EQ(solved[1], 300);
}

TEST(SolveFourCoplanar, WedgeFacesAtWorkingRanges)
{
	std::mt19937 rng(11);
	std::uniform_real_distribution<double> ang(-40.0, 40.0);
	std::uniform_real_distribution<double> range(150.0, 2100.0);
	for (int trial = 0; trial < 200; ++trial) {
		Pose truth;
		truth.R = rotationFromRollPanTiltDeg({ ang(rng), ang(rng), ang(rng) });
		truth.t_mm = { 0.05 * ang(rng), 0.05 * ang(rng), range(rng) };
		for (const auto &f : kWedge.faces) {
			Eigen::Vector3d quad[4];
			for (int i = 0; i < 4; ++i)
				quad[i] = kWedge.points_mm[f[i]];
			Eigen::Vector2d xy[4];
			projectIdeal(truth, quad, 4, xy);
			Pose pose;
			ASSERT_TRUE(solveFourCoplanar(quad, xy, &pose));
			EXPECT_LT(angleRad(pose.R, truth.R), 1e-9);
			EXPECT_LT((pose.t_mm - truth.t_mm).norm(), 1e-9 * truth.t_mm.norm());
		}
	}
}

TEST(SolveFourCoplanar, RefusesCollinearPoints)
{
	const Eigen::Vector3d square[4] = { { 0, 0, 0 },
					    { 100, 0, 0 },
					    { 100, 100, 0 },
					    { 0, 100, 0 } };
	Pose truth;
	truth.R = rotationFromRollPanTiltDeg({ 10, -20, 5 });
	truth.t_mm = { 20, -10, 800 };
	Eigen::Vector2d xy[4];
	projectIdeal(truth, square, 4, xy);
	Pose pose;
	ASSERT_TRUE(solveFourCoplanar(square, xy, &pose));

	/* Three image points on a line (the third moved onto the line of 1 and 3). */
	Eigen::Vector2d bad[4] = { xy[0], xy[1], 0.5 * (xy[1] + xy[3]), xy[3] };
	EXPECT_FALSE(solveFourCoplanar(square, bad, &pose));
	/* All four image points on a line. */
	for (int i = 0; i < 4; ++i)
		bad[i] = xy[0] + (xy[2] - xy[0]) * (0.3 * i);
	EXPECT_FALSE(solveFourCoplanar(square, bad, &pose));
	/* Three collinear model points. */
	const Eigen::Vector3d line_model[4] = { { 0, 0, 0 },
						{ 100, 0, 0 },
						{ 200, 0, 0 },
						{ 0, 100, 0 } };
	EXPECT_FALSE(solveFourCoplanar(line_model, xy, &pose));
	/* A face seen exactly edge-on. */
	Pose edge = truth;
	edge.R << 1, 0, 0, 0, 0, -1, 0, 1, 0; /* the square's plane contains the optical axis */
	edge.t_mm = { 0, 0, 800 };
	projectIdeal(edge, square, 4, bad);
	EXPECT_FALSE(solveFourCoplanar(square, bad, &pose));
	/* Coincident points and non-finite input. */
	for (int i = 0; i < 4; ++i)
		bad[i] = xy[0];
	EXPECT_FALSE(solveFourCoplanar(square, bad, &pose));
	bad[0] = xy[0];
	bad[1] = { std::nan(""), 0.0 };
	bad[2] = xy[2];
	bad[3] = xy[3];
	EXPECT_FALSE(solveFourCoplanar(square, bad, &pose));
}

TEST(SolveFourCoplanar, RefusesCrossedOrder)
{
	/* A convex image quad matched in crossed (bow-tie) order gives depths of mixed sign. */
	std::mt19937 rng(12);
	for (int trial = 0; trial < 200; ++trial) {
		Eigen::Vector3d quad[4];
		randomConvexQuad(rng, quad);
		const Pose truth = randomPoseFacing(rng, quad, trial % 2 == 0, 70.0);
		Eigen::Vector2d xy[4];
		projectIdeal(truth, quad, 4, xy);
		std::swap(xy[1], xy[2]);
		Pose pose;
		EXPECT_FALSE(solveFourCoplanar(quad, xy, &pose)) << "trial " << trial;
	}
}

TEST(SolveFourCoplanar, WrongCyclicMatchShowsInTheFitError)
{
	std::mt19937 rng(13);
	std::vector<double> relative_rms;
	for (int trial = 0; trial < 200; ++trial) {
		Eigen::Vector3d quad[4];
		randomConvexQuad(rng, quad);
		const Pose truth = randomPoseFacing(rng, quad, true, 60.0);
		Eigen::Vector2d xy[4], shifted[4];
		projectIdeal(truth, quad, 4, xy);
		for (int i = 0; i < 4; ++i)
			shifted[i] = xy[(i + 1) % 4];
		const double size = (quad[0] - quad[2]).norm();
		Pose pose;
		double rms = 0.0;
		if (solveFourCoplanar(quad, shifted, &pose, &rms))
			relative_rms.push_back(rms / size);
		else
			relative_rms.push_back(1.0);
	}
	std::sort(relative_rms.begin(), relative_rms.end());
	EXPECT_GT(relative_rms[relative_rms.size() / 2], 0.02);
	EXPECT_GT(relative_rms[relative_rms.size() / 10], 1e-3);
}

TEST(SolveFourCoplanar, DegradesGracefullyWithNoise)
{
	std::mt19937 rng(14);
	std::normal_distribution<double> noise(0.0, 0.3 / 1739.0);
	std::vector<double> rot_err, rel_t_err;
	for (int trial = 0; trial < 300; ++trial) {
		Eigen::Vector3d quad[4];
		for (int i = 0; i < 4; ++i)
			quad[i] = kWedge.points_mm[i];
		Pose truth;
		truth.R = rotationFromRollPanTiltDeg({ 10.0, 20.0, -5.0 });
		truth.t_mm = { 30, -20, 600 };
		Eigen::Vector2d xy[4];
		projectIdeal(truth, quad, 4, xy);
		for (auto &p : xy)
			p += Eigen::Vector2d(noise(rng), noise(rng));
		Pose pose;
		ASSERT_TRUE(solveFourCoplanar(quad, xy, &pose));
		rot_err.push_back(rotationAngleDeg(pose.R, truth.R));
		rel_t_err.push_back((pose.t_mm - truth.t_mm).norm() / truth.t_mm.norm());
	}
	std::sort(rot_err.begin(), rot_err.end());
	std::sort(rel_t_err.begin(), rel_t_err.end());
	/* 0.3 px on a ~90 px face: errors of a degree or so, percent of range or less. */
	EXPECT_LT(rot_err[rot_err.size() / 2], 2.0);
	EXPECT_GT(rot_err[rot_err.size() / 2], 1e-4); /* the noise does reach the result */
	EXPECT_LT(rel_t_err[rel_t_err.size() / 2], 0.01);
}

/* ---------------------------------------------------------------------- Horn */

TEST(HornFit, ExactOnNoiseFreeData)
{
	std::mt19937 rng(20);
	std::uniform_real_distribution<double> coord(-100.0, 100.0);
	std::uniform_real_distribution<double> scale(0.3, 3.0);
	std::uniform_int_distribution<int> count(3, 16);
	for (int trial = 0; trial < 500; ++trial) {
		const int n = count(rng);
		const bool planar = trial % 3 == 0;
		/* Far from the origin on both sides: the centroid form of t matters. */
		const Eigen::Vector3d centre{ 400.0 + coord(rng), -300.0 + coord(rng),
					      200.0 + coord(rng) };
		Eigen::Vector3d M[16], P[16];
		const Eigen::Matrix3d R = randomRotation(rng);
		const Eigen::Vector3d t{ 5 * coord(rng), 5 * coord(rng), 1000.0 + 5 * coord(rng) };
		const double s = trial % 2 ? scale(rng) : 1.0;
		for (int i = 0; i < n; ++i) {
			M[i] = centre +
			       Eigen::Vector3d(coord(rng), coord(rng), planar ? 0.0 : coord(rng));
			P[i] = s * R * M[i] + t;
		}
		Pose pose;
		double s_fit = 0.0, sse = -1.0;
		ASSERT_TRUE(hornFit(M, P, n, &pose, s != 1.0, &s_fit, &sse)) << trial;
		EXPECT_LT(angleRad(pose.R, R), 1e-10) << trial;
		EXPECT_LT((pose.t_mm - t).norm(), 1e-9 * t.norm()) << trial;
		EXPECT_NEAR(s_fit, s, 1e-12 * s);
		EXPECT_LT(sse, 1e-16 * n * t.squaredNorm());

		/*
		 * The test discriminates the centroid form: the paper's swapped
		 * form (t = M_bar - s R P_bar) is far from the truth here.
		 */
		Eigen::Vector3d m_bar = Eigen::Vector3d::Zero(), p_bar = Eigen::Vector3d::Zero();
		for (int i = 0; i < n; ++i) {
			m_bar += M[i] / n;
			p_bar += P[i] / n;
		}
		EXPECT_GT((m_bar - s * R * p_bar - t).norm(), 10.0);
	}
}

TEST(HornFit, MatchesUmeyamaOnNoisyData)
{
	std::mt19937 rng(21);
	std::uniform_real_distribution<double> coord(-100.0, 100.0);
	std::normal_distribution<double> noise(0.0, 5.0);
	for (int trial = 0; trial < 300; ++trial) {
		const int n = 3 + trial % 14;
		const bool with_scale = trial % 2 == 1;
		Eigen::Vector3d M[16], P[16];
		Eigen::Matrix<double, 3, Eigen::Dynamic> src(3, n), dst(3, n);
		const Eigen::Matrix3d R = randomRotation(rng);
		const Eigen::Vector3d t{ coord(rng), coord(rng), 800.0 };
		const double s = with_scale ? 1.7 : 1.0;
		for (int i = 0; i < n; ++i) {
			M[i] = Eigen::Vector3d(coord(rng), coord(rng), coord(rng)) +
			       Eigen::Vector3d(50, 60, -70);
			P[i] = s * R * M[i] + t +
			       Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
			src.col(i) = M[i];
			dst.col(i) = P[i];
		}
		Pose pose;
		double s_fit = 0.0, sse = 0.0;
		ASSERT_TRUE(hornFit(M, P, n, &pose, with_scale, &s_fit, &sse));

		/* The rotation is the least-squares one whatever the scale estimator. */
		const Eigen::Matrix4d T = Eigen::umeyama(src, dst, false);
		EXPECT_LT(angleRad(pose.R, T.topLeftCorner<3, 3>()), 1e-9) << trial;
		const Eigen::Vector3d m_bar = src.rowwise().mean(), p_bar = dst.rowwise().mean();
		if (!with_scale) {
			EXPECT_LT((pose.t_mm - T.topRightCorner<3, 1>()).norm(), 1e-8) << trial;
			EXPECT_EQ(s_fit, 1.0);
		} else {
			/* Horn's symmetric scale, and t = P_bar - s R M_bar. */
			const double expected_s = std::sqrt((dst.colwise() - p_bar).squaredNorm() /
							    (src.colwise() - m_bar).squaredNorm());
			EXPECT_NEAR(s_fit, expected_s, 1e-12 * expected_s);
			EXPECT_LT((pose.t_mm - (p_bar - s_fit * pose.R * m_bar)).norm(), 1e-9);
		}
		double expected_sse = 0.0;
		for (int i = 0; i < n; ++i)
			expected_sse += (P[i] - (s_fit * pose.R * M[i] + pose.t_mm)).squaredNorm();
		EXPECT_NEAR(sse, expected_sse, 1e-9 * expected_sse);

		/* A minimum: small turns about the centroid only make it worse. */
		for (int k = 0; k < 6; ++k) {
			const Eigen::Matrix3d dR =
				Eigen::AngleAxisd(1e-3, randomUnit(rng)).toRotationMatrix();
			const Eigen::Matrix3d R2 = dR * pose.R;
			const Eigen::Vector3d t2 = p_bar - s_fit * R2 * m_bar;
			double sse2 = 0.0;
			for (int i = 0; i < n; ++i)
				sse2 += (P[i] - (s_fit * R2 * M[i] + t2)).squaredNorm();
			EXPECT_GT(sse2, sse);
		}
	}
}

TEST(HornFit, RefusesDegenerateInput)
{
	const Eigen::Vector3d M[4] = { { 0, 0, 0 }, { 10, 0, 0 }, { 0, 10, 0 }, { 0, 0, 10 } };
	const Eigen::Vector3d line[4] = { { 0, 0, 0 },
					  { 10, 10, 10 },
					  { 20, 20, 20 },
					  { -5, -5, -5 } };
	const Eigen::Vector3d same[4] = { { 1, 2, 3 }, { 1, 2, 3 }, { 1, 2, 3 }, { 1, 2, 3 } };
	Pose pose;
	EXPECT_TRUE(hornFit(M, M, 4, &pose));
	EXPECT_TRUE(hornFit(M, M, 3, &pose));
	EXPECT_FALSE(hornFit(M, M, 2, &pose));
	EXPECT_FALSE(hornFit(M, M, 0, &pose));
	EXPECT_FALSE(hornFit(line, line, 4, &pose)); /* collinear both */
	EXPECT_FALSE(hornFit(line, M, 4, &pose)); /* collinear model */
	EXPECT_FALSE(hornFit(M, line, 4, &pose)); /* collinear measurements */
	EXPECT_FALSE(hornFit(M, same, 4, &pose, true)); /* all measurements at one point */
	EXPECT_FALSE(hornFit(same, M, 4, &pose));
}

/* ------------------------------------------------------------------ refinement */

namespace {

struct Scene {
	CameraModel camera{ distortedCamera() };
	Eigen::Vector3d model[8];
	int n = 8;
};

/* The wedge plus two LEDs on its ridge, off-centre (8 points, non-coplanar). */
Scene wedgeScene()
{
	Scene s;
	for (int i = 0; i < 6; ++i)
		s.model[i] = kWedge.points_mm[i];
	s.model[6] = { -44.5, 0.0, -20.0 };
	s.model[7] = { 44.5, 20.0, -20.0 };
	return s;
}

void projectPixels(const Scene &s, const Pose &pose, Eigen::Vector2d *px)
{
	for (int i = 0; i < s.n; ++i)
		ASSERT_TRUE(s.camera.project(pose.apply(s.model[i]), &px[i]));
}

Pose perturb(const Pose &p, std::mt19937 &rng, double deg, double mm)
{
	Pose out;
	out.R = Eigen::AngleAxisd(deg * kDeg, randomUnit(rng)).toRotationMatrix() * p.R;
	out.t_mm = p.t_mm + mm * randomUnit(rng);
	return out;
}

double sse(const Scene &s, const Pose &pose, const Eigen::Vector2d *px)
{
	double sum = 0.0;
	for (int i = 0; i < s.n; ++i) {
		Eigen::Vector2d uv;
		if (!s.camera.project(pose.apply(s.model[i]), &uv))
			return std::numeric_limits<double>::infinity();
		sum += (uv - px[i]).squaredNorm();
	}
	return sum;
}

} /* namespace */

TEST(RefinePose, ExactOnNoiseFreeData)
{
	std::mt19937 rng(30);
	std::uniform_real_distribution<double> ang(-40.0, 40.0);
	std::uniform_real_distribution<double> range(300.0, 2000.0);
	const Scene s = wedgeScene();
	for (int trial = 0; trial < 100; ++trial) {
		Pose truth;
		truth.R = rotationFromRollPanTiltDeg({ ang(rng), ang(rng), ang(rng) });
		truth.t_mm = { 0.1 * ang(rng), 0.1 * ang(rng), range(rng) };
		Eigen::Vector2d px[8];
		projectPixels(s, truth, px);
		const Pose start = perturb(truth, rng, 5.0, 0.05 * truth.t_mm.z());
		RefineResult r;
		ASSERT_TRUE(refinePose(s.camera, s.model, px, s.n, start, RefineOptions{}, &r))
			<< trial;
		EXPECT_TRUE(r.converged);
		EXPECT_LT(r.iterations, RefineOptions{}.max_iterations);
		EXPECT_LT(angleRad(r.pose.R, truth.R), 1e-9) << trial;
		EXPECT_LT((r.pose.t_mm - truth.t_mm).norm(), 1e-9 * truth.t_mm.norm()) << trial;
		EXPECT_LT(r.rms_px, 1e-8);
		EXPECT_LT(r.max_px, 1e-8);
		EXPECT_NEAR(r.pose.R.determinant(), 1.0, 1e-12);
	}
}

TEST(RefinePose, ConvergesToTheLeastSquaresMinimumOnNoisyPoints)
{
	std::mt19937 rng(31);
	std::normal_distribution<double> noise(0.0, 0.3);
	std::uniform_real_distribution<double> ang(-40.0, 40.0);
	std::uniform_real_distribution<double> range(300.0, 2000.0);
	const Scene s = wedgeScene();
	int within_3_sigma = 0;
	const int trials = 100;
	for (int trial = 0; trial < trials; ++trial) {
		Pose truth;
		truth.R = rotationFromRollPanTiltDeg({ ang(rng), ang(rng), ang(rng) });
		truth.t_mm = { 0.1 * ang(rng), 0.1 * ang(rng), range(rng) };
		Eigen::Vector2d px[8];
		projectPixels(s, truth, px);
		double max_noise = 0.0;
		for (int i = 0; i < s.n; ++i) {
			const Eigen::Vector2d e{ noise(rng), noise(rng) };
			px[i] += e;
			max_noise = std::max(max_noise, e.norm());
		}
		const Pose start = perturb(truth, rng, 5.0, 0.05 * truth.t_mm.z());
		RefineOptions opt;
		opt.sigma_px = 0.3;
		RefineResult r;
		ASSERT_TRUE(refinePose(s.camera, s.model, px, s.n, start, opt, &r)) << trial;
		EXPECT_TRUE(r.converged);

		/* The same minimum as when started from the truth. */
		RefineResult r0;
		ASSERT_TRUE(refinePose(s.camera, s.model, px, s.n, truth, opt, &r0));
		EXPECT_LT(angleRad(r.pose.R, r0.pose.R), 1e-7);
		EXPECT_LT((r.pose.t_mm - r0.pose.t_mm).norm(), 1e-6 * truth.t_mm.norm());

		/* rms and max agree with an independent evaluation, and it is a minimum. */
		const double e = sse(s, r.pose, px);
		EXPECT_NEAR(r.rms_px, std::sqrt(e / s.n), 1e-12);
		EXPECT_LE(r.max_px, std::sqrt(e) + 1e-12);
		EXPECT_GE(r.max_px, r.rms_px - 1e-12);
		EXPECT_LT(r.rms_px, max_noise);
		for (int k = 0; k < 6; ++k) {
			const Pose p2 = perturb(r.pose, rng, 1e-3, 1e-3);
			EXPECT_GE(sse(s, p2, px), e - 1e-12);
		}

		/* The error against the truth is as large as the covariance says. */
		Eigen::Matrix<double, 6, 1> err;
		err.head<3>() = truth.t_mm - r.pose.t_mm; /* truth = estimate + err */
		err.tail<3>() = logRotation(truth.R * r.pose.R.transpose());
		const double chi2 = err.dot(r.covariance.ldlt().solve(err));
		within_3_sigma += chi2 < 16.8; /* 99% quantile of chi^2 with 6 d.o.f. */
	}
	EXPECT_GE(within_3_sigma, trials * 9 / 10);
}

TEST(RefinePose, CovarianceMatchesEmpiricalScatter)
{
	const Scene s = wedgeScene();
	std::mt19937 rng(32);
	const double sigma = 0.3;
	std::normal_distribution<double> noise(0.0, sigma);

	const Eigen::Vector3d rpy_true{ 15.0, -25.0, 10.0 };
	const Pose truth{ rotationFromRollPanTiltDeg(rpy_true),
			  Eigen::Vector3d(40.0, -30.0, 900.0) };
	Eigen::Vector2d clean[8];
	projectPixels(s, truth, clean);

	for (const double floor_px : { sigma, 0.01 }) {
		RefineOptions opt;
		opt.sigma_px = floor_px;
		const int draws = 600;
		Eigen::Matrix<double, 6, 6> scatter = Eigen::Matrix<double, 6, 6>::Zero();
		Eigen::Matrix<double, 6, 6> mean_cov = Eigen::Matrix<double, 6, 6>::Zero();
		Eigen::Vector3d rpy_var = Eigen::Vector3d::Zero(),
				rpy_sigma_sum = Eigen::Vector3d::Zero();
		double chi2_sum = 0.0;
		for (int d = 0; d < draws; ++d) {
			Eigen::Vector2d px[8];
			for (int i = 0; i < s.n; ++i)
				px[i] = clean[i] + Eigen::Vector2d(noise(rng), noise(rng));
			RefineResult r;
			ASSERT_TRUE(refinePose(s.camera, s.model, px, s.n, truth, opt, &r));
			Eigen::Matrix<double, 6, 1> err;
			err.head<3>() = truth.t_mm - r.pose.t_mm; /* truth = estimate + err */
			err.tail<3>() = logRotation(truth.R * r.pose.R.transpose());
			scatter += err * err.transpose() / draws;
			mean_cov += r.covariance / draws;
			chi2_sum += err.dot(r.covariance.ldlt().solve(err));

			const Eigen::Vector3d rpy_err =
				rollPanTiltDegFromRotation(r.pose.R) - rpy_true;
			rpy_var += rpy_err.cwiseAbs2() / draws;
			rpy_sigma_sum += rollPanTiltSigmaDeg(r.pose.R, r.covariance) / draws;
		}
		for (int k = 0; k < 6; ++k) {
			const double ratio = std::sqrt(mean_cov(k, k) / scatter(k, k));
			EXPECT_GT(ratio, 1.0 / 1.5) << "floor " << floor_px << " component " << k;
			EXPECT_LT(ratio, 1.5) << "floor " << floor_px << " component " << k;
		}
		/* The whole matrix (correlations too): E[e^T C^-1 e] = 6. */
		const double chi2_mean = chi2_sum / draws;
		EXPECT_GT(chi2_mean, 6.0 / 1.5) << "floor " << floor_px;
		EXPECT_LT(chi2_mean, 6.0 * 1.5) << "floor " << floor_px;
		for (int k = 0; k < 3; ++k) {
			const double ratio = rpy_sigma_sum(k) / std::sqrt(rpy_var(k));
			EXPECT_GT(ratio, 1.0 / 1.5) << "floor " << floor_px << " angle " << k;
			EXPECT_LT(ratio, 1.5) << "floor " << floor_px << " angle " << k;
		}
	}
}

TEST(RefinePose, SigmaFloorApplies)
{
	const Scene s = wedgeScene();
	const Pose truth{ rotationFromRollPanTiltDeg({ 5, 10, -5 }), Eigen::Vector3d(0, 0, 700) };
	Eigen::Vector2d px[8];
	projectPixels(s, truth, px);
	RefineOptions a, b;
	a.sigma_px = 0.1;
	b.sigma_px = 0.4;
	RefineResult ra, rb;
	ASSERT_TRUE(refinePose(s.camera, s.model, px, s.n, truth, a, &ra));
	ASSERT_TRUE(refinePose(s.camera, s.model, px, s.n, truth, b, &rb));
	/* Noise-free: the floor is the sigma, and the covariance scales with its square. */
	EXPECT_LT((rb.covariance - 16.0 * ra.covariance).norm(), 1e-9 * rb.covariance.norm());
	EXPECT_GT(ra.covariance(2, 2), 0.0);
}

TEST(RefinePose, RefusesBadInput)
{
	const Scene s = wedgeScene();
	const Pose truth{ rotationFromRollPanTiltDeg({ 5, 10, -5 }), Eigen::Vector3d(0, 0, 700) };
	Eigen::Vector2d px[8];
	projectPixels(s, truth, px);
	RefineResult r;
	EXPECT_FALSE(refinePose(s.camera, s.model, px, 2, truth, RefineOptions{}, &r));
	EXPECT_FALSE(refinePose(s.camera, s.model, px, 17, truth, RefineOptions{}, &r));
	/* A point behind the camera at the start. */
	Pose behind = truth;
	behind.t_mm.z() = 20.0;
	EXPECT_FALSE(refinePose(s.camera, s.model, px, s.n, behind, RefineOptions{}, &r));
	behind.t_mm.z() = -700.0;
	EXPECT_FALSE(refinePose(s.camera, s.model, px, s.n, behind, RefineOptions{}, &r));
	/* Three collinear points: the turn about their line is not observable. */
	const Eigen::Vector3d line[3] = { { -50, 0, 0 }, { 0, 0, 0 }, { 70, 0, 0 } };
	Eigen::Vector2d lpx[3];
	for (int i = 0; i < 3; ++i)
		ASSERT_TRUE(s.camera.project(truth.apply(line[i]), &lpx[i]));
	EXPECT_FALSE(refinePose(s.camera, line, lpx, 3, truth, RefineOptions{}, &r));
	/* Three general points are enough. */
	EXPECT_TRUE(refinePose(s.camera, s.model, px, 3, truth, RefineOptions{}, &r));
}

TEST(RefinePose, RollPanTiltSigmaMatchesNumericPropagation)
{
	std::mt19937 rng(33);
	std::uniform_real_distribution<double> ang(-170.0, 170.0);
	std::uniform_real_distribution<double> pan(-80.0, 80.0);
	for (int trial = 0; trial < 200; ++trial) {
		const Eigen::Matrix3d R =
			rotationFromRollPanTiltDeg({ ang(rng), pan(rng), ang(rng) });
		Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Random();
		const Eigen::Matrix<double, 6, 6> cov = 1e-4 * A * A.transpose();
		/* d(rpy)/dw by central differences of the left perturbation. */
		Eigen::Matrix3d J;
		const double h = 1e-6;
		for (int k = 0; k < 3; ++k) {
			const Eigen::Vector3d w = h * Eigen::Vector3d::Unit(k);
			const Eigen::Vector3d plus = rollPanTiltDegFromRotation(
				Eigen::AngleAxisd(h, w / h).toRotationMatrix() * R);
			const Eigen::Vector3d minus = rollPanTiltDegFromRotation(
				Eigen::AngleAxisd(-h, w / h).toRotationMatrix() * R);
			J.col(k) = (plus - minus) / (2.0 * h);
		}
		const Eigen::Matrix3d C = J * cov.bottomRightCorner<3, 3>() * J.transpose();
		const Eigen::Vector3d expected = C.diagonal().cwiseSqrt();
		const Eigen::Vector3d got = rollPanTiltSigmaDeg(R, cov);
		EXPECT_LT((got - expected).norm(), 1e-5 * expected.norm())
			<< got.transpose() << " vs " << expected.transpose();
	}
	/* Gimbal lock: roll and tilt undefined, pan still finite. */
	Eigen::Matrix<double, 6, 6> cov = 1e-6 * Eigen::Matrix<double, 6, 6>::Identity();
	const Eigen::Vector3d lock =
		rollPanTiltSigmaDeg(rotationFromRollPanTiltDeg({ 30, 90, 0 }), cov);
	EXPECT_TRUE(std::isfinite(lock.y()));
	EXPECT_NEAR(lock.y(), 1e-3 * 180.0 / kPi, 1e-9);
	EXPECT_FALSE(std::isfinite(lock.x()) && lock.x() < 1e3);
}

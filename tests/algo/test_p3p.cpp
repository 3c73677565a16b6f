/* SPDX-License-Identifier: MIT */
/*
 * P3P: for random poses and triangles, one of the returned poses is the true
 * one, and every returned pose puts the three points on their rays.
 */
#include <random>

#include <gtest/gtest.h>

#include "algo/p3p.h"

using namespace dockpose;

TEST(P3p, OneSolutionIsTheTruthAndAllFitTheRays)
{
	std::mt19937 rng(17);
	std::uniform_real_distribution<double> u(-1.0, 1.0);
	int found = 0;
	const int trials = 2000;
	for (int t = 0; t < trials; ++t) {
		Eigen::Vector3d model[3];
		for (auto &m : model)
			m = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 100.0;
		Pose truth;
		truth.R = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng))
				  .normalized()
				  .toRotationMatrix();
		truth.t_mm = Eigen::Vector3d(u(rng) * 200.0, u(rng) * 200.0,
					     600.0 + 1500.0 * (u(rng) + 1.0));
		Eigen::Vector2d xy[3];
		bool front = true;
		for (int i = 0; i < 3; ++i) {
			const Eigen::Vector3d c = truth.apply(model[i]);
			front = front && c.z() > 1.0;
			xy[i] = c.head<2>() / c.z();
		}
		if (!front)
			continue;
		Pose poses[4];
		const int n = solveP3p(model, xy, poses);
		ASSERT_LE(n, 4);
		bool hit = false;
		for (int k = 0; k < n; ++k) {
			for (int i = 0; i < 3; ++i) {
				const Eigen::Vector3d c = poses[k].apply(model[i]);
				ASSERT_GT(c.z(), 0.0);
				EXPECT_LT((c.head<2>() / c.z() - xy[i]).norm(), 1e-6)
					<< "trial " << t;
			}
			hit = hit ||
			      (rotationAngleDeg(poses[k].R, truth.R) < 1e-3 &&
			       (poses[k].t_mm - truth.t_mm).norm() < 1e-3 * truth.t_mm.norm());
		}
		found += hit;
	}
	/* Near-degenerate configurations (a ray pair almost parallel) may lose the root. */
	EXPECT_GE(found, trials * 99 / 100);
}

TEST(P3p, CollinearModelGivesNothing)
{
	const Eigen::Vector3d model[3] = { { 0, 0, 0 }, { 50, 0, 0 }, { 100, 0, 0 } };
	const Eigen::Vector2d xy[3] = { { 0.0, 0.0 }, { 0.05, 0.0 }, { 0.1, 0.001 } };
	Pose poses[4];
	EXPECT_EQ(solveP3p(model, xy, poses), 0);
}

/*
 * The depths depend on the rays and the side lengths only: a congruent copy
 * of the model triangle (moved and turned in the model frame) seen along the
 * same rays shares them, and its poses put its own points on the rays.
 */
TEST(P3p, CongruentTrianglesShareTheirDepths)
{
	const Eigen::Vector3d model[3] = { { -89, -38, 0 }, { -89, 38, 0 }, { 0, 38, -40 } };
	Pose move;
	move.R = Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.5, 0.8).normalized())
			 .toRotationMatrix();
	move.t_mm = Eigen::Vector3d(40.0, -25.0, 13.0);
	Eigen::Vector3d copy[3];
	for (int i = 0; i < 3; ++i)
		copy[i] = move.apply(model[i]);
	double sides[3], copy_sides[3];
	p3pSides(model, sides);
	p3pSides(copy, copy_sides);
	for (int k = 0; k < 3; ++k)
		EXPECT_NEAR(sides[k], copy_sides[k], 1e-9 * sides[k]);

	Pose truth;
	truth.R = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1.0, 0.2, 0.1).normalized())
			  .toRotationMatrix();
	truth.t_mm = Eigen::Vector3d(30.0, -20.0, 650.0);
	Eigen::Vector2d xy[3];
	for (int i = 0; i < 3; ++i) {
		const Eigen::Vector3d c = truth.apply(model[i]);
		xy[i] = c.head<2>() / c.z();
	}
	P3pDepths depths;
	solveP3pDepths(xy, sides, &depths);
	ASSERT_GE(depths.n, 1);

	/* The two-step solution is solveP3p's. */
	Pose direct[4], stepwise[4];
	const int n = solveP3p(model, xy, direct);
	ASSERT_EQ(p3pPoses(p3pModel(model), xy, depths, stepwise), n);
	bool truth_found = false;
	for (int k = 0; k < n; ++k) {
		EXPECT_LT((direct[k].R - stepwise[k].R).norm(), 1e-12);
		EXPECT_LT((direct[k].t_mm - stepwise[k].t_mm).norm(), 1e-9);
		truth_found = truth_found || (rotationAngleDeg(stepwise[k].R, truth.R) < 1e-6 &&
					      (stepwise[k].t_mm - truth.t_mm).norm() < 1e-6);
	}
	EXPECT_TRUE(truth_found);

	/* The copy's poses from the same depths: one of them is truth o move^-1. */
	Pose copies[4];
	const int m = p3pPoses(p3pModel(copy), xy, depths, copies);
	ASSERT_EQ(m, n);
	Pose expected;
	expected.R = truth.R * move.R.transpose();
	expected.t_mm = truth.t_mm - expected.R * move.t_mm;
	bool copy_found = false;
	for (int k = 0; k < m; ++k) {
		for (int i = 0; i < 3; ++i) {
			const Eigen::Vector3d c = copies[k].apply(copy[i]);
			EXPECT_LT((c.head<2>() / c.z() - xy[i]).norm(), 1e-9);
		}
		copy_found = copy_found || (rotationAngleDeg(copies[k].R, expected.R) < 1e-6 &&
					    (copies[k].t_mm - expected.t_mm).norm() < 1e-6);
	}
	EXPECT_TRUE(copy_found);
}

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

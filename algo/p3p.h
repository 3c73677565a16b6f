/* SPDX-License-Identifier: MIT */
/*
 * The perspective-three-point problem: the poses that put three known model
 * points on three known viewing rays. Grunert's solution (as reviewed by
 * Haralick et al., IJCV 1994): the ratios of the three depths satisfy a
 * quartic; each real root gives the depths (polished by Newton on the side
 * lengths), and the rotation between orthonormal frames built on the model
 * triangle and on the congruent camera-frame triangle (a triad) gives the pose.
 *
 * Units: model points in mm, rays as normalised image coordinates (x, y, 1).
 * Allocates: never (fixed-size Eigen types only).
 */
#pragma once

#include <array>

#include <Eigen/Core>

#include "algo/pose.h"

namespace dockpose {

/*
 * Up to four poses with R model_mm[i] + t on the ray through xy[i]
 * (i = 0, 1, 2), every point in front of the camera. Returns how many were
 * written to poses[]. Degenerate input (collinear model points, coincident
 * rays) gives none.
 */
int solveP3p(const Eigen::Vector3d model_mm[3], const Eigen::Vector2d xy[3], Pose poses[4]);

/*
 * The same in two steps, for several model triangles with equal sides seen
 * along the same rays (a rectangular face's corners, congruent faces): the
 * depths depend on the rays and the three side lengths only, so they are
 * solved once and each model triangle needs only its rotation.
 */
struct P3pDepths {
	Eigen::Vector3d ray[3]; /* unit rays through xy[] */
	double depth_mm[4][3]; /* each solution's distance along each ray */
	int n = 0;
};
/* Squared side lengths opposite model points 0, 1, 2 (mm^2): the key of the depths. */
void p3pSides(const Eigen::Vector3d model_mm[3], double sides_mm2[3]);
void solveP3pDepths(const Eigen::Vector2d xy[3], const double sides_mm2[3], P3pDepths *depths);
/*
 * What p3pPoses() needs of a model triangle, computed once for a triangle
 * solved many times (the frame built on it, its centroid). ok: false for a
 * degenerate (collinear) triangle, which gives no pose.
 */
struct P3pModel {
	std::array<Eigen::Vector3d, 3> model_mm;
	Eigen::Matrix3d frame_t; /* transposed orthonormal frame on the triangle */
	Eigen::Vector3d centroid_mm;
	bool ok = false;
};
P3pModel p3pModel(const Eigen::Vector3d model_mm[3]);
/* solveP3p()'s poses from the depths solved for this model triangle's sides. */
int p3pPoses(const P3pModel &model, const Eigen::Vector2d xy[3], const P3pDepths &depths,
	     Pose poses[4]);

} /* namespace dockpose */

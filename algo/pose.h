/* SPDX-License-Identifier: MIT */
/*
 * Pose of the target in the camera frame, and the solvers that find it:
 *  - solveFourCoplanar(): closed form for the four corners of one face
 *    (method.md section 5, after Abidi and Chandra);
 *  - hornFit(): least-squares rigid (optionally similarity) fit with unit
 *    quaternions (method.md section 6, Horn 1987, correct translation form);
 *  - refinePose(): Gauss-Newton/Levenberg-Marquardt over all matched LEDs,
 *    minimising reprojection error in pixels through the full lens model, with
 *    the 6x6 covariance of the result.
 *
 * Conventions: X_c = R X_t + t (target -> camera), millimetres; quaternion
 * (w, x, y, z) with w >= 0; R = Rx(roll) * Ry(pan) * Rz(tilt), degrees.
 * Allocates: never (fixed-size Eigen types and caller-owned arrays only).
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "algo/camera_model.h"

namespace dockpose {

struct Pose {
	Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
	Eigen::Vector3d t_mm = Eigen::Vector3d::Zero();

	Eigen::Vector3d apply(const Eigen::Vector3d &x_target) const { return R * x_target + t_mm; }
};

/* Unit quaternion of R with w >= 0. */
Eigen::Quaterniond quaternionFromRotation(const Eigen::Matrix3d &R);

/* (roll, pan, tilt) in degrees with R = Rx(roll) Ry(pan) Rz(tilt); pan in [-90, 90]. */
Eigen::Vector3d rollPanTiltDegFromRotation(const Eigen::Matrix3d &R);

/* R = Rx(roll) Ry(pan) Rz(tilt) from degrees. */
Eigen::Matrix3d rotationFromRollPanTiltDeg(const Eigen::Vector3d &rpy_deg);

/* Rotation angle between two rotations, degrees. */
double rotationAngleDeg(const Eigen::Matrix3d &a, const Eigen::Matrix3d &b);

/*
 * Closed-form pose of four coplanar model points from their ideal normalised
 * image coordinates (undistorted rays q_i = (x_i, y_i, 1)).
 *
 * The points are in corresponding order (model_mm[i] <-> xy[i]). Depths follow
 * Z_m ∝ D_(m) / A_(m); the scale is the least-squares fit of the six pairwise
 * distances; the rotation and translation are the rigid fit of the model to
 * the reconstructed camera-frame points (Horn's, in its closed form for two
 * planar sets: normals aligned, then the best in-plane turn).
 *
 * Returns false (and says nothing else) when the face is unusable: a
 * near-collinear triangle (|D| or |A| tiny), depths of mixed sign (the order
 * does not correspond to a front view), or a non-finite result.
 * fit_rms_mm, when given, receives the rms 3-D residual of the rigid fit in
 * mm: a first test of whether the four points can be this face.
 */
bool solveFourCoplanar(const Eigen::Vector3d model_mm[4], const Eigen::Vector2d xy[4], Pose *pose,
		       double *fit_rms_mm = nullptr);

/*
 * Horn's closed-form absolute orientation: minimise
 * sum |measured_i - (s R model_i + t)|^2 over n >= 3 pairs.
 * With estimate_scale false, s = 1 (rigid). scale and sse (sum of squared
 * residuals, mm^2) are written when non-null. Returns false for degenerate
 * input (n < 3, collinear points).
 */
bool hornFit(const Eigen::Vector3d *model_mm, const Eigen::Vector3d *measured_mm, int n, Pose *pose,
	     bool estimate_scale = false, double *scale = nullptr, double *sse = nullptr);

struct RefineOptions {
	int max_iterations = 20;
	/*
	 * Pixel noise of one centroid. Without per-point covariances: the floor
	 * of the covariance's sigma. With them: the sigma of a point whose
	 * covariance is unknown (not positive definite, e.g. all 0).
	 */
	double sigma_px = 0.15;
	/*
	 * 1-sigma tolerance of each LED's position in the target, mm, isotropic
	 * (TargetModel::led_sigma_mm). Used with per-point covariances only: each
	 * point's covariance gains J_p R (s^2 I) R^T J_p^T.
	 */
	double led_sigma_mm = 0.0;
	/* Compute the covariance (skipped for internal screening steps). */
	bool covariance = true;
};

struct RefineResult {
	Pose pose;
	double rms_px = 0.0; /* rms reprojection error over all points */
	double max_px = 0.0; /* largest reprojection error */
	int iterations = 0;
	bool converged = false;
	/*
	 * Sum of r^T S^-1 r over the points at the result, S each point's
	 * covariance (pixel covariance plus the LED tolerance; sigma_px^2 I
	 * without per-point covariances). About chi^2 with 2n - 6 degrees of
	 * freedom when the match is right and the covariances honest.
	 */
	double chi2 = 0.0;
	/*
	 * Covariance of (tx, ty, tz [mm], rx, ry, rz [rad]) where (rx, ry, rz) is a
	 * small rotation applied on the left: R_true = exp([r]x) R.
	 * Without per-point covariances: sigma^2 (J^T J)^-1 with sigma^2 =
	 * max(sigma_px^2, residual variance). With them: (J^T W J)^-1, W the
	 * inverse point covariances, no floor and no scaling by the residuals,
	 * plus D S_cal D^T when the camera carries calibration sigmas
	 * (D = -(J^T W J)^-1 J^T W dr/dtheta over fx, fy, cx, cy, k1, k2, p1, p2).
	 */
	Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

/*
 * Minimise the reprojection error of n >= 3 model points against their
 * observed pixels (distorted, as measured) starting from `initial`.
 * pixel_cov, when given, holds n 2x2 centroid covariances (px^2, e.g. from
 * Blob::cov_*): the error minimised is then the whitened (Mahalanobis) one,
 * with options.led_sigma_mm added to every point, and the covariance is
 * propagated from them (see RefineResult). rms_px and max_px are the plain
 * pixel figures either way. Returns false when the problem is degenerate or
 * a point falls behind the camera. Allocates: never (n <= kMaxLeds).
 */
bool refinePose(const CameraModel &camera, const Eigen::Vector3d *model_mm,
		const Eigen::Vector2d *pixels, int n, const Pose &initial,
		const RefineOptions &options, RefineResult *result,
		const Eigen::Matrix2d *pixel_cov = nullptr);

/*
 * Standard deviations of (roll, pan, tilt) in degrees from the 6x6 covariance
 * of refinePose() at rotation R (first-order propagation).
 */
Eigen::Vector3d rollPanTiltSigmaDeg(const Eigen::Matrix3d &R,
				    const Eigen::Matrix<double, 6, 6> &covariance);

} /* namespace dockpose */

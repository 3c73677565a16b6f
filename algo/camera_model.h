/* SPDX-License-Identifier: MIT */
/*
 * Pinhole camera with Brown-Conrady distortion (k1, k2, p1, p2), as in
 * method.md section 2 and OpenCV's first four coefficients.
 *
 * Units: pixels for (u, v); normalised image coordinates (x, y) = (X/Z, Y/Z);
 * camera-frame points in mm. Allocates: never.
 */
#pragma once

#include <string>

#include <Eigen/Core>

#include "algo/status.h"

namespace dockpose {

struct CameraIntrinsics {
	int width = 0;
	int height = 0;
	double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
	double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0;
	/*
	 * Optional 1-sigma uncertainty of each parameter from the calibration
	 * (the camera file's "sigma" object), same units; 0: exact. refinePose()
	 * adds its effect to the pose covariance.
	 */
	struct Sigma {
		double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
		double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0;

		bool any() const
		{
			return fx > 0.0 || fy > 0.0 || cx > 0.0 || cy > 0.0 || k1 > 0.0 ||
			       k2 > 0.0 || p1 > 0.0 || p2 > 0.0;
		}
	} sigma;

	/*
	 * Plausibility bounds no real camera leaves (a camera file outside them is a typo or a
	 * unit mix-up, and would give wrong poses): the field of view across each side, the
	 * pixel aspect fy/fx, and the radial factor 1 + k1 r^2 + k2 r^4 at the image corner
	 * farthest from the principal point (r from the distorted corner, an approximation
	 * that is exact without distortion), and a radial mapping that keeps growing out to
	 * that corner (a distortion that folds the image back gives two undistorted positions
	 * for one pixel near the edge).
	 */
	static constexpr double kMinFieldOfViewDeg = 0.5;
	static constexpr double kMaxFieldOfViewDeg = 175.0;
	static constexpr double kMaxPixelAspect = 2.0;
	static constexpr double kMaxCornerDistortion = 4.0;

	/* Ok when valid, else an error naming the bad value. Allocates: the message. */
	Status validate() const;

private:
	/* validate()'s plausibility bounds, once each value is in its own range. */
	Status checkPlausible() const;
	/* The ideal radius where r (1 + k1 r^2 + k2 r^4) stops growing before it reaches
	 * r_distorted_max (normalised), or 0 when it grows all the way. */
	double radialFold(double r_distorted_max) const;
};

class CameraModel
{
public:
	explicit CameraModel(const CameraIntrinsics &intrinsics);

	const CameraIntrinsics &intrinsics() const { return k_; }

	/* Ideal normalised (x, y) -> distorted normalised (x', y'). */
	Eigen::Vector2d distort(const Eigen::Vector2d &xy) const;

	/*
	 * Distorted normalised -> ideal normalised, by Newton iteration on the
	 * distortion model. Returns false when it does not converge (a point far
	 * outside the lens's valid field).
	 */
	bool undistort(const Eigen::Vector2d &xy_distorted, Eigen::Vector2d *xy) const;

	/* Pixel -> ideal normalised coordinates. */
	bool pixelToNormalized(const Eigen::Vector2d &uv, Eigen::Vector2d *xy) const;

	/* Ideal normalised -> pixel (applies distortion). */
	Eigen::Vector2d normalizedToPixel(const Eigen::Vector2d &xy) const;

	/*
	 * Camera-frame point (mm) -> pixel. Returns false for points at or behind
	 * the camera (Z <= 1e-6 mm). When jacobian is given it receives d(u,v)/d(X,Y,Z).
	 */
	bool project(const Eigen::Vector3d &p_mm, Eigen::Vector2d *uv,
		     Eigen::Matrix<double, 2, 3> *jacobian = nullptr) const;

	/* True when the pixel lies inside the sensor (with a margin in pixels). */
	bool inImage(const Eigen::Vector2d &uv, double margin_px = 0.0) const;

private:
	/* d(distorted)/d(ideal) at xy. */
	Eigen::Matrix2d distortJacobian(const Eigen::Vector2d &xy) const;

	CameraIntrinsics k_;
};

} /* namespace dockpose */

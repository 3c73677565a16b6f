/* SPDX-License-Identifier: MIT */
#include "algo/camera_model.h"

#include <cmath>
#include <sstream>

#include <Eigen/LU>

namespace dockpose {

Status CameraIntrinsics::validate() const
{
	std::ostringstream err;
	if (width <= 0 || height <= 0 || width > 16384 || height > 16384)
		err << "camera size " << width << "x" << height
		    << " is not a sensor size (1..16384 per side)";
	else if (!(std::isfinite(fx) && fx > 0.0) || !(std::isfinite(fy) && fy > 0.0))
		err << "camera focal lengths fx=" << fx << ", fy=" << fy
		    << " must be positive pixels";
	else if (!std::isfinite(cx) || !std::isfinite(cy) || cx < -0.5 * width ||
		 cx > 1.5 * width || cy < -0.5 * height || cy > 1.5 * height)
		err << "camera principal point (" << cx << ", " << cy << ") is not near the "
		    << width << "x" << height << " sensor";
	else if (!std::isfinite(k1) || !std::isfinite(k2) || !std::isfinite(p1) ||
		 !std::isfinite(p2) || std::abs(k1) > 10.0 || std::abs(k2) > 100.0 ||
		 std::abs(p1) > 1.0 || std::abs(p2) > 1.0)
		err << "camera distortion k1=" << k1 << " k2=" << k2 << " p1=" << p1 << " p2=" << p2
		    << " is out of range";
	else if (Status s = checkPlausible(); !s.isOk())
		return s;
	else
		return Status::ok();
	return Status::error(err.str());
}

Status CameraIntrinsics::checkPlausible() const
{
	std::ostringstream err;
	const double fov_x_deg = 2.0 * std::atan(0.5 * width / fx) * 180.0 / M_PI;
	const double fov_y_deg = 2.0 * std::atan(0.5 * height / fy) * 180.0 / M_PI;
	const double aspect = fy / fx;
	/* The image corner farthest from the principal point, in normalised (distorted)
	 * coordinates, and the radial factor there: how much the model scales the corners. */
	double r2_max = 0.0;
	for (const double u : { 0.0, static_cast<double>(width) })
		for (const double v : { 0.0, static_cast<double>(height) }) {
			const double x = (u - cx) / fx, y = (v - cy) / fy;
			r2_max = std::max(r2_max, x * x + y * y);
		}
	const double corner_factor = 1.0 + k1 * r2_max + k2 * r2_max * r2_max;
	if (!(fov_x_deg >= kMinFieldOfViewDeg && fov_x_deg <= kMaxFieldOfViewDeg &&
	      fov_y_deg >= kMinFieldOfViewDeg && fov_y_deg <= kMaxFieldOfViewDeg))
		err << "camera field of view " << fov_x_deg << " x " << fov_y_deg
		    << " degrees (fx=" << fx << ", fy=" << fy << " on " << width << "x" << height
		    << ") is not a lens's: each must be in [" << kMinFieldOfViewDeg << ", "
		    << kMaxFieldOfViewDeg << "]";
	else if (!(aspect >= 1.0 / kMaxPixelAspect && aspect <= kMaxPixelAspect))
		err << "camera pixel aspect fy/fx = " << aspect << " (fx=" << fx << ", fy=" << fy
		    << ") is not a sensor's: it must be in [" << 1.0 / kMaxPixelAspect << ", "
		    << kMaxPixelAspect << "]";
	else if (!(corner_factor >= 1.0 / kMaxCornerDistortion &&
		   corner_factor <= kMaxCornerDistortion))
		err << "camera distortion k1=" << k1 << " k2=" << k2
		    << " scales the image corners by " << corner_factor
		    << "; a lens's stays within [" << 1.0 / kMaxCornerDistortion << ", "
		    << kMaxCornerDistortion << "]";
	else if (const double fold = radialFold(std::sqrt(r2_max)); fold > 0.0)
		err << "camera distortion k1=" << k1 << " k2=" << k2
		    << " folds the image: its radial mapping stops growing at radius " << fold
		    << " (normalised), inside the image corner's " << std::sqrt(r2_max)
		    << ", so points near the edge would have two undistorted positions";
	else
		return Status::ok();
	return Status::error(err.str());
}

double CameraIntrinsics::radialFold(double r_distorted_max) const
{
	/* r_d(r) = r (1 + k1 r^2 + k2 r^4); its slope 1 + 3 k1 r^2 + 5 k2 r^4 must stay positive
	 * (by a margin: a slope near 0 amplifies noise without bound) until r_d reaches the
	 * corner. Steps of 1/1000 of the corner's radius; a mapping that has not reached the
	 * corner at 4x its radius compresses it more than kMaxCornerDistortion allows anyway. */
	constexpr double kMinSlope = 0.05;
	const double step = r_distorted_max / 1000.0;
	for (double r = 0.0; r <= 4.0 * r_distorted_max; r += step) {
		const double r2 = r * r;
		if (r * (1.0 + k1 * r2 + k2 * r2 * r2) >= r_distorted_max)
			return 0.0;
		if (1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 < kMinSlope)
			return r;
	}
	return 4.0 * r_distorted_max;
}

CameraModel::CameraModel(const CameraIntrinsics &intrinsics)
	: k_(intrinsics)
{
}

Eigen::Vector2d CameraModel::distort(const Eigen::Vector2d &xy) const
{
	const double x = xy.x(), y = xy.y();
	const double r2 = x * x + y * y;
	const double radial = 1.0 + k_.k1 * r2 + k_.k2 * r2 * r2;
	return { x * radial + 2.0 * k_.p1 * x * y + k_.p2 * (r2 + 2.0 * x * x),
		 y * radial + k_.p1 * (r2 + 2.0 * y * y) + 2.0 * k_.p2 * x * y };
}

Eigen::Matrix2d CameraModel::distortJacobian(const Eigen::Vector2d &xy) const
{
	const double x = xy.x(), y = xy.y();
	const double r2 = x * x + y * y;
	const double radial = 1.0 + k_.k1 * r2 + k_.k2 * r2 * r2;
	const double dradial = k_.k1 + 2.0 * k_.k2 * r2; /* d radial / d r2 */
	Eigen::Matrix2d j;
	j(0, 0) = radial + 2.0 * x * x * dradial + 2.0 * k_.p1 * y + 6.0 * k_.p2 * x;
	j(0, 1) = 2.0 * x * y * dradial + 2.0 * k_.p1 * x + 2.0 * k_.p2 * y;
	j(1, 0) = 2.0 * x * y * dradial + 2.0 * k_.p1 * x + 2.0 * k_.p2 * y;
	j(1, 1) = radial + 2.0 * y * y * dradial + 6.0 * k_.p1 * y + 2.0 * k_.p2 * x;
	return j;
}

bool CameraModel::undistort(const Eigen::Vector2d &xy_distorted, Eigen::Vector2d *xy) const
{
	Eigen::Vector2d p = xy_distorted;
	if (k_.k1 == 0.0 && k_.k2 == 0.0 && k_.p1 == 0.0 && k_.p2 == 0.0) {
		*xy = p;
		return true;
	}
	for (int it = 0; it < 30; ++it) {
		const Eigen::Vector2d r = distort(p) - xy_distorted;
		if (r.squaredNorm() < 1e-26)
			break;
		const Eigen::Matrix2d j = distortJacobian(p);
		const double det = j.determinant();
		if (!(std::abs(det) > 1e-12))
			return false;
		Eigen::Vector2d step = j.inverse() * r;
		/* Damp long steps: the model is only trusted near the field of view. */
		const double n = step.norm();
		if (n > 0.5)
			step *= 0.5 / n;
		p -= step;
		if (!p.allFinite())
			return false;
	}
	if ((distort(p) - xy_distorted).squaredNorm() > 1e-18)
		return false;
	/* The distortion polynomial must still be monotonic here (a fold means a
	 * second, spurious solution far outside the lens's field). */
	if (distortJacobian(p).determinant() <= 0.0)
		return false;
	*xy = p;
	return true;
}

bool CameraModel::pixelToNormalized(const Eigen::Vector2d &uv, Eigen::Vector2d *xy) const
{
	const Eigen::Vector2d d{ (uv.x() - k_.cx) / k_.fx, (uv.y() - k_.cy) / k_.fy };
	return undistort(d, xy);
}

Eigen::Vector2d CameraModel::normalizedToPixel(const Eigen::Vector2d &xy) const
{
	const Eigen::Vector2d d = distort(xy);
	return { k_.fx * d.x() + k_.cx, k_.fy * d.y() + k_.cy };
}

bool CameraModel::project(const Eigen::Vector3d &p_mm, Eigen::Vector2d *uv,
			  Eigen::Matrix<double, 2, 3> *jacobian) const
{
	const double z = p_mm.z();
	if (!(z > 1e-6))
		return false;
	const double inv_z = 1.0 / z;
	const Eigen::Vector2d xy{ p_mm.x() * inv_z, p_mm.y() * inv_z };
	*uv = normalizedToPixel(xy);
	if (jacobian) {
		Eigen::Matrix<double, 2, 3> dxy;
		dxy << inv_z, 0.0, -xy.x() * inv_z, 0.0, inv_z, -xy.y() * inv_z;
		Eigen::Matrix2d f = Eigen::Matrix2d::Zero();
		f(0, 0) = k_.fx;
		f(1, 1) = k_.fy;
		*jacobian = f * distortJacobian(xy) * dxy;
	}
	return true;
}

bool CameraModel::inImage(const Eigen::Vector2d &uv, double margin_px) const
{
	return uv.x() >= -0.5 + margin_px && uv.y() >= -0.5 + margin_px &&
	       uv.x() <= k_.width - 0.5 - margin_px && uv.y() <= k_.height - 0.5 - margin_px;
}

} /* namespace dockpose */

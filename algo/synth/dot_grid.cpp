/* SPDX-License-Identifier: MIT */
#include "algo/synth/dot_grid.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Geometry>

namespace dockpose {

namespace {

constexpr double kPi = 3.14159265358979323846;

} /* namespace */

std::string DotGrid::json() const
{
	return R"({"rows": )" + std::to_string(rows) + R"(, "cols": )" + std::to_string(cols) +
	       R"(, "spacing_mm": )" + std::to_string(spacing_mm) + R"(, "layout": ")" +
	       (asymmetric ? "asymmetric" : "symmetric") + "\"}\n";
}

Image renderDotGrid(const CameraModel &camera, const DotGrid &grid, const Pose &pose,
		    double noise_sigma, std::uint64_t seed,
		    const std::vector<Eigen::Vector3d> &extras)
{
	const CameraIntrinsics &k = camera.intrinsics();
	std::vector<double> level(static_cast<std::size_t>(k.width) * k.height, 0.0);
	std::vector<Eigen::Vector3d> dots;
	for (int i = 0; i < grid.rows; ++i)
		for (int j = 0; j < grid.cols; ++j)
			dots.push_back(grid.point(i, j));
	dots.insert(dots.end(), extras.begin(), extras.end());
	const Eigen::Vector3d normal = pose.R.col(2);
	constexpr int kSub = 4;
	for (const Eigen::Vector3d &dot : dots) {
		/* The disc's image: a box around 16 points of its rim, 2 px of margin. */
		double u0 = 1e9, u1 = -1e9, v0 = 1e9, v1 = -1e9;
		for (int a = 0; a < 16; ++a) {
			const double phi = a * kPi / 8.0;
			const Eigen::Vector3d rim =
				dot + grid.dot_radius_mm *
					      Eigen::Vector3d(std::cos(phi), std::sin(phi), 0.0);
			Eigen::Vector2d uv;
			if (!camera.project(pose.apply(rim), &uv))
				return {};
			u0 = std::min(u0, uv.x());
			u1 = std::max(u1, uv.x());
			v0 = std::min(v0, uv.y());
			v1 = std::max(v1, uv.y());
		}
		const int x0 = std::max(0, static_cast<int>(std::floor(u0)) - 2);
		const int x1 = std::min(k.width - 1, static_cast<int>(std::ceil(u1)) + 2);
		const int y0 = std::max(0, static_cast<int>(std::floor(v0)) - 2);
		const int y1 = std::min(k.height - 1, static_cast<int>(std::ceil(v1)) + 2);
		for (int y = y0; y <= y1; ++y)
			for (int x = x0; x <= x1; ++x) {
				int inside = 0;
				for (int sy = 0; sy < kSub; ++sy)
					for (int sx = 0; sx < kSub; ++sx) {
						const Eigen::Vector2d uv(
							x - 0.5 + (sx + 0.5) / kSub,
							y - 0.5 + (sy + 0.5) / kSub);
						Eigen::Vector2d xy;
						if (!camera.pixelToNormalized(uv, &xy))
							continue;
						const Eigen::Vector3d ray(xy.x(), xy.y(), 1.0);
						const double s =
							normal.dot(pose.t_mm) / normal.dot(ray);
						const Eigen::Vector3d on_plane =
							pose.R.transpose() * (s * ray - pose.t_mm);
						inside += (on_plane - dot).head<2>().norm() <=
							  grid.dot_radius_mm;
					}
				level[static_cast<std::size_t>(y) * k.width + x] +=
					200.0 * inside / (kSub * kSub);
			}
	}
	synth::Rng rng(seed);
	Image image(k.width, k.height);
	for (int y = 0; y < k.height; ++y)
		for (int x = 0; x < k.width; ++x) {
			const double v = 15.0 + level[static_cast<std::size_t>(y) * k.width + x] +
					 noise_sigma * rng.normal();
			image.at(x, y) =
				static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
		}
	return image;
}

bool dotGridInFrame(const CameraModel &camera, const DotGrid &grid, const Pose &pose,
		    double margin_px)
{
	for (int i = 0; i < grid.rows; ++i)
		for (int j = 0; j < grid.cols; ++j) {
			Eigen::Vector2d uv;
			if (!camera.project(pose.apply(grid.point(i, j)), &uv) ||
			    !camera.inImage(uv, margin_px))
				return false;
		}
	return true;
}

bool dotGridView(const CameraModel &camera, const DotGrid &grid, int n, synth::Rng *rng, Pose *pose,
		 bool centre_only)
{
	const CameraIntrinsics &k = camera.intrinsics();
	static constexpr double kPlaces[9][2] = { { 0.15, 0.15 }, { 0.85, 0.15 }, { 0.15, 0.85 },
						  { 0.85, 0.85 }, { 0.5, 0.12 },  { 0.5, 0.88 },
						  { 0.12, 0.5 },  { 0.88, 0.5 },  { 0.5, 0.5 } };
	const double tilt_deg = rng->uniform(30.0, 45.0);
	const double axis_deg = 40.0 * n + rng->uniform(-10.0, 10.0);
	const double roll_deg = rng->uniform(-30.0, 30.0);
	const Eigen::Vector3d axis(std::cos(axis_deg * kPi / 180.0),
				   std::sin(axis_deg * kPi / 180.0), 0.0);
	const Eigen::Matrix3d tilt =
		(Eigen::AngleAxisd(roll_deg * kPi / 180.0, Eigen::Vector3d::UnitZ()) *
		 Eigen::AngleAxisd(tilt_deg * kPi / 180.0, axis))
			.toRotationMatrix();
	const double width_mm = grid.widthMm();
	const double height_mm = (grid.rows - 1) * grid.spacing_mm;
	const double range_mm =
		k.fx * std::max(width_mm / (0.45 * k.width), height_mm / (0.45 * k.height)) *
		rng->uniform(0.9, 1.15);
	const double *place = kPlaces[centre_only ? 8 : n % 9];
	for (double pull = 0.0; pull <= 1.0; pull += 0.05) {
		const double u = k.width * (place[0] + pull * (0.5 - place[0]));
		const double v = k.height * (place[1] + pull * (0.5 - place[1]));
		Eigen::Vector2d xy;
		if (!camera.pixelToNormalized({ u, v }, &xy))
			continue;
		const Eigen::Vector3d aim =
			range_mm * Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
		/* Tilted from facing the camera along the line of sight to its centre. */
		pose->R = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), aim)
				  .toRotationMatrix() *
			  tilt;
		pose->t_mm = aim - pose->R * grid.centre();
		if (dotGridInFrame(camera, grid, *pose, 10.0))
			return true;
	}
	return false;
}

} /* namespace dockpose */

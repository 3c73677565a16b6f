/* SPDX-License-Identifier: MIT */
/*
 * dockpose's camera model and pose solvers against OpenCV 4.6 as an
 * independent reference:
 *  - CameraModel::project() against cv::projectPoints(), and
 *    pixelToNormalized() against cv::undistortPoints();
 *  - pose accuracy on the same noisy image points (0.3 px): OpenCV's SQPnP
 *    followed by solvePnPRefineLM, against dockpose's closed form on one face
 *    followed by refinePose() over all points. dockpose's median rotation and
 *    translation errors must be within 10% of OpenCV's, or better.
 */
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "algo/camera_model.h"
#include "algo/pose.h"
#include "fixtures.h"

using namespace dockpose;

namespace {

using test::distortedCamera;
using test::paperCamera;

cv::Matx33d cvCameraMatrix(const CameraIntrinsics &k)
{
	return { k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0 };
}

std::vector<double> cvDistortion(const CameraIntrinsics &k)
{
	return { k.k1, k.k2, k.p1, k.p2 };
}

struct Target {
	const char *name;
	std::vector<Eigen::Vector3d> points;
	std::vector<std::array<int, 4>> faces;
};

/* The wedge of method.md section 3. */
Target wedge()
{
	const TargetModel m = test::wedgeModel();
	return { "wedge",
		 { m.points_mm.begin(), m.points_mm.end() },
		 { m.faces.begin(), m.faces.end() } };
}

/* A wedge with a flat top: 8 LEDs, three faces. */
Target roof()
{
	return { "roof",
		 { { -89, -38, 0 },
		   { -89, 38, 0 },
		   { -30, 38, -40 },
		   { -30, -38, -40 },
		   { 30, -38, -40 },
		   { 30, 38, -40 },
		   { 89, -38, 0 },
		   { 89, 38, 0 } },
		 { { 0, 1, 2, 3 }, { 3, 2, 5, 4 }, { 4, 5, 7, 6 } } };
}

/* One face alone: four coplanar LEDs. */
Target face()
{
	return { "face",
		 { { -89, -38, 0 }, { -89, 38, 0 }, { 0, 38, -40 }, { 0, -38, -40 } },
		 { { 0, 1, 2, 3 } } };
}

struct Errors {
	double rot_deg;
	double trans_mm;
};

double median(std::vector<double> v)
{
	std::sort(v.begin(), v.end());
	return v[v.size() / 2];
}

/* dockpose: closed form on each face, refined over all points; the lowest rms wins. */
bool dockposeSolve(const CameraModel &cam, const Target &target,
		   const std::vector<Eigen::Vector2d> &px, Pose *pose)
{
	const int n = static_cast<int>(target.points.size());
	double best_rms = std::numeric_limits<double>::infinity();
	for (const auto &f : target.faces) {
		Eigen::Vector3d model[4];
		Eigen::Vector2d xy[4];
		bool ok = true;
		for (int i = 0; i < 4; ++i) {
			model[i] = target.points[f[i]];
			ok = ok && cam.pixelToNormalized(px[f[i]], &xy[i]);
		}
		Pose initial;
		if (!ok || !solveFourCoplanar(model, xy, &initial))
			continue;
		RefineResult r;
		if (!refinePose(cam, target.points.data(), px.data(), n, initial, RefineOptions{},
				&r))
			continue;
		if (r.rms_px < best_rms) {
			best_rms = r.rms_px;
			*pose = r.pose;
		}
	}
	return std::isfinite(best_rms);
}

/* OpenCV: SQPnP, then Levenberg-Marquardt on the reprojection error. */
bool opencvSolve(const CameraIntrinsics &k, const Target &target,
		 const std::vector<Eigen::Vector2d> &px, Pose *pose)
{
	std::vector<cv::Point3d> obj;
	std::vector<cv::Point2d> img;
	for (std::size_t i = 0; i < target.points.size(); ++i) {
		obj.emplace_back(target.points[i].x(), target.points[i].y(), target.points[i].z());
		img.emplace_back(px[i].x(), px[i].y());
	}
	cv::Mat rvec, tvec;
	const cv::Matx33d K = cvCameraMatrix(k);
	const std::vector<double> dist = cvDistortion(k);
	if (!cv::solvePnP(obj, img, K, dist, rvec, tvec, false, cv::SOLVEPNP_SQPNP))
		return false;
	cv::solvePnPRefineLM(obj, img, K, dist, rvec, tvec);
	cv::Matx33d R;
	cv::Rodrigues(rvec, R);
	for (int r = 0; r < 3; ++r) {
		for (int c = 0; c < 3; ++c)
			pose->R(r, c) = R(r, c);
		pose->t_mm(r) = tvec.at<double>(r);
	}
	return true;
}

/*
 * Random poses (roll, pan, tilt within +-40 deg, range 300-2000 mm) with
 * every LED inside the frame, 0.3 px noise, both solvers on the same points.
 */
void comparePnP(const Target &target, int trials, unsigned seed)
{
	std::mt19937 rng(seed);
	std::uniform_real_distribution<double> ang(-40.0, 40.0);
	std::uniform_real_distribution<double> range(300.0, 2000.0);
	std::uniform_real_distribution<double> lateral(-0.25, 0.25);
	std::normal_distribution<double> noise(0.0, 0.3);

	std::vector<double> dp_rot, dp_t, cv_rot, cv_t;
	int dp_failed = 0, cv_failed = 0, same = 0;
	for (int trial = 0; trial < trials; ++trial) {
		const CameraIntrinsics k = trial % 2 ? distortedCamera() : paperCamera();
		const CameraModel cam(k);
		Pose truth;
		std::vector<Eigen::Vector2d> px(target.points.size());
		for (;;) {
			truth.R = rotationFromRollPanTiltDeg({ ang(rng), ang(rng), ang(rng) });
			const double z = range(rng);
			truth.t_mm = { lateral(rng) * z, lateral(rng) * z, z };
			bool inside = true;
			for (std::size_t i = 0; i < px.size(); ++i)
				inside = inside &&
					 cam.project(truth.apply(target.points[i]), &px[i]) &&
					 cam.inImage(px[i], 5.0);
			if (inside)
				break;
		}
		for (auto &p : px)
			p += Eigen::Vector2d(noise(rng), noise(rng));

		Pose dp, ocv;
		const bool dp_ok = dockposeSolve(cam, target, px, &dp);
		const bool cv_ok = opencvSolve(k, target, px, &ocv);
		dp_failed += !dp_ok;
		cv_failed += !cv_ok;
		const double inf = std::numeric_limits<double>::infinity();
		dp_rot.push_back(dp_ok ? rotationAngleDeg(dp.R, truth.R) : inf);
		dp_t.push_back(dp_ok ? (dp.t_mm - truth.t_mm).norm() : inf);
		cv_rot.push_back(cv_ok ? rotationAngleDeg(ocv.R, truth.R) : inf);
		cv_t.push_back(cv_ok ? (ocv.t_mm - truth.t_mm).norm() : inf);
		if (dp_ok && cv_ok && rotationAngleDeg(dp.R, ocv.R) < 1e-3 &&
		    (dp.t_mm - ocv.t_mm).norm() < 1e-2)
			++same;
	}
	const Errors dp{ median(dp_rot), median(dp_t) };
	const Errors ocv{ median(cv_rot), median(cv_t) };
	std::printf("%-6s %d trials: median rotation error dockpose %.4f deg, OpenCV %.4f deg; "
		    "median translation error dockpose %.3f mm, OpenCV %.3f mm; "
		    "failures dockpose %d, OpenCV %d; same minimum in %d\n",
		    target.name, trials, dp.rot_deg, ocv.rot_deg, dp.trans_mm, ocv.trans_mm,
		    dp_failed, cv_failed, same);
	EXPECT_LE(dp.rot_deg, 1.1 * ocv.rot_deg);
	EXPECT_LE(dp.trans_mm, 1.1 * ocv.trans_mm);
	EXPECT_LE(dp_failed, trials / 100);
	/* The errors are those of 0.3 px noise, not of a broken solver. */
	EXPECT_LT(dp.rot_deg, 2.0);
	EXPECT_GT(dp.rot_deg, 0.0);
}

} /* namespace */

TEST(CameraModelVsOpenCV, ProjectMatchesProjectPoints)
{
	for (const CameraIntrinsics &k : { paperCamera(), distortedCamera() }) {
		const CameraModel cam(k);
		std::mt19937 rng(40);
		std::uniform_real_distribution<double> lateral(-0.4, 0.4);
		std::uniform_real_distribution<double> range(150.0, 3000.0);
		std::vector<cv::Point3d> pts;
		for (int i = 0; i < 500; ++i) {
			const double z = range(rng);
			pts.emplace_back(lateral(rng) * z, lateral(rng) * z, z);
		}
		std::vector<cv::Point2d> ref;
		cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cvCameraMatrix(k),
				  cvDistortion(k), ref);
		for (std::size_t i = 0; i < pts.size(); ++i) {
			Eigen::Vector2d uv;
			ASSERT_TRUE(cam.project({ pts[i].x, pts[i].y, pts[i].z }, &uv));
			EXPECT_NEAR(uv.x(), ref[i].x, 1e-9);
			EXPECT_NEAR(uv.y(), ref[i].y, 1e-9);
		}
	}
}

TEST(CameraModelVsOpenCV, UndistortMatchesUndistortPoints)
{
	for (const CameraIntrinsics &k : { paperCamera(), distortedCamera() }) {
		const CameraModel cam(k);
		std::vector<cv::Point2d> px;
		for (int iy = 0; iy <= 16; ++iy)
			for (int ix = 0; ix <= 16; ++ix)
				px.emplace_back(-0.5 + k.width * ix / 16.0,
						-0.5 + k.height * iy / 16.0);
		std::vector<cv::Point2d> ref;
		cv::undistortPoints(
			px, ref, cvCameraMatrix(k), cvDistortion(k), cv::noArray(), cv::noArray(),
			cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 200,
					 1e-15));
		for (std::size_t i = 0; i < px.size(); ++i) {
			Eigen::Vector2d xy;
			ASSERT_TRUE(cam.pixelToNormalized({ px[i].x, px[i].y }, &xy));
			/* OpenCV's fixed-point iteration stops a little short: 1e-8 of the focal length. */
			EXPECT_NEAR(xy.x(), ref[i].x, 1e-8);
			EXPECT_NEAR(xy.y(), ref[i].y, 1e-8);
		}
	}
}

TEST(PoseVsOpenCV, NonCoplanarWedge)
{
	comparePnP(wedge(), 300, 50);
}

TEST(PoseVsOpenCV, NonCoplanarRoof)
{
	comparePnP(roof(), 300, 51);
}

TEST(PoseVsOpenCV, PlanarFace)
{
	comparePnP(face(), 300, 52);
}

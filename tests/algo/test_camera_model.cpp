/* SPDX-License-Identifier: MIT */
/*
 * CameraModel: distortion against the formula of method.md section 2,
 * undistort(distort(x)) round trips over the whole field of both reference
 * cameras, the projection jacobian against finite differences, and points
 * at or behind the camera refused.
 */
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "algo/camera_model.h"
#include "fixtures.h"

using namespace dockpose;

namespace {

using test::distortedCamera;
using test::paperCamera;

/* method.md section 2, written out independently of camera_model.cpp. */
Eigen::Vector2d referenceDistort(const CameraIntrinsics &k, double x, double y)
{
	const double r2 = x * x + y * y;
	const double r4 = r2 * r2;
	const double xd =
		x * (1.0 + k.k1 * r2 + k.k2 * r4) + 2.0 * k.p1 * x * y + k.p2 * (r2 + 2.0 * x * x);
	const double yd =
		y * (1.0 + k.k1 * r2 + k.k2 * r4) + k.p1 * (r2 + 2.0 * y * y) + 2.0 * k.p2 * x * y;
	return { xd, yd };
}

class CameraModelTest : public ::testing::TestWithParam<CameraIntrinsics>
{
};

} /* namespace */

TEST_P(CameraModelTest, IntrinsicsAreValid)
{
	EXPECT_EQ(GetParam().validate().message(), "");
}

TEST_P(CameraModelTest, DistortMatchesTheFormula)
{
	const CameraIntrinsics k = GetParam();
	const CameraModel cam(k);
	std::mt19937 rng(11);
	std::uniform_real_distribution<double> u(-0.5, 0.5);
	for (int i = 0; i < 1000; ++i) {
		const double x = u(rng), y = u(rng);
		const Eigen::Vector2d d = cam.distort({ x, y });
		const Eigen::Vector2d ref = referenceDistort(k, x, y);
		EXPECT_NEAR(d.x(), ref.x(), 1e-15);
		EXPECT_NEAR(d.y(), ref.y(), 1e-15);
		const Eigen::Vector2d uv = cam.normalizedToPixel({ x, y });
		EXPECT_NEAR(uv.x(), k.fx * ref.x() + k.cx, 1e-10);
		EXPECT_NEAR(uv.y(), k.fy * ref.y() + k.cy, 1e-10);
	}
}

/* Every pixel of a dense grid over the sensor, corners included, round trips. */
TEST_P(CameraModelTest, PixelRoundTripOverTheField)
{
	const CameraIntrinsics k = GetParam();
	const CameraModel cam(k);
	const int steps = 64;
	double worst = 0.0;
	for (int iy = 0; iy <= steps; ++iy)
		for (int ix = 0; ix <= steps; ++ix) {
			/* From the outer edge of the corner pixels (-0.5) to the opposite edge. */
			const Eigen::Vector2d uv{ -0.5 + k.width * ix / double(steps),
						  -0.5 + k.height * iy / double(steps) };
			Eigen::Vector2d xy;
			ASSERT_TRUE(cam.pixelToNormalized(uv, &xy)) << uv.transpose();
			const Eigen::Vector2d back = cam.normalizedToPixel(xy);
			worst = std::max(worst, (back - uv).norm());
			/* The ideal point is where the reference formula says. */
			const Eigen::Vector2d d = referenceDistort(k, xy.x(), xy.y());
			EXPECT_NEAR(k.fx * d.x() + k.cx, uv.x(), 1e-8);
			EXPECT_NEAR(k.fy * d.y() + k.cy, uv.y(), 1e-8);
		}
	EXPECT_LT(worst, 1e-9);
}

/* Ideal normalised points covering the field (and a margin) round trip too. */
TEST_P(CameraModelTest, NormalizedRoundTripOverTheField)
{
	const CameraIntrinsics k = GetParam();
	const CameraModel cam(k);
	const double x_max = 1.1 * (k.width / 2.0) / k.fx;
	const double y_max = 1.1 * (k.height / 2.0) / k.fy;
	for (int iy = -20; iy <= 20; ++iy)
		for (int ix = -20; ix <= 20; ++ix) {
			const Eigen::Vector2d xy{ x_max * ix / 20.0, y_max * iy / 20.0 };
			Eigen::Vector2d back;
			ASSERT_TRUE(cam.undistort(cam.distort(xy), &back)) << xy.transpose();
			EXPECT_LT((back - xy).norm(), 1e-12) << xy.transpose();
		}
}

TEST_P(CameraModelTest, ProjectJacobianMatchesFiniteDifferences)
{
	const CameraModel cam(GetParam());
	std::mt19937 rng(5);
	std::uniform_real_distribution<double> lateral(-0.35, 0.35);
	std::uniform_real_distribution<double> range(150.0, 3000.0);
	for (int i = 0; i < 200; ++i) {
		const double z = range(rng);
		const Eigen::Vector3d p{ lateral(rng) * z, lateral(rng) * z, z };
		Eigen::Vector2d uv;
		Eigen::Matrix<double, 2, 3> J;
		ASSERT_TRUE(cam.project(p, &uv, &J));
		/* The projection itself. */
		EXPECT_LT((uv - cam.normalizedToPixel({ p.x() / p.z(), p.y() / p.z() })).norm(),
			  1e-12);
		Eigen::Matrix<double, 2, 3> Jn;
		for (int c = 0; c < 3; ++c) {
			const double h = 1e-4 * z;
			Eigen::Vector3d dp = Eigen::Vector3d::Zero();
			dp(c) = h;
			Eigen::Vector2d plus, minus;
			ASSERT_TRUE(cam.project(p + dp, &plus));
			ASSERT_TRUE(cam.project(p - dp, &minus));
			Jn.col(c) = (plus - minus) / (2.0 * h);
		}
		EXPECT_LT((J - Jn).norm(), 1e-6 * Jn.norm()) << "J\n" << J << "\nnumeric\n" << Jn;
	}
}

TEST_P(CameraModelTest, RefusesPointsAtOrBehindTheCamera)
{
	const CameraModel cam(GetParam());
	Eigen::Vector2d uv{ 123.0, 456.0 };
	Eigen::Matrix<double, 2, 3> J;
	EXPECT_FALSE(cam.project({ 10.0, 20.0, -500.0 }, &uv, &J));
	EXPECT_FALSE(cam.project({ 10.0, 20.0, 0.0 }, &uv));
	EXPECT_FALSE(cam.project({ 0.0, 0.0, 1e-7 }, &uv));
	EXPECT_FALSE(cam.project({ 0.0, 0.0, std::nan("") }, &uv));
	EXPECT_TRUE(cam.project({ 0.0, 0.0, 1e-3 }, &uv));
	EXPECT_TRUE(cam.project({ 10.0, 20.0, 500.0 }, &uv, &J));
}

TEST_P(CameraModelTest, InImage)
{
	const CameraIntrinsics k = GetParam();
	const CameraModel cam(k);
	EXPECT_TRUE(cam.inImage({ 0.0, 0.0 }));
	EXPECT_TRUE(cam.inImage({ -0.5, -0.5 }));
	EXPECT_FALSE(cam.inImage({ -0.6, 10.0 }));
	EXPECT_TRUE(cam.inImage({ k.width - 0.5, k.height - 0.5 }));
	EXPECT_FALSE(cam.inImage({ k.width - 0.4, 10.0 }));
	EXPECT_FALSE(cam.inImage({ 10.0, k.height - 0.4 }));
	EXPECT_FALSE(cam.inImage({ 2.0, 10.0 }, 3.0));
	EXPECT_TRUE(cam.inImage({ 2.6, 10.0 }, 3.0));
}

INSTANTIATE_TEST_SUITE_P(ReferenceCameras, CameraModelTest,
			 ::testing::Values(paperCamera(), distortedCamera()),
			 [](const ::testing::TestParamInfo<CameraIntrinsics> &param_info) {
				 return param_info.param.width == 512 ? std::string("Paper512")
								      : std::string("Sensor1456");
			 });

/*
 * Strong barrel distortion folds over: r_d(r) = r (1 + k1 r^2) peaks at
 * r = 1/sqrt(-3 k1). Distorted radii beyond the peak have no inverse and must
 * be refused; radii inside it must invert to the branch through the centre.
 */
TEST(CameraModel, UndistortRefusesPointsBeyondTheFold)
{
	CameraIntrinsics k = distortedCamera();
	k.k1 = -0.4;
	k.k2 = 0.0;
	k.p1 = 0.0;
	k.p2 = 0.0;
	const CameraModel cam(k);
	const double r_peak = 1.0 / std::sqrt(-3.0 * k.k1);
	const double rd_peak = r_peak * (1.0 + k.k1 * r_peak * r_peak);
	Eigen::Vector2d xy;
	EXPECT_FALSE(cam.undistort({ 1.1 * rd_peak, 0.0 }, &xy));
	EXPECT_FALSE(cam.undistort({ 0.8 * rd_peak, 0.8 * rd_peak }, &xy));
	ASSERT_TRUE(cam.undistort({ 0.5 * rd_peak, 0.0 }, &xy));
	EXPECT_LT(xy.x(), r_peak);
	EXPECT_NEAR(cam.distort(xy).x(), 0.5 * rd_peak, 1e-13);
	EXPECT_NEAR(xy.y(), 0.0, 1e-15);
}

TEST(CameraModel, ValidateNamesBadValues)
{
	CameraIntrinsics k = distortedCamera();
	k.fx = -1.0;
	EXPECT_NE(k.validate().message(), "");
	k = distortedCamera();
	k.width = 0;
	EXPECT_NE(k.validate().message(), "");
	k = distortedCamera();
	k.k1 = std::nan("");
	EXPECT_NE(k.validate().message(), "");
}

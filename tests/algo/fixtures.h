/* SPDX-License-Identifier: MIT */
/*
 * Fixtures shared by the algo tests: the wedge target of method.md section 3
 * and the two reference cameras (the paper's 512x512 camera and the
 * 1456x1088 sensor with a real lens). Values in mm and pixels. Test-only,
 * header-only; each builder returns by value (the model's name string may
 * allocate).
 */
#pragma once

#include <string>

#include <Eigen/Core>

#include "algo/camera_model.h"
#include "algo/target_model.h"

namespace dockpose::test {

#ifdef DOCKPOSE_TEST_DATA
/* A file of tests/data (the test's build defines DOCKPOSE_TEST_DATA). Allocates: the string. */
inline std::string dataPath(const std::string &name)
{
	return std::string(DOCKPOSE_TEST_DATA) + "/" + name;
}
#endif

/* The wedge of method.md section 3: six LEDs, two faces sharing the ridge. */
inline TargetModel wedgeModel()
{
	TargetModel m;
	m.name = "wedge";
	for (const auto &p : { Eigen::Vector3d(-89, -38, 0), Eigen::Vector3d(-89, 38, 0),
			       Eigen::Vector3d(0, 38, -40), Eigen::Vector3d(0, -38, -40),
			       Eigen::Vector3d(89, -38, 0), Eigen::Vector3d(89, 38, 0) })
		m.points_mm.push_back(p);
	m.faces.push_back({ 0, 1, 2, 3 });
	m.faces.push_back({ 3, 2, 5, 4 });
	return m;
}

/* The paper's 512x512 camera (6 mm lens), no distortion. */
inline CameraIntrinsics paperCamera()
{
	CameraIntrinsics k;
	k.width = 512;
	k.height = 512;
	k.fx = 700.0;
	k.fy = 702.0;
	k.cx = 255.5;
	k.cy = 255.5;
	return k;
}

/*
 * The 1456x1088 sensor with a real lens: radial k1 = -0.12, k2 = 0.03 and
 * the given tangential terms (none by default).
 */
inline CameraIntrinsics camera1456(double p1 = 0.0, double p2 = 0.0)
{
	CameraIntrinsics k;
	k.width = 1456;
	k.height = 1088;
	k.fx = 1739.0;
	k.fy = 1739.0;
	k.cx = 727.5;
	k.cy = 543.5;
	k.k1 = -0.12;
	k.k2 = 0.03;
	k.p1 = p1;
	k.p2 = p2;
	return k;
}

/* camera1456() with tangential distortion p1 = 0.001, p2 = -0.0005. */
inline CameraIntrinsics distortedCamera()
{
	return camera1456(0.001, -0.0005);
}

} /* namespace dockpose::test */

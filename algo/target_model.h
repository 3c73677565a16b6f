/* SPDX-License-Identifier: MIT */
/*
 * The LED target: LED centres in the target frame (mm) and its faces, each a
 * convex planar quadrilateral of LED indices in cyclic order (either
 * direction). See method.md section 3.
 */
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "algo/capacities.h"
#include "algo/static_vector.h"
#include "algo/status.h"

namespace dockpose {

struct TargetModel {
	std::string name;
	StaticVector<Eigen::Vector3d, kMaxLeds> points_mm;
	StaticVector<std::array<int, 4>, kMaxFaces> faces;
	/* Optional: 1-sigma tolerance of each LED's position, mm, isotropic ("led_sigma_mm"; 0: exact). */
	double led_sigma_mm = 0.0;
	/*
	 * Optional approach prior ("approach": {"axis": [x, y, z], "max_deg": a}):
	 * poses that put the camera more than max_deg from `axis` (a unit vector
	 * in the target frame, from the LEDs' centroid towards the camera) are not
	 * considered. Without it, the target may be seen from any side its LEDs
	 * face.
	 */
	struct Approach {
		bool set = false;
		Eigen::Vector3d axis = -Eigen::Vector3d::UnitZ();
		double max_deg = 180.0;
	} approach;

	/* A target's size (diameterMm()) lies in these bounds: smaller is a unit mix-up (metres
	 * for mm) or coincident LEDs, larger no docking target. */
	static constexpr double kMinDiameterMm = 1.0;
	static constexpr double kMaxDiameterMm = 100000.0;

	/*
	 * Check the model: capacities, indices in range, a size in [kMinDiameterMm,
	 * kMaxDiameterMm], distinct LEDs, every face planar (within tolerance), convex and
	 * non-degenerate.
	 * Ok when valid, else an error whose message names the problem.
	 * Allocates: the error message only.
	 */
	Status validate() const;

	/* Size of the target: largest distance between two LEDs, in mm. */
	double diameterMm() const;

	/*
	 * Unit normal of each face pointing to the side its LEDs shine to (the
	 * front), in the target frame, from the model's own geometry. Faces that
	 * share an edge are oriented consistently (the shared edge runs in
	 * opposite directions); each connected group of faces then faces outward,
	 * away from the LEDs' centroid. A planar group (no outside) faces the
	 * approach axis when one is set, else -z: at the nominal docking pose
	 * (R = I) the camera looks along the target's +z axis, as for the wedge
	 * of method.md. Allocates: never.
	 */
	void frontNormals(StaticVector<Eigen::Vector3d, kMaxFaces> *normals) const;
};

} /* namespace dockpose */

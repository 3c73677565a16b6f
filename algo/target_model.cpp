/* SPDX-License-Identifier: MIT */
#include "algo/target_model.h"

#include <cmath>
#include <sstream>

#include <Eigen/Geometry>

namespace dockpose {

double TargetModel::diameterMm() const
{
	double d = 0.0;
	for (std::size_t i = 0; i < points_mm.size(); ++i)
		for (std::size_t j = i + 1; j < points_mm.size(); ++j)
			d = std::max(d, (points_mm[i] - points_mm[j]).norm());
	return d;
}

void TargetModel::frontNormals(StaticVector<Eigen::Vector3d, kMaxFaces> *normals) const
{
	const std::size_t nf = faces.size();
	normals->clear();
	StaticVector<Eigen::Vector3d, kMaxFaces> centres;
	Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
	for (const auto &p : points_mm)
		centroid += p;
	if (!points_mm.empty())
		centroid /= static_cast<double>(points_mm.size());
	for (const auto &face : faces) {
		const Eigen::Vector3d p0 = points_mm[face[0]], p1 = points_mm[face[1]];
		const Eigen::Vector3d p2 = points_mm[face[2]], p3 = points_mm[face[3]];
		normals->push_back((p2 - p0).cross(p3 - p1).normalized());
		centres.push_back((p0 + p1 + p2 + p3) / 4.0);
	}

	/* Does face g contain the directed edge a -> b? */
	auto has_edge = [&](std::size_t g, int a, int b) {
		for (int k = 0; k < 4; ++k)
			if (faces[g][k] == a && faces[g][(k + 1) % 4] == b)
				return true;
		return false;
	};

	std::array<int, kMaxFaces> group{};
	group.fill(-1);
	int groups = 0;
	for (std::size_t seed = 0; seed < nf; ++seed) {
		if (group[seed] >= 0)
			continue;
		/* Breadth-first over shared edges. */
		std::array<std::size_t, kMaxFaces> queue{};
		std::size_t head = 0, tail = 0;
		queue[tail++] = seed;
		group[seed] = groups;
		while (head < tail) {
			const std::size_t f = queue[head++];
			for (std::size_t g = 0; g < nf; ++g) {
				if (group[g] >= 0)
					continue;
				for (int k = 0; k < 4; ++k) {
					const int a = faces[f][k], b = faces[f][(k + 1) % 4];
					const bool same = has_edge(g, a, b);
					if (!same && !has_edge(g, b, a))
						continue;
					if (same)
						(*normals)[g] = -(*normals)[g];
					group[g] = groups;
					queue[tail++] = g;
					break;
				}
			}
		}
		/*
		 * The group faces outward, away from the LEDs' centroid (the LEDs
		 * of a polyhedral target shine out of its hull). A planar group has
		 * no outside: it faces the approach prior's axis when the file gives
		 * one, else -z (the camera at the nominal docking pose, method.md).
		 */
		double outward = 0.0, towards_camera = 0.0;
		const Eigen::Vector3d axis =
			approach.set ? approach.axis : Eigen::Vector3d(-Eigen::Vector3d::UnitZ());
		for (std::size_t f = 0; f < nf; ++f)
			if (group[f] == groups) {
				outward += (*normals)[f].dot(centres[f] - centroid);
				towards_camera += (*normals)[f].dot(axis);
			}
		const double scale = std::max(diameterMm(), 1e-9);
		const bool flip = std::abs(outward) > 1e-6 * scale ? outward < 0.0
								   : towards_camera < 0.0;
		if (flip)
			for (std::size_t f = 0; f < nf; ++f)
				if (group[f] == groups)
					(*normals)[f] = -(*normals)[f];
		++groups;
	}
}

Status TargetModel::validate() const
{
	std::ostringstream err;
	if (points_mm.size() < 4) {
		err << "target '" << name << "' has " << points_mm.size()
		    << " LEDs; at least 4 (one face) are needed";
		return Status::error(err.str());
	}
	if (faces.empty()) {
		err << "target '" << name
		    << "' has no faces; at least one quadrilateral face is needed";
		return Status::error(err.str());
	}
	for (const auto &p : points_mm)
		if (!p.allFinite())
			return Status::error("target '" + name +
					     "' has a non-finite LED coordinate");

	const double diameter = diameterMm();
	if (!(diameter >= kMinDiameterMm && diameter <= kMaxDiameterMm)) {
		err << "target '" << name << "' is " << diameter
		    << " mm across; a docking target's "
		    << "LEDs span " << kMinDiameterMm << " mm to " << kMaxDiameterMm
		    << " mm (coordinates are in mm)";
		return Status::error(err.str());
	}
	for (std::size_t i = 0; i < points_mm.size(); ++i)
		for (std::size_t j = i + 1; j < points_mm.size(); ++j)
			if ((points_mm[i] - points_mm[j]).norm() < 1e-3 * diameter) {
				err << "target '" << name << "': LEDs " << i << " and " << j
				    << " coincide";
				return Status::error(err.str());
			}

	for (std::size_t f = 0; f < faces.size(); ++f) {
		const auto &face = faces[f];
		for (int k = 0; k < 4; ++k) {
			if (face[k] < 0 || face[k] >= static_cast<int>(points_mm.size())) {
				err << "target '" << name << "': face " << f << " names LED "
				    << face[k] << ", but the model has LEDs 0.."
				    << points_mm.size() - 1;
				return Status::error(err.str());
			}
			for (int m = 0; m < k; ++m)
				if (face[m] == face[k]) {
					err << "target '" << name << "': face " << f
					    << " lists LED " << face[k] << " twice";
					return Status::error(err.str());
				}
		}
		/* Planarity: distance of each vertex from the plane of the other three. */
		Eigen::Vector3d p[4];
		for (int k = 0; k < 4; ++k)
			p[k] = points_mm[face[k]];
		const Eigen::Vector3d n = (p[2] - p[0]).cross(p[3] - p[1]);
		const double n_norm = n.norm();
		const double scale = std::max((p[2] - p[0]).norm(), (p[3] - p[1]).norm());
		if (n_norm < 1e-6 * scale * scale) {
			err << "target '" << name << "': face " << f
			    << " is degenerate (its diagonals are parallel)";
			return Status::error(err.str());
		}
		const Eigen::Vector3d unit = n / n_norm;
		const Eigen::Vector3d centre = (p[0] + p[1] + p[2] + p[3]) / 4.0;
		for (int k = 0; k < 4; ++k)
			if (std::abs(unit.dot(p[k] - centre)) > 0.02 * scale) {
				err << "target '" << name << "': face " << f
				    << " is not planar (LED " << face[k] << " is "
				    << std::abs(unit.dot(p[k] - centre))
				    << " mm off the face's plane)";
				return Status::error(err.str());
			}
		/* Convexity in cyclic order: all turns have the same sign w.r.t. n. */
		int sign = 0;
		for (int k = 0; k < 4; ++k) {
			const Eigen::Vector3d e0 = p[(k + 1) % 4] - p[k];
			const Eigen::Vector3d e1 = p[(k + 2) % 4] - p[(k + 1) % 4];
			const double turn = unit.dot(e0.cross(e1));
			const int s = turn > 0 ? 1 : -1;
			if (std::abs(turn) < 1e-6 * scale * scale || (sign != 0 && s != sign)) {
				err << "target '" << name << "': face " << f
				    << " is not a convex quadrilateral in the listed cyclic order";
				return Status::error(err.str());
			}
			sign = s;
		}
	}
	return Status::ok();
}

} /* namespace dockpose */

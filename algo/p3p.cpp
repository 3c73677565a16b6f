/* SPDX-License-Identifier: MIT */
#include "algo/p3p.h"

#include <algorithm>
#include <cmath>

#include <Eigen/LU> /* MatrixBase::inverse, determinant */

namespace dockpose {

namespace {

/* The largest real root of m^3 + a m^2 + b m + c = 0 (Cardano; trigonometric with three real roots). */
double largestCubicRoot(double a, double b, double c)
{
	const double q = (a * a - 3.0 * b) / 9.0;
	const double r = (2.0 * a * a * a - 9.0 * a * b + 27.0 * c) / 54.0;
	const double q3 = q * q * q;
	if (r * r < q3) {
		const double theta = std::acos(std::clamp(r / std::sqrt(q3), -1.0, 1.0));
		return -2.0 * std::sqrt(q) *
			       std::cos((theta - 2.0 * 3.14159265358979323846) / 3.0) -
		       a / 3.0;
	}
	const double A = -std::copysign(std::cbrt(std::abs(r) + std::sqrt(r * r - q3)), r);
	const double B = A != 0.0 ? q / A : 0.0;
	return A + B - a / 3.0;
}

/*
 * Real roots of c[4] v^4 + ... + c[0] = 0 (c[4] != 0) by Ferrari's method,
 * each polished by Newton's method.
 */
int quarticRoots(const double c[5], double roots[4])
{
	const double a = c[3] / c[4], b = c[2] / c[4], cc = c[1] / c[4], d = c[0] / c[4];
	/* Depressed: v = y - a/4, y^4 + p y^2 + q y + r = 0. */
	const double a2 = a * a;
	const double p = b - 3.0 * a2 / 8.0;
	const double q = cc - a * b / 2.0 + a2 * a / 8.0;
	const double r = d - a * cc / 4.0 + a2 * b / 16.0 - 3.0 * a2 * a2 / 256.0;
	double y[4];
	int ny = 0;
	auto quadratic = [&](double B, double C) {
		const double disc = B * B - 4.0 * C;
		if (disc < 0.0)
			return;
		const double sq = std::sqrt(disc);
		y[ny++] = 0.5 * (-B + sq);
		y[ny++] = 0.5 * (-B - sq);
	};
	if (std::abs(q) < 1e-14 * (1.0 + std::abs(p) * std::abs(p) + std::abs(r))) {
		/* Biquadratic: z = y^2. */
		const double disc = p * p - 4.0 * r;
		if (disc >= 0.0) {
			const double sq = std::sqrt(disc);
			for (const double z : { 0.5 * (-p + sq), 0.5 * (-p - sq) })
				if (z >= 0.0) {
					y[ny++] = std::sqrt(z);
					y[ny++] = -std::sqrt(z);
				}
		}
	} else {
		/* Resolvent cubic 8m^3 + 8p m^2 + (2p^2 - 8r) m - q^2 = 0 has a root m > 0. */
		const double m = largestCubicRoot(p, p * p / 4.0 - r, -q * q / 8.0);
		if (!(m > 0.0))
			return 0;
		const double s2m = std::sqrt(2.0 * m);
		quadratic(s2m, p / 2.0 + m - q / (2.0 * s2m));
		quadratic(-s2m, p / 2.0 + m + q / (2.0 * s2m));
	}
	int n = 0;
	for (int i = 0; i < ny; ++i) {
		double v = y[i] - a / 4.0;
		for (int it = 0; it < 4; ++it) {
			const double f = (((c[4] * v + c[3]) * v + c[2]) * v + c[1]) * v + c[0];
			const double df =
				((4.0 * c[4] * v + 3.0 * c[3]) * v + 2.0 * c[2]) * v + c[1];
			if (!(std::abs(df) > 1e-300))
				break;
			v -= f / df;
		}
		if (std::isfinite(v))
			roots[n++] = v;
	}
	return n;
}

/*
 * An orthonormal frame on a triangle: first axis along the first edge, third
 * along the normal. False for a degenerate (collinear) triangle.
 */
bool triangleFrame(const Eigen::Vector3d p[3], Eigen::Matrix3d *F)
{
	const Eigen::Vector3d a = p[1] - p[0], b = p[2] - p[0];
	const Eigen::Vector3d n = a.cross(b);
	const double na = a.norm(), nn = n.norm();
	if (!(na > 0.0) || !(nn > 1e-12 * na * b.norm()))
		return false;
	const Eigen::Vector3d e1 = a / na, e3 = n / nn;
	F->col(0) = e1;
	F->col(1) = e3.cross(e1);
	F->col(2) = e3;
	return true;
}

} /* namespace */

void solveP3pDepths(const Eigen::Vector2d xy[3], const double sides_mm2[3], P3pDepths *depths)
{
	P3pDepths *out = depths;
	out->n = 0;
	Eigen::Vector3d *j = out->ray;
	for (int i = 0; i < 3; ++i)
		j[i] = Eigen::Vector3d(xy[i].x(), xy[i].y(), 1.0).normalized();
	/* Haralick's notation: a, b, c the sides opposite points 1, 2, 3; alpha, beta, gamma the ray angles. */
	const double a2 = sides_mm2[0], b2 = sides_mm2[1], c2 = sides_mm2[2];
	const double scale2 = std::max({ a2, b2, c2 });
	if (!(b2 > 1e-12 * scale2) || !(a2 > 1e-12 * scale2) || !(c2 > 1e-12 * scale2))
		return;
	/* Collinear (Heron: 16 area^2 = 2(a2 b2 + b2 c2 + c2 a2) - a2^2 - b2^2 - c2^2). */
	const double area16 = 2.0 * (a2 * b2 + b2 * c2 + c2 * a2) - a2 * a2 - b2 * b2 - c2 * c2;
	if (!(area16 >= 4.0 * 1e-8 * scale2 * scale2))
		return;
	const double ca = j[1].dot(j[2]), cb = j[0].dot(j[2]), cg = j[0].dot(j[1]);
	const double amc = (a2 - c2) / b2, apc = (a2 + c2) / b2;
	const double c_b = c2 / b2, a_b = a2 / b2, bmc = (b2 - c2) / b2, bma = (b2 - a2) / b2;

	double coef[5];
	coef[4] = (amc - 1.0) * (amc - 1.0) - 4.0 * c_b * ca * ca;
	coef[3] = 4.0 * (amc * (1.0 - amc) * cb - (1.0 - apc) * ca * cg + 2.0 * c_b * ca * ca * cb);
	coef[2] = 2.0 * (amc * amc - 1.0 + 2.0 * amc * amc * cb * cb + 2.0 * bmc * ca * ca -
			 4.0 * apc * ca * cb * cg + 2.0 * bma * cg * cg);
	coef[1] =
		4.0 * (-amc * (1.0 + amc) * cb + 2.0 * a_b * cg * cg * cb - (1.0 - apc) * ca * cg);
	coef[0] = (1.0 + amc) * (1.0 + amc) - 4.0 * a_b * cg * cg;
	if (!(std::abs(coef[4]) > 1e-12 * (std::abs(coef[0]) + std::abs(coef[2]) + 1e-300)))
		return;

	double roots[4];
	const int nr = quarticRoots(coef, roots);
	for (int r = 0; r < nr; ++r) {
		const double v = roots[r];
		const double den = 2.0 * (cg - v * ca);
		if (!(std::abs(den) > 1e-12) || !(v > 0.0))
			continue;
		const double u = ((-1.0 + amc) * v * v - 2.0 * amc * cb * v + 1.0 + amc) / den;
		if (!(u > 0.0))
			continue;
		const double d = 1.0 + v * v - 2.0 * v * cb;
		if (!(d > 0.0))
			continue;
		double s[3];
		s[0] = std::sqrt(b2 / d);
		s[1] = u * s[0];
		s[2] = v * s[0];
		/* Newton on the three side equations polishes the depths. */
		const double cosines[3] = { ca, cb, cg }; /* ray pairs (1,2), (0,2), (0,1) */
		const int pi[3] = { 1, 0, 0 }, pj[3] = { 2, 2, 1 };
		for (int it = 0; it < 3; ++it) {
			Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
			Eigen::Vector3d f;
			for (int e = 0; e < 3; ++e) {
				const double si = s[pi[e]], sj = s[pj[e]];
				f(e) = si * si + sj * sj - 2.0 * si * sj * cosines[e] -
				       sides_mm2[e];
				J(e, pi[e]) = 2.0 * si - 2.0 * sj * cosines[e];
				J(e, pj[e]) = 2.0 * sj - 2.0 * si * cosines[e];
			}
			/* 3x3: cofactors (Eigen's closed form), no pivoting search. */
			const double det = J.determinant();
			if (!(std::abs(det) > 1e-300))
				break;
			const Eigen::Vector3d step = J.inverse() * f;
			if (!step.allFinite())
				break;
			for (int i = 0; i < 3; ++i)
				s[i] -= step(i);
			/* Converged: a further step would be below rounding. */
			if (step.cwiseAbs().maxCoeff() <= 1e-12 * std::max({ s[0], s[1], s[2] }))
				break;
		}
		if (!(s[0] > 0.0 && s[1] > 0.0 && s[2] > 0.0))
			continue;
		for (int i = 0; i < 3; ++i)
			out->depth_mm[out->n][i] = s[i];
		++out->n;
	}
}

/*
 * The rigid transform that takes the model triangle onto each camera-frame
 * triangle of the depths (congruent to it, to Newton's precision): with
 * frames built alike on both, R = F_c F_m^T, t through the centroids. Exact
 * for congruent triangles, where Horn's least squares would give the same
 * pose through a 4x4 eigen-solve; each result is checked against the rays.
 */
P3pModel p3pModel(const Eigen::Vector3d model_mm[3])
{
	P3pModel m;
	Eigen::Matrix3d Fm = Eigen::Matrix3d::Identity();
	for (int i = 0; i < 3; ++i)
		m.model_mm[i] = model_mm[i];
	m.ok = triangleFrame(model_mm, &Fm);
	m.frame_t = Fm.transpose();
	m.centroid_mm = (model_mm[0] + model_mm[1] + model_mm[2]) / 3.0;
	return m;
}

int p3pPoses(const P3pModel &model, const Eigen::Vector2d xy[3], const P3pDepths &depths,
	     Pose poses[4])
{
	if (depths.n == 0 || !model.ok)
		return 0;
	const Eigen::Matrix3d &FmT = model.frame_t;
	const Eigen::Vector3d &m_bar = model.centroid_mm;
	const Eigen::Vector3d *model_mm = model.model_mm.data();
	double fit2[3];
	for (int i = 0; i < 3; ++i) {
		const double tol = 1e-7 * (1.0 + xy[i].norm());
		fit2[i] = tol * tol;
	}
	int n = 0;
	for (int r = 0; r < depths.n; ++r) {
		Eigen::Vector3d camera_mm[3];
		for (int i = 0; i < 3; ++i)
			camera_mm[i] = depths.depth_mm[r][i] * depths.ray[i];
		Eigen::Matrix3d Fc;
		if (!triangleFrame(camera_mm, &Fc))
			continue;
		Pose pose;
		pose.R = Fc * FmT;
		const Eigen::Vector3d c_bar = (camera_mm[0] + camera_mm[1] + camera_mm[2]) / 3.0;
		pose.t_mm = c_bar - pose.R * m_bar;
		if (!pose.R.allFinite() || !pose.t_mm.allFinite())
			continue;
		/* An ill-conditioned root (rays nearly parallel) may not fit its rays: drop it. */
		bool fits = true;
		for (int i = 0; i < 3 && fits; ++i) {
			const Eigen::Vector3d c = pose.apply(model_mm[i]);
			fits = c.z() > 0.0 &&
			       (c.head<2>() / c.z() - xy[i]).squaredNorm() <= fit2[i];
		}
		if (!fits)
			continue;
		/* Two roots can give the same pose: keep one. */
		bool duplicate = false;
		for (int k = 0; k < n; ++k)
			duplicate = duplicate ||
				    ((poses[k].t_mm - pose.t_mm).norm() < 1e-6 * pose.t_mm.norm() &&
				     (poses[k].R - pose.R).norm() < 1e-6);
		if (!duplicate && n < 4)
			poses[n++] = pose;
	}
	return n;
}

void p3pSides(const Eigen::Vector3d model_mm[3], double sides_mm2[3])
{
	sides_mm2[0] = (model_mm[1] - model_mm[2]).squaredNorm();
	sides_mm2[1] = (model_mm[0] - model_mm[2]).squaredNorm();
	sides_mm2[2] = (model_mm[0] - model_mm[1]).squaredNorm();
}

int solveP3p(const Eigen::Vector3d model_mm[3], const Eigen::Vector2d xy[3], Pose poses[4])
{
	double sides[3];
	p3pSides(model_mm, sides);
	P3pDepths depths;
	solveP3pDepths(xy, sides, &depths);
	return p3pPoses(p3pModel(model_mm), xy, depths, poses);
}

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
/*
 * Pose solvers: rotation conventions, the closed form for four coplanar
 * points (method.md section 5), Horn's quaternion fit (section 6) and the
 * Levenberg-Marquardt refinement with its covariance.
 *
 * Everything here works on fixed-size Eigen types on the stack: nothing
 * allocates.
 */
#include "algo/pose.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "algo/capacities.h"

namespace dockpose {

namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;
constexpr double kRadPerDeg = std::numbers::pi / 180.0;

/*
 * solveFourCoplanar(): a triangle of image rays whose (twice) signed area is
 * below this fraction of the squared diameter of the four image points is
 * near-collinear. Image noise dominates such a triangle's area long before
 * (the face is then within about half a degree of edge-on).
 */
constexpr double kMinImageTriangle = 1e-3;
/* The same for the model triangles (the model is exact: only true degeneracy). */
constexpr double kMinModelTriangle = 1e-6;

/*
 * hornFit(): the gap between the two largest eigenvalues of Horn's matrix,
 * relative to the scatter of the points, below which the rotation is not
 * determined (collinear or coincident points).
 */
constexpr double kMinHornGap = 1e-9;

/* The triangles of a quadrilateral: kOmit[m] omits vertex m (ascending order). */
constexpr int kOmit[4][3] = { { 1, 2, 3 }, { 0, 2, 3 }, { 0, 1, 3 }, { 0, 1, 2 } };

Eigen::Matrix3d skew(const Eigen::Vector3d &v)
{
	Eigen::Matrix3d s;
	s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
	return s;
}

/* exp([w]x) by Rodrigues' formula (w in radians). */
Eigen::Matrix3d expRotation(const Eigen::Vector3d &w)
{
	const double angle = w.norm();
	if (angle < 1e-300)
		return Eigen::Matrix3d::Identity();
	return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

/*
 * Horn's rotation from the cross-covariance S = sum M'_i P'_i^T of centred
 * model and measured points: the unit quaternion is the eigenvector of the
 * largest eigenvalue of Horn's symmetric 4x4 matrix N(S). *gap receives the
 * difference of the two largest eigenvalues (zero when the rotation is not
 * determined).
 */
bool hornRotation(const Eigen::Matrix3d &S, Eigen::Matrix3d *R, double *gap)
{
	const double sxx = S(0, 0), sxy = S(0, 1), sxz = S(0, 2);
	const double syx = S(1, 0), syy = S(1, 1), syz = S(1, 2);
	const double szx = S(2, 0), szy = S(2, 1), szz = S(2, 2);

	Eigen::Matrix4d N;
	N << sxx + syy + szz, syz - szy, szx - sxz, sxy - syx, syz - szy, sxx - syy - szz,
		sxy + syx, szx + sxz, szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy, sxy - syx,
		szx + sxz, syz + szy, -sxx - syy + szz;

	const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(N);
	if (es.info() != Eigen::Success)
		return false;
	/* Eigenvalues are in increasing order. */
	*gap = es.eigenvalues()(3) - es.eigenvalues()(2);
	const Eigen::Vector4d v = es.eigenvectors().col(3);
	const Eigen::Quaterniond q(v(0), v(1), v(2), v(3));
	*R = q.normalized().toRotationMatrix();
	return true;
}

/* Rotation angle of a rotation matrix, radians, accurate at 0 and near pi. */
double rotationAngleRad(const Eigen::Matrix3d &R)
{
	const double c = 0.5 * (R.trace() - 1.0);
	const Eigen::Vector3d s{ R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1) };
	return std::atan2(0.5 * s.norm(), c);
}

} /* namespace */

Eigen::Quaterniond quaternionFromRotation(const Eigen::Matrix3d &R)
{
	Eigen::Quaterniond q(R);
	q.normalize();
	if (q.w() < 0.0)
		q.coeffs() = -q.coeffs();
	return q;
}

/*
 * R = Rx(a) Ry(b) Rz(c) =
 *   [ cb cc,               -cb sc,                sb    ]
 *   [ ca sc + sa sb cc,     ca cc - sa sb sc,    -sa cb ]
 *   [ sa sc - ca sb cc,     sa cc + ca sb sc,     ca cb ]
 */
Eigen::Vector3d rollPanTiltDegFromRotation(const Eigen::Matrix3d &R)
{
	const double cb = std::hypot(R(1, 2), R(2, 2));
	/* At gimbal lock (pan = +-90 deg) only roll +- tilt is defined: take roll = 0. */
	const double roll = cb > 1e-12 ? std::atan2(-R(1, 2), R(2, 2)) : 0.0;
	const double ca = std::cos(roll), sa = std::sin(roll);
	/*
	 * Pan and tilt from Rx(roll)^T R = Ry(pan) Rz(tilt), whose second row is
	 * (sin tilt, cos tilt, 0) and whose third column is (sb, 0, cb): this
	 * stays consistent with R even close to gimbal lock.
	 */
	const double pan = std::atan2(R(0, 2), ca * R(2, 2) - sa * R(1, 2));
	const double tilt = std::atan2(ca * R(1, 0) + sa * R(2, 0), ca * R(1, 1) + sa * R(2, 1));
	/* Keep pan within [-90, 90] after the conversion to degrees. */
	return { roll * kDegPerRad, std::clamp(pan * kDegPerRad, -90.0, 90.0), tilt * kDegPerRad };
}

Eigen::Matrix3d rotationFromRollPanTiltDeg(const Eigen::Vector3d &rpy_deg)
{
	const Eigen::Vector3d r = rpy_deg * kRadPerDeg;
	return (Eigen::AngleAxisd(r.x(), Eigen::Vector3d::UnitX()) *
		Eigen::AngleAxisd(r.y(), Eigen::Vector3d::UnitY()) *
		Eigen::AngleAxisd(r.z(), Eigen::Vector3d::UnitZ()))
		.toRotationMatrix();
}

double rotationAngleDeg(const Eigen::Matrix3d &a, const Eigen::Matrix3d &b)
{
	return rotationAngleRad(a.transpose() * b) * kDegPerRad;
}

bool solveFourCoplanar(const Eigen::Vector3d model_mm[4], const Eigen::Vector2d xy[4], Pose *pose,
		       double *fit_rms_mm)
{
	/* Model: the face normal, then the signed areas of the four triangles in the face's plane. */
	Eigen::Vector3d c[4];
	int best = 0;
	double best_norm2 = -1.0;
	for (int m = 0; m < 4; ++m) {
		const Eigen::Vector3d &pi = model_mm[kOmit[m][0]];
		c[m] = (model_mm[kOmit[m][1]] - pi).cross(model_mm[kOmit[m][2]] - pi);
		const double n2 = c[m].squaredNorm();
		if (n2 > best_norm2) {
			best_norm2 = n2;
			best = m;
		}
	}
	Eigen::Vector3d normal = Eigen::Vector3d::Zero();
	for (const Eigen::Vector3d &cm : c)
		normal += cm.dot(c[best]) >= 0.0 ? cm : Eigen::Vector3d(-cm);
	const double normal_norm = normal.norm();

	double model_d2 = 0.0, image_d2 = 0.0;
	double d_model[6];
	int e = 0;
	for (int i = 0; i < 4; ++i)
		for (int j = i + 1; j < 4; ++j, ++e) {
			const double dm2 = (model_mm[i] - model_mm[j]).squaredNorm();
			d_model[e] = std::sqrt(dm2);
			model_d2 = std::max(model_d2, dm2);
			image_d2 = std::max(image_d2, (xy[i] - xy[j]).squaredNorm());
		}
	if (!(normal_norm > 0.0) || !(model_d2 > 0.0) || !(image_d2 > 0.0))
		return false;
	normal /= normal_norm;

	/*
	 * Depth ratios Z_m = D_(m) / A_(m), with D and A twice the signed
	 * areas of the image and model triangles that omit m. D is det[q_i q_j
	 * q_k] for q = (x, y, 1), i.e. the 2-D cross product of the image edges.
	 */
	double z[4];
	int positive = 0;
	for (int m = 0; m < 4; ++m) {
		const double A = normal.dot(c[m]);
		const Eigen::Vector2d &qi = xy[kOmit[m][0]];
		const Eigen::Vector2d u = xy[kOmit[m][1]] - qi;
		const Eigen::Vector2d v = xy[kOmit[m][2]] - qi;
		const double D = u.x() * v.y() - u.y() * v.x();
		if (!(std::abs(A) > kMinModelTriangle * model_d2) ||
		    !(std::abs(D) > kMinImageTriangle * image_d2))
			return false;
		z[m] = D / A;
		positive += z[m] > 0.0;
	}
	/*
	 * Z_i Z_j Z_k D = 2 h A with h the signed distance of the camera from
	 * the face's plane: the four ratios share the sign of h, which depends
	 * on the side the face is seen from. Mixed signs mean the points cannot
	 * be this face in this order.
	 */
	if (positive != 0 && positive != 4)
		return false;
	const double sign = positive == 4 ? 1.0 : -1.0;

	Eigen::Vector3d P[4];
	for (int m = 0; m < 4; ++m)
		P[m] = sign * z[m] * Eigen::Vector3d(xy[m].x(), xy[m].y(), 1.0);

	/* Common scale: least squares over the six pairwise distances. */
	double num = 0.0, den = 0.0;
	e = 0;
	for (int i = 0; i < 4; ++i)
		for (int j = i + 1; j < 4; ++j, ++e) {
			const double d = (P[i] - P[j]).norm();
			num += d * d_model[e];
			den += d * d;
		}
	if (!(den > 0.0))
		return false;
	const double scale = num / den;
	for (Eigen::Vector3d &p : P)
		p *= scale;

	/*
	 * Rigid fit of the model to the reconstructed points. Both sets are
	 * planar (the reconstruction is, to its centroids' noise), so Horn's
	 * 4x4 eigen-solve reduces to its closed form for planes: the rotation
	 * takes the model's normal onto the points' (the same signed sum of
	 * the four triangles' cross products, whose signs a rotation keeps) and
	 * then turns the plane by the angle that best aligns the in-plane
	 * coordinates (2-D Procrustes); the translation joins the centroids.
	 */
	Eigen::Vector3d normal_p = Eigen::Vector3d::Zero();
	for (int m = 0; m < 4; ++m) {
		const Eigen::Vector3d &pi = P[kOmit[m][0]];
		const Eigen::Vector3d cp = (P[kOmit[m][1]] - pi).cross(P[kOmit[m][2]] - pi);
		normal_p += c[m].dot(c[best]) >= 0.0 ? cp : Eigen::Vector3d(-cp);
	}
	const double normal_p_norm = normal_p.norm();
	if (!(normal_p_norm > 0.0))
		return false;
	normal_p /= normal_p_norm;
	const Eigen::Vector3d m_bar =
		0.25 * (model_mm[0] + model_mm[1] + model_mm[2] + model_mm[3]);
	const Eigen::Vector3d p_bar = 0.25 * (P[0] + P[1] + P[2] + P[3]);
	/* In-plane axes: the first along the first point's offset, the second normal x first. */
	auto axes = [](const Eigen::Vector3d &n, const Eigen::Vector3d &d, Eigen::Vector3d *e1,
		       Eigen::Vector3d *e2) {
		const Eigen::Vector3d in_plane = d - d.dot(n) * n;
		const double len = in_plane.norm();
		if (!(len > 0.0))
			return false;
		*e1 = in_plane / len;
		*e2 = n.cross(*e1);
		return true;
	};
	Eigen::Vector3d e1_m, e2_m, e1_p, e2_p;
	if (!axes(normal, model_mm[0] - m_bar, &e1_m, &e2_m) ||
	    !axes(normal_p, P[0] - p_bar, &e1_p, &e2_p))
		return false;
	double sum_cross = 0.0, sum_dot = 0.0;
	for (int i = 0; i < 4; ++i) {
		const Eigen::Vector3d dm = model_mm[i] - m_bar, dp = P[i] - p_bar;
		const double ax = dm.dot(e1_m), ay = dm.dot(e2_m);
		const double bx = dp.dot(e1_p), by = dp.dot(e2_p);
		sum_cross += ax * by - ay * bx;
		sum_dot += ax * bx + ay * by;
	}
	const double turn = std::hypot(sum_cross, sum_dot);
	if (!(turn > 0.0))
		return false;
	const double cos_a = sum_dot / turn, sin_a = sum_cross / turn;
	Eigen::Matrix3d to, from;
	to.col(0) = cos_a * e1_p + sin_a * e2_p;
	to.col(1) = -sin_a * e1_p + cos_a * e2_p;
	to.col(2) = normal_p;
	from.col(0) = e1_m;
	from.col(1) = e2_m;
	from.col(2) = normal;
	Pose fit;
	fit.R = to * from.transpose();
	fit.t_mm = p_bar - fit.R * m_bar;
	double sse = 0.0;
	for (int i = 0; i < 4; ++i)
		sse += (fit.apply(model_mm[i]) - P[i]).squaredNorm();
	if (!fit.R.allFinite() || !fit.t_mm.allFinite() || !std::isfinite(sse))
		return false;
	*pose = fit;
	if (fit_rms_mm)
		*fit_rms_mm = std::sqrt(sse / 4.0);
	return true;
}

bool hornFit(const Eigen::Vector3d *model_mm, const Eigen::Vector3d *measured_mm, int n, Pose *pose,
	     bool estimate_scale, double *scale, double *sse)
{
	if (n < 3)
		return false;

	Eigen::Vector3d m_bar = Eigen::Vector3d::Zero(), p_bar = Eigen::Vector3d::Zero();
	for (int i = 0; i < n; ++i) {
		m_bar += model_mm[i];
		p_bar += measured_mm[i];
	}
	m_bar /= n;
	p_bar /= n;

	Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
	double m2 = 0.0, p2 = 0.0;
	for (int i = 0; i < n; ++i) {
		const Eigen::Vector3d mc = model_mm[i] - m_bar;
		const Eigen::Vector3d pc = measured_mm[i] - p_bar;
		S += mc * pc.transpose();
		m2 += mc.squaredNorm();
		p2 += pc.squaredNorm();
	}
	if (!(m2 > 0.0) || !(p2 > 0.0) || !S.allFinite())
		return false;

	Eigen::Matrix3d R;
	double gap = 0.0;
	if (!hornRotation(S, &R, &gap))
		return false;
	/*
	 * For noise-free data the gap is 2 (c2 + c3) with c1 >= c2 >= c3 the
	 * principal moments of the points: zero exactly when they are collinear.
	 * Collinear measured points make S rank one, with the same effect.
	 */
	if (!(gap > kMinHornGap * std::sqrt(m2 * p2)))
		return false;

	const double s = estimate_scale ? std::sqrt(p2 / m2) : 1.0;
	pose->R = R;
	pose->t_mm = p_bar - s * R * m_bar;
	if (scale)
		*scale = s;
	if (sse) {
		double sum = 0.0;
		for (int i = 0; i < n; ++i)
			sum += (measured_mm[i] - (s * R * model_mm[i] + pose->t_mm)).squaredNorm();
		*sse = sum;
	}
	return true;
}

namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

struct Evaluation {
	double sse = 0.0; /* sum of squared pixel errors */
	double max_px = 0.0; /* largest pixel error */
	double cost = 0.0; /* what is minimised: sse, or sum r^T S^-1 r when weighted */
	Matrix6d JtJ = Matrix6d::Zero(); /* J^T W J (W = I unweighted) */
	Vector6d Jtr = Vector6d::Zero(); /* J^T W r */
};

/* The points' covariances, when given: pixel_cov plus the LED tolerance. */
struct Weights {
	const Eigen::Matrix2d *pixel_cov = nullptr;
	double fallback_px2 = 0.0; /* for a point whose covariance is unknown */
	double led_mm2 = 0.0;
};

/*
 * Inverse covariance of point i projected with jacobian jp (d uv / d X_c):
 * S = pixel_cov[i] (or fallback_px2 I when not positive definite) +
 * led_mm2 jp jp^T (J_p R s^2 I R^T J_p^T = s^2 J_p J_p^T).
 */
Eigen::Matrix2d inverseCovariance(const Weights &w, int i, const Eigen::Matrix<double, 2, 3> &jp)
{
	Eigen::Matrix2d S = w.pixel_cov[i];
	const bool known = S.allFinite() && S(0, 0) > 0.0 && S(1, 1) > 0.0 &&
			   S(0, 0) * S(1, 1) - S(0, 1) * S(1, 0) > 0.0;
	if (!known)
		S = w.fallback_px2 * Eigen::Matrix2d::Identity();
	if (w.led_mm2 > 0.0)
		S.noalias() += w.led_mm2 * jp * jp.transpose();
	S(0, 1) = S(1, 0) = 0.5 * (S(0, 1) + S(1, 0));
	return S.inverse();
}

/*
 * Reprojection residuals r_i = project(R M_i + t) - pixel_i and the normal
 * equations of their jacobian w.r.t. (dt, w): d(R M + t) = dt - [R M]x w,
 * weighted by the inverse point covariances when `weights` has them.
 * False when a point is at or behind the camera.
 */
bool evaluate(const CameraModel &camera, const Eigen::Vector3d *model_mm,
	      const Eigen::Vector2d *pixels, int n, const Pose &pose, bool with_jacobian,
	      const Weights &weights, Evaluation *ev)
{
	ev->sse = 0.0;
	ev->max_px = 0.0;
	ev->cost = 0.0;
	ev->JtJ.setZero();
	ev->Jtr.setZero();
	const bool weighted = weights.pixel_cov != nullptr;
	for (int i = 0; i < n; ++i) {
		const Eigen::Vector3d rm = pose.R * model_mm[i];
		Eigen::Vector2d uv;
		Eigen::Matrix<double, 2, 3> jp;
		if (!camera.project(rm + pose.t_mm, &uv, with_jacobian || weighted ? &jp : nullptr))
			return false;
		const Eigen::Vector2d r = uv - pixels[i];
		const double r2 = r.squaredNorm();
		ev->sse += r2;
		ev->max_px = std::max(ev->max_px, std::sqrt(r2));
		Eigen::Matrix2d W = Eigen::Matrix2d::Identity();
		if (weighted) {
			W = inverseCovariance(weights, i, jp);
			ev->cost += r.dot(W * r);
		}
		if (with_jacobian) {
			Eigen::Matrix<double, 2, 6> J;
			J.leftCols<3>() = jp;
			J.rightCols<3>() = -jp * skew(rm);
			const Eigen::Matrix<double, 6, 2> JtW = J.transpose() * W;
			ev->JtJ.noalias() += JtW * J;
			ev->Jtr.noalias() += JtW * r;
		}
	}
	if (!weighted)
		ev->cost = ev->sse;
	return std::isfinite(ev->sse) && std::isfinite(ev->cost);
}

using Matrix68d = Eigen::Matrix<double, 6, 8>;

/*
 * Sum of J_i^T W_i dr_i/dtheta over the points, theta = (fx, fy, cx, cy, k1,
 * k2, p1, p2): u = fx x' + cx, v = fy y' + cy with (x', y') the distorted
 * normalised point, so the derivatives are those of method.md's model.
 */
bool calibrationCoupling(const CameraModel &camera, const Eigen::Vector3d *model_mm, int n,
			 const Pose &pose, const Weights &weights, Matrix68d *G)
{
	const CameraIntrinsics &k = camera.intrinsics();
	G->setZero();
	for (int i = 0; i < n; ++i) {
		const Eigen::Vector3d rm = pose.R * model_mm[i];
		const Eigen::Vector3d p = rm + pose.t_mm;
		Eigen::Vector2d uv;
		Eigen::Matrix<double, 2, 3> jp;
		if (!camera.project(p, &uv, &jp))
			return false;
		const double x = p.x() / p.z(), y = p.y() / p.z();
		const Eigen::Vector2d d = camera.distort({ x, y });
		const double r2 = x * x + y * y;
		Eigen::Matrix<double, 2, 8> Jt;
		Jt << d.x(), 0.0, 1.0, 0.0, k.fx * x * r2, k.fx * x * r2 * r2, k.fx * 2.0 * x * y,
			k.fx * (r2 + 2.0 * x * x), 0.0, d.y(), 0.0, 1.0, k.fy * y * r2,
			k.fy * y * r2 * r2, k.fy * (r2 + 2.0 * y * y), k.fy * 2.0 * x * y;
		Eigen::Matrix<double, 2, 6> J;
		J.leftCols<3>() = jp;
		J.rightCols<3>() = -jp * skew(rm);
		const Eigen::Matrix2d W = inverseCovariance(weights, i, jp);
		G->noalias() += J.transpose() * W * Jt;
	}
	return G->allFinite();
}

Pose applyStep(const Pose &pose, const Vector6d &delta)
{
	Pose out;
	out.t_mm = pose.t_mm + delta.head<3>();
	const Eigen::Matrix3d R = expRotation(delta.tail<3>()) * pose.R;
	/* Keep R orthonormal over many small updates. */
	out.R = Eigen::Quaterniond(R).normalized().toRotationMatrix();
	return out;
}

} /* namespace */

bool refinePose(const CameraModel &camera, const Eigen::Vector3d *model_mm,
		const Eigen::Vector2d *pixels, int n, const Pose &initial,
		const RefineOptions &options, RefineResult *result,
		const Eigen::Matrix2d *pixel_cov)
{
	*result = RefineResult{};
	result->pose = initial;
	if (n < 3 || n > static_cast<int>(kMaxLeds) || !initial.R.allFinite() ||
	    !initial.t_mm.allFinite())
		return false;

	Weights weights;
	weights.pixel_cov = pixel_cov;
	weights.fallback_px2 = options.sigma_px * options.sigma_px;
	weights.led_mm2 = options.led_sigma_mm * options.led_sigma_mm;
	if (pixel_cov && !(weights.fallback_px2 > 0.0))
		return false;

	Pose pose = initial;
	Evaluation ev;
	if (!evaluate(camera, model_mm, pixels, n, pose, true, weights, &ev))
		return false;

	/* The cost of one point one sigma off: 1 when weighted, else sigma_px^2. */
	const double unit_cost = pixel_cov ? 1.0 : weights.fallback_px2;
	/* Marquardt's damping, scaled by the diagonal of J^T J. */
	double lambda = 1e-3;
	constexpr double kMaxLambda = 1e12;
	int it = 0;
	bool converged = false;
	while (it < options.max_iterations && !converged) {
		++it;
		/* A perfect fit (noise-free data) cannot improve further. */
		if (ev.sse <= 1e-24 * n) {
			converged = true;
			break;
		}
		bool accepted = false;
		while (!accepted && lambda <= kMaxLambda) {
			Matrix6d A = ev.JtJ;
			A.diagonal() += lambda * ev.JtJ.diagonal();
			const Eigen::LDLT<Matrix6d> ldlt(A);
			if (ldlt.info() != Eigen::Success) {
				lambda *= 10.0;
				continue;
			}
			const Vector6d delta = ldlt.solve(-ev.Jtr);
			if (!delta.allFinite()) {
				lambda *= 10.0;
				continue;
			}
			/*
			 * The decrease the linearised model promises, -J^T W r . delta
			 * (in the cost's units): below 1e-10 of one point's variance, and
			 * a small share of the cost (so noise-free data still converge
			 * to working precision), the step would move the pose by some
			 * 1e-5 of its sigma: the pose is converged. Without this, a pose
			 * at the minimum raised the damping through some fifteen refused
			 * trials.
			 */
			const double promised = -ev.Jtr.dot(delta);
			if (promised <= 1e-10 * unit_cost && promised <= 1e-3 * ev.cost) {
				converged = true;
				accepted = true;
				break;
			}
			const Pose candidate = applyStep(pose, delta);
			Evaluation next;
			/*
			 * Trial steps need only the error; the jacobian only once a step
			 * is taken. With per-point covariances the error needs each
			 * point's projection jacobian anyway (the weights), so the trial
			 * is evaluated whole at once rather than twice when taken.
			 */
			const bool whole = weights.pixel_cov != nullptr;
			if (evaluate(camera, model_mm, pixels, n, candidate, whole, weights,
				     &next) &&
			    next.cost < ev.cost &&
			    (whole || evaluate(camera, model_mm, pixels, n, candidate, true,
					       weights, &next))) {
				const double decrease = ev.cost - next.cost;
				const bool small_step = delta.head<3>().norm() <=
								1e-10 * (1.0 + pose.t_mm.norm()) &&
							delta.tail<3>().norm() <= 1e-12;
				pose = candidate;
				ev = next;
				lambda = std::max(lambda * 0.2, 1e-9);
				accepted = true;
				/* A relative decrease of 1e-9 moves the pose by far less than its uncertainty. */
				if (small_step || decrease <= 1e-9 * ev.cost)
					converged = true;
			} else {
				lambda *= 10.0;
			}
		}
		/*
		 * No step decreases the error, not even a tiny gradient step: the
		 * pose is at the minimum to working precision.
		 */
		if (!accepted)
			converged = true;
	}

	result->pose = pose;
	result->iterations = it;
	result->converged = converged;
	result->rms_px = std::sqrt(ev.sse / n);
	result->max_px = ev.max_px;
	result->chi2 = pixel_cov ? ev.cost : ev.sse / weights.fallback_px2;
	if (!options.covariance)
		return true;

	/*
	 * Covariance sigma^2 (J^T J)^-1, inverted after Jacobi scaling (the
	 * translation and rotation columns differ by orders of magnitude) by
	 * Cholesky: the scaled matrix has a unit diagonal, and one whose
	 * condition number (1-norm, exact from the inverse) is above 1e12 leaves
	 * some direction of the pose undetermined. (A 6x6 eigen-solve made the
	 * same test at 8 % of a tracked frame's time, Eigen's rcond estimate at 3 %.)
	 */
	const Vector6d d = ev.JtJ.diagonal();
	if (!(d.minCoeff() > 0.0) || !d.allFinite())
		return false;
	const Vector6d inv_sqrt = d.cwiseSqrt().cwiseInverse();
	const Matrix6d B = inv_sqrt.asDiagonal() * ev.JtJ * inv_sqrt.asDiagonal();
	const Eigen::LLT<Matrix6d> llt(B);
	if (llt.info() != Eigen::Success)
		return false;
	const Matrix6d B_inv = llt.solve(Matrix6d::Identity());
	const double norm1 = B.cwiseAbs().colwise().sum().maxCoeff();
	const double inv_norm1 = B_inv.cwiseAbs().colwise().sum().maxCoeff();
	if (!B_inv.allFinite() || !(norm1 * inv_norm1 < 1e12))
		return false;
	const Matrix6d inv = inv_sqrt.asDiagonal() * B_inv * inv_sqrt.asDiagonal();
	if (!pixel_cov) {
		double sigma2 = options.sigma_px * options.sigma_px;
		if (2 * n > 6)
			sigma2 = std::max(sigma2, ev.sse / (2 * n - 6));
		result->covariance = sigma2 * inv;
		return true;
	}

	/* Whitened: (J^T W J)^-1 as it is, plus the calibration's share. */
	result->covariance = inv;
	const CameraIntrinsics::Sigma &cal = camera.intrinsics().sigma;
	if (cal.any()) {
		Matrix68d G;
		if (!calibrationCoupling(camera, model_mm, n, pose, weights, &G))
			return false;
		Eigen::Matrix<double, 8, 1> var;
		var << cal.fx, cal.fy, cal.cx, cal.cy, cal.k1, cal.k2, cal.p1, cal.p2;
		var = var.cwiseAbs2();
		const Matrix68d D = inv * G; /* the sign does not matter in D S D^T */
		result->covariance.noalias() += D * var.asDiagonal() * D.transpose();
	}
	result->covariance = 0.5 * (result->covariance + result->covariance.transpose()).eval();
	return true;
}

Eigen::Vector3d rollPanTiltSigmaDeg(const Eigen::Matrix3d &R,
				    const Eigen::Matrix<double, 6, 6> &covariance)
{
	/*
	 * With R = Rx(a) Ry(b) Rz(c), dR R^T = [w]x where
	 * w = M (da, db, dc), M = [e_x, Rx(a) e_y, Rx(a) Ry(b) e_z]
	 *   = [1, 0, sb; 0, ca, -sa cb; 0, sa, ca cb], det M = cb.
	 * So cov(a, b, c) = M^-1 cov(w) M^-T.
	 */
	const Eigen::Vector3d rpy = rollPanTiltDegFromRotation(R) * kRadPerDeg;
	const double ca = std::cos(rpy.x()), sa = std::sin(rpy.x());
	const double cb = std::cos(rpy.y()), sb = std::sin(rpy.y());
	const Eigen::Matrix3d Cw = covariance.bottomRightCorner<3, 3>();
	if (std::abs(cb) < 1e-12) {
		/* Gimbal lock: roll and tilt are not separable, only pan is. */
		const double inf = std::numeric_limits<double>::infinity();
		const Eigen::Vector3d e_pan{ 0.0, ca, sa }; /* dpan = <e_pan, w> at cb = 0 */
		return { inf, std::sqrt(std::max(0.0, e_pan.dot(Cw * e_pan))) * kDegPerRad, inf };
	}
	Eigen::Matrix3d M;
	M << 1.0, 0.0, sb, 0.0, ca, -sa * cb, 0.0, sa, ca * cb;
	const Eigen::Matrix3d Minv = M.inverse();
	const Eigen::Matrix3d C = Minv * Cw * Minv.transpose();
	return Eigen::Vector3d(std::sqrt(std::max(0.0, C(0, 0))), std::sqrt(std::max(0.0, C(1, 1))),
			       std::sqrt(std::max(0.0, C(2, 2)))) *
	       kDegPerRad;
}

} /* namespace dockpose */

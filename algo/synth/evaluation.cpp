/* SPDX-License-Identifier: MIT */
#include "algo/synth/evaluation.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <vector>

#include "algo/synth/rng.h"

namespace dockpose {

namespace {

using synth::Rng;
using synth::splitmix64;

struct ScenarioInfo {
	Scenario scenario;
	const char *name;
};

constexpr ScenarioInfo kScenarios[] = {
	{ Scenario::Legacy, "legacy" },
	{ Scenario::Clean, "clean" },
	{ Scenario::Cluttered, "cluttered" },
	{ Scenario::HeavyClutter, "heavy-clutter" },
	{ Scenario::Bloom, "bloom" },
	{ Scenario::Blur, "blur" },
	{ Scenario::Dim, "dim" },
	{ Scenario::Sunlit, "sunlit" },
	{ Scenario::OneFace, "one-face" },
	{ Scenario::TwoHidden, "two-hidden" },
	{ Scenario::TargetFree, "target-free" },
	{ Scenario::Combined, "combined" },
	{ Scenario::Scrambled, "scrambled" },
	{ Scenario::Mix, "mix" },
};

/* Light clutter under every effect: the legacy amounts. */
void lightClutter(Rng &r, RenderOptions *o)
{
	o->reflections = r.index(9);
	o->glints = r.index(3);
	o->hot_pixels = r.index(30);
}

/* 12-30 LED-like reflections, a quarter to a half of them near the target, elliptic. */
void heavyClutter(Rng &r, RenderOptions *o)
{
	const int n = 12 + r.index(19);
	const int near = static_cast<int>(std::lround(n * r.uniform(0.25, 0.5)));
	o->reflections = n - near;
	o->near_reflections = near;
	o->reflection_squash = 0.5;
	o->glints = 2 + r.index(5);
	o->hot_pixels = r.index(61);
}

void bloom(Rng &r, RenderOptions *o)
{
	o->bloom = r.uniform(2.0, 3.0);
	o->bloom_overexposure = r.uniform(3.0, 8.0);
	o->bloom_halo_peak = r.uniform(40.0, 120.0);
}

void motionBlur(Rng &r, RenderOptions *o)
{
	o->motion_blur_px = r.uniform(3.0, 12.0);
	o->motion_blur_reflections = r.chance(0.5); /* camera or target motion */
}

void dim(Rng &r, RenderOptions *o)
{
	o->dimmed_leds = 1 + r.index(2);
}

void sunlit(Rng &r, RenderOptions *o)
{
	o->sun_patches = 1 + r.index(3);
	o->background = r.uniform(15.0, 50.0);
	o->gradient = r.uniform(60.0, 200.0);
}

/* The legacy frame's render options (the draws in their historical order). */
template<typename Uniform>
RenderOptions legacyOptions(bool clutter, Uniform &&unit)
{
	RenderOptions o;
	o.noise_sigma = 1.0 + 2.0 * unit();
	o.gradient = 30.0 * unit();
	if (clutter) {
		o.reflections = static_cast<int>(9 * unit());
		o.glints = static_cast<int>(3 * unit());
		o.hot_pixels = static_cast<int>(30 * unit());
		o.occluded_leds = unit() < 0.5 ? 1 : 0;
	}
	return o;
}

std::uint32_t faceMask(const TargetModel &target, std::size_t f)
{
	std::uint32_t m = 0;
	for (int v : target.faces[f])
		m |= 1u << v;
	return m;
}

/*
 * The proper rigid symmetries of the LED set (rotation and translation in the
 * target frame mapping every LED onto an LED within tol_mm), identity first:
 * a pose composed with one of them shows the same image.
 */
struct Symmetry {
	Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
	Eigen::Vector3d t = Eigen::Vector3d::Zero();
};

Eigen::Matrix3d triangleFrame(const Eigen::Vector3d &p, const Eigen::Vector3d &q,
			      const Eigen::Vector3d &r)
{
	Eigen::Matrix3d m;
	const Eigen::Vector3d e1 = (q - p).normalized();
	const Eigen::Vector3d e3 = e1.cross(r - p).normalized();
	m.col(0) = e1;
	m.col(1) = e3.cross(e1);
	m.col(2) = e3;
	return m;
}

std::vector<Symmetry> modelSymmetries(const TargetModel &target, double tol_mm)
{
	std::vector<Symmetry> out(1);
	const int n = static_cast<int>(target.points_mm.size());
	if (n < 3)
		return out;
	/* A non-degenerate triangle of LEDs: 0, 1 and the one farthest from their line. */
	const Eigen::Vector3d a = target.points_mm[0], b = target.points_mm[1];
	int c = 2;
	double best = -1.0;
	for (int k = 2; k < n; ++k) {
		const double d = (target.points_mm[k] - a).cross(b - a).norm();
		if (d > best) {
			best = d;
			c = k;
		}
	}
	const Eigen::Vector3d cc = target.points_mm[c];
	const Eigen::Matrix3d F = triangleFrame(a, b, cc);
	for (int i = 0; i < n; ++i)
		for (int j = 0; j < n; ++j)
			for (int k = 0; k < n; ++k) {
				if (i == j || j == k || i == k || (i == 0 && j == 1 && k == c))
					continue;
				const Eigen::Vector3d p = target.points_mm[i],
						      q = target.points_mm[j],
						      r = target.points_mm[k];
				if (std::abs((q - p).norm() - (b - a).norm()) > tol_mm ||
				    std::abs((r - p).norm() - (cc - a).norm()) > tol_mm ||
				    std::abs((r - q).norm() - (cc - b).norm()) > tol_mm)
					continue;
				Symmetry sym;
				sym.R = triangleFrame(p, q, r) * F.transpose();
				sym.t = p - sym.R * a;
				bool maps = true;
				for (int m = 0; m < n && maps; ++m) {
					const Eigen::Vector3d x =
						sym.R * target.points_mm[m] + sym.t;
					double nearest = 1e30;
					for (int l = 0; l < n; ++l)
						nearest = std::min(
							nearest, (x - target.points_mm[l]).norm());
					maps = nearest <= tol_mm;
				}
				if (maps)
					out.push_back(sym);
			}
	return out;
}

} /* namespace */

const char *scenarioName(Scenario scenario)
{
	for (const ScenarioInfo &info : kScenarios)
		if (info.scenario == scenario)
			return info.name;
	return "unknown";
}

std::string scenarioNames()
{
	std::string names;
	for (const ScenarioInfo &info : kScenarios)
		names += (names.empty() ? "" : ", ") + std::string(info.name);
	return names;
}

bool parseScenario(const std::string &name, Scenario *scenario)
{
	for (const ScenarioInfo &info : kScenarios)
		if (name == info.name) {
			*scenario = info.scenario;
			return true;
		}
	return false;
}

void accumulate(ScenarioTally *a, const ScenarioTally &b)
{
	a->frames += b.frames;
	a->target_free += b.target_free;
	a->face_complete += b.face_complete;
	a->found += b.found;
	a->correct += b.correct;
	a->wrong += b.wrong;
	a->face_complete_correct += b.face_complete_correct;
	for (int k = 0; k < kStatusSlots; ++k)
		a->misses[k] += b.misses[k];
	a->face_complete_wrong += b.face_complete_wrong;
	a->target_free_wrong += b.target_free_wrong;
}

RenderOptions scenarioOptions(Scenario scenario, std::uint64_t seed)
{
	Rng r(splitmix64(seed ^ 0x7363656eULL));
	RenderOptions o;
	o.noise_sigma = r.uniform(1.0, 3.0);
	o.gradient = r.uniform(0.0, 30.0);
	switch (scenario) {
	case Scenario::Legacy:
	case Scenario::Mix:
	case Scenario::Clean:
		break;
	case Scenario::Cluttered:
		lightClutter(r, &o);
		o.occluded_leds = r.chance(0.5) ? 1 : 0;
		break;
	case Scenario::HeavyClutter:
		heavyClutter(r, &o);
		o.occluded_leds = r.chance(0.3) ? 1 : 0;
		break;
	case Scenario::Bloom:
		lightClutter(r, &o);
		bloom(r, &o);
		break;
	case Scenario::Blur:
		lightClutter(r, &o);
		motionBlur(r, &o);
		break;
	case Scenario::Dim:
		lightClutter(r, &o);
		dim(r, &o);
		break;
	case Scenario::Sunlit:
		lightClutter(r, &o);
		sunlit(r, &o);
		break;
	case Scenario::OneFace:
		lightClutter(r, &o);
		o.one_face_only = true;
		break;
	case Scenario::TwoHidden:
		lightClutter(r, &o);
		o.occluded_leds = 2;
		break;
	case Scenario::TargetFree: {
		o.draw_target = false;
		const int n = r.index(31);
		const int near = static_cast<int>(std::lround(n * r.uniform(0.0, 0.5)));
		o.reflections = n - near;
		o.near_reflections = near;
		o.reflection_squash = 0.5;
		o.glints = r.index(7);
		o.hot_pixels = r.index(61);
		if (r.chance(0.3))
			sunlit(r, &o);
		if (r.chance(0.3))
			bloom(r, &o);
		if (r.chance(0.3))
			motionBlur(r, &o);
		break;
	}
	case Scenario::Combined: {
		heavyClutter(r, &o);
		if (r.chance(0.35))
			bloom(r, &o);
		if (r.chance(0.35))
			motionBlur(r, &o);
		if (r.chance(0.35))
			dim(r, &o);
		if (r.chance(0.35))
			sunlit(r, &o);
		o.blur_sigma_px = r.uniform(0.6, 1.4);
		switch (r.index(4)) {
		case 1:
			o.occluded_leds = 1;
			break;
		case 2:
			o.occluded_leds = 2;
			break;
		case 3:
			o.one_face_only = true;
			break;
		default:
			break;
		}
		break;
	}
	case Scenario::Scrambled:
		lightClutter(r, &o);
		o.scramble = r.uniform(0.3, 0.6);
		break;
	}
	return o;
}

EvaluationTally evaluate(const TargetModel &target, const CameraIntrinsics &camera,
			 const PipelineConfig &pipeline_config, const EvaluationConfig &config,
			 const std::function<void(const FrameOutcome &, const Image &)> &on_frame)
{
	FrameRenderer renderer(target, camera);
	Pipeline pipeline(target, camera, pipeline_config);
	/* The legacy stream: its draws, in their order, make the historical frames. */
	std::mt19937_64 rng(config.seed);
	std::uniform_real_distribution<double> unit(0.0, 1.0);
	auto uniform = [&]() {
		return unit(rng);
	};
	auto symmetric = [&](double a) {
		return a * (2.0 * unit(rng) - 1.0);
	};
	const bool legacy_frames = config.scenario == Scenario::Legacy && !config.any_side;
	const int n_faces = static_cast<int>(target.faces.size());
	/*
	 * A symmetric target's pose is defined only up to its symmetries (the
	 * wedge's half turn about z, seen with any roll): the new scenarios
	 * compare modulo them; the legacy frames keep the plain comparison.
	 */
	std::vector<Symmetry> symmetries(1);
	if (!legacy_frames && config.modulo_symmetry)
		symmetries = modelSymmetries(target, 0.5);

	/* Mix: every scenario but Legacy and Scrambled (the false-alarm test's own), target-free weighted. */
	std::array<double, kScenarioCount> mix_weight{};
	double mix_total = 0.0;
	for (int s = 1; s < kScenarioCount; ++s) {
		const auto scenario = static_cast<Scenario>(s);
		mix_weight[s] = scenario == Scenario::TargetFree
					? std::max(0.0, config.mix_target_free_weight)
				: scenario == Scenario::Scrambled ? 0.0
								  : 1.0;
		mix_total += mix_weight[s];
	}

	Image frame;
	EvaluationTally tally;
	for (int i = 0; i < std::max(config.first_frame, 0) + config.frames; ++i) {
		FrameOutcome out;
		out.index = i;
		RenderOptions o;
		const std::uint64_t render_seed =
			config.seed * 1000003u + static_cast<std::uint64_t>(i);
		if (legacy_frames) {
			/* Log-uniform range; the target anywhere it fits, nearer the centre when close. */
			const double range =
				config.min_range_mm *
				std::pow(config.max_range_mm / config.min_range_mm, unit(rng));
			const Eigen::Vector3d rpy{ symmetric(config.max_angle_deg),
						   symmetric(config.max_angle_deg),
						   symmetric(config.max_angle_deg) };
			const double spread =
				std::min(0.3, 0.3 * range / config.max_range_mm + 0.05);
			out.range_mm = range;
			out.truth = poseAt(camera, target, range, rpy, 0.5 + symmetric(spread),
					   0.5 + symmetric(spread));
			o = legacyOptions(config.clutter, uniform);
		} else {
			/* One stream per frame: a frame is the same whatever came before it. */
			Rng r(splitmix64(config.seed * 0x9e3779b97f4a7c15ULL +
					 static_cast<std::uint64_t>(i)));
			Scenario scenario = config.scenario;
			if (scenario == Scenario::Mix) {
				double pick = r.uniform(0.0, mix_total);
				scenario = Scenario::Clean;
				for (int s = 1; s < kScenarioCount; ++s) {
					if (pick < mix_weight[s]) {
						scenario = static_cast<Scenario>(s);
						break;
					}
					pick -= mix_weight[s];
				}
			}
			out.scenario = scenario;
			const double range =
				config.min_range_mm *
				std::pow(config.max_range_mm / config.min_range_mm, r.uniform());
			out.range_mm = range;
			if (config.any_side && n_faces > 0) {
				SideView view;
				const int face = r.index(n_faces);
				out.in_frame = sampleSideView(camera, target, face, range,
							      config.side_max_angle_deg, r.next(),
							      &out.truth, &view);
				out.view_face = face;
				out.view_angle_deg = view.angle_deg;
			} else {
				const double a = config.max_angle_deg;
				const Eigen::Vector3d rpy{ r.uniform(-a, a), r.uniform(-a, a),
							   r.uniform(-a, a) };
				const double spread =
					std::min(0.3, 0.3 * range / config.max_range_mm + 0.05);
				out.truth = poseAt(camera, target, range, rpy,
						   0.5 + r.uniform(-spread, spread),
						   0.5 + r.uniform(-spread, spread));
			}
			const std::uint64_t option_seed = r.next();
			if (scenario == Scenario::Legacy) {
				o = legacyOptions(config.clutter, [&]() { return r.uniform(); });
			} else {
				o = scenarioOptions(scenario, option_seed);
				o.fast_noise = config.fast_noise;
			}
		}

		if (i < config.first_frame)
			continue;
		renderer.render(out.truth, o, render_seed, &frame, &out.render);
		if (!config.track)
			pipeline.reset();
		const PoseResult &r = pipeline.process(frame.view());
		out.result = &r;
		out.target_free = !out.render.target_drawn || out.render.scrambled;
		for (int f = 0; f < n_faces && !out.face_complete && !out.target_free; ++f) {
			const std::uint32_t m = faceMask(target, static_cast<std::size_t>(f));
			out.face_complete = (out.render.visible_mask & m) == m;
		}

		++tally.frames;
		const bool solvable = std::popcount(out.render.visible_mask) >=
				      config.min_visible_leds;
		tally.solvable += solvable ? 1 : 0;
		ScenarioTally &st = tally.scenarios[static_cast<int>(out.scenario)];
		++st.frames;
		st.target_free += out.target_free ? 1 : 0;
		st.face_complete += out.face_complete ? 1 : 0;
		if (r.found) {
			++tally.found;
			++st.found;
			const double trans_tol =
				std::max(config.min_trans_err_mm,
					 config.trans_err_frac * out.truth.t_mm.norm());
			for (std::size_t k = 0; k < symmetries.size(); ++k) {
				/* The truth composed with symmetry k: X_c = R (S X + s) + t. */
				const Eigen::Matrix3d R_k = out.truth.R * symmetries[k].R;
				const Eigen::Vector3d t_k =
					out.truth.R * symmetries[k].t + out.truth.t_mm;
				const double rot = rotationAngleDeg(R_k, r.R);
				const double trans = (t_k - r.t_mm).norm();
				const bool ok = rot <= config.max_rot_err_deg && trans <= trans_tol;
				if (k == 0 || (ok && !out.correct)) {
					out.rot_err_deg = rot;
					out.trans_err_mm = trans;
					out.correct = ok;
					out.symmetry = static_cast<int>(k);
				}
			}
			out.correct = out.correct && !out.target_free;
			out.wrong = !out.correct;
			if (out.correct) {
				++tally.correct;
				++st.correct;
				tally.solvable_correct += solvable ? 1 : 0;
				tally.worst_rot_err_deg =
					std::max(tally.worst_rot_err_deg, out.rot_err_deg);
				tally.worst_trans_err_frac =
					std::max(tally.worst_trans_err_frac,
						 out.trans_err_mm / out.truth.t_mm.norm());
			} else {
				++tally.wrong;
				++st.wrong;
				st.target_free_wrong += out.target_free ? 1 : 0;
			}
		}
		if (out.face_complete) {
			if (out.correct)
				++st.face_complete_correct;
			else if (r.found)
				++st.face_complete_wrong;
			else
				++st.misses[std::min(static_cast<int>(r.status), kStatusSlots - 1)];
		}
		if (on_frame)
			on_frame(out, frame);
	}
	for (const ScenarioTally &st : tally.scenarios)
		accumulate(&tally.total, st);
	tally.face_complete = tally.total.face_complete;
	tally.face_complete_correct = tally.total.face_complete_correct;
	tally.target_free = tally.total.target_free;
	return tally;
}

} /* namespace dockpose */

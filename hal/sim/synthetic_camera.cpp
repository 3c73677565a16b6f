/* SPDX-License-Identifier: MIT */
/*
 * The synthetic camera (see synthetic_camera.h).
 */
#include "hal/sim/synthetic_camera.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

namespace dockpose::hal {

SyntheticCamera::SyntheticCamera(const TargetModel &target, const CameraIntrinsics &intrinsics,
				 const SyntheticScene &scene, const StrobeController *strobe)
	: SimCameraBase(LatePolicy::Skip),
	  target_(target),
	  intrinsics_(intrinsics),
	  scene_(scene),
	  strobe_(strobe),
	  renderer_(target, intrinsics)
{
}

SyntheticCamera::~SyntheticCamera()
{
	stop();
}

std::string SyntheticCamera::name() const
{
	return "synthetic camera (" +
	       (target_.name.empty() ? std::string("target") : target_.name) + ", " +
	       std::to_string(intrinsics_.width) + "x" + std::to_string(intrinsics_.height) + ")";
}

Status SyntheticCamera::configure(const CameraConfig &config)
{
	if (Status bad = intrinsics_.validate(); !bad)
		return fail(name() + ": bad intrinsics: " + bad.message());
	if (target_.points_mm.empty())
		return fail(name() + ": the target model has no LEDs");
	if ((config.width != 0 && config.width != intrinsics_.width) ||
	    (config.height != 0 && config.height != intrinsics_.height))
		return fail(name() + ": requested size " + std::to_string(config.width) + "x" +
			    std::to_string(config.height) + " does not match the intrinsics' " +
			    std::to_string(intrinsics_.width) + "x" +
			    std::to_string(intrinsics_.height) +
			    " (use 0x0 or the intrinsics' size)");
	for (int i = 0; i < 6; ++i)
		if (!std::isfinite(scene_.from[i]) || !std::isfinite(scene_.to[i]))
			return fail(name() + ": the scene's trajectory is not finite");
	if (!std::isfinite(scene_.duration_s) || scene_.duration_s < 0.0)
		return fail(name() + ": scene duration_s " + std::to_string(scene_.duration_s) +
			    " must be 0 or more");
	if (!std::isfinite(scene_.noise_sigma) || scene_.noise_sigma < 0.0)
		return fail(name() + ": scene noise_sigma " + std::to_string(scene_.noise_sigma) +
			    " must be 0 or more");
	if (scene_.reflections < 0 || scene_.glints < 0 || scene_.hot_pixels < 0)
		return fail(name() + ": scene clutter counts must be 0 or more");
	return setup(config, intrinsics_.width, intrinsics_.height);
}

Pose SyntheticCamera::truthAt(std::uint64_t sequence) const
{
	const double t_s = static_cast<double>(sequence) * static_cast<double>(periodNs()) * 1e-9;
	double u = 1.0;
	if (scene_.duration_s > 0.0) {
		u = t_s / scene_.duration_s;
		if (scene_.loop)
			u -= std::floor(u);
		else
			u = std::min(u, 1.0);
	}
	double v[6];
	for (int i = 0; i < 6; ++i)
		v[i] = scene_.from[i] + u * (scene_.to[i] - scene_.from[i]);
	Pose pose;
	pose.t_mm = Eigen::Vector3d(v[0], v[1], v[2]);
	pose.R = rotationFromRollPanTiltDeg(Eigen::Vector3d(v[3], v[4], v[5]));
	return pose;
}

std::uint64_t SyntheticCamera::frameSeed(std::uint64_t scene_seed, std::uint64_t sequence)
{
	return scene_seed * 0x9e3779b97f4a7c15ULL + sequence + 1;
}

bool SyntheticCamera::produceFrame(const Exposure &exposure, Image *image)
{
	const Lighting lighting = strobe_ ? strobe_->lighting(exposure.start_ns, exposure.end_ns)
					  : Lighting::Lit;
	double led_gain = 1.0;
	switch (lighting) {
	case Lighting::Lit:
		led_gain = 1.0;
		break;
	case Lighting::Mixed:
		led_gain = 0.5;
		break;
	case Lighting::Unlit:
		led_gain = 0.0;
		break;
	}
	led_gain *= std::clamp(std::sqrt(exposure.exposure_us * exposure.analogue_gain / 2000.0),
			       0.5, 2.0);

	RenderOptions options;
	options.noise_sigma = scene_.noise_sigma;
	options.reflections = scene_.reflections;
	options.glints = scene_.glints;
	options.hot_pixels = scene_.hot_pixels;
	options.clutter_seed = scene_.seed != 0 ? scene_.seed : kDefaultClutterSeed;
	options.led_gain = led_gain;
	renderer_.render(truthAt(exposure.sequence), options,
			 frameSeed(scene_.seed, exposure.sequence), image);
	return true;
}

} /* namespace dockpose::hal */

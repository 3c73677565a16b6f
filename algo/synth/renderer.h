/* SPDX-License-Identifier: MIT */
/*
 * Synthetic frames with known truth: the target's LEDs as elliptical spots
 * that shrink and dim with range and viewing angle, sensor noise, an ambient
 * gradient, and optional clutter (hot pixels, LED-like reflections, long
 * glints) and occlusion. Used by tests, the `dockpose render` tool and the
 * simulated camera. Deterministic for a given seed.
 *
 * Visibility: an LED shines into the half-space in front of its faces (the
 * fronts of TargetModel::frontNormals, shared with the solver); an LED is
 * visible when the camera sees at least one of its faces from the front
 * (viewing angle below max_view_angle_deg).
 *
 * Allocates: render() writes into a caller-owned Image of the camera's size
 * (allocated by the caller once); no other allocation per frame.
 */
#pragma once

#include <cstdint>

#include <Eigen/Core>

#include "algo/camera_model.h"
#include "algo/image.h"
#include "algo/pose.h"
#include "algo/static_vector.h"
#include "algo/target_model.h"

namespace dockpose {

struct RenderOptions {
	/* LED spot: radius of the emitting disc (mm) and optical blur (px, sigma). */
	double led_radius_mm = 2.5;
	double blur_sigma_px = 0.8;
	/* Peak brightness above background of an LED at reference_range_mm, head on. */
	double led_peak = 230.0;
	double reference_range_mm = 600.0;
	/* LED spot never dimmer than this at its peak (sensor gain would rise). */
	double min_led_peak = 60.0;
	double max_view_angle_deg = 75.0;

	/* Background: level at the image centre, gradient across the frame, noise. */
	double background = 12.0;
	double gradient = 10.0;		/* levels from one side of the frame to the other */
	double noise_sigma = 2.0;	/* Gaussian read noise, levels */

	/* Clutter. */
	int hot_pixels = 0;		/* single saturated pixels */
	int reflections = 0;		/* LED-like round spots in random places */
	int glints = 0;			/* long thin bright streaks */
	/* Occlusion: hide this many randomly chosen visible LEDs ... */
	int occluded_leds = 0;
	/* ... or exactly these (bit i hides LED i); applied in addition. */
	std::uint32_t occlusion_mask = 0;

	/*
	 * Scene and lighting, for the simulated camera. clutter_seed seeds the
	 * scene (background gradient, reflections, glints, hot pixels); 0: the
	 * frame's seed. With a fixed clutter_seed, frames of different seeds
	 * share their clutter (ambient light sources stay put) while the read
	 * noise and random occlusion follow the frame's seed. Clutter keeps
	 * clear of the LEDs, so it only moves where the target moves onto it (and
	 * a reflection's size follows the target's range). led_gain scales the
	 * LED spots alone (0: LEDs dark, 0.5: a half-lit exposure): the clutter's
	 * places and brightness do not depend on it, unlike occlusion.
	 */
	std::uint64_t clutter_seed = 0;
	double led_gain = 1.0;
};

struct RenderTruth {
	Pose pose;
	/* Ideal (noise-free) image position of every LED, and whether it was drawn. */
	StaticVector<Eigen::Vector2d, kMaxLeds> led_px;
	std::uint32_t visible_mask = 0;	 /* LEDs drawn in the frame */
	std::uint32_t occluded_mask = 0; /* LEDs hidden by occlusion */
	int clutter_blobs = 0;		 /* reflections + glints drawn */
};

class FrameRenderer
{
public:
	FrameRenderer(const TargetModel &target, const CameraIntrinsics &camera);

	/* Render one frame of the camera's size into *out (resized if needed). */
	void render(const Pose &pose, const RenderOptions &options, std::uint64_t seed, Image *out,
		    RenderTruth *truth = nullptr) const;

	/* Whether LED i faces the camera at this pose (before occlusion). */
	bool ledVisible(const Pose &pose, int led, double max_view_angle_deg) const;

	/* Front unit normal of face f (target frame), see the visibility rule above. */
	const Eigen::Vector3d &faceNormal(int f) const { return normals_[f]; }

private:
	TargetModel target_;
	CameraModel camera_;
	StaticVector<Eigen::Vector3d, kMaxFaces> normals_;
};

/*
 * A pose looking at the target from `range_mm` along the camera's optical
 * axis, target rotated by (roll, pan, tilt) degrees and offset laterally so
 * its centre lands at (u_frac, v_frac) of the frame (0.5, 0.5 = centre).
 */
Pose poseAt(const CameraIntrinsics &camera, const TargetModel &target, double range_mm,
	    const Eigen::Vector3d &rpy_deg, double u_frac = 0.5, double v_frac = 0.5);

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
/*
 * Synthetic frames with known truth: the target's LEDs as elliptical spots
 * that shrink and dim with range and viewing angle, sensor noise, an ambient
 * gradient, and optional clutter (hot pixels, LED-like reflections, also close
 * to the target, long glints), sunlit patches, blooming, motion blur, dimmed
 * LEDs, occlusion (random LEDs, or all but one face) and target-free frames.
 * Used by tests, the `dockpose render` tool, the simulated camera and the
 * accuracy evaluation. Deterministic for a given seed. Every effect is off by
 * default, and the defaults render exactly the frames they always did.
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
#include <limits>

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
	double gradient = 10.0; /* levels from one side of the frame to the other */
	double noise_sigma = 2.0; /* Gaussian read noise, levels */
	/*
	 * Faster read noise (about 5x) for long evaluations: the sum of four
	 * uniforms per pixel, scaled to noise_sigma (nearly Gaussian, tails cut
	 * at 3.5 sigma); a different pattern from the default Box-Muller noise.
	 */
	bool fast_noise = false;
	/*
	 * Shot noise, levels per electron: a pixel whose noise-free level is v
	 * gets the variance noise_sigma^2 + shot_gain * v (Poisson, in its
	 * Gaussian approximation; 0: read noise only).
	 */
	double shot_gain = 0.0;

	/* Clutter. */
	int hot_pixels = 0; /* single saturated pixels */
	int reflections = 0; /* LED-like round spots in random places */
	int glints = 0; /* long thin bright streaks */
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

	/*
	 * Harder scenes (all off by default). Random choices that belong to the
	 * scene (reflection shapes and places, sunlit patches) follow the scene
	 * seed; those that belong to the frame (dimmed LEDs, the face kept, the
	 * blur direction) follow the frame's seed.
	 */

	/*
	 * Reflections near the target: this many more LED-like reflections placed
	 * among and around the LEDs (inside their image's bounding box grown by
	 * half its size on each side), clear of the LED spots by only
	 * near_clearance_px beyond both spots' extents, so each is still a blob of
	 * its own. reflection_squash makes every reflection elliptic (minor/major
	 * axis drawn in [1 - squash, 1], random orientation), like a foreshortened
	 * LED; 0 keeps them round.
	 */
	int near_reflections = 0;
	double near_clearance_px = 1.5;
	double reflection_squash = 0.0;

	/*
	 * Blooming: overexposed LED spots whose cores clip at 255, each with a
	 * round soft halo. bloom > 0 turns it on and is the halo's radius (at half
	 * its level) in multiples of the spot's radius (its largest semi-axis, at
	 * least the blur sigma); 2-3 is typical. The spot's peak is multiplied by
	 * bloom_overexposure and made at least 1.5 x 255 (so it clips, unless it is
	 * also dimmed: dimming applies last);
	 * bloom_halo_peak is the halo's level above background at its centre.
	 * With bloom_reflections the LED-like reflections bloom the same way.
	 */
	double bloom = 0.0;
	double bloom_overexposure = 4.0;
	double bloom_halo_peak = 80.0;
	bool bloom_reflections = true;

	/*
	 * Linear motion blur: every LED spot (and halo) smeared uniformly along a
	 * straight streak of motion_blur_px pixels centred on the LED's position
	 * (the mid-exposure position, so the truth stays the streak's centre),
	 * direction motion_blur_angle_deg in the image (0: +u, 90: +v; NaN: random
	 * per frame). The LED's energy is spread along the streak (its peak
	 * falls), but no further than min_led_peak (the sensor gain would rise).
	 * With motion_blur_reflections the reflections streak too (the camera
	 * moved, not the target).
	 */
	double motion_blur_px = 0.0;
	double motion_blur_angle_deg = std::numeric_limits<double>::quiet_NaN();
	bool motion_blur_reflections = true;

	/*
	 * Dimmed LEDs: this many randomly chosen drawn LEDs, plus those of
	 * dim_mask, shine at a brightness factor drawn per LED in [dim_min,
	 * dim_max] (after the floor at min_led_peak: a weak LED, same gain).
	 */
	int dimmed_leds = 0;
	std::uint32_t dim_mask = 0;
	double dim_min = 0.25;
	double dim_max = 0.40;

	/*
	 * Sunlit patches: large, smooth, bright regions (soft-edged ellipses of
	 * 6-25% of the frame's larger side per semi-axis, a smooth edge 15 px to
	 * half the minor semi-axis wide) whose level above background is drawn in
	 * [sun_peak_min, sun_peak_max]; above 255 they saturate in their middle.
	 * They may lie over the target: an LED whose background there leaves it
	 * less than half its contrast below 255 is washed out (not counted as
	 * drawn, see RenderTruth::washed_out_mask). Strong gradients: `gradient`.
	 */
	int sun_patches = 0;
	double sun_peak_min = 60.0;
	double sun_peak_max = 320.0;

	/*
	 * Occlusion of all but one face: every LED not on the kept face is
	 * hidden. keep_face >= 0 keeps that face; one_face_only keeps a random
	 * face among those whose four LEDs are drawable (the one with the most
	 * drawable LEDs when none is complete). Applied before occluded_leds.
	 */
	bool one_face_only = false;
	int keep_face = -1;

	/* Target-free frame: no LED is drawn, only the scene; clutter may be anywhere. */
	bool draw_target = true;

	/*
	 * Scrambled target: every LED is drawn (same brightness, size and
	 * visibility rule) displaced in 3-D by a random direction and a length
	 * drawn per LED in [0.5, 1] x scramble x the target's diameter (0: off).
	 * The frame then holds LEDs at the target's scale that form no rigid
	 * copy of its geometry except by chance: any pose found on it is wrong
	 * (RenderTruth::scrambled). The displacements follow the frame's seed.
	 */
	double scramble = 0.0;
};

struct RenderTruth {
	Pose pose;
	/* Ideal (noise-free) image position of every LED, and whether it was drawn. */
	StaticVector<Eigen::Vector2d, kMaxLeds> led_px;
	std::uint32_t visible_mask = 0; /* LEDs drawn in the frame */
	std::uint32_t occluded_mask = 0; /* LEDs hidden by occlusion */
	int clutter_blobs = 0; /* reflections + glints drawn */
	/* LEDs dimmed, and drawn but lost in a saturated sunlit patch (not in visible_mask). */
	std::uint32_t dimmed_mask = 0;
	std::uint32_t washed_out_mask = 0;
	int kept_face = -1; /* the face kept by one-face occlusion, else -1 */
	double motion_blur_angle_deg = 0.0; /* the streak's direction, when blurred */
	int sun_patches = 0; /* sunlit patches drawn */
	bool target_drawn = true; /* false on a target-free frame */
	bool scrambled =
		false; /* the LEDs were drawn displaced (RenderOptions::scramble): no true pose */
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

/*
 * A view of the target from one side, inside the emission cone of one face:
 * the camera sits on the line from the face's centre along a direction at
 * angle_deg from the face's front normal (TargetModel::frontNormals) and at
 * azimuth_deg about it (measured from the normal's unitOrthogonal(), towards
 * normal x unitOrthogonal()); it is rolled by roll_deg about its line of
 * sight to the face's centre, which lands at (u_frac, v_frac) of the frame.
 */
struct SideView {
	int face = 0;
	double angle_deg = 0.0;
	double azimuth_deg = 0.0;
	double roll_deg = 0.0;
	double u_frac = 0.5, v_frac = 0.5;
};

/* The pose of a SideView with the camera range_mm from the face's centre. */
Pose poseFromSide(const CameraIntrinsics &camera, const TargetModel &target, double range_mm,
		  const SideView &view);

/*
 * Draw a view of face `face` from range_mm: the direction uniform over the
 * cone (in solid angle) up to max_angle_deg from the face's front normal, a
 * uniform roll, and the face's centre anywhere in the frame such that every
 * LED of the target projects at least margin_px inside it (and in front of
 * the camera). Returns false when no placement fits after a number of
 * attempts (the target too large for the frame at this range); *pose is then
 * the last attempt, with the face's centre in the frame's centre.
 * Deterministic for a seed. Allocates: never.
 */
bool sampleSideView(const CameraIntrinsics &camera, const TargetModel &target, int face,
		    double range_mm, double max_angle_deg, std::uint64_t seed, Pose *pose,
		    SideView *view = nullptr, double margin_px = 4.0);

/*
 * Whether every LED of the target projects in front of the camera, at least
 * margin_px inside the frame and inside the lens's valid field.
 */
bool targetInFrame(const CameraModel &camera, const TargetModel &target, const Pose &pose,
		   double margin_px);

} /* namespace dockpose */

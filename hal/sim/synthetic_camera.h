/* SPDX-License-Identifier: MIT */
/*
 * SyntheticCamera: a simulated camera that renders the target (FrameRenderer,
 * algo/synth/renderer.h) along a docking approach, in real time, for tests,
 * demos and the sim board. It behaves like a real camera (see
 * sim_camera_base.h): own capture thread on a fixed frame grid, bounded
 * buffers, drops counted.
 *
 * Trajectory: a deterministic function of the frame sequence number. Frame n
 * shows the target at pose(u), u = n * frame_period / duration_s, linear
 * between `from` (u = 0) and `to` (u = 1) in x, y, z (mm) and in roll, pan,
 * tilt (degrees, R = Rx(roll) Ry(pan) Rz(tilt)); held at `to` for u > 1, or
 * starting again at `from` when looping. truthAt(n) is that pose.
 *
 * Each frame is FrameRenderer::render(truthAt(n), options, seed_n) with the
 * RenderOptions defaults except:
 *   noise_sigma, reflections, glints, hot_pixels  from the scene,
 *   clutter_seed = scene.seed (kDefaultClutterSeed when 0): the clutter and
 *                  the background gradient are the same in every frame
 *                  (ambient light sources), the noise is fresh per frame
 *                  (seed_n = frameSeed(scene.seed, n)),
 *   led_gain     = lighting x exposure: the StrobeController's lighting() of
 *                  the exposure window: Lit 1, Mixed 0.5 (a partly lit
 *                  exposure), Unlit 0 (no LEDs, same clutter); nullptr
 *                  controller: always Lit. Times sqrt(exposure_us x gain /
 *                  2000 us), clamped to [0.5, 2]: 1 at the default controls.
 *
 * Allocates: the constructor and configure() (buffers); the capture loop and
 * the frame path never.
 */
#pragma once

#include <cstdint>
#include <string>

#include "algo/camera_model.h"
#include "algo/pose.h"
#include "algo/synth/renderer.h"
#include "algo/target_model.h"
#include "hal/sim/sim_camera_base.h"
#include "hal/sim/synthetic_scene.h"
#include "hal/strobe.h"

namespace dockpose::hal {

class SyntheticCamera : public SimCameraBase
{
public:
	/* Clutter seed used when scene.seed is 0. */
	static constexpr std::uint64_t kDefaultClutterSeed = 0x5eed5eed5eedULL;

	/* strobe: the lighting source (not owned; nullptr: LEDs always lit). */
	SyntheticCamera(const TargetModel &target, const CameraIntrinsics &intrinsics,
			const SyntheticScene &scene, const StrobeController *strobe);
	~SyntheticCamera() override;

	std::string name() const override;
	/* Size: config width/height must be 0 or the intrinsics' size. */
	Status configure(const CameraConfig &config) override;

	/* The target pose of frame `sequence` (uses the configured frame period). */
	Pose truthAt(std::uint64_t sequence) const;

	/* The noise seed of frame `sequence`. */
	static std::uint64_t frameSeed(std::uint64_t scene_seed, std::uint64_t sequence);

protected:
	bool produceFrame(const Exposure &exposure, Image *image) override;

private:
	TargetModel target_;
	CameraIntrinsics intrinsics_;
	SyntheticScene scene_;
	const StrobeController *strobe_;
	FrameRenderer renderer_;
};

} /* namespace dockpose::hal */

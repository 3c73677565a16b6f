/* SPDX-License-Identifier: MIT */
/*
 * The synthetic camera's scene (hal/sim/synthetic_camera.h): the approach it
 * renders and the clutter in it. A board file's camera.synthetic section is
 * read into this struct (board/board_config.h); no copy in between.
 */
#pragma once

#include <cstdint>

namespace dockpose::hal {

struct SyntheticScene {
	/* Target pose in the camera frame: x, y, z (mm), roll, pan, tilt (degrees). */
	double from[6] = { 120.0, -60.0, 1500.0, 3.0, 10.0, -2.0 };
	double to[6] = { 40.0, -10.0, 300.0, 0.5, 2.0, 0.0 };
	double duration_s = 5.0; /* from -> to; 0: always at `to` */
	bool loop = false; /* start again at `from` after duration_s */
	int reflections = 2;
	int glints = 1;
	int hot_pixels = 20;
	double noise_sigma = 2.0; /* read noise, grey levels */
	std::uint64_t seed = 1;
};

} /* namespace dockpose::hal */

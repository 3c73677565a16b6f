/* SPDX-License-Identifier: MIT */
/* The sim board's pieces that tests reuse when they wire simulated backends themselves. */
#pragma once

#include "firmware/config.h"
#include "hal/sim/synthetic_camera.h"

namespace dockpose::board {

/* The synthetic camera's scene from a board file's camera.synthetic section. Allocates: never. */
hal::SyntheticScene syntheticScene(const firmware::SyntheticCameraConfig &config);

} /* namespace dockpose::board */

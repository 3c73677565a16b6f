/* SPDX-License-Identifier: MIT */
/*
 * Ambient-light removal for the alternate strobe mode: a frame with the LEDs
 * lit minus the neighbouring frame with the LEDs off, saturated at zero. What
 * does not blink with the LEDs (lamps, sunlight, their reflections, hot
 * pixels) cancels; the LEDs stay.
 *
 * Allocates: never. Both inputs must have the same size; out has that size
 * and its own stride. Per-pixel code: keep it out of virtual calls.
 */
#pragma once

#include <cstdint>

#include "algo/image.h"

namespace dockpose {

/* out = max(lit - unlit, 0) pixel by pixel. False (out untouched) if the sizes differ. */
bool subtractAmbient(const ImageView &lit, const ImageView &unlit, std::uint8_t *out,
		     int out_stride_bytes);

} /* namespace dockpose */

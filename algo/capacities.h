/* SPDX-License-Identifier: MIT */
/*
 * Compile-time capacities of the frame path. Every buffer is sized from these
 * at construction; exceeding one is reported per frame, never a crash.
 */
#pragma once

#include <cstddef>

namespace dockpose {

/* LEDs in one target model. */
inline constexpr std::size_t kMaxLeds = 16;
/* Convex quadrilateral faces in one target model. */
inline constexpr std::size_t kMaxFaces = 8;
/* Blobs that survive the shape filter and enter correspondence. */
inline constexpr std::size_t kMaxCandidates = 64;
/* Connected components tracked while labelling one frame (before filtering). */
inline constexpr std::size_t kMaxComponents = 16384;
/*
 * Components of one frame dropped by the blob filter that clipped, whose
 * boxes are looked at again for clipped cores (an LED merged with a bright
 * surrounding); beyond these, the rest are not looked at.
 */
inline constexpr std::size_t kMaxMergedCores = 16;
/* Largest frame the pipeline accepts, in pixels per side. */
inline constexpr int kMaxFrameSide = 8192;

} /* namespace dockpose */

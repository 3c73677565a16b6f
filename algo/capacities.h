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
 * Components of one frame dropped by the blob filter whose boxes are looked at
 * again for LEDs merged with a bright surrounding (clipped cores, peaks that
 * stand out of the surrounding); beyond these, the rest are not looked at.
 */
inline constexpr std::size_t kMaxDropped = 16;
/* Peaks labelled round inside those boxes per frame (BlobDetector::lookForPeaks()). */
inline constexpr std::size_t kMaxInnerPeaks = 64;
/* The radius of the ring whose plane is a peak's background there, pixels. */
inline constexpr int kPeakRingPx = 5;
/* Largest frame the pipeline accepts, in pixels per side. */
inline constexpr int kMaxFrameSide = 8192;

} /* namespace dockpose */

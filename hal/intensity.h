/* SPDX-License-Identifier: MIT */
/*
 * Camera pixel formats to 8-bit intensity.
 *
 * The pipeline works on one 8-bit intensity plane. Mono and YUV formats carry
 * it already (the Y plane, or every other byte of packed 4:2:2), RGB formats
 * are reduced to luma. Byte orders follow the DRM fourcc names that libcamera
 * uses (include/uapi/drm/drm_fourcc.h, libcamera's formats.yaml): the RGB names
 * describe a little-endian word, so in memory the bytes come in reverse:
 *
 *   RGB888   (DRM RG24, V4L2 BGR24)  bytes B, G, R
 *   BGR888   (DRM BG24, V4L2 RGB24)  bytes R, G, B
 *   XRGB8888 (DRM XR24, V4L2 XRGB32) bytes B, G, R, X
 *   XBGR8888 (DRM XB24, V4L2 XBGR32) bytes R, G, B, X
 *
 * Luma is BT.601 with integer weights summing to 256, rounded:
 *   Y = (77 R + 150 G + 29 B + 128) >> 8
 * so grey (v, v, v) maps to exactly v.
 *
 * Allocates: never. Per-pixel loops are plain, non-virtual code.
 */
#pragma once

#include <cstdint>

namespace dockpose::hal {

enum class PixelLayout : std::uint8_t {
	Gray8, /* one byte per pixel: R8 (V4L2 GREY, "Y8") */
	YUV420, /* planar: Y plane first (also YVU420) */
	NV12, /* semi-planar: Y plane first (also NV16) */
	NV21, /* semi-planar: Y plane first (also NV61) */
	YUYV, /* packed 4:2:2, Y at even bytes (also YVYU) */
	UYVY, /* packed 4:2:2, Y at odd bytes (also VYUY) */
	RGB888, /* bytes B, G, R */
	BGR888, /* bytes R, G, B */
	XRGB8888, /* bytes B, G, R, X */
	XBGR8888, /* bytes R, G, B, X */
};

/* "RGB888", "NV12", ... Allocates: never. */
const char *pixelLayoutName(PixelLayout layout);

/*
 * True when the first plane of the frame is itself the 8-bit intensity image
 * (Gray8 and the Y plane of YUV420/NV12/NV21): the frame is used in place
 * with its stride, nothing is copied.
 */
bool isZeroCopy(PixelLayout layout);

/* Bytes the first plane holds per pixel: 1 (mono, Y planes), 2 (packed 4:2:2), 3 or 4 (RGB). */
int bytesPerPixel(PixelLayout layout);

/* The fewest bytes one row of `width` pixels occupies in the first plane. */
int minStrideBytes(PixelLayout layout, int width);

/*
 * Convert the first plane of a width x height frame (rows stride_bytes apart)
 * into 8-bit intensity at out (rows out_stride apart). Only the bytes of the
 * width pixels of each row are read: padding at the end of a row is never
 * touched, and only width bytes of each output row are written.
 *
 * Returns false, touching nothing, when an argument is invalid: null pointers,
 * width or height <= 0, stride_bytes < minStrideBytes(), out_stride < width.
 * Allocates: never.
 */
[[nodiscard]] bool toIntensity(const std::uint8_t *data, int width, int height, int stride_bytes,
			       PixelLayout layout, std::uint8_t *out, int out_stride);

/* BT.601 integer luma of one pixel (see above). */
inline std::uint8_t lumaBt601(std::uint8_t r, std::uint8_t g, std::uint8_t b)
{
	return static_cast<std::uint8_t>((77u * r + 150u * g + 29u * b + 128u) >> 8);
}

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * Camera pixel formats to 8-bit intensity: see intensity.h.
 */
#include "hal/intensity.h"

#include <cstddef>
#include <cstring>

namespace dockpose::hal {

namespace {

/* Copy one byte of every `step`, starting at `first`. */
void extractBytes(const std::uint8_t *data, int width, int height, int stride_bytes, int first,
		  int step, std::uint8_t *out, int out_stride)
{
	for (int y = 0; y < height; ++y) {
		const std::uint8_t *src =
			data + static_cast<std::ptrdiff_t>(y) * stride_bytes + first;
		std::uint8_t *dst = out + static_cast<std::ptrdiff_t>(y) * out_stride;
		for (int x = 0; x < width; ++x)
			dst[x] = src[static_cast<std::ptrdiff_t>(x) * step];
	}
}

/* Luma of pixels `step` bytes apart whose R, G, B bytes sit at offsets r, g, b. */
void lumaRows(const std::uint8_t *data, int width, int height, int stride_bytes, int step, int r,
	      int g, int b, std::uint8_t *out, int out_stride)
{
	for (int y = 0; y < height; ++y) {
		const std::uint8_t *src = data + static_cast<std::ptrdiff_t>(y) * stride_bytes;
		std::uint8_t *dst = out + static_cast<std::ptrdiff_t>(y) * out_stride;
		for (int x = 0; x < width; ++x, src += step)
			dst[x] = lumaBt601(src[r], src[g], src[b]);
	}
}

} /* namespace */

const char *pixelLayoutName(PixelLayout layout)
{
	switch (layout) {
	case PixelLayout::Gray8:
		return "Gray8";
	case PixelLayout::YUV420:
		return "YUV420";
	case PixelLayout::NV12:
		return "NV12";
	case PixelLayout::NV21:
		return "NV21";
	case PixelLayout::YUYV:
		return "YUYV";
	case PixelLayout::UYVY:
		return "UYVY";
	case PixelLayout::RGB888:
		return "RGB888";
	case PixelLayout::BGR888:
		return "BGR888";
	case PixelLayout::XRGB8888:
		return "XRGB8888";
	case PixelLayout::XBGR8888:
		return "XBGR8888";
	}
	return "unknown";
}

bool isZeroCopy(PixelLayout layout)
{
	switch (layout) {
	case PixelLayout::Gray8:
	case PixelLayout::YUV420:
	case PixelLayout::NV12:
	case PixelLayout::NV21:
		return true;
	default:
		return false;
	}
}

int bytesPerPixel(PixelLayout layout)
{
	switch (layout) {
	case PixelLayout::Gray8:
	case PixelLayout::YUV420:
	case PixelLayout::NV12:
	case PixelLayout::NV21:
		return 1;
	case PixelLayout::YUYV:
	case PixelLayout::UYVY:
		return 2;
	case PixelLayout::RGB888:
	case PixelLayout::BGR888:
		return 3;
	case PixelLayout::XRGB8888:
	case PixelLayout::XBGR8888:
		return 4;
	}
	return 0;
}

int minStrideBytes(PixelLayout layout, int width)
{
	return width * bytesPerPixel(layout);
}

bool toIntensity(const std::uint8_t *data, int width, int height, int stride_bytes,
		 PixelLayout layout, std::uint8_t *out, int out_stride)
{
	if (!data || !out || width <= 0 || height <= 0 || bytesPerPixel(layout) == 0)
		return false;
	if (stride_bytes < minStrideBytes(layout, width) || out_stride < width)
		return false;

	switch (layout) {
	case PixelLayout::Gray8:
	case PixelLayout::YUV420:
	case PixelLayout::NV12:
	case PixelLayout::NV21:
		for (int y = 0; y < height; ++y)
			std::memcpy(out + static_cast<std::ptrdiff_t>(y) * out_stride,
				    data + static_cast<std::ptrdiff_t>(y) * stride_bytes,
				    static_cast<std::size_t>(width));
		return true;
	case PixelLayout::YUYV:
		extractBytes(data, width, height, stride_bytes, 0, 2, out, out_stride);
		return true;
	case PixelLayout::UYVY:
		extractBytes(data, width, height, stride_bytes, 1, 2, out, out_stride);
		return true;
	case PixelLayout::RGB888:
		lumaRows(data, width, height, stride_bytes, 3, 2, 1, 0, out, out_stride);
		return true;
	case PixelLayout::BGR888:
		lumaRows(data, width, height, stride_bytes, 3, 0, 1, 2, out, out_stride);
		return true;
	case PixelLayout::XRGB8888:
		lumaRows(data, width, height, stride_bytes, 4, 2, 1, 0, out, out_stride);
		return true;
	case PixelLayout::XBGR8888:
		lumaRows(data, width, height, stride_bytes, 4, 0, 1, 2, out, out_stride);
		return true;
	}
	return false;
}

} /* namespace dockpose::hal */

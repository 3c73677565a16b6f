/* SPDX-License-Identifier: MIT */
/*
 * 8-bit intensity images: a non-owning view (what the frame path sees) and an
 * owning buffer (for tools, tests and the simulated camera).
 *
 * Pixel convention (method.md section 2): (u, v) with u right and v down,
 * (0, 0) is the centre of the top-left pixel.
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace dockpose {

/* A read-only view of an 8-bit frame. Allocates: never. */
struct ImageView {
	const std::uint8_t *data = nullptr;
	int width = 0;
	int height = 0;
	int stride_bytes = 0; /* bytes from one row to the next, >= width */

	const std::uint8_t *row(int y) const
	{
		return data + static_cast<std::ptrdiff_t>(y) * stride_bytes;
	}
	std::uint8_t at(int x, int y) const { return row(y)[x]; }
	bool valid() const { return data && width > 0 && height > 0 && stride_bytes >= width; }
};

/*
 * Bring the bytes [x0, x1) of one row (x0 < x1) towards the cache, a
 * prefetch per 64-byte line. Allocates: never.
 */
inline void prefetchRow(const std::uint8_t *row, int x0, int x1)
{
	for (int x = x0 & ~63; x < x1; x += 64)
		__builtin_prefetch(row + x);
	__builtin_prefetch(row + x1 - 1);
}

/* An owning 8-bit frame with stride == width. Allocates: in the constructor. */
class Image
{
public:
	Image() = default;
	Image(int width, int height, std::uint8_t fill = 0)
		: width_(width),
		  height_(height),
		  pixels_(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), fill)
	{
	}

	int width() const { return width_; }
	int height() const { return height_; }
	std::uint8_t *data() { return pixels_.data(); }
	const std::uint8_t *data() const { return pixels_.data(); }
	std::uint8_t &at(int x, int y) { return pixels_[static_cast<std::size_t>(y) * width_ + x]; }
	std::uint8_t at(int x, int y) const
	{
		return pixels_[static_cast<std::size_t>(y) * width_ + x];
	}
	bool empty() const { return pixels_.empty(); }

	ImageView view() const { return ImageView{ pixels_.data(), width_, height_, width_ }; }

private:
	int width_ = 0;
	int height_ = 0;
	std::vector<std::uint8_t> pixels_;
};

/* A rectangle of a frame: columns [x0, x1), rows [y0, y1), pixels. */
struct PixelWindow {
	int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

} /* namespace dockpose */

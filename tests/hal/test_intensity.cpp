/* SPDX-License-Identifier: MIT */
/*
 * hal/intensity: every layout converts hand-made frames to the expected
 * intensity, honours the input stride without reading its padding, writes only
 * width bytes per output row, and rejects invalid arguments.
 */
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hal/intensity.h"

using dockpose::hal::bytesPerPixel;
using dockpose::hal::isZeroCopy;
using dockpose::hal::lumaBt601;
using dockpose::hal::minStrideBytes;
using dockpose::hal::PixelLayout;
using dockpose::hal::pixelLayoutName;
using dockpose::hal::toIntensity;

namespace {

constexpr std::uint8_t kInPad = 0xEE; /* input row padding: must never reach the output */
constexpr std::uint8_t kOutPad = 0x55; /* output row padding: must stay untouched */

/* A frame of `rows`, each row's bytes followed by padding up to `stride`. */
std::vector<std::uint8_t> frameWithPadding(const std::vector<std::vector<std::uint8_t>> &rows,
					   int stride)
{
	std::vector<std::uint8_t> data(rows.size() * static_cast<std::size_t>(stride), kInPad);
	for (std::size_t y = 0; y < rows.size(); ++y)
		for (std::size_t i = 0; i < rows[y].size(); ++i)
			data[y * static_cast<std::size_t>(stride) + i] = rows[y][i];
	return data;
}

struct Converted {
	bool ok = false;
	std::vector<std::uint8_t> out;
};

/* Converts a 3x2 frame into an output with stride 5 (2 padding bytes per row). */
Converted convert3x2(PixelLayout layout, const std::vector<std::vector<std::uint8_t>> &rows,
		     int stride)
{
	const std::vector<std::uint8_t> data = frameWithPadding(rows, stride);
	Converted c;
	c.out.assign(2 * 5, kOutPad);
	c.ok = toIntensity(data.data(), 3, 2, stride, layout, c.out.data(), 5);
	return c;
}

void expectOutput(const Converted &c, const std::vector<std::uint8_t> &expected)
{
	ASSERT_TRUE(c.ok);
	for (int y = 0; y < 2; ++y) {
		for (int x = 0; x < 3; ++x)
			EXPECT_EQ(c.out[y * 5 + x], expected[y * 3 + x])
				<< "pixel " << x << "," << y;
		EXPECT_EQ(c.out[y * 5 + 3], kOutPad) << "output padding written, row " << y;
		EXPECT_EQ(c.out[y * 5 + 4], kOutPad) << "output padding written, row " << y;
	}
}

/* Luma of pure red, green, blue under (77 R + 150 G + 29 B + 128) >> 8, worked by hand. */
constexpr std::uint8_t kRed = 77; /* (77*255 + 128) >> 8 = 19763 >> 8 */
constexpr std::uint8_t kGreen = 149; /* (150*255 + 128) >> 8 = 38378 >> 8 */
constexpr std::uint8_t kBlue = 29; /* (29*255 + 128) >> 8 = 7523 >> 8 */
constexpr std::uint8_t kMix = 18; /* R 10, G 20, B 30: (770 + 3000 + 870 + 128) >> 8 = 4768 >> 8 */

} /* namespace */

TEST(Intensity, LumaWeightsAreBt601AndGreyIsIdentity)
{
	EXPECT_EQ(lumaBt601(255, 0, 0), kRed);
	EXPECT_EQ(lumaBt601(0, 255, 0), kGreen);
	EXPECT_EQ(lumaBt601(0, 0, 255), kBlue);
	EXPECT_EQ(lumaBt601(10, 20, 30), kMix);
	for (int v = 0; v < 256; ++v) {
		const auto u = static_cast<std::uint8_t>(v);
		ASSERT_EQ(lumaBt601(u, u, u), u) << v;
	}
}

TEST(Intensity, ZeroCopyLayoutsAreMonoAndYPlanes)
{
	EXPECT_TRUE(isZeroCopy(PixelLayout::Gray8));
	EXPECT_TRUE(isZeroCopy(PixelLayout::YUV420));
	EXPECT_TRUE(isZeroCopy(PixelLayout::NV12));
	EXPECT_TRUE(isZeroCopy(PixelLayout::NV21));
	EXPECT_FALSE(isZeroCopy(PixelLayout::YUYV));
	EXPECT_FALSE(isZeroCopy(PixelLayout::UYVY));
	EXPECT_FALSE(isZeroCopy(PixelLayout::RGB888));
	EXPECT_FALSE(isZeroCopy(PixelLayout::BGR888));
	EXPECT_FALSE(isZeroCopy(PixelLayout::XRGB8888));
	EXPECT_FALSE(isZeroCopy(PixelLayout::XBGR8888));
}

TEST(Intensity, BytesPerPixelAndMinimumStride)
{
	EXPECT_EQ(bytesPerPixel(PixelLayout::Gray8), 1);
	EXPECT_EQ(bytesPerPixel(PixelLayout::NV12), 1);
	EXPECT_EQ(bytesPerPixel(PixelLayout::YUYV), 2);
	EXPECT_EQ(bytesPerPixel(PixelLayout::RGB888), 3);
	EXPECT_EQ(bytesPerPixel(PixelLayout::XBGR8888), 4);
	EXPECT_EQ(minStrideBytes(PixelLayout::BGR888, 1920), 5760);
	EXPECT_EQ(minStrideBytes(PixelLayout::UYVY, 7), 14);
}

TEST(Intensity, NamesAreDistinct)
{
	const PixelLayout all[] = { PixelLayout::Gray8,	   PixelLayout::YUV420,
				    PixelLayout::NV12,	   PixelLayout::NV21,
				    PixelLayout::YUYV,	   PixelLayout::UYVY,
				    PixelLayout::RGB888,   PixelLayout::BGR888,
				    PixelLayout::XRGB8888, PixelLayout::XBGR8888 };
	std::set<std::string> names;
	for (const auto layout : all)
		names.insert(pixelLayoutName(layout));
	EXPECT_EQ(names.size(), std::size(all));
	EXPECT_STREQ(pixelLayoutName(PixelLayout::RGB888), "RGB888");
}

TEST(Intensity, Gray8AndYPlanesCopyTheFirstPlaneRows)
{
	const std::vector<std::vector<std::uint8_t>> rows = { { 10, 20, 30 }, { 40, 50, 60 } };
	for (const auto layout :
	     { PixelLayout::Gray8, PixelLayout::YUV420, PixelLayout::NV12, PixelLayout::NV21 }) {
		SCOPED_TRACE(pixelLayoutName(layout));
		expectOutput(convert3x2(layout, rows, 8), { 10, 20, 30, 40, 50, 60 });
	}
}

TEST(Intensity, YuyvTakesEvenBytes)
{
	/* Y0 U0 Y1 V0 Y2 U1 per row (odd width: the last macro-pixel is cut). */
	const std::vector<std::vector<std::uint8_t>> rows = { { 11, 200, 12, 201, 13, 202 },
							      { 21, 210, 22, 211, 23, 212 } };
	expectOutput(convert3x2(PixelLayout::YUYV, rows, 9), { 11, 12, 13, 21, 22, 23 });
}

TEST(Intensity, UyvyTakesOddBytes)
{
	const std::vector<std::vector<std::uint8_t>> rows = { { 200, 11, 201, 12, 202, 13 },
							      { 210, 21, 211, 22, 212, 23 } };
	expectOutput(convert3x2(PixelLayout::UYVY, rows, 10), { 11, 12, 13, 21, 22, 23 });
}

TEST(Intensity, Rgb888IsStoredBgrInMemory)
{
	/* libcamera RGB888 = DRM RG24 = V4L2 BGR24: bytes B, G, R. */
	const std::vector<std::vector<std::uint8_t>> rows = {
		{ 0, 0, 255, /**/ 0, 255, 0, /**/ 255, 0, 0 }, /* red, green, blue */
		{ 30, 20, 10, /**/ 7, 7, 7, /**/ 255, 255, 255 }, /* (10,20,30), grey 7, white */
	};
	expectOutput(convert3x2(PixelLayout::RGB888, rows, 11),
		     { kRed, kGreen, kBlue, kMix, 7, 255 });
}

TEST(Intensity, Bgr888IsStoredRgbInMemory)
{
	/* libcamera BGR888 = DRM BG24 = V4L2 RGB24: bytes R, G, B (vimc's default). */
	const std::vector<std::vector<std::uint8_t>> rows = {
		{ 255, 0, 0, /**/ 0, 255, 0, /**/ 0, 0, 255 },
		{ 10, 20, 30, /**/ 7, 7, 7, /**/ 0, 0, 0 },
	};
	expectOutput(convert3x2(PixelLayout::BGR888, rows, 12),
		     { kRed, kGreen, kBlue, kMix, 7, 0 });
}

TEST(Intensity, Xrgb8888IsBgrxInMemoryAndIgnoresX)
{
	const std::vector<std::vector<std::uint8_t>> rows = {
		{ 0, 0, 255, 0xAA, /**/ 0, 255, 0, 0xAA, /**/ 255, 0, 0, 0xAA },
		{ 30, 20, 10, 0xFF, /**/ 9, 9, 9, 0x00, /**/ 0, 0, 0, 0xFF },
	};
	expectOutput(convert3x2(PixelLayout::XRGB8888, rows, 13),
		     { kRed, kGreen, kBlue, kMix, 9, 0 });
}

TEST(Intensity, Xbgr8888IsRgbxInMemoryAndIgnoresX)
{
	const std::vector<std::vector<std::uint8_t>> rows = {
		{ 255, 0, 0, 0xAA, /**/ 0, 255, 0, 0xAA, /**/ 0, 0, 255, 0xAA },
		{ 10, 20, 30, 0xFF, /**/ 9, 9, 9, 0x00, /**/ 255, 255, 255, 0xFF },
	};
	expectOutput(convert3x2(PixelLayout::XBGR8888, rows, 16),
		     { kRed, kGreen, kBlue, kMix, 9, 255 });
}

TEST(Intensity, ExactStrideWithoutPaddingWorks)
{
	/* stride == width * bpp: the last byte of the buffer is the last pixel's. */
	const std::vector<std::uint8_t> data = { 255, 0, 0, 0, 255, 0 }; /* BGR888, 2x1 */
	std::uint8_t out[2] = { 0, 0 };
	ASSERT_TRUE(toIntensity(data.data(), 2, 1, 6, PixelLayout::BGR888, out, 2));
	EXPECT_EQ(out[0], kRed);
	EXPECT_EQ(out[1], kGreen);
}

TEST(Intensity, RejectsInvalidArgumentsWithoutWriting)
{
	std::vector<std::uint8_t> data(64, 100);
	std::vector<std::uint8_t> out(64, kOutPad);
	/* Stride shorter than a row of pixels. */
	EXPECT_FALSE(toIntensity(data.data(), 4, 2, 11, PixelLayout::RGB888, out.data(), 4));
	EXPECT_FALSE(toIntensity(data.data(), 4, 2, 7, PixelLayout::YUYV, out.data(), 4));
	EXPECT_FALSE(toIntensity(data.data(), 4, 2, 3, PixelLayout::Gray8, out.data(), 4));
	/* Output stride shorter than the width. */
	EXPECT_FALSE(toIntensity(data.data(), 4, 2, 4, PixelLayout::Gray8, out.data(), 3));
	/* Empty sizes and null pointers. */
	EXPECT_FALSE(toIntensity(data.data(), 0, 2, 4, PixelLayout::Gray8, out.data(), 4));
	EXPECT_FALSE(toIntensity(data.data(), 4, -1, 4, PixelLayout::Gray8, out.data(), 4));
	EXPECT_FALSE(toIntensity(nullptr, 4, 2, 4, PixelLayout::Gray8, out.data(), 4));
	EXPECT_FALSE(toIntensity(data.data(), 4, 2, 4, PixelLayout::Gray8, nullptr, 4));
	for (const auto b : out)
		ASSERT_EQ(b, kOutPad);
	/* The same call with valid strides does write. */
	EXPECT_TRUE(toIntensity(data.data(), 4, 2, 4, PixelLayout::Gray8, out.data(), 4));
	EXPECT_EQ(out[0], 100);
}

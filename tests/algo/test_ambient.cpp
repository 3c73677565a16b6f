/* SPDX-License-Identifier: MIT */
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "algo/ambient.h"

namespace dockpose {
namespace {

TEST(Ambient, SubtractsAndSaturatesAtZeroWithStrides)
{
	const int w = 37, h = 11, lit_stride = 40, unlit_stride = 48, out_stride = 45;
	std::vector<std::uint8_t> lit(static_cast<std::size_t>(lit_stride * h), 0xEE);
	std::vector<std::uint8_t> unlit(static_cast<std::size_t>(unlit_stride * h), 0x11);
	std::vector<std::uint8_t> out(static_cast<std::size_t>(out_stride * h), 0x77);
	std::mt19937 rng(5);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x) {
			lit[static_cast<std::size_t>(y * lit_stride + x)] =
				static_cast<std::uint8_t>(rng());
			unlit[static_cast<std::size_t>(y * unlit_stride + x)] =
				static_cast<std::uint8_t>(rng());
		}
	ASSERT_TRUE(subtractAmbient(ImageView{ lit.data(), w, h, lit_stride },
				    ImageView{ unlit.data(), w, h, unlit_stride }, out.data(),
				    out_stride));
	int clipped = 0;
	for (int y = 0; y < h; ++y) {
		for (int x = 0; x < w; ++x) {
			const int a = lit[static_cast<std::size_t>(y * lit_stride + x)];
			const int b = unlit[static_cast<std::size_t>(y * unlit_stride + x)];
			const int expected = a > b ? a - b : 0;
			clipped += a <= b;
			ASSERT_EQ(out[static_cast<std::size_t>(y * out_stride + x)], expected)
				<< x << "," << y;
		}
		/* Padding beyond the width is never written. */
		for (int x = w; x < out_stride; ++x)
			ASSERT_EQ(out[static_cast<std::size_t>(y * out_stride + x)], 0x77);
	}
	EXPECT_GT(clipped, 0);
}

TEST(Ambient, RefusesMismatchedSizes)
{
	std::vector<std::uint8_t> a(100, 9), b(100, 1), out(100, 3);
	EXPECT_FALSE(subtractAmbient(ImageView{ a.data(), 10, 10, 10 },
				     ImageView{ b.data(), 9, 10, 10 }, out.data(), 10));
	EXPECT_FALSE(
		subtractAmbient(ImageView{ a.data(), 10, 10, 10 }, ImageView{}, out.data(), 10));
	EXPECT_FALSE(subtractAmbient(ImageView{ a.data(), 10, 10, 10 },
				     ImageView{ b.data(), 10, 10, 10 }, out.data(), 9));
	EXPECT_EQ(out[0], 3);
}

} /* namespace */
} /* namespace dockpose */

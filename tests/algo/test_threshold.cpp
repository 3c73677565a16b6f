/* SPDX-License-Identifier: MIT */
/*
 * Segmentation levels: fixed mode, the automatic level on flat and graded
 * backgrounds with several noise levels, the guard against bright spots,
 * and odd frames.
 */
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "algo/blob_detector.h"
#include "algo/threshold.h"

using namespace dockpose;

namespace {

constexpr int kW = 1456;
constexpr int kH = 1088;

struct Spot {
	double u, v, peak, sigma;
};

/*
 * A frame: background(x, y) + Gaussian spots + Gaussian read noise, rounded
 * and clipped to 0..255, with an optional row padding.
 */
struct Frame {
	int width, height, stride;
	std::vector<std::uint8_t> bytes;
	ImageView view() const { return ImageView{ bytes.data(), width, height, stride }; }
	std::uint8_t at(int x, int y) const
	{
		return bytes[static_cast<std::size_t>(y) * stride + x];
	}
};

Frame render(int w, int h, const std::function<double(int, int)> &background, double noise_sigma,
	     const std::vector<Spot> &spots, std::uint32_t seed, int pad = 0)
{
	Frame f{ w, h, w + pad, {} };
	f.bytes.assign(static_cast<std::size_t>(f.stride) * h, 0xAB);
	std::vector<double> value(static_cast<std::size_t>(w) * h);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x)
			value[static_cast<std::size_t>(y) * w + x] = background(x, y);
	for (const Spot &s : spots) {
		const int r = static_cast<int>(std::ceil(8 * s.sigma));
		for (int y = std::max(0, static_cast<int>(s.v) - r);
		     y <= std::min(h - 1, static_cast<int>(s.v) + r); ++y)
			for (int x = std::max(0, static_cast<int>(s.u) - r);
			     x <= std::min(w - 1, static_cast<int>(s.u) + r); ++x) {
				const double dx = x - s.u, dy = y - s.v;
				value[static_cast<std::size_t>(y) * w + x] +=
					s.peak *
					std::exp(-0.5 * (dx * dx + dy * dy) / (s.sigma * s.sigma));
			}
	}
	std::mt19937 rng(seed);
	std::normal_distribution<double> noise(0.0, noise_sigma > 0 ? noise_sigma : 1.0);
	for (int y = 0; y < h; ++y) {
		for (int x = 0; x < w; ++x) {
			double v = value[static_cast<std::size_t>(y) * w + x];
			if (noise_sigma > 0)
				v += noise(rng);
			f.bytes[static_cast<std::size_t>(y) * f.stride + x] =
				static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
		}
	}
	return f;
}

std::function<double(int, int)> flat(double level)
{
	return [level](int, int) {
		return level;
	};
}

/* Per-pixel noise of the rounded frame, what the estimator sees. */
double quantisedSigma(double sigma)
{
	return std::sqrt(sigma * sigma + 1.0 / 12.0);
}

} /* namespace */

TEST(Threshold, FixedMode)
{
	ThresholdConfig cfg;
	cfg.mode = ThresholdMode::Fixed;
	cfg.fixed_level = 77;
	Thresholder th(kW, kH, cfg);
	const Frame f = render(200, 100, flat(20), 2.0, {}, 1);
	ThresholdStats stats;
	const ThresholdMap &map = th.compute(f.view(), &stats);
	EXPECT_TRUE(stats.valid);
	EXPECT_EQ(stats.level_min, 77);
	EXPECT_EQ(stats.level_max, 77);
	for (int y = 0; y < 100; y += 7)
		for (int x = 0; x < 200; x += 5)
			EXPECT_EQ(map.levelAt(x, y), 77);
	EXPECT_EQ(map.levelAt(8000, 8000), 77);

	cfg.fixed_level = 300; /* clamped */
	Thresholder th2(kW, kH, cfg);
	EXPECT_EQ(th2.compute(f.view(), &stats).levelAt(0, 0), 255);
	EXPECT_EQ(th2.config().fixed_level, 255);
}

TEST(Threshold, MapBasics)
{
	ThresholdMap map(100, 50, 16, 40);
	EXPECT_EQ(map.cols(), 7);
	EXPECT_EQ(map.rows(), 4);
	map.setLevel(6, 3, 99);
	map.setLevel(2, 1, 55);
	EXPECT_EQ(map.levelAt(99, 49), 99);
	EXPECT_EQ(map.levelAt(500, 500), 99); /* beyond the grid: the last tile */
	EXPECT_EQ(map.levelAt(32, 16), 55);
	EXPECT_EQ(map.levelAt(47, 31), 55);
	EXPECT_EQ(map.levelAt(48, 31), 40);
	EXPECT_EQ(ThresholdMap().levelAt(3, 3), 255);
	ThresholdMap empty;
	empty.setUniform(17);
	EXPECT_EQ(empty.levelAt(3, 3), 17);
	EXPECT_EQ(empty.cols(), 0);
	EXPECT_EQ(ThresholdMap::uniform(9).levelAt(8191, 0), 9);
	EXPECT_TRUE(map.reshape(50, 50, 16));
	EXPECT_EQ(map.cols(), 4);
	EXPECT_FALSE(map.reshape(1000, 1000, 16));
	EXPECT_EQ(map.cols(), 4);
	map.setUniform(12);
	EXPECT_EQ(map.levelAt(1000, 1000), 12);
}

TEST(Threshold, FlatBackgroundNoiseSigma2)
{
	Thresholder th(kW, kH, ThresholdConfig{});
	const Frame f = render(kW, kH, flat(20), 2.0, {}, 2);
	ThresholdStats stats;
	const ThresholdMap &map = th.compute(f.view(), &stats);
	ASSERT_TRUE(stats.valid);
	EXPECT_NEAR(stats.noise_sigma, quantisedSigma(2.0), 0.1);
	EXPECT_NEAR(stats.background, 20.0, 0.5);
	/* level = bg + 6 * sigma = 20 + 12 */
	EXPECT_GE(stats.level_min, 31);
	EXPECT_LE(stats.level_max, 34);
	EXPECT_EQ(stats.tiles_x, 23);
	EXPECT_EQ(stats.tiles_y, 17);
	int lo = 255, hi = 0;
	for (int r = 0; r < map.rows(); ++r)
		for (int c = 0; c < map.cols(); ++c) {
			lo = std::min<int>(lo, map.level(c, r));
			hi = std::max<int>(hi, map.level(c, r));
		}
	EXPECT_EQ(lo, stats.level_min);
	EXPECT_EQ(hi, stats.level_max);
}

namespace {

double meanLevel(const ThresholdMap &map)
{
	double sum = 0;
	for (int r = 0; r < map.rows(); ++r)
		for (int c = 0; c < map.cols(); ++c)
			sum += map.level(c, r);
	return sum / (map.rows() * map.cols());
}

/*
 * How far a tile's level may stray from background + contrast on a flat
 * frame: 5 % of the contrast (the noise estimate), the extremes of the tile
 * medians over a few hundred tiles (about 3.5 x 1.25 sigma / sqrt(16)), and
 * the rounding of the medians and of the level.
 */
double levelTolerance(double contrast, double sigma)
{
	return 0.05 * contrast + 1.1 * sigma + 1.5;
}

} /* namespace */

TEST(Threshold, NoiseEstimateAcrossLevels)
{
	Thresholder th(800, 600, ThresholdConfig{});
	for (double sigma : { 0.6, 1.0, 1.5, 3.0, 5.0, 8.0 }) {
		const Frame f = render(800, 600, flat(100), sigma, {}, 3);
		ThresholdStats stats;
		const ThresholdMap &map = th.compute(f.view(), &stats);
		const double s = quantisedSigma(sigma);
		EXPECT_NEAR(stats.noise_sigma, s, 0.07 * s) << sigma;
		EXPECT_NEAR(stats.background, 100.0, 0.1 * sigma + 0.5) << sigma;
		/* The level follows: 100 + max(6 sigma, 12). */
		const double contrast = std::max(6.0 * s, 12.0);
		EXPECT_NEAR(meanLevel(map), 100 + contrast, 0.05 * contrast + 0.3 * sigma + 0.5)
			<< sigma;
		EXPECT_NEAR(stats.level_min, 100 + contrast, levelTolerance(contrast, sigma))
			<< sigma;
		EXPECT_NEAR(stats.level_max, 100 + contrast, levelTolerance(contrast, sigma))
			<< sigma;
	}
}

TEST(Threshold, MinContrastAndKSigma)
{
	/* Low noise: the minimum contrast rules. */
	{
		Thresholder th(640, 480, ThresholdConfig{});
		const Frame f = render(640, 480, flat(30), 0.4, {}, 4);
		ThresholdStats stats;
		th.compute(f.view(), &stats);
		EXPECT_EQ(stats.level_min, 42);
		EXPECT_EQ(stats.level_max, 42);
	}
	/* k_sigma 10 on sigma 3: 30 levels above the background. */
	{
		ThresholdConfig cfg;
		cfg.k_sigma = 10.0;
		cfg.min_contrast = 5;
		Thresholder th(640, 480, cfg);
		const Frame f = render(640, 480, flat(50), 3.0, {}, 5);
		ThresholdStats stats;
		const ThresholdMap &map = th.compute(f.view(), &stats);
		const double contrast = 10.0 * quantisedSigma(3.0);
		EXPECT_NEAR(meanLevel(map), 50 + contrast, 0.05 * contrast + 0.3 * 3.0 + 0.5);
		EXPECT_GE(stats.level_min, 50 + contrast - levelTolerance(contrast, 3.0));
		EXPECT_LE(stats.level_max, 50 + contrast + levelTolerance(contrast, 3.0));
	}
	/* Saturation: the level clamps at 255. */
	{
		Thresholder th(640, 480, ThresholdConfig{});
		const Frame f = render(640, 480, flat(250), 2.0, {}, 6);
		ThresholdStats stats;
		const ThresholdMap &map = th.compute(f.view(), &stats);
		EXPECT_EQ(stats.level_min, 255);
		EXPECT_EQ(map.levelAt(320, 240), 255);
	}
}

TEST(Threshold, GradientDoesNotBiasNoiseOrMargin)
{
	/* 0 -> 80 levels across the frame, 0 -> 30 down it. */
	auto grad = [](int x, int y) {
		return 80.0 * x / (kW - 1) + 30.0 * y / (kH - 1);
	};
	Thresholder th(kW, kH, ThresholdConfig{});
	const Frame f = render(kW, kH, grad, 2.0, {}, 7);
	ThresholdStats stats;
	const ThresholdMap &map = th.compute(f.view(), &stats);
	EXPECT_NEAR(stats.noise_sigma, quantisedSigma(2.0), 0.12);
	/*
	 * In every tile the level keeps the contrast (12) above the brightest
	 * background of the tile: on average (no bias), and in every tile up to
	 * the error of the tile estimate (a median of 16 samples: about
	 * 0.3 sigma, and half again at the frame edges, where the background is
	 * extrapolated): 3 levels. Nor is it raised by more than a few levels.
	 */
	const int t = map.tilePx();
	double margin_sum = 0.0;
	for (int r = 0; r < map.rows(); ++r) {
		for (int c = 0; c < map.cols(); ++c) {
			const int x1 = std::min(kW - 1, (c + 1) * t - 1),
				  y1 = std::min(kH - 1, (r + 1) * t - 1);
			const double bg_max = grad(x1, y1);
			margin_sum += map.level(c, r) - bg_max;
			EXPECT_GE(map.level(c, r), bg_max + 12.0 - 3.0) << c << "," << r;
			EXPECT_LE(map.level(c, r), bg_max + 12.0 + 4.0) << c << "," << r;
		}
	}
	const double mean_margin = margin_sum / (map.rows() * map.cols());
	EXPECT_GE(mean_margin, 12.0 - 0.3);
	EXPECT_LE(mean_margin, 12.0 + 2.0);
}

TEST(Threshold, BrightSpotDoesNotRaiseItsTile)
{
	/* A large spot filling most of tile (5, 5) and spilling into its neighbours. */
	const std::vector<Spot> spots = { { 5 * 64 + 32.3, 5 * 64 + 31.6, 200.0, 14.0 } };
	Thresholder th(kW, kH, ThresholdConfig{});
	const Frame f = render(kW, kH, flat(20), 2.0, spots, 8);
	ThresholdStats stats;
	const ThresholdMap &map = th.compute(f.view(), &stats);
	for (int r = 4; r <= 6; ++r)
		for (int c = 4; c <= 6; ++c)
			EXPECT_LE(map.level(c, r), 20 + 12 + 2) << c << "," << r;
	/* The spot itself must be over the level at more than half of its tile's pixels. */
	int above = 0;
	for (int y = 320; y < 384; ++y)
		for (int x = 320; x < 384; ++x)
			above += f.at(x, y) >= map.levelAt(x, y);
	EXPECT_GT(above, 64 * 64 / 2);
}

TEST(Threshold, SpotsEverywhereOnAStrongGradient)
{
	/* A grid of dim to bright small spots over a 0 -> 80 gradient with noise. */
	auto grad = [](int x, int y) {
		return 80.0 * x / (kW - 1) + 10.0 * y / (kH - 1);
	};
	std::vector<Spot> spots;
	std::mt19937 rng(10);
	std::uniform_real_distribution<double> jitter(-20.0, 20.0), peak(45.0, 200.0),
		sig(0.9, 1.6);
	for (int j = 0; j < 6; ++j)
		for (int i = 0; i < 9; ++i)
			spots.push_back({ 80.0 + i * 160.0 + jitter(rng),
					  70.0 + j * 180.0 + jitter(rng), peak(rng), sig(rng) });
	for (std::uint32_t seed : { 11u, 12u, 13u }) {
		const Frame f = render(kW, kH, grad, 2.0, spots, seed, seed == 12u ? 7 : 0);
		BlobDetector det(kW, kH, ThresholdConfig{}, BlobFilterConfig{});
		StaticVector<Blob, kMaxCandidates> blobs;
		BlobStats stats;
		ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
		/* Every spot found once, nothing else, not even a speck of background. */
		EXPECT_EQ(blobs.size(), spots.size());
		EXPECT_EQ(stats.components, static_cast<int>(spots.size())) << "seed " << seed;
		for (const Spot &s : spots) {
			int matches = 0;
			for (const Blob &b : blobs) {
				if (std::hypot(b.u_px - s.u, b.v_px - s.v) < 0.25)
					++matches;
			}
			EXPECT_EQ(matches, 1) << s.u << "," << s.v << " peak " << s.peak;
		}
	}
}

TEST(Threshold, OddFramesAndStride)
{
	Thresholder th(300, 200, ThresholdConfig{});
	ThresholdStats stats;
	for (auto [w, h] :
	     { std::pair{ 1, 1 }, { 1, 200 }, { 300, 1 }, { 9, 7 }, { 2, 2 }, { 65, 129 } }) {
		const Frame f = render(w, h, flat(40), 2.0, {}, 20);
		const ThresholdMap &map = th.compute(f.view(), &stats);
		EXPECT_TRUE(stats.valid) << w << "x" << h;
		EXPECT_GE(stats.level_min, 40 + 6) << w << "x" << h;
		EXPECT_LE(stats.level_max, 40 + 40) << w << "x" << h;
		EXPECT_EQ(map.cols(), (w + 63) / 64);
		EXPECT_EQ(map.rows(), (h + 63) / 64);
	}

	/* The same pixels with row padding give the same map. */
	const Frame a = render(250, 180, flat(40), 3.0, { { 100, 90, 150, 2 } }, 21, 0);
	const Frame b = render(250, 180, flat(40), 3.0, { { 100, 90, 150, 2 } }, 21, 13);
	const ThresholdMap ma = th.compute(a.view(), &stats);
	const double sigma_a = stats.noise_sigma;
	const ThresholdMap &mb = th.compute(b.view(), &stats);
	EXPECT_EQ(stats.noise_sigma, sigma_a);
	for (int r = 0; r < ma.rows(); ++r)
		for (int c = 0; c < ma.cols(); ++c)
			EXPECT_EQ(ma.level(c, r), mb.level(c, r));

	/* Too large or invalid: a uniform 255 map and valid == false. */
	const Frame big = render(301, 10, flat(40), 2.0, {}, 22);
	EXPECT_EQ(th.compute(big.view(), &stats).levelAt(0, 0), 255);
	EXPECT_FALSE(stats.valid);
	th.compute(ImageView{}, &stats);
	EXPECT_FALSE(stats.valid);
	EXPECT_EQ(stats.level_min, 255);
}

TEST(Threshold, TileAndStepConfiguration)
{
	ThresholdConfig cfg;
	cfg.tile_px = 32;
	cfg.sample_step_px = 1;
	Thresholder th(640, 480, cfg);
	const Frame f = render(640, 480, flat(60), 2.5, {}, 30);
	ThresholdStats stats;
	th.compute(f.view(), &stats);
	EXPECT_EQ(stats.tiles_x, 20);
	EXPECT_EQ(stats.tiles_y, 15);
	EXPECT_NEAR(stats.noise_sigma, quantisedSigma(2.5), 0.08);
	EXPECT_GE(stats.level_min, 60 + 14);
	EXPECT_LE(stats.level_max, 60 + 17);

	/* A tile of 9 with a step of 2: the last sample of a tile sits on its last pixel. */
	{
		ThresholdConfig odd;
		odd.tile_px = 9;
		odd.sample_step_px = 2;
		Thresholder th9(630, 477, odd);
		const Frame g = render(630, 477, flat(60), 2.5, {}, 31);
		th9.compute(g.view(), &stats);
		EXPECT_EQ(stats.tiles_x, 70);
		EXPECT_EQ(stats.tiles_y, 53);
		EXPECT_NEAR(stats.noise_sigma, quantisedSigma(2.5), 0.1);
	}

	/* Out-of-range values are clamped, not trusted. */
	cfg.tile_px = 0;
	cfg.sample_step_px = 1000;
	cfg.k_sigma = -3.0;
	Thresholder th2(640, 480, cfg);
	EXPECT_EQ(th2.config().tile_px, 8);
	EXPECT_EQ(th2.config().sample_step_px, 2);
	EXPECT_EQ(th2.config().k_sigma, 0.0);
	const ThresholdMap &map = th2.compute(f.view(), &stats);
	EXPECT_TRUE(stats.valid);
	EXPECT_EQ(stats.tiles_x, 80);
	/* min_contrast alone; 16 samples per tile make noisier tile medians */
	EXPECT_NEAR(meanLevel(map), 60 + 12, 1.0);
	EXPECT_GE(stats.level_min, 60 + 12 - 4);
}

/*
 * The background's slope around a point: a plane through the tile backgrounds, with an honest
 * sigma. One thresholder sees every plane in turn: the fits it keeps by tile follow each compute().
 */
TEST(Threshold, BackgroundSlopeOfAPlane)
{
	const int w = 800, h = 600;
	std::mt19937 rng(8);
	std::normal_distribution<double> noise(0.0, 2.0);
	Thresholder t(w, h, ThresholdConfig{});
	for (const auto &[gx, gy] :
	     { std::pair{ 0.05, -0.03 }, std::pair{ 0.0, 0.0 }, std::pair{ -0.007, 0.002 } }) {
		std::vector<std::uint8_t> pixels(static_cast<std::size_t>(w) * h);
		for (int y = 0; y < h; ++y)
			for (int x = 0; x < w; ++x)
				pixels[static_cast<std::size_t>(y) * w + x] =
					static_cast<std::uint8_t>(std::clamp(
						std::lround(60.0 + gx * x + gy * y + noise(rng)),
						0L, 255L));
		t.compute(ImageView{ pixels.data(), w, h, w });
		for (const auto &[u, v] : { std::pair{ 400.0, 300.0 }, std::pair{ 10.0, 590.0 },
					    std::pair{ 790.0, 5.0 } }) {
			double sx = 0.0, sy = 0.0, sigma = 0.0;
			ASSERT_TRUE(t.backgroundSlope(u, v, &sx, &sy, &sigma));
			/* Another pixel of the same 64 px tile: the same fit. */
			double sx2 = 0.0, sy2 = 0.0, sigma2 = 0.0;
			ASSERT_TRUE(t.backgroundSlope(u + (u > 400.0 ? -20.0 : 20.0), v, &sx2, &sy2,
						      &sigma2));
			EXPECT_EQ(sx2, sx);
			EXPECT_EQ(sy2, sy);
			EXPECT_EQ(sigma2, sigma);
			EXPECT_GT(sigma, 0.0);
			EXPECT_LT(
				sigma,
				0.01); /* 5 x 5 tiles of 64 px: a few thousandths of a level per pixel */
			EXPECT_NEAR(sx, gx, std::max(4.0 * sigma, 0.002)) << u << ", " << v;
			EXPECT_NEAR(sy, gy, std::max(4.0 * sigma, 0.002)) << u << ", " << v;
		}
	}
	/* Fixed mode and an invalid frame have no background to fit. */
	ThresholdConfig fixed;
	fixed.mode = ThresholdMode::Fixed;
	Thresholder f(w, h, fixed);
	std::vector<std::uint8_t> flat(static_cast<std::size_t>(w) * h, 30);
	f.compute(ImageView{ flat.data(), w, h, w });
	double sx = 0.0, sy = 0.0, sigma = 0.0;
	EXPECT_FALSE(f.backgroundSlope(100.0, 100.0, &sx, &sy, &sigma));
	Thresholder a(w, h, ThresholdConfig{});
	a.compute(ImageView{});
	EXPECT_FALSE(a.backgroundSlope(100.0, 100.0, &sx, &sy, &sigma));
}

/*
 * The cells (Thresholder::cellMap()): on the 0 -> 80 gradient no tile is
 * steep and every cell keeps its tile's level; on the flank of a bright
 * disc (150 levels, its edge falling over 30 px) the cells below the flank
 * keep the contrast above the background there, far below their tile's
 * level, and no cell is ever above its tile.
 */
TEST(Threshold, CellsFollowASteepFlank)
{
	Thresholder th(kW, kH, ThresholdConfig{});
	auto grad = [](int x, int y) {
		return 80.0 * x / (kW - 1) + 30.0 * y / (kH - 1);
	};
	const Frame plane = render(kW, kH, grad, 2.0, {}, 7);
	const ThresholdMap &tiles = th.compute(plane.view());
	EXPECT_FALSE(th.hasSteepTiles());
	const ThresholdMap &cells = th.cellMap();
	for (int y = 0; y < kH; y += 8)
		for (int x = 0; x < kW; x += 8)
			ASSERT_EQ(cells.levelAt(x, y), tiles.levelAt(x, y)) << x << "," << y;

	auto disc = [](int x, int y) {
		const double r = std::hypot(x - 200.0, y - 150.0);
		const double e = std::clamp((180.0 - r) / 30.0, 0.0, 1.0);
		return 10.0 + 150.0 * e * e * (3.0 - 2.0 * e);
	};
	const Frame patch = render(kW, kH, disc, 2.0, {}, 8);
	const ThresholdMap &tiles2 = th.compute(patch.view());
	EXPECT_TRUE(th.hasSteepTiles());
	int below_flank = 0;
	for (int y = 0; y < kH; y += 4)
		for (int x = 0; x < kW; x += 4) {
			const int cell = th.cellMap().levelAt(x, y), tile = tiles2.levelAt(x, y);
			ASSERT_LE(cell, tile) << x << "," << y;
			/* Beyond the disc (the background at 10): the cell keeps its contrast. */
			if (std::hypot(x - 200.0, y - 150.0) > 181.0) {
				ASSERT_GE(cell, 10 + 12 - 3) << x << "," << y;
				below_flank += tile - cell >= 40;
			}
		}
	EXPECT_GT(below_flank, 50);

	/* Tiles a quarter does not divide: whole cells in every tile, none above its tile. */
	for (const int tile_px : { 50, 33 }) {
		ThresholdConfig config;
		config.tile_px = tile_px;
		Thresholder odd(kW, kH, config);
		const ThresholdMap &odd_tiles = odd.compute(patch.view());
		EXPECT_EQ(odd.cellMap().tilePx(), tile_px % 2 == 0 ? tile_px / 2 : tile_px);
		for (int y = 0; y < kH; y += 3)
			for (int x = 0; x < kW; x += 3) {
				const int cell = odd.cellMap().levelAt(x, y);
				ASSERT_LE(cell, odd_tiles.levelAt(x, y))
					<< tile_px << ": " << x << "," << y;
				if (std::hypot(x - 200.0, y - 150.0) > 181.0) {
					ASSERT_GE(cell, 10 + 12 - 3)
						<< tile_px << ": " << x << "," << y;
				}
			}
	}
}

/*
 * The sensor's gain from the frame's own noise against its level
 * (ThresholdStats::noise_gain): a background ramp with shot noise gives its
 * levels per electron; read noise alone, on a flat background or on a
 * gradient, gives 0 (a slope within twice its error is no gain); nothing is
 * claimed from a fixed level's frame (no backgrounds).
 */
TEST(Threshold, NoiseGainFromTheFrame)
{
	struct Case {
		int width, height;
		double gain, read_sigma, level_lo, level_hi;
	};
	for (const Case c :
	     { Case{ kW, kH, 0.5, 1.5, 8.0, 60.0 }, Case{ kW, kH, 1.0, 2.5, 5.0, 35.0 },
	       Case{ 512, 512, 0.25, 1.0, 10.0, 50.0 }, Case{ 640, 480, 0.0, 2.0, 10.0, 40.0 },
	       Case{ kW, kH, 0.0, 3.0, 20.0, 20.0 } }) {
		std::mt19937 rng(
			static_cast<std::uint32_t>(c.width + 1000 * c.gain + 10 * c.read_sigma));
		std::normal_distribution<double> unit(0.0, 1.0);
		Frame f{ c.width, c.height, c.width, {} };
		f.bytes.resize(static_cast<std::size_t>(c.width) * c.height);
		for (int y = 0; y < c.height; ++y)
			for (int x = 0; x < c.width; ++x) {
				const double level = c.level_lo + (c.level_hi - c.level_lo) *
									  (x + y) /
									  (c.width + c.height);
				const double v = level + std::sqrt(c.read_sigma * c.read_sigma +
								   c.gain * level) *
								 unit(rng);
				f.bytes[static_cast<std::size_t>(y) * c.width + x] =
					static_cast<std::uint8_t>(
						std::clamp(std::lround(v), 0L, 255L));
			}
		Thresholder th(c.width, c.height, ThresholdConfig{});
		ThresholdStats stats;
		th.compute(f.view(), &stats);
		if (c.gain > 0.0)
			EXPECT_NEAR(stats.noise_gain, c.gain, 0.25 * c.gain)
				<< c.width << " px, gain " << c.gain;
		else
			EXPECT_EQ(stats.noise_gain, 0.0) << c.width << " px, read noise only";
		Thresholder fixed(c.width, c.height,
				  ThresholdConfig{ .mode = ThresholdMode::Fixed });
		fixed.compute(f.view(), &stats);
		EXPECT_EQ(stats.noise_gain, 0.0);
	}
}

/* SPDX-License-Identifier: MIT */
/*
 * Streaming labelling against a naive flood fill, blob measurement against
 * hand-computed moments, the shape filter, capacities and odd frames.
 */
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <numbers>
#include <random>
#include <tuple>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "algo/blob_detector.h"

using namespace dockpose;

namespace {

/* A frame with a row stride of its own (stride >= width), filled with garbage in the padding. */
struct StridedFrame {
	int width = 0, height = 0, stride = 0;
	std::vector<std::uint8_t> bytes;

	StridedFrame(int w, int h, int s, std::uint8_t pad = 255)
		: width(w),
		  height(h),
		  stride(s),
		  bytes(static_cast<std::size_t>(s) * h + 64, pad)
	{
		for (int y = 0; y < h; ++y)
			for (int x = 0; x < w; ++x)
				at(x, y) = 0;
	}
	std::uint8_t &at(int x, int y) { return bytes[static_cast<std::size_t>(y) * stride + x]; }
	std::uint8_t at(int x, int y) const
	{
		return bytes[static_cast<std::size_t>(y) * stride + x];
	}
	ImageView view() const { return ImageView{ bytes.data(), width, height, stride }; }
};

using Key = std::tuple<std::uint16_t, std::uint16_t, std::uint16_t, std::uint16_t, std::uint32_t,
		       std::uint64_t, std::uint64_t, std::uint64_t, std::uint64_t, std::uint64_t,
		       std::uint64_t, std::uint8_t>;

Key key(const BlobMoments &m)
{
	return { m.y_min,  m.x_min,  m.y_max,	m.x_max,   m.area,    m.sum_w,
		 m.sum_wx, m.sum_wy, m.sum_wxx, m.sum_wyy, m.sum_wxy, m.peak };
}

/*
 * The reference: segment with the map (v >= level), fill gaps of up to
 * fill_gap pixels between segmented pixels of a row, then breadth-first
 * flood fill over a plain label image, 8-connected, and sum the moments
 * pixel by pixel (filled gap pixels count in the area with weight 0).
 */
std::vector<BlobMoments> referenceLabel(const ImageView &img, const ThresholdMap &map, int fill_gap)
{
	const int w = img.width, h = img.height;
	/* 1 segmented, 2 filled */
	std::vector<std::uint8_t> seg(static_cast<std::size_t>(w) * h, 0);
	for (int y = 0; y < h; ++y) {
		int last = -1;
		for (int x = 0; x < w; ++x) {
			if (img.at(x, y) >= map.levelAt(x, y)) {
				if (last >= 0 && x - last - 1 <= fill_gap) {
					for (int g = last + 1; g < x; ++g)
						seg[static_cast<std::size_t>(y) * w + g] = 2;
				}
				seg[static_cast<std::size_t>(y) * w + x] = 1;
				last = x;
			}
		}
	}
	std::vector<int> label(static_cast<std::size_t>(w) * h, -1);
	std::vector<BlobMoments> out;
	std::deque<std::pair<int, int>> queue;
	for (int y0 = 0; y0 < h; ++y0) {
		for (int x0 = 0; x0 < w; ++x0) {
			const std::size_t i0 = static_cast<std::size_t>(y0) * w + x0;
			if (!seg[i0] || label[i0] >= 0)
				continue;
			const int id = static_cast<int>(out.size());
			BlobMoments m;
			m.x_min = m.x_max = static_cast<std::uint16_t>(x0);
			m.y_min = m.y_max = static_cast<std::uint16_t>(y0);
			label[i0] = id;
			queue.emplace_back(x0, y0);
			while (!queue.empty()) {
				const auto [x, y] = queue.front();
				queue.pop_front();
				const std::size_t i = static_cast<std::size_t>(y) * w + x;
				m.area += 1;
				if (seg[i] == 1) {
					const std::uint8_t v = img.at(x, y);
					const std::uint64_t wt =
						std::uint64_t{ v } - map.levelAt(x, y) + 1;
					const std::uint64_t ux = static_cast<std::uint64_t>(x),
							    uy = static_cast<std::uint64_t>(y);
					m.sum_w += wt;
					m.sum_wx += wt * ux;
					m.sum_wy += wt * uy;
					m.sum_wxx += wt * ux * ux;
					m.sum_wyy += wt * uy * uy;
					m.sum_wxy += wt * ux * uy;
					m.peak = std::max(m.peak, v);
				}
				m.x_min = std::min<std::uint16_t>(m.x_min,
								  static_cast<std::uint16_t>(x));
				m.x_max = std::max<std::uint16_t>(m.x_max,
								  static_cast<std::uint16_t>(x));
				m.y_min = std::min<std::uint16_t>(m.y_min,
								  static_cast<std::uint16_t>(y));
				m.y_max = std::max<std::uint16_t>(m.y_max,
								  static_cast<std::uint16_t>(y));
				for (int dy = -1; dy <= 1; ++dy) {
					for (int dx = -1; dx <= 1; ++dx) {
						const int nx = x + dx, ny = y + dy;
						if (nx < 0 || ny < 0 || nx >= w || ny >= h)
							continue;
						const std::size_t j =
							static_cast<std::size_t>(ny) * w + nx;
						if (seg[j] && label[j] < 0) {
							label[j] = id;
							queue.emplace_back(nx, ny);
						}
					}
				}
			}
			out.push_back(m);
		}
	}
	return out;
}

std::vector<BlobMoments> detectorLabel(BlobDetector &det, const ImageView &img,
				       const ThresholdMap &map, bool *ok)
{
	std::vector<BlobMoments> out;
	*ok = det.label(img, map, [&](const BlobMoments &m) { out.push_back(m); });
	return out;
}

void expectSameComponents(std::vector<BlobMoments> a, std::vector<BlobMoments> b, const char *what)
{
	ASSERT_EQ(a.size(), b.size()) << what;
	auto less = [](const BlobMoments &p, const BlobMoments &q) {
		return key(p) < key(q);
	};
	std::sort(a.begin(), a.end(), less);
	std::sort(b.begin(), b.end(), less);
	for (std::size_t i = 0; i < a.size(); ++i)
		ASSERT_TRUE(key(a[i]) == key(b[i]))
			<< what << ": component " << i << " bbox (" << a[i].x_min << ","
			<< a[i].y_min << ")-(" << a[i].x_max << "," << a[i].y_max << ") area "
			<< a[i].area << " vs " << b[i].area << " sum_w " << a[i].sum_w << " vs "
			<< b[i].sum_w;
}

/* Random shapes of random brightness on a noisy background. */
void paintRandom(StridedFrame *f, std::mt19937 &rng)
{
	const int w = f->width, h = f->height;
	std::uniform_int_distribution<int> bg(0, 60);
	const int base = bg(rng);
	std::uniform_int_distribution<int> noise_amp(0, 40);
	const int amp = noise_amp(rng);
	std::uniform_int_distribution<int> n01(0, 1 << 20);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x)
			f->at(x, y) = static_cast<std::uint8_t>(
				std::min(255, base + (amp ? n01(rng) % (amp + 1) : 0)));

	std::uniform_int_distribution<int> nshapes(0, 30);
	std::uniform_real_distribution<double> ux(-5.0, w + 5.0), uy(-5.0, h + 5.0), u01(0.0, 1.0);
	std::uniform_int_distribution<int> bright(40, 255);
	const int n = nshapes(rng);
	auto put = [&](int x, int y, int v) {
		if (x >= 0 && y >= 0 && x < w && y < h)
			f->at(x, y) = static_cast<std::uint8_t>(
				std::max<int>(f->at(x, y), std::min(v, 255)));
	};
	for (int s = 0; s < n; ++s) {
		const int kind = static_cast<int>(u01(rng) * 6);
		const double cx = ux(rng), cy = uy(rng);
		const int peak = bright(rng);
		if (kind == 0) { /* ellipse with a smooth profile */
			const double a = 0.5 + u01(rng) * 12, b = 0.5 + u01(rng) * 6,
				     th = u01(rng) * 3.14159;
			const double ct = std::cos(th), st = std::sin(th);
			const int r = static_cast<int>(a) + 2;
			for (int y = static_cast<int>(cy) - r; y <= static_cast<int>(cy) + r; ++y)
				for (int x = static_cast<int>(cx) - r;
				     x <= static_cast<int>(cx) + r; ++x) {
					const double dx = x - cx, dy = y - cy;
					const double p = (ct * dx + st * dy) / a,
						     q = (-st * dx + ct * dy) / b;
					put(x, y,
					    static_cast<int>(
						    peak * std::exp(-0.5 * (p * p + q * q) * 4.0)));
				}
		} else if (kind == 1) { /* rectangle */
			const int rw = 1 + static_cast<int>(u01(rng) * 15),
				  rh = 1 + static_cast<int>(u01(rng) * 15);
			for (int y = 0; y < rh; ++y)
				for (int x = 0; x < rw; ++x)
					put(static_cast<int>(cx) + x, static_cast<int>(cy) + y,
					    peak);
		} else if (kind == 2) { /* line */
			const double th = u01(rng) * 6.283, len = u01(rng) * 40;
			for (double t = 0; t < len; t += 0.5)
				put(static_cast<int>(cx + t * std::cos(th)),
				    static_cast<int>(cy + t * std::sin(th)), peak);
		} else if (kind == 3) { /* random walk: twisty, U shapes, merges */
			int x = static_cast<int>(cx), y = static_cast<int>(cy);
			const int steps = static_cast<int>(u01(rng) * 120);
			for (int t = 0; t < steps; ++t) {
				put(x, y, peak);
				x += static_cast<int>(u01(rng) * 3) - 1;
				y += static_cast<int>(u01(rng) * 3) - 1;
			}
		} else if (kind == 4) { /* ring */
			const double r = 2 + u01(rng) * 10;
			for (double t = 0; t < 6.283; t += 0.05)
				put(static_cast<int>(cx + r * std::cos(t)),
				    static_cast<int>(cy + r * std::sin(t)), peak);
		} else { /* salt: isolated pixels and near misses */
			const int k = static_cast<int>(u01(rng) * 40);
			for (int t = 0; t < k; ++t)
				put(static_cast<int>(ux(rng)), static_cast<int>(uy(rng)), peak);
		}
	}
}

/* A map of random tile size and levels, for a frame of (about) w x h. */
ThresholdMap randomMap(int w, int h, std::mt19937 &rng)
{
	std::uniform_int_distribution<int> kind(0, 9);
	const int k = kind(rng);
	if (k == 0)
		return ThresholdMap::uniform(
			static_cast<std::uint8_t>(std::uniform_int_distribution<int>(0, 255)(rng)));
	if (k == 1) {
		/* no tiles: 255 everywhere, or a level set without storage */
		ThresholdMap empty;
		if (rng() & 1)
			empty.setUniform(static_cast<std::uint8_t>(
				std::uniform_int_distribution<int>(20, 255)(rng)));
		return empty;
	}
	std::uniform_int_distribution<int> tile(1, 70);
	/* sometimes a grid for a smaller frame: the last tiles extend over the rest */
	const int mw = k == 2 ? std::max(1, w / 2) : w;
	const int mh = k == 2 ? std::max(1, h / 3) : h;
	ThresholdMap map(mw, mh, tile(rng));
	std::uniform_int_distribution<int> level(k == 3 ? 0 : 30, k == 4 ? 255 : 200);
	for (int r = 0; r < map.rows(); ++r)
		for (int c = 0; c < map.cols(); ++c)
			map.setLevel(c, r, static_cast<std::uint8_t>(level(rng)));
	return map;
}

BlobFilterConfig filterWithGap(int gap, int max_area = 0)
{
	BlobFilterConfig f;
	f.fill_gap_px = gap;
	f.max_area_px = max_area;
	return f;
}

ThresholdConfig fixedThreshold(int level)
{
	ThresholdConfig t;
	t.mode = ThresholdMode::Fixed;
	t.fixed_level = level;
	return t;
}

} /* namespace */

TEST(BlobLabel, MatchesFloodFillOnRandomImages)
{
	std::mt19937 rng(20240601);
	int total_components = 0;
	for (int iter = 0; iter < 600; ++iter) {
		std::uniform_int_distribution<int> dim(1, 180);
		const int w = iter % 17 == 0 ? 1 : dim(rng);
		const int h = iter % 19 == 0 ? 1 : dim(rng);
		const int stride =
			w + (iter % 3 == 0 ? 0 : std::uniform_int_distribution<int>(1, 37)(rng));
		StridedFrame f(w, h, stride);
		paintRandom(&f, rng);
		const ThresholdMap map = randomMap(w, h, rng);
		const int gap = std::uniform_int_distribution<int>(0, 3)(rng);

		BlobDetector det(200, 200, ThresholdConfig{}, filterWithGap(gap));
		bool ok = false;
		const auto got = detectorLabel(det, f.view(), map, &ok);
		ASSERT_TRUE(ok) << "iteration " << iter;
		const auto want = referenceLabel(f.view(), map, gap);
		total_components += static_cast<int>(want.size());
		expectSameComponents(got, want, ("iteration " + std::to_string(iter)).c_str());
		if (HasFatalFailure())
			return;
	}
	/* The generator must produce a real workload. */
	EXPECT_GT(total_components, 3000);
}

TEST(BlobLabel, MatchesFloodFillOnAutoThresholdFrames)
{
	/* Full size frames through the Thresholder's own map, with the detector reused. */
	std::mt19937 rng(99);
	BlobDetector det(700, 500, ThresholdConfig{}, BlobFilterConfig{});
	for (int iter = 0; iter < 6; ++iter) {
		const int w = 700 - iter * 37, h = 500 - iter * 23;
		StridedFrame f(w, h, w + iter * 5);
		paintRandom(&f, rng);
		const ThresholdMap &map = det.thresholder().compute(f.view());
		bool ok = false;
		const auto got = detectorLabel(det, f.view(), map, &ok);
		ASSERT_TRUE(ok);
		expectSameComponents(got, referenceLabel(f.view(), map, 1), "auto map");
	}
}

TEST(BlobLabel, DenseNoiseAndFullForeground)
{
	/* Everything segmented: one component covering the frame, touching every border. */
	StridedFrame f(97, 41, 111);
	std::mt19937 rng(1);
	for (int y = 0; y < f.height; ++y)
		for (int x = 0; x < f.width; ++x)
			f.at(x, y) = static_cast<std::uint8_t>(rng() & 0xff);
	BlobDetector det(128, 64, ThresholdConfig{}, BlobFilterConfig{});
	bool ok = false;
	auto got = detectorLabel(det, f.view(), ThresholdMap::uniform(0), &ok);
	ASSERT_TRUE(ok);
	ASSERT_EQ(got.size(), 1u);
	EXPECT_EQ(got[0].area, 97u * 41u);
	EXPECT_EQ(got[0].x_min, 0);
	EXPECT_EQ(got[0].x_max, 96);
	EXPECT_EQ(got[0].y_max, 40);
	expectSameComponents(got, referenceLabel(f.view(), ThresholdMap::uniform(0), 1), "full");

	/* Half the pixels at random: many merges of every shape. */
	for (int gap = 0; gap <= 2; ++gap) {
		BlobDetector d2(128, 64, ThresholdConfig{}, filterWithGap(gap));
		got = detectorLabel(d2, f.view(), ThresholdMap::uniform(128), &ok);
		ASSERT_TRUE(ok);
		expectSameComponents(got, referenceLabel(f.view(), ThresholdMap::uniform(128), gap),
				     "half");
	}
}

TEST(BlobLabel, GapFillingAndDiagonals)
{
	StridedFrame f(20, 5, 20);
	/* row 0: pixels at 2 and 4 (gap 1), 7 and 10 (gap 2) */
	f.at(2, 0) = f.at(4, 0) = f.at(7, 0) = f.at(10, 0) = 200;
	/* diagonal chain: 8-connected */
	f.at(15, 1) = f.at(16, 2) = f.at(17, 3) = f.at(18, 4) = 200;
	BlobDetector det(32, 8, ThresholdConfig{}, filterWithGap(1));
	bool ok = false;
	auto got = detectorLabel(det, f.view(), ThresholdMap::uniform(100), &ok);
	ASSERT_TRUE(ok);
	ASSERT_EQ(got.size(), 4u); /* {2..4}, {7}, {10}, diagonal */
	EXPECT_EQ(got[0].area, 3u);
	EXPECT_EQ(got[0].sum_w, 2u * 101u); /* the filled pixel weighs 0 */
	EXPECT_EQ(got[0].sum_wx, 101u * (2 + 4));
	EXPECT_EQ(got[3].area, 4u);

	BlobDetector det2(32, 8, ThresholdConfig{}, filterWithGap(2));
	got = detectorLabel(det2, f.view(), ThresholdMap::uniform(100), &ok);
	ASSERT_TRUE(ok);
	ASSERT_EQ(got.size(), 2u); /* {2..10}, diagonal */
	EXPECT_EQ(got[0].area, 9u);
	EXPECT_EQ(got[0].sum_w, 4u * 101u);
	EXPECT_EQ(got[0].x_max, 10);
}

TEST(BlobLabel, OneAndTwoPixelWideFrames)
{
	for (int w : { 1, 2 }) {
		StridedFrame f(w, 50, w + 3);
		for (int y = 0; y < 50; ++y)
			f.at(w - 1, y) = (y % 10 < 6) ? 180 : 10;
		BlobDetector det(4, 64, ThresholdConfig{}, BlobFilterConfig{});
		bool ok = false;
		const auto got = detectorLabel(det, f.view(), ThresholdMap::uniform(100), &ok);
		ASSERT_TRUE(ok);
		ASSERT_EQ(got.size(), 5u);
		for (const auto &m : got) {
			EXPECT_EQ(m.area, 6u);
			EXPECT_EQ(m.x_min, w - 1);
		}
	}
}

TEST(BlobLabel, CapacityExactlyAndOverflow)
{
	/* Isolated pixels on a grid of pitch 2: n x n components (no gap filling). */
	auto grid = [](int n) {
		StridedFrame f(2 * n, 2 * n, 2 * n);
		for (int y = 0; y < n; ++y)
			for (int x = 0; x < n; ++x)
				f.at(2 * x, 2 * y) = 255;
		return f;
	};
	{
		const StridedFrame f = grid(128); /* 16384 == kMaxComponents */
		static_assert(kMaxComponents == 16384);
		BlobDetector det(256, 256, fixedThreshold(128), filterWithGap(0));
		StaticVector<Blob, kMaxCandidates> blobs;
		BlobStats stats;
		EXPECT_TRUE(det.detect(f.view(), &blobs, &stats));
		EXPECT_FALSE(stats.component_overflow);
		EXPECT_EQ(stats.components, 16384);
		EXPECT_EQ(stats.dropped_small, 16384);
		EXPECT_TRUE(blobs.empty());
	}
	{
		const StridedFrame f = grid(150);
		BlobDetector det(300, 300, fixedThreshold(128), filterWithGap(0));
		StaticVector<Blob, kMaxCandidates> blobs;
		BlobStats stats;
		EXPECT_FALSE(det.detect(f.view(), &blobs, &stats));
		EXPECT_TRUE(stats.component_overflow);
		EXPECT_TRUE(blobs.empty());
		bool ok = true;
		detectorLabel(det, f.view(), ThresholdMap::uniform(128), &ok);
		EXPECT_FALSE(ok);

		/* The detector still works on the next frame. */
		const StridedFrame g = grid(10);
		EXPECT_TRUE(det.detect(g.view(), &blobs, &stats));
		EXPECT_EQ(stats.components, 100);
	}
}

TEST(BlobLabel, RejectsOversizeAndInvalidFrames)
{
	BlobDetector det(64, 48, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	const StridedFrame wide(65, 10, 65), tall(10, 49, 10), fits(64, 48, 70);
	EXPECT_FALSE(det.detect(wide.view(), &blobs, &stats));
	EXPECT_FALSE(stats.component_overflow);
	EXPECT_FALSE(det.detect(tall.view(), &blobs, &stats));
	EXPECT_TRUE(det.detect(fits.view(), &blobs, &stats));
	EXPECT_FALSE(det.detect(ImageView{}, &blobs, &stats));
	/* stride < width */
	EXPECT_FALSE(det.detect(ImageView{ fits.bytes.data(), 10, 10, 5 }, &blobs, &stats));
	bool ok = true;
	detectorLabel(det, wide.view(), ThresholdMap::uniform(1), &ok);
	EXPECT_FALSE(ok);
	/* stats may be null */
	EXPECT_TRUE(det.detect(fits.view(), &blobs, nullptr));
}

namespace {

/* Moments of one component summed in doubles, for the measure tests. */
struct DoubleMoments {
	double sw = 0, sx = 0, sy = 0;
	int area = 0;
	int peak = 0;
};

} /* namespace */

TEST(BlobMeasure, GaussianEllipse)
{
	/* A rendered Gaussian ellipse: sigmas 3.0 and 1.5, rotated 30 degrees. */
	const double u0 = 40.37, v0 = 31.81, s1 = 3.0, s2 = 1.5,
		     th = 30.0 * std::numbers::pi / 180.0;
	const int w = 80, h = 64, level = 30;
	StridedFrame f(w, h, w);
	DoubleMoments ref;
	for (int y = 0; y < h; ++y) {
		for (int x = 0; x < w; ++x) {
			const double dx = x - u0, dy = y - v0;
			const double p = std::cos(th) * dx + std::sin(th) * dy;
			const double q = -std::sin(th) * dx + std::cos(th) * dy;
			const double val = 10.0 + 220.0 * std::exp(-0.5 * (p * p / (s1 * s1) +
									   q * q / (s2 * s2)));
			f.at(x, y) = static_cast<std::uint8_t>(std::lround(val));
			if (f.at(x, y) >= level) {
				const double wt = f.at(x, y) - level + 1;
				ref.sw += wt;
				ref.sx += wt * x;
				ref.sy += wt * y;
				ref.area += 1;
				ref.peak = std::max<int>(ref.peak, f.at(x, y));
			}
		}
	}
	const double mu = ref.sx / ref.sw, mv = ref.sy / ref.sw;
	Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x)
			if (f.at(x, y) >= level) {
				const double wt = f.at(x, y) - level + 1;
				const Eigen::Vector2d d(x - mu, y - mv);
				cov += wt * d * d.transpose();
			}
	cov /= ref.sw;
	cov += Eigen::Matrix2d::Identity() / 12.0;
	Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);

	BlobDetector det(w, h, fixedThreshold(level), filterWithGap(0, 10000));
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	ASSERT_EQ(blobs.size(), 1u);
	const Blob &b = blobs[0];
	/* Truth: the rendered centre. */
	EXPECT_NEAR(b.u_px, u0, 0.05);
	EXPECT_NEAR(b.v_px, v0, 0.05);
	/* Exactly the hand-computed moments. */
	EXPECT_NEAR(b.u_px, mu, 1e-9);
	EXPECT_NEAR(b.v_px, mv, 1e-9);
	EXPECT_NEAR(b.sigma_major_px, std::sqrt(eig.eigenvalues()(1)), 1e-9);
	EXPECT_NEAR(b.sigma_minor_px, std::sqrt(eig.eigenvalues()(0)), 1e-9);
	EXPECT_NEAR(b.elongation, b.sigma_major_px / b.sigma_minor_px, 1e-12);
	EXPECT_EQ(b.area_px, ref.area);
	EXPECT_EQ(b.weight, ref.sw);
	EXPECT_NEAR(b.fill,
		    ref.area / (std::numbers::pi * 4.0 * b.sigma_major_px * b.sigma_minor_px),
		    1e-12);
	/* The shape of the rendered ellipse: axes ratio 2, major axis at 30 degrees. */
	EXPECT_NEAR(b.elongation, s1 / s2, 0.15);
	const Eigen::Vector2d major = eig.eigenvectors().col(1);
	EXPECT_NEAR(std::abs(major.dot(Eigen::Vector2d(std::cos(th), std::sin(th)))), 1.0, 1e-3);
	EXPECT_EQ(b.peak, ref.peak);
	EXPECT_GT(ref.peak, 200);
}

/* The light of a Gaussian spot of sigma s centred at c that falls on pixel [x - 0.5, x + 0.5). */
double pixelShare(int x, double c, double s)
{
	const auto cdf = [&](double t) {
		return 0.5 * std::erfc(-(t - c) / (s * std::numbers::sqrt2));
	};
	return cdf(x + 0.5) - cdf(x - 0.5);
}

TEST(BlobMeasure, SmallSpotsDoNotLockToThePixelGrid)
{
	/*
	 * Pixel-integrated Gaussian spots of sigma 0.8 px (peak ~200 levels over
	 * a background of 10, no noise) at sub-pixel phases 0, 1/8 ... 7/8 in x and
	 * y (64 spots: kMaxCandidates). The thresholded centroid locks to the grid (its error follows the
	 * phase); detect()'s three-point fit is exact for a sampled Gaussian up to
	 * the rounding of the pixels to integer levels (~0.3 / 200 of the peak's
	 * curvature: below 0.005 px).
	 */
	const int w = 136, h = 136;
	const double sigma = 0.8, amplitude = 1000.0;
	StridedFrame f(w, h, w);
	std::vector<Eigen::Vector2d> truth;
	for (int j = 0; j < 8; ++j)
		for (int i = 0; i < 8; ++i)
			truth.emplace_back(8.0 + 16.0 * i + 0.125 * i, 8.0 + 16.0 * j + 0.125 * j);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x) {
			double v = 10.0;
			for (const Eigen::Vector2d &c : truth)
				if (std::abs(x - c.x()) < 6.0 && std::abs(y - c.y()) < 6.0)
					v += amplitude * pixelShare(x, c.x(), sigma) *
					     pixelShare(y, c.y(), sigma);
			f.at(x, y) = static_cast<std::uint8_t>(std::lround(std::min(v, 254.0)));
		}
	BlobDetector det(w, h, fixedThreshold(30), filterWithGap(0));
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	ASSERT_EQ(blobs.size(), truth.size());
	double fit_worst_px = 0.0;
	for (const Blob &b : blobs) {
		double nearest_px = 1e9;
		for (const Eigen::Vector2d &c : truth)
			nearest_px =
				std::min(nearest_px, (Eigen::Vector2d(b.u_px, b.v_px) - c).norm());
		fit_worst_px = std::max(fit_worst_px, nearest_px);
		EXPECT_EQ(b.saturated_px, 0);
		/* Its covariance: the rounding's (1/12 level^2) propagated, well under 0.01 px. */
		EXPECT_GT(b.cov_uu_px2, 0.0);
		EXPECT_LT(std::sqrt(b.cov_uu_px2), 0.01);
		EXPECT_LT(std::sqrt(b.cov_vv_px2), 0.01);
	}
	/* The thresholded centroid of the same spots, for comparison. */
	double centroid_worst_px = 0.0;
	ASSERT_TRUE(det.label(f.view(), ThresholdMap::uniform(30), [&](const BlobMoments &m) {
		const Blob b = BlobDetector::measure(m);
		double nearest_px = 1e9;
		for (const Eigen::Vector2d &c : truth)
			nearest_px =
				std::min(nearest_px, (Eigen::Vector2d(b.u_px, b.v_px) - c).norm());
		centroid_worst_px = std::max(centroid_worst_px, nearest_px);
	}));
	EXPECT_LT(fit_worst_px, 0.005);
	EXPECT_GT(centroid_worst_px, 4.0 * fit_worst_px);
}

TEST(BlobMeasure, UniformDiscAndSinglePixel)
{
	/* A uniform disc of radius r: sigma r / 2 along every axis, fill 1. */
	const double r = 9.3, cx = 20.5, cy = 19.25;
	StridedFrame f(48, 40, 48);
	int area = 0;
	for (int y = 0; y < 40; ++y)
		for (int x = 0; x < 48; ++x)
			if ((x - cx) * (x - cx) + (y - cy) * (y - cy) <= r * r) {
				f.at(x, y) = 200;
				++area;
			}
	BlobDetector det(48, 40, fixedThreshold(100), filterWithGap(1, 10000));
	StaticVector<Blob, kMaxCandidates> blobs;
	ASSERT_TRUE(det.detect(f.view(), &blobs, nullptr));
	ASSERT_EQ(blobs.size(), 1u);
	EXPECT_NEAR(blobs[0].u_px, cx, 0.05);
	EXPECT_NEAR(blobs[0].v_px, cy, 0.05);
	EXPECT_NEAR(blobs[0].sigma_major_px, r / 2, 0.1);
	EXPECT_NEAR(blobs[0].sigma_minor_px, r / 2, 0.1);
	EXPECT_NEAR(blobs[0].fill, 1.0, 0.05);
	EXPECT_EQ(blobs[0].area_px, area);
	EXPECT_EQ(blobs[0].weight, 101.0 * area);

	/* One pixel: a unit square, sigma sqrt(1/12) both ways. */
	BlobMoments m;
	m.area = 1;
	/* one pixel at (5, 3) of weight 7 */
	m.sum_w = 7;
	m.sum_wx = 35;
	m.sum_wy = 21;
	m.sum_wxx = 175;
	m.sum_wyy = 63;
	m.sum_wxy = 105;
	const Blob one = BlobDetector::measure(m);
	EXPECT_DOUBLE_EQ(one.u_px, 5.0);
	EXPECT_DOUBLE_EQ(one.v_px, 3.0);
	EXPECT_NEAR(one.sigma_major_px, std::sqrt(1.0 / 12.0), 1e-12);
	EXPECT_NEAR(one.elongation, 1.0, 1e-12);
	EXPECT_NEAR(one.fill, 3.0 / std::numbers::pi, 1e-12);
}

TEST(BlobFilter, RejectsLinesDropsSpecksKeepsDiscs)
{
	StridedFrame f(200, 120, 203);
	/* Discs of radius 3 with a smooth profile. */
	auto disc = [&](double cx, double cy, int peak) {
		for (int y = static_cast<int>(cy) - 5; y <= static_cast<int>(cy) + 5; ++y)
			for (int x = static_cast<int>(cx) - 5; x <= static_cast<int>(cx) + 5; ++x) {
				const double d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
				if (d2 <= 9.0)
					f.at(x, y) = static_cast<std::uint8_t>(
						peak - static_cast<int>(4 * d2));
			}
	};
	disc(20.3, 20.7, 250);
	disc(60.0, 25.5, 200);
	disc(100.5, 90.0, 150);
	/* A horizontal line, a diagonal line, a 2-pixel-thick streak. */
	for (int x = 120; x < 150; ++x)
		f.at(x, 10) = 240;
	for (int t = 0; t < 25; ++t)
		f.at(10 + t, 60 + t) = 240;
	for (int x = 40; x < 90; ++x)
		f.at(x, 100) = f.at(x, 101) = 240;
	/* Single pixels and a sparse ring. */
	f.at(180, 5) = f.at(190, 50) = f.at(170, 110) = 255;
	for (double t = 0; t < 6.283; t += 0.02)
		f.at(static_cast<int>(160 + 12 * std::cos(t)),
		     static_cast<int>(60 + 12 * std::sin(t))) = 230;

	BlobDetector det(200, 120, fixedThreshold(100), filterWithGap(0));
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	ASSERT_EQ(blobs.size(), 3u);
	/* Sorted by weight, strongest first. */
	EXPECT_NEAR(blobs[0].u_px, 20.3, 0.3);
	EXPECT_NEAR(blobs[1].u_px, 60.0, 0.3);
	EXPECT_NEAR(blobs[2].u_px, 100.5, 0.3);
	EXPECT_GT(blobs[0].weight, blobs[1].weight);
	EXPECT_GT(blobs[1].weight, blobs[2].weight);
	EXPECT_EQ(stats.components, 3 + 3 + 3 + 1);
	EXPECT_EQ(stats.dropped_small, 3);
	EXPECT_EQ(stats.dropped_shape, 4); /* three lines, the ring */
	EXPECT_EQ(stats.dropped_large, 0);
	EXPECT_EQ(stats.dropped_capacity, 0);
	for (const Blob &b : blobs) {
		EXPECT_LT(b.elongation, 1.3);
		EXPECT_GT(b.fill, 0.7);
	}
}

TEST(BlobFilter, AreaLimitsAndCapacity)
{
	/* 100 squares of 3x3 with distinct brightness, and one big square. */
	const int w = 400, h = 300;
	StridedFrame f(w, h, w);
	for (int i = 0; i < 100; ++i) {
		const int x0 = 5 + (i % 20) * 19, y0 = 5 + (i / 20) * 19;
		for (int y = 0; y < 3; ++y)
			for (int x = 0; x < 3; ++x)
				f.at(x0 + x, y0 + y) = static_cast<std::uint8_t>(120 + i);
	}
	/* 30 x 30 = 900 px, above 400 * 300 / 200 = 600 */
	for (int y = 200; y < 230; ++y)
		for (int x = 200; x < 230; ++x)
			f.at(x, y) = 250;
	BlobDetector det(w, h, fixedThreshold(100), BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	EXPECT_EQ(stats.components, 101);
	EXPECT_EQ(stats.dropped_large, 1);
	EXPECT_EQ(stats.dropped_capacity, 100 - static_cast<int>(kMaxCandidates));
	ASSERT_EQ(blobs.size(), kMaxCandidates);
	/* The strongest 64, in order: square i has weight 9 * (120 + i - 100 + 1). */
	for (std::size_t k = 0; k < blobs.size(); ++k) {
		const int i = 99 - static_cast<int>(k);
		EXPECT_EQ(blobs[k].weight, 9.0 * (120 + i - 100 + 1)) << k;
		EXPECT_NEAR(blobs[k].u_px, 5 + (i % 20) * 19 + 1, 1e-9);
		const int row = i / 20;
		EXPECT_NEAR(blobs[k].v_px, 5 + row * 19 + 1, 1e-9);
	}

	/* An explicit max_area keeps the big square; min_area 10 drops the small ones. */
	BlobFilterConfig filter;
	filter.max_area_px = 1000;
	filter.min_area_px = 10;
	BlobDetector det2(w, h, fixedThreshold(100), filter);
	ASSERT_TRUE(det2.detect(f.view(), &blobs, &stats));
	ASSERT_EQ(blobs.size(), 1u);
	EXPECT_EQ(blobs[0].area_px, 900.0);
	EXPECT_EQ(stats.dropped_small, 100);
}

namespace {

/* Smooth discs of radius 3 at random places on a noisy, sloping background (auto threshold). */
StridedFrame spotsFrame(int w, int h, int spots, unsigned seed,
			std::vector<Eigen::Vector2d> *centres)
{
	StridedFrame f(w, h, w + 13);
	std::mt19937 rng(seed);
	std::normal_distribution<double> noise(0.0, 2.0);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x)
			f.at(x, y) = static_cast<std::uint8_t>(
				std::clamp(30.0 + 0.05 * x + noise(rng), 0.0, 255.0));
	std::uniform_real_distribution<double> ux(8.0, w - 9.0), uy(8.0, h - 9.0);
	for (int s = 0; s < spots; ++s) {
		const Eigen::Vector2d c{ ux(rng), uy(rng) };
		centres->push_back(c);
		for (int y = static_cast<int>(c.y()) - 5; y <= static_cast<int>(c.y()) + 5; ++y)
			for (int x = static_cast<int>(c.x()) - 5; x <= static_cast<int>(c.x()) + 5;
			     ++x) {
				const double d2 =
					(x - c.x()) * (x - c.x()) + (y - c.y()) * (y - c.y());
				if (d2 <= 9.0)
					f.at(x, y) = static_cast<std::uint8_t>(
						220 - static_cast<int>(10 * d2));
			}
	}
	return f;
}

bool sameBlob(const Blob &a, const Blob &b)
{
	return a.u_px == b.u_px && a.v_px == b.v_px && a.area_px == b.area_px &&
	       a.weight == b.weight && a.cov_uu_px2 == b.cov_uu_px2 &&
	       a.cov_uv_px2 == b.cov_uv_px2 && a.cov_vv_px2 == b.cov_vv_px2 && a.x_min == b.x_min &&
	       a.y_max == b.y_max && a.peak == b.peak;
}

} /* namespace */

TEST(BlobWindows, GiveExactlyTheBlobsOfTheWholeFrameInsideThem)
{
	int compared = 0;
	for (unsigned seed = 1; seed <= 20; ++seed) {
		std::vector<Eigen::Vector2d> centres;
		const StridedFrame f = spotsFrame(700, 500, 12, seed, &centres);
		BlobDetector det(700, 500, ThresholdConfig{}, BlobFilterConfig{});
		StaticVector<Blob, kMaxCandidates> whole, windowed;
		BlobStats stats;
		ASSERT_TRUE(det.detect(f.view(), &whole, &stats));
		/* Windows around every other whole-frame blob, of odd sizes at odd places. */
		std::vector<PixelWindow> windows;
		std::vector<Blob> expected;
		for (std::size_t i = 0; i < whole.size(); i += 2) {
			const int u = static_cast<int>(whole[i].u_px),
				  v = static_cast<int>(whole[i].v_px);
			const int half = 9 + static_cast<int>((seed + i) % 40);
			const PixelWindow w{ std::max(u - half, 0), std::max(v - half - 1, 0),
					     std::min(u + half + 3, 700), std::min(v + half, 500) };
			bool overlaps = false;
			for (const PixelWindow &o : windows)
				overlaps |= w.x0 <= o.x1 && o.x0 <= w.x1 && w.y0 <= o.y1 &&
					    o.y0 <= w.y1;
			if (overlaps)
				continue;
			windows.push_back(w);
		}
		for (const Blob &b : whole)
			for (const PixelWindow &w : windows)
				if (b.x_min >= w.x0 && b.x_max < w.x1 && b.y_min >= w.y0 &&
				    b.y_max < w.y1)
					expected.push_back(b);
		const bool ok = det.detectWindows(f.view(), windows.data(), windows.size(),
						  &windowed, &stats);
		if (!ok) {
			/* Only a spot crossing a window's side may refuse the windows. */
			EXPECT_TRUE(stats.window_cut) << seed;
			continue;
		}
		ASSERT_EQ(windowed.size(), expected.size()) << seed;
		compared += static_cast<int>(expected.size());
		for (const Blob &b : expected) {
			const bool found =
				std::any_of(windowed.begin(), windowed.end(),
					    [&](const Blob &o) { return sameBlob(o, b); });
			EXPECT_TRUE(found) << seed << " blob at " << b.u_px << ", " << b.v_px;
		}
	}
	EXPECT_GE(compared, 60); /* most frames' windows were read, not refused */
}

TEST(BlobWindows, RefuseACutSpotAFrameWithoutReferenceAndBadWindows)
{
	std::vector<Eigen::Vector2d> centres;
	const StridedFrame f = spotsFrame(300, 200, 1, 5, &centres);
	BlobDetector det(300, 200, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	const int u = static_cast<int>(centres[0].x()), v = static_cast<int>(centres[0].y());
	const PixelWindow around{ u - 8, v - 8, u + 9, v + 9 };
	/* No detect() yet: no level map to read the windows against. */
	EXPECT_FALSE(det.detectWindows(f.view(), &around, 1, &blobs, &stats));
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	ASSERT_EQ(blobs.size(), 1u);
	const Blob spot = blobs[0];

	ASSERT_TRUE(det.detectWindows(f.view(), &around, 1, &blobs, &stats));
	ASSERT_EQ(blobs.size(), 1u);
	EXPECT_TRUE(sameBlob(blobs[0], spot));
	EXPECT_EQ(stats.components, 1);

	/* The window's side through the spot: refused, not a partial blob. */
	const PixelWindow cut{ u - 8, v - 8, u + 1, v + 9 };
	EXPECT_FALSE(det.detectWindows(f.view(), &cut, 1, &blobs, &stats));
	EXPECT_TRUE(stats.window_cut);
	EXPECT_EQ(blobs.size(), 0u);

	/* A window beyond the frame, an empty one, and a frame of another size. */
	const PixelWindow outside{ 290, 190, 310, 210 };
	EXPECT_FALSE(det.detectWindows(f.view(), &outside, 1, &blobs, &stats));
	const PixelWindow empty{ 10, 10, 10, 20 };
	EXPECT_FALSE(det.detectWindows(f.view(), &empty, 1, &blobs, &stats));
	const StridedFrame smaller(200, 100, 200);
	EXPECT_FALSE(det.detectWindows(smaller.view(), &around, 1, &blobs, &stats));

	/* A window that only touches the frame's own edge is fine (nothing lies beyond). */
	const PixelWindow corner{ 0, 0, 40, 40 };
	EXPECT_TRUE(det.detectWindows(f.view(), &corner, 1, &blobs, &stats));
}

/*
 * A window whose side cuts a spot names where it must reach
 * (BlobStats::cut_reach): widened so, it reads the spot as detect() does.
 * Both cuts: the labelling's (a side through the spot) and grow()'s (a side
 * just outside the thresholded spot, inside the faint skirt it measures).
 */
TEST(BlobWindows, ACutWindowWidenedToItsReachReadsTheSpotWhole)
{
	/* A Gaussian spot (sigma 2 px, 150 levels) on a noisy background: a skirt below the threshold. */
	StridedFrame f(300, 200, 313);
	std::mt19937 rng(11);
	std::normal_distribution<double> noise(0.0, 2.0);
	const double cu = 150.3, cv = 100.6;
	for (int y = 0; y < 200; ++y)
		for (int x = 0; x < 300; ++x) {
			const double d2 = (x - cu) * (x - cu) + (y - cv) * (y - cv);
			f.at(x, y) = static_cast<std::uint8_t>(std::clamp(
				30.0 + 150.0 * std::exp(-d2 / 8.0) + noise(rng), 0.0, 255.0));
		}
	const std::vector<Eigen::Vector2d> centres{ { cu, cv } };
	BlobDetector det(300, 200, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	ASSERT_EQ(blobs.size(), 1u);
	const Blob spot = blobs[0];
	/*
	 * Windows centred on the spot and off it, from one through its middle to
	 * ones holding its skirt: each refused one is widened to its reach until
	 * it is read (at most 3 times, as the pipeline does).
	 */
	const int u = static_cast<int>(cu), v = static_cast<int>(cv);
	int refused = 0;
	for (int half = 1; half <= 14; ++half)
		for (int shift = -half; shift <= half; shift += half) {
			PixelWindow w{ u + shift - half, v - half, u + shift + half + 1,
				       v + half + 1 };
			int widenings = 0;
			while (!det.detectWindows(f.view(), &w, 1, &blobs, &stats)) {
				ASSERT_TRUE(stats.window_cut) << half << " " << shift;
				ASSERT_LT(widenings, 3) << half << " " << shift;
				const PixelWindow r = stats.cut_reach;
				ASSERT_TRUE(r.x0 >= 0 && r.y0 >= 0 && r.x1 <= 300 && r.y1 <= 200 &&
					    r.x0 < r.x1 && r.y0 < r.y1);
				/* The reach touches the window that cut (the cut part lies in both). */
				ASSERT_TRUE(r.x0 <= w.x1 && w.x0 <= r.x1 && r.y0 <= w.y1 &&
					    w.y0 <= r.y1);
				w = PixelWindow{ std::min(w.x0, r.x0), std::min(w.y0, r.y0),
						 std::max(w.x1, r.x1), std::max(w.y1, r.y1) };
				++widenings;
			}
			refused += widenings > 0;
			ASSERT_EQ(blobs.size(), 1u) << half << " " << shift;
			EXPECT_TRUE(sameBlob(blobs[0], spot)) << half << " " << shift;
		}
	EXPECT_GE(refused, 20);
}

/*
 * A faint spot at the foot of a sunlit patch's flank: its 64 px tile reaches
 * up onto the patch, the tile's level (its brightest corner's interpolation
 * plus the contrast) lies far above the spot's peak, and only the
 * threshold's finer cells (Thresholder::cellMap()) see it.
 */
TEST(BlobSteepBackground, AFaintSpotAtTheFootOfABrightPatchIsFound)
{
	constexpr int kSize = 512;
	/* The patch: a disc of radius 150 px at 150 levels, its edge falling over 30 px (smoothstep). */
	const double patch_u = 200.0, patch_v = 150.0;
	const double spot_u = 300.3, spot_v = 311.6; /* 190 px from the patch's centre */
	std::mt19937 rng(7);
	std::normal_distribution<double> noise(0.0, 2.0);
	auto paint = [&](StridedFrame *f, double spot_peak) {
		for (int y = 0; y < kSize; ++y)
			for (int x = 0; x < kSize; ++x) {
				const double r = std::hypot(x - patch_u, y - patch_v);
				const double e = std::clamp((180.0 - r) / 30.0, 0.0, 1.0);
				const double ds2 =
					(x - spot_u) * (x - spot_u) + (y - spot_v) * (y - spot_v);
				const double v = 10.0 + 150.0 * e * e * (3.0 - 2.0 * e) +
						 spot_peak * std::exp(-ds2 / (2.0 * 1.2 * 1.2)) +
						 noise(rng);
				f->at(x, y) = static_cast<std::uint8_t>(
					std::clamp(std::lround(v), 0L, 255L));
			}
	};
	auto near_spot = [&](const StaticVector<Blob, kMaxCandidates> &blobs) {
		const Blob *found = nullptr;
		for (const Blob &b : blobs)
			if (std::hypot(b.u_px - spot_u, b.v_px - spot_v) < 5.0)
				found = &b;
		return found;
	};
	StridedFrame f(kSize, kSize, kSize);
	paint(&f, 45.0);
	BlobDetector det(kSize, kSize, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	/* The spot's brightest pixel lies far below its tile's level (the case this is about). */
	const ThresholdMap &tiles = det.thresholder().map();
	EXPECT_LT(f.at(300, 312) + 40, tiles.levelAt(300, 312));
	EXPECT_TRUE(det.thresholder().hasSteepTiles());
	const Blob *spot = near_spot(blobs);
	ASSERT_NE(spot, nullptr);
	EXPECT_GE(stats.below_tile_level, 1);
	EXPECT_NEAR(spot->u_px, spot_u, 0.15);
	EXPECT_NEAR(spot->v_px, spot_v, 0.15);

	/* Without the spot: nothing there. */
	StridedFrame g(kSize, kSize, kSize);
	paint(&g, 0.0);
	ASSERT_TRUE(det.detect(g.view(), &blobs, &stats));
	EXPECT_EQ(near_spot(blobs), nullptr);
}

/*
 * A faint spot drawn out by motion blur into a streak whose plateau lies
 * near the detecting level shows only the pixels that the noise lifts above
 * it, often in two or three pieces, whose centroids lie anywhere along the
 * streak (1-2 px off, where their covariance says 0.1 px). Measured down to
 * 3 sigma over the background from its pieces (BlobDetector::grow()), each
 * streak is one blob on its LED's mid-exposure place, within its own sigma.
 */
TEST(BlobGrow, AFaintBlurredStreakIsOneBlobOnItsMiddle)
{
	constexpr int kSize = 256;
	constexpr double kNoise = 3.5, kBackground = 9.0, kLength = 11.0, kPsf = 1.0;
	/* 16 vertical streaks at sub-pixel places; the plateau 6.5 sigma over the background. */
	std::vector<Eigen::Vector2d> truth;
	for (int j = 0; j < 4; ++j)
		for (int i = 0; i < 4; ++i)
			truth.emplace_back(32.0 + 60.0 * i + 0.13 * (i + 4 * j),
					   32.0 + 60.0 * j + 0.29 * (i + 4 * j));
	const double plateau = 7.5 * kNoise;
	std::mt19937 rng(2027);
	std::normal_distribution<double> noise(0.0, kNoise);
	StridedFrame f(kSize, kSize, kSize);
	for (int y = 0; y < kSize; ++y)
		for (int x = 0; x < kSize; ++x) {
			double v = kBackground + noise(rng);
			for (const Eigen::Vector2d &c : truth) {
				if (std::abs(x - c.x()) > 6.0 || std::abs(y - c.y()) > 12.0)
					continue;
				/* A Gaussian across, a segment of kLength blurred by the PSF along. */
				const double across =
					std::exp(-0.5 * (x - c.x()) * (x - c.x()) / (kPsf * kPsf));
				const double z0 =
					(y - c.y() + 0.5 * kLength) / (std::numbers::sqrt2 * kPsf);
				const double z1 =
					(y - c.y() - 0.5 * kLength) / (std::numbers::sqrt2 * kPsf);
				v += plateau * across * 0.5 * (std::erf(z0) - std::erf(z1));
			}
			f.at(x, y) =
				static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
		}
	BlobDetector det(kSize, kSize, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	/* The pieces at the detecting level: more than one per streak in this frame. */
	int pieces = 0;
	ASSERT_TRUE(det.label(f.view(), det.thresholder().map(),
			      [&](const BlobMoments &m) { pieces += m.area >= 2 ? 1 : 0; }));
	EXPECT_GT(pieces, static_cast<int>(truth.size()) + 4);

	double z2_sum = 0.0;
	int z_count = 0;
	for (const Eigen::Vector2d &c : truth) {
		int near = 0;
		for (const Blob &b : blobs) {
			if (std::abs(b.u_px - c.x()) > 3.0 ||
			    std::abs(b.v_px - c.y()) > 0.5 * kLength + 2.0)
				continue;
			++near;
			const double dv = b.v_px - c.y();
			EXPECT_LT(std::abs(dv), 0.6) << "streak at " << c.transpose();
			EXPECT_LT(std::abs(b.u_px - c.x()), 0.3) << "streak at " << c.transpose();
			ASSERT_GT(b.cov_vv_px2, 0.0);
			z2_sum += dv * dv / b.cov_vv_px2;
			++z_count;
		}
		EXPECT_EQ(near, 1) << "streak at " << c.transpose();
	}
	/* Along the streak, error / sigma about 1: its mean square within 0.3 .. 3 over 16. */
	ASSERT_GT(z_count, 0);
	EXPECT_LT(z2_sum / z_count, 3.0);
	EXPECT_GT(z2_sum / z_count, 0.3);
}

/*
 * The second look's labelling may overflow (more components in the steep
 * tiles than it holds) where the first look's did not: the frame keeps what
 * the first look found, and says that the second look was cut short.
 */
TEST(BlobSteepBackground, ASecondLookThatOverflowsKeepsTheFirstLooksBlobs)
{
	constexpr int kSize = 1024;
	/* A ramp of 0.22 levels/px: ~14 levels over a 64 px tile, so every tile is steep. */
	auto ramp = [](int x) {
		return 10.0 + 0.22 * x;
	};
	const double spot_u = 520.4, spot_v = 500.7;
	auto paint = [&](StridedFrame *f) {
		for (int y = 0; y < kSize; ++y)
			for (int x = 0; x < kSize; ++x) {
				const double ds2 =
					(x - spot_u) * (x - spot_u) + (y - spot_v) * (y - spot_v);
				const double v =
					ramp(x) + 150.0 * std::exp(-ds2 / (2.0 * 1.5 * 1.5));
				f->at(x, y) = static_cast<std::uint8_t>(
					std::clamp(std::lround(v), 0L, 255L));
			}
	};
	StridedFrame f(kSize, kSize, kSize);
	paint(&f);
	BlobDetector det(kSize, kSize, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	ASSERT_TRUE(det.thresholder().hasSteepTiles());
	ASSERT_EQ(blobs.size(), 1U);
	EXPECT_FALSE(stats.below_tile_overflow);

	/*
	 * Specks 3 px apart (separate components) one level above the cells' level
	 * and below the tiles' level, wherever there is room between the two: only
	 * the second look segments them, and there are more of them than it holds.
	 */
	const ThresholdMap tiles = det.thresholder().map();
	const ThresholdMap cells = det.thresholder().cellMap();
	int specks = 0;
	for (int y = 1; y < kSize - 1; y += 3)
		for (int x = 1; x < kSize - 1; x += 3) {
			if (std::hypot(x - spot_u, y - spot_v) < 12.0)
				continue;
			const int level = cells.levelAt(x, y) + 1;
			if (level + 2 <= tiles.levelAt(x, y) && level > f.at(x, y)) {
				f.at(x, y) = static_cast<std::uint8_t>(level);
				++specks;
			}
		}
	ASSERT_GT(specks, static_cast<int>(kMaxComponents));
	ASSERT_TRUE(det.detect(f.view(), &blobs, &stats));
	EXPECT_FALSE(stats.component_overflow);
	EXPECT_TRUE(stats.below_tile_overflow);
	ASSERT_EQ(blobs.size(), 1U);
	EXPECT_NEAR(blobs[0].u_px, spot_u, 0.2);
	EXPECT_NEAR(blobs[0].v_px, spot_v, 0.2);
}

/*
 * An LED that clips, merged with a bright surrounding (here a reflection too
 * large for a spot, touching it): the first look drops the merged component,
 * the third finds the LED's clipped core at its centre, with the plateau's
 * edge uncertainty in its covariance. An LED that clips on its own is found
 * once, and a surrounding without a clipped core adds nothing.
 */
TEST(BlobClippedCores, AnLedMergedWithABrightPatchKeepsItsCore)
{
	constexpr int kSize = 256;
	const double led_u = 100.3, led_v = 120.6;
	std::mt19937 rng(11);
	std::normal_distribution<double> noise(0.0, 2.0);
	auto paint = [&](StridedFrame *f, bool led, bool patch, double led_peak) {
		for (int y = 0; y < kSize; ++y)
			for (int x = 0; x < kSize; ++x) {
				const double d2 =
					(x - led_u) * (x - led_u) + (y - led_v) * (y - led_v);
				double v = 20.0 + noise(rng);
				/* The reflection: 60 x 40 px at 150 levels, its left side 6 px right of the LED's centre. */
				if (patch && x >= 106 && x < 166 && y >= 100 && y < 140)
					v += 130.0;
				if (led)
					v += led_peak * std::exp(-d2 / (2.0 * 3.0 * 3.0));
				f->at(x, y) = static_cast<std::uint8_t>(
					std::clamp(std::lround(v), 0L, 255L));
			}
	};
	BlobDetector det(kSize, kSize, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	auto near_led = [&] {
		int n = 0;
		const Blob *found = nullptr;
		for (const Blob &b : blobs)
			if (std::hypot(b.u_px - led_u, b.v_px - led_v) < 3.0) {
				found = &b;
				++n;
			}
		return std::make_pair(found, n);
	};

	StridedFrame merged(kSize, kSize, kSize);
	paint(&merged, true, true, 800.0);
	ASSERT_TRUE(det.detect(merged.view(), &blobs, &stats));
	EXPECT_GE(stats.dropped_large, 1);
	EXPECT_EQ(stats.clipped_cores, 1);
	const auto [core, cores] = near_led();
	ASSERT_NE(core, nullptr);
	EXPECT_EQ(cores, 1);
	EXPECT_GT(core->saturated_px, 0);
	/* The patch pushes the plateau's right edge out: within the covariance it states. */
	EXPECT_LT(std::abs(core->u_px - led_u), 3.0 * std::sqrt(core->cov_uu_px2));
	EXPECT_LT(std::abs(core->v_px - led_v), 3.0 * std::sqrt(core->cov_vv_px2));
	const double edge = 4.0 / (std::numbers::pi * std::numbers::pi);
	EXPECT_GE(core->cov_uu_px2, edge * edge);

	/* The LED alone: one blob, from the first look. */
	StridedFrame alone(kSize, kSize, kSize);
	paint(&alone, true, false, 800.0);
	ASSERT_TRUE(det.detect(alone.view(), &blobs, &stats));
	EXPECT_EQ(stats.clipped_cores, 0);
	EXPECT_EQ(near_led().second, 1);

	/*
	 * An LED that does not clip, merged with the patch: no core (the fourth
	 * look, BlobInnerPeaks, finds it as a peak, within its covariance).
	 */
	StridedFrame dim(kSize, kSize, kSize);
	paint(&dim, true, true, 90.0);
	ASSERT_TRUE(det.detect(dim.view(), &blobs, &stats));
	EXPECT_EQ(stats.clipped_cores, 0);
	const auto [peak, peaks] = near_led();
	ASSERT_EQ(peaks, 1);
	EXPECT_EQ(stats.inner_peaks, 1);
	EXPECT_LT(std::abs(peak->u_px - led_u), 3.0 * std::sqrt(peak->cov_uu_px2));
	EXPECT_LT(std::abs(peak->v_px - led_v), 3.0 * std::sqrt(peak->cov_vv_px2));
}

/*
 * An LED that does not clip, on a reflection too large for a spot (and
 * above its tile's level): the first look drops the merged component, the
 * fourth finds the LED as a peak above the plane of a ring round it, within
 * the covariance it states. The reflection alone adds nothing.
 */
TEST(BlobInnerPeaks, AnLedOnABrightSlopedPatchIsFound)
{
	constexpr int kSize = 256;
	const double led_u = 130.4, led_v = 125.7;
	auto paint = [&](StridedFrame *f, bool led) {
		std::mt19937 rng(17);
		std::normal_distribution<double> noise(0.0, 2.0);
		for (int y = 0; y < kSize; ++y)
			for (int x = 0; x < kSize; ++x) {
				double v = 20.0 + noise(rng);
				/* The reflection: 140 x 140 px, 100 levels up, rising 0.5 level/px to the right. */
				if (x >= 60 && x < 200 && y >= 60 && y < 200)
					v += 100.0 + 0.5 * (x - 60);
				if (led) {
					const double d2 = (x - led_u) * (x - led_u) +
							  (y - led_v) * (y - led_v);
					v += 60.0 * std::exp(-d2 / (2.0 * 1.2 * 1.2));
				}
				f->at(x, y) = static_cast<std::uint8_t>(
					std::clamp(std::lround(v), 0L, 255L));
			}
	};
	BlobDetector det(kSize, kSize, ThresholdConfig{}, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	StridedFrame with(kSize, kSize, kSize);
	paint(&with, true);
	ASSERT_TRUE(det.detect(with.view(), &blobs, &stats));
	EXPECT_GE(stats.dropped_large, 1);
	EXPECT_EQ(stats.inner_peaks, 1);
	const Blob *led = nullptr;
	for (const Blob &b : blobs)
		if (std::hypot(b.u_px - led_u, b.v_px - led_v) < 2.0)
			led = &b;
	ASSERT_NE(led, nullptr);
	EXPECT_LT(std::abs(led->u_px - led_u), 3.0 * std::sqrt(led->cov_uu_px2));
	EXPECT_LT(std::abs(led->v_px - led_v), 3.0 * std::sqrt(led->cov_vv_px2));
	EXPECT_LT(std::hypot(led->u_px - led_u, led->v_px - led_v), 0.2);

	StridedFrame without(kSize, kSize, kSize);
	paint(&without, false);
	ASSERT_TRUE(det.detect(without.view(), &blobs, &stats));
	EXPECT_EQ(stats.inner_peaks, 0);
	for (const Blob &b : blobs)
		EXPECT_FALSE(b.u_px > 60 && b.u_px < 200 && b.v_px > 60 && b.v_px < 200)
			<< b.u_px << "," << b.v_px;
}

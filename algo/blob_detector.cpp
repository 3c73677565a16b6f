/* SPDX-License-Identifier: MIT */
/*
 * Streaming connected-component labelling with integer moments, see
 * blob_detector.h.
 *
 * One pass over the rows. In each row, background is skipped 64 and 16
 * bytes at a time with GCC vector extensions (SSE2 on x86-64, NEON on
 * aarch64, no intrinsics); the few blocks that hold a segmented pixel are
 * scanned pixel by pixel into runs (gaps of up to fill_gap_px filled); a
 * 16-byte step visits only the bytes its comparison's bit mask marks (a
 * window's short rows are mostly such steps and one overlapping the row's
 * end). A finished run is connected to the runs of the previous row that
 * touch it (8-connectivity: overlap after widening by one pixel), the provisional
 * labels merge in a union-find forest with path halving, and each root owns
 * the integer moment accumulator of its component (merged on union). At the
 * end the roots are compacted into the component list. No label image.
 */
#include "algo/blob_detector.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <numbers>
#include <vector>

namespace dockpose {

namespace {

using U8x16 = std::uint8_t __attribute__((vector_size(16)));
using U64x2 = std::uint64_t __attribute__((vector_size(16)));

inline U8x16 load16(const std::uint8_t *p)
{
	U8x16 v;
	std::memcpy(&v, p, sizeof(v));
	return v;
}

inline U8x16 splat16(std::uint8_t v)
{
	return U8x16{ v, v, v, v, v, v, v, v, v, v, v, v, v, v, v, v };
}

inline U8x16 max16(U8x16 a, U8x16 b)
{
	return a > b ? a : b;
}

/* Whether any byte of v is >= the byte of level. */
inline bool anyAtLeast(U8x16 v, U8x16 level)
{
	const U64x2 m = std::bit_cast<U64x2>(v >= level);
	return (m[0] | m[1]) != 0;
}

/* Whether every byte of v is >= the byte of level. */
inline bool allAtLeast(U8x16 v, U8x16 level)
{
	const U64x2 m = std::bit_cast<U64x2>(v >= level);
	return (m[0] & m[1]) == ~std::uint64_t{ 0 };
}

/*
 * Bit i set where byte i of v is >= the byte of level. Portable (no movemask
 * on NEON): each 0x00/0xff byte keeps a distinct bit, and one multiply adds
 * the eight bytes of a 64-bit lane into its top byte.
 */
inline std::uint32_t atLeastMask(U8x16 v, U8x16 level)
{
	const U64x2 m = std::bit_cast<U64x2>(v >= level);
	constexpr std::uint64_t kBitOfByte = 0x8040201008040201ull;
	constexpr std::uint64_t kSumBytes = 0x0101010101010101ull;
	const std::uint64_t lo = ((m[0] & kBitOfByte) * kSumBytes) >> 56;
	const std::uint64_t hi = ((m[1] & kBitOfByte) * kSumBytes) >> 56;
	return static_cast<std::uint32_t>(lo | (hi << 8));
}

constexpr std::uint32_t kNoLabel = 0xffffffffu;

/*
 * Rows the labelling prefetches ahead of the row it reads: a window's (at
 * most kNarrowPx wide), and a wider read's (the whole frame).
 */
constexpr int kPrefetchRows = 8;
constexpr int kPrefetchRowsWide = 2;
constexpr int kNarrowPx = 1024;

/* Variance of the rounding of a pixel to an integer level, levels^2. */
constexpr double kQuantisationVar = 1.0 / 12.0;
/*
 * Systematic centroid errors of a sampled spot (pixel locking), as the
 * variance of the weight of each pixel of an edge ring, calibrated by
 * Monte-Carlo over subpixel phases on rendered spots (docs/vision.md):
 *  - the ring where the spot crosses its threshold: a pixel enters or
 *    leaves with a step of one level, ~0.5 level^2 each;
 *  - the edge of a clipped plateau: each edge pixel's share of the plateau
 *    is quantised, ~(0.06 of the clip weight)^2 each (the sharpest edges:
 *    an LED many times brighter than the clip level).
 */
constexpr double kThresholdRingVar = 0.5;
constexpr double kPlateauEdgeFraction2 = 4e-3;

/*
 * The measurement of a spot reaches below the level that detected it
 * (hysteresis): down to kGrowSigma times the frame's noise over the
 * background (at least kGrowMinContrast levels), where background noise
 * alone passes one pixel in ~740. Only for components whose box is at most
 * kGrowMaxBox on a side, grown within kGrowMargin of it (see grow()).
 */
constexpr double kGrowSigma = 3.0;
constexpr int kGrowMinContrast = 2;
constexpr int kGrowMaxBox = 32;
constexpr int kGrowMargin = 16;
constexpr int kGrowSide = kGrowMaxBox + 2 * kGrowMargin;

/* The grown spot's level over the background, levels, for a frame of noise sigma `noise`. */
int growContrast(double noise)
{
	return std::max(kGrowMinContrast, static_cast<int>(std::ceil(kGrowSigma * noise)));
}

struct Run {
	int x0, x1; /* inclusive */
	std::uint32_t label;
};

/*
 * The sub-pixel fit of a small spot reads the pixels within this Chebyshev
 * distance of its peak pixel: the 3 x 3 core it fits and, at the outer ring
 * (7 x 7 border, 24 pixels), the local background.
 */
constexpr int kFitRing = 3;
constexpr int kFitRingPixels = 8 * kFitRing;

/*
 * One axis of the three-point Gaussian fit: the offset of the peak from the
 * middle sample of s[-1], s[0], s[1] (background-subtracted marginals, all
 * > 0): d = (l- - l+) / (2 (l- - 2 l0 + l+)), l = ln s, exact for a sampled
 * Gaussian whatever its width. grad gets dd/ds. False when the three are not
 * a peak (the log profile not concave, or the peak beyond the next pixel).
 */
bool gaussianPeak3(const double s[3], double *d, double grad[3])
{
	const double a = std::log(s[0]), b = std::log(s[1]), c = std::log(s[2]);
	const double den = a - 2.0 * b + c;
	if (!(den < 0.0))
		return false;
	const double num = a - c;
	*d = 0.5 * num / den;
	if (!(std::abs(*d) <= 1.0))
		return false;
	grad[0] = (den - num) / (2.0 * den * den) / s[0];
	grad[1] = num / (den * den) / s[1];
	grad[2] = (-den - num) / (2.0 * den * den) / s[2];
	return true;
}

/*
 * The model-based centre of an unsaturated spot that the pixel grid
 * undersamples (docs/vision.md, "Sub-pixel centre of small spots"). The
 * thresholded, intensity-weighted centroid locks to the pixel grid there
 * (pixels enter and leave the segmentation with the spot's sub-pixel phase:
 * up to ~0.04 px at a blur sigma of 0.5-1.2 px). A pixel-integrated Gaussian
 * is still a Gaussian to a good approximation, so a three-point fit on the
 * log of the 3 x 3 core's background-subtracted marginals (row and column
 * sums) has no such bias; its background is the median of the ring at
 * kFitRing, where the spot has faded. Its covariance is the first-order
 * propagation of the pixel noise s2 through the fit (each marginal sums 3
 * pixels; the background is common to all). It replaces the centroid of
 * every spot whose segmented pixels lie inside the ring (choosing the one
 * with the smaller covariance let the choice follow the noise and the
 * sub-pixel phase, and the locking came back). Allocates: never.
 */
void fitSmallSpot(const ImageView &image, double s2, double gain, Blob *b)
{
	const int cx = static_cast<int>(std::lround(b->u_px));
	const int cy = static_cast<int>(std::lround(b->v_px));
	if (cx - kFitRing < 0 || cy - kFitRing < 0 || cx + kFitRing >= image.width ||
	    cy + kFitRing >= image.height)
		return;
	/* The ring must lie outside the segmented spot: larger spots keep their centroid. */
	if (b->x_min <= cx - kFitRing || b->x_max >= cx + kFitRing || b->y_min <= cy - kFitRing ||
	    b->y_max >= cy + kFitRing)
		return;
	std::array<std::uint8_t, kFitRingPixels> ring{};
	std::size_t n = 0;
	for (int k = -kFitRing; k < kFitRing; ++k) {
		ring[n++] = image.at(cx + k, cy - kFitRing);
		ring[n++] = image.at(cx + kFitRing, cy + k);
		ring[n++] = image.at(cx - k, cy + kFitRing);
		ring[n++] = image.at(cx - kFitRing, cy - k);
	}
	std::nth_element(ring.begin(), ring.begin() + kFitRingPixels / 2, ring.end());
	const std::uint8_t upper = ring[kFitRingPixels / 2];
	const std::uint8_t lower =
		*std::max_element(ring.begin(), ring.begin() + kFitRingPixels / 2);
	const double background = 0.5 * (static_cast<double>(lower) + upper);

	double sx[3] = { 0.0, 0.0, 0.0 }, sy[3] = { 0.0, 0.0, 0.0 };
	double var[3][3]; /* each core pixel's: s2 and its shot noise */
	for (int j = -1; j <= 1; ++j)
		for (int i = -1; i <= 1; ++i) {
			const double v = static_cast<double>(image.at(cx + i, cy + j)) - background;
			sx[i + 1] += v;
			sy[j + 1] += v;
			var[j + 1][i + 1] = s2 + gain * std::max(0.0, v);
		}
	for (int k = 0; k < 3; ++k)
		if (!(sx[k] > 0.0) || !(sy[k] > 0.0))
			return;
	double dx = 0.0, dy = 0.0, gx[3], gy[3];
	if (!gaussianPeak3(sx, &dx, gx) || !gaussianPeak3(sy, &dy, gy))
		return;

	/*
	 * Pixel (i, j) of the core enters sx[i] and sy[j] with its variance,
	 * s2 and its shot noise gain * (v - background) (ThresholdStats::
	 * noise_gain); each marginal holds 3 pixels and 3 times the background. The median of n samples has the
	 * variance pi / 2 s2 / n (at least the rounding of one level).
	 */
	const double gxs = gx[0] + gx[1] + gx[2], gys = gy[0] + gy[1] + gy[2];
	const double var_bg =
		std::max(0.5 * std::numbers::pi * s2 / kFitRingPixels, kQuantisationVar);
	double cuu = 9.0 * var_bg * gxs * gxs;
	double cvv = 9.0 * var_bg * gys * gys;
	double cuv = 9.0 * var_bg * gxs * gys;
	for (int j = 0; j < 3; ++j)
		for (int i = 0; i < 3; ++i) {
			cuu += var[j][i] * gx[i] * gx[i];
			cvv += var[j][i] * gy[j] * gy[j];
			cuv += var[j][i] * gx[i] * gy[j];
		}
	b->u_px = cx + dx;
	b->v_px = cy + dy;
	b->cov_uu_px2 = cuu;
	b->cov_vv_px2 = cvv;
	b->cov_uv_px2 = cuv;
}

} /* namespace */

struct BlobDetector::Impl {
	Impl(int max_w, int max_h)
		: max_width(max_w),
		  max_height(max_h),
		  parent(kMaxComponents),
		  acc(kMaxComponents),
		  runs_a(static_cast<std::size_t>(max_w) / 2 + 2),
		  runs_b(static_cast<std::size_t>(max_w) / 2 + 2),
		  level_row(static_cast<std::size_t>(max_w) + 64),
		  block_level(static_cast<std::size_t>(max_w) / 64 + 1),
		  grow_low(static_cast<std::size_t>(kGrowSide) * kGrowSide),
		  grow_stack(4 * static_cast<std::size_t>(kGrowSide) * kGrowSide)
	{
	}

	/* `next`: the window read after this one, whose first rows the last rows prefetch. */
	bool label(const ImageView &image, const ThresholdMap &map, int fill_gap, int clip_level,
		   const PixelWindow &window, const PixelWindow *next = nullptr);

	std::uint32_t find(std::uint32_t x)
	{
		while (parent[x] != x) {
			parent[x] = parent[parent[x]];
			x = parent[x];
		}
		return x;
	}

	/* Merge two roots, keeping the smaller label as root. */
	std::uint32_t unite(std::uint32_t a, std::uint32_t b)
	{
		if (b < a)
			std::swap(a, b);
		parent[b] = a;
		BlobMoments &d = acc[a];
		const BlobMoments &s = acc[b];
		d.area += s.area;
		d.sum_w += s.sum_w;
		d.sum_wx += s.sum_wx;
		d.sum_wy += s.sum_wy;
		d.sum_wxx += s.sum_wxx;
		d.sum_wyy += s.sum_wyy;
		d.sum_wxy += s.sum_wxy;
		d.x_min = std::min(d.x_min, s.x_min);
		d.x_max = std::max(d.x_max, s.x_max);
		d.y_min = std::min(d.y_min, s.y_min);
		d.y_max = std::max(d.y_max, s.y_max);
		d.peak = std::max(d.peak, s.peak);
		d.noisy += s.noisy;
		d.sum_x += s.sum_x;
		d.sum_y += s.sum_y;
		d.sum_xx += s.sum_xx;
		d.sum_yy += s.sum_yy;
		d.sum_xy += s.sum_xy;
		d.saturated += s.saturated;
		d.sat_x += s.sat_x;
		d.sat_y += s.sat_y;
		d.sat_xx += s.sat_xx;
		d.sat_yy += s.sat_yy;
		d.sat_xy += s.sat_xy;
		d.sat_x_min = std::min(d.sat_x_min, s.sat_x_min);
		d.sat_x_max = std::max(d.sat_x_max, s.sat_x_max);
		d.sat_y_min = std::min(d.sat_y_min, s.sat_y_min);
		d.sat_y_max = std::max(d.sat_y_max, s.sat_y_max);
		d.sum_t += s.sum_t;
		d.sum_tx += s.sum_tx;
		d.sum_ty += s.sum_ty;
		d.level_min = std::min(d.level_min, s.level_min);
		return a;
	}

	int max_width;
	int max_height;
	std::vector<std::uint32_t> parent;
	std::vector<BlobMoments> acc;
	std::vector<Run> runs_a, runs_b;
	/* The level of every pixel of the current tile row; the lowest level of each 64-byte block. */
	std::vector<std::uint8_t> level_row;
	std::vector<U8x16> block_level;
	/* grow(): its area's low levels, kGrowSide per tile row; its span fill's seeds (x | y << 16). */
	std::vector<std::uint8_t> grow_low;
	std::vector<std::uint32_t> grow_stack;
	std::size_t labels = 0;
	std::size_t components = 0;
	bool overflow = false;
};

bool BlobDetector::Impl::label(const ImageView &image, const ThresholdMap &map, int fill_gap,
			       int clip_level, const PixelWindow &window, const PixelWindow *next)
{
	labels = 0;
	components = 0;
	overflow = false;

	/* The columns [wx0, wx1) of the rows [window.y0, window.y1), in frame coordinates. */
	const int wx0 = window.x0;
	const int wx1 = window.x1;

	/* The map: one without tiles reads one level everywhere. */
	const std::uint8_t empty_level = map.levelAt(0, 0);
	const int map_cols = map.cols() > 0 ? map.cols() : 1;
	const int map_rows = map.rows() > 0 ? map.rows() : 1;
	const int tile = map.cols() > 0 ? map.tilePx() : kMaxFrameSide;
	const int blocks = (wx1 - wx0) / 64;
	/* The clip level in every byte (clip_level 256: nothing clips, never compared). */
	const U8x16 clip16 = splat16(static_cast<std::uint8_t>(std::min(clip_level, 255)));

	Run *prev = runs_a.data();
	Run *cur = runs_b.data();
	int nprev = 0;
	std::uint32_t *par = parent.data();
	BlobMoments *mom = acc.data();
	std::uint8_t *lrow = level_row.data();
	U8x16 *blv = block_level.data();
	int lrow_map_row = -1;

	/*
	 * A narrow window reads a short piece of many rows, each in another
	 * cache line (and often another page) of a frame fresh from the camera:
	 * the hardware prefetcher does not follow, so the rows ahead are
	 * prefetched (without, reading the windows was bound by memory latency),
	 * past the window's last row into `next`'s first: the next labelling
	 * finds them on their way. A wide read streams, but the hardware
	 * prefetcher starts again at every 4 KB page (a 1456 px frame crosses one
	 * every 2.8 rows) and falls behind: its rows are prefetched two ahead
	 * (measured against 1 to 16, docs/accuracy.md).
	 */
	const bool narrow = wx1 - wx0 <= kNarrowPx;
	const bool prefetch_next = narrow && next && next->x1 - next->x0 <= kNarrowPx;
	const int ahead =
		std::min(narrow ? kPrefetchRows : kPrefetchRowsWide, window.y1 - window.y0);
	for (int y = window.y0; y < window.y0 + ahead; ++y)
		prefetchRow(image.row(y), wx0, wx1);
	int map_row = 0;
	int next_tile_y = window.y0;
	for (int y = window.y0; y < window.y1; ++y) {
		const std::uint8_t *p = image.row(y);
		if (y + ahead < window.y1) {
			prefetchRow(image.row(y + ahead), wx0, wx1);
		} else if (prefetch_next) {
			const int next_y = next->y0 + (y + ahead - window.y1);
			if (next_y < next->y1)
				prefetchRow(image.row(next_y), next->x0, next->x1);
		}
		/* The tile row, stepped instead of divided for (a short window row costs little else). */
		if (y >= next_tile_y) {
			map_row = std::min(y / tile, map_rows - 1);
			next_tile_y = map_row == map_rows - 1 ? window.y1 : (map_row + 1) * tile;
		}
		if (map_row != lrow_map_row) {
			/* The level of every pixel of this tile row, and the lowest of each 64-byte block. */
			const std::uint8_t *levels = map.cols() > 0 ? map.rowLevels(map_row)
								    : &empty_level;
			/* From the window's first tile (a map of 1 px tiles has as many as the frame has columns). */
			for (int c = std::min(wx0 / tile, map_cols - 1); c < map_cols; ++c) {
				const int xa = std::max(c * tile, wx0);
				if (xa >= wx1)
					break;
				const int xb = c == map_cols - 1 ? wx1
								 : std::min(wx1, (c + 1) * tile);
				if (xb > xa)
					std::memset(lrow + xa, levels[c],
						    static_cast<std::size_t>(xb - xa));
			}
			for (int k = 0; k < blocks; ++k)
				blv[k] = splat16(*std::min_element(
					lrow + wx0 + std::ptrdiff_t{ 64 } * k,
					lrow + wx0 + std::ptrdiff_t{ 64 } * (k + 1)));
			lrow_map_row = map_row;
		}
		const std::uint64_t yy = static_cast<std::uint64_t>(y);

		int ncur = 0;
		int j = 0; /* first run of the previous row that may touch the next run */

		/* The open run. */
		bool open = false;
		int rx0 = 0, rx1 = 0;
		std::uint32_t area = 0;
		std::uint64_t sw = 0, swx = 0, swxx = 0;
		std::uint8_t peak = 0;
		/* unweighted sums of the run's noisy pixels; its saturated pixels */
		std::uint32_t nn = 0, ns = 0;
		std::uint64_t sx = 0, sxx = 0, ssx = 0, ssxx = 0;
		int sx0 = 0, sx1 = 0;
		/* the levels of the run's segmented pixels */
		std::uint64_t st = 0, stx = 0;
		std::uint8_t lmin = 255;

		auto close_run = [&]() {
			while (j < nprev && prev[j].x1 < rx0 - 1)
				++j;
			std::uint32_t root = kNoLabel;
			for (int k = j; k < nprev && prev[k].x0 <= rx1 + 1; ++k) {
				const std::uint32_t r = find(prev[k].label);
				if (root == kNoLabel)
					root = r;
				else if (r != root)
					root = unite(root, r);
			}
			if (root == kNoLabel) {
				if (labels == kMaxComponents) {
					overflow = true;
					return;
				}
				root = static_cast<std::uint32_t>(labels++);
				par[root] = root;
				BlobMoments &m = mom[root];
				m = BlobMoments{};
				m.x_min = static_cast<std::uint16_t>(rx0);
				m.x_max = static_cast<std::uint16_t>(rx1);
				m.y_min = m.y_max = static_cast<std::uint16_t>(y);
			}
			BlobMoments &m = mom[root];
			m.area += area;
			m.sum_w += sw;
			m.sum_wx += swx;
			m.sum_wxx += swxx;
			m.sum_wy += yy * sw;
			m.sum_wyy += yy * yy * sw;
			m.sum_wxy += yy * swx;
			m.x_min = std::min(m.x_min, static_cast<std::uint16_t>(rx0));
			m.x_max = std::max(m.x_max, static_cast<std::uint16_t>(rx1));
			m.y_max = static_cast<std::uint16_t>(y);
			m.peak = std::max(m.peak, peak);
			m.noisy += nn;
			m.sum_x += sx;
			m.sum_xx += sxx;
			m.sum_y += yy * nn;
			m.sum_yy += yy * yy * nn;
			m.sum_xy += yy * sx;
			m.sum_t += st;
			m.sum_tx += stx;
			m.sum_ty += yy * st;
			m.level_min = std::min(m.level_min, lmin);
			if (ns > 0) {
				m.saturated += ns;
				m.sat_x += ssx;
				m.sat_y += yy * ns;
				m.sat_xx += ssxx;
				m.sat_yy += yy * yy * ns;
				m.sat_xy += yy * ssx;
				m.sat_x_min =
					std::min(m.sat_x_min, static_cast<std::uint16_t>(sx0));
				m.sat_x_max =
					std::max(m.sat_x_max, static_cast<std::uint16_t>(sx1));
				m.sat_y_min = std::min(m.sat_y_min, static_cast<std::uint16_t>(y));
				m.sat_y_max = std::max(m.sat_y_max, static_cast<std::uint16_t>(y));
			}
			cur[ncur++] = Run{ rx0, rx1, root };
		};

		/*
		 * The n segmented pixels from x join the open run (across a gap of
		 * at most fill_gap: the gap counts in its area) or open a new one.
		 */
		auto take = [&](int x, int n) {
			if (open && x - rx1 - 1 <= fill_gap) {
				area += static_cast<std::uint32_t>(x + n - 1 - rx1);
				return;
			}
			if (open)
				close_run();
			open = true;
			rx0 = x;
			area = static_cast<std::uint32_t>(n);
			sw = swx = swxx = 0;
			peak = 0;
			nn = ns = 0;
			sx = sxx = ssx = ssxx = 0;
			st = stx = 0;
			lmin = 255;
		};

		auto pixel = [&](int x, std::uint8_t v, std::uint8_t level) {
			take(x, 1);
			const std::uint64_t w = std::uint64_t{ v } - level + 1; /* v >= level */
			const std::uint64_t ux = static_cast<std::uint64_t>(x);
			sw += w;
			swx += w * ux;
			swxx += w * ux * ux;
			peak = std::max(peak, v);
			st += level;
			stx += std::uint64_t{ level } * ux;
			lmin = std::min(lmin, level);
			if (v < clip_level) {
				++nn;
				sx += ux;
				sxx += ux * ux;
			} else {
				if (ns == 0)
					sx0 = x;
				++ns;
				ssx += ux;
				ssxx += ux * ux;
				sx1 = x;
			}
			rx1 = x;
		};

		/*
		 * pixel() for the 16 pixels from x, all segmented and all or none
		 * clipped (a bright patch's or a bloom's inside): the same sums, taken
		 * about x in 32 bits (w d^2 <= 256 * 15^2 per pixel) and moved to the
		 * frame's origin once.
		 */
		auto sixteen = [&](int x, bool clipped) {
			take(x, 16);
			std::uint32_t cw = 0, cwd = 0, cwdd = 0, ct = 0, ctd = 0;
			std::uint8_t cpeak = 0, clmin = 255;
			for (std::uint32_t d = 0; d < 16; ++d) {
				const std::uint8_t v = p[x + static_cast<int>(d)];
				const std::uint8_t t = lrow[x + static_cast<int>(d)];
				const std::uint32_t w = std::uint32_t{ v } - t + 1U;
				cw += w;
				cwd += w * d;
				cwdd += w * d * d;
				ct += t;
				ctd += std::uint32_t{ t } * d;
				cpeak = std::max(cpeak, v);
				clmin = std::min(clmin, t);
			}
			const auto ux = static_cast<std::uint64_t>(x);
			sw += cw;
			swx += ux * cw + cwd;
			swxx += ux * ux * cw + 2U * ux * cwd + cwdd;
			st += ct;
			stx += ux * ct + ctd;
			peak = std::max(peak, cpeak);
			lmin = std::min(lmin, clmin);
			/* sum d = 120, sum d^2 = 1240 over d = 0 .. 15 */
			const std::uint64_t run_x = 16U * ux + 120U;
			const std::uint64_t run_xx = 16U * ux * ux + 240U * ux + 1240U;
			if (clipped) {
				if (ns == 0)
					sx0 = x;
				ns += 16;
				ssx += run_x;
				ssxx += run_xx;
				sx1 = x + 15;
			} else {
				nn += 16;
				sx += run_x;
				sxx += run_xx;
			}
			rx1 = x + 15;
		};
		/*
		 * Every byte of v (16 pixels) segmented against level, and either
		 * none or all of them clipped (sixteen()'s `clipped`).
		 */
		auto whole = [&](U8x16 v, U8x16 level, bool *clipped) {
			if (!allAtLeast(v, level))
				return false;
			if (clip_level > 255 || !anyAtLeast(v, clip16)) {
				*clipped = false;
				return true;
			}
			*clipped = true;
			return allAtLeast(v, clip16);
		};

		/* The segmented pixels of the 16 bytes v read at x (most such reads have none). */
		auto hits = [&](int x, U8x16 v, U8x16 level, int skip = 0) {
			if (!anyAtLeast(v, level))
				return;
			bool clipped = false;
			if (skip == 0 && whole(v, level, &clipped)) {
				sixteen(x, clipped);
				return;
			}
			std::uint32_t mask = atLeastMask(v, level) >> skip << skip;
			for (; mask != 0; mask &= mask - 1) {
				const int xi = x + std::countr_zero(mask);
				pixel(xi, p[xi], lrow[xi]);
			}
		};
		auto scalar = [&](int x, int end) {
			for (; x < end; ++x) {
				if (p[x] >= lrow[x])
					pixel(x, p[x], lrow[x]);
			}
		};

		/* Skip the background: 64 bytes against the block's lowest level, then 16 exactly. */
		int x = wx0;
		for (int k = 0; k < blocks; ++k, x += 64) {
			const U8x16 a = load16(p + x);
			const U8x16 b = load16(p + x + 16);
			const U8x16 c = load16(p + x + 32);
			const U8x16 d = load16(p + x + 48);
			if (!anyAtLeast(max16(max16(a, b), max16(c, d)), blv[k]))
				continue;
			const U8x16 chunks[4] = { a, b, c, d };
			for (int q = 0; q < 4; ++q) {
				const int xq = x + 16 * q;
				const U8x16 lq = load16(lrow + xq);
				if (!anyAtLeast(chunks[q], lq))
					continue;
				bool clipped = false;
				if (whole(chunks[q], lq, &clipped))
					sixteen(xq, clipped);
				else
					scalar(xq, xq + 16);
			}
		}
		for (; x + 16 <= wx1; x += 16)
			hits(x, load16(p + x), load16(lrow + x));
		/* The last bytes: the 16 that end the row, those not read yet (a narrow window's rows are
		 * mostly this tail). */
		if (x < wx1) {
			if (wx1 - wx0 < 16)
				scalar(x, wx1);
			else /* of those 16, the first 16 - (wx1 - x) were read above */
				hits(wx1 - 16, load16(p + wx1 - 16), load16(lrow + wx1 - 16),
				     16 - (wx1 - x));
		}
		if (open)
			close_run();
		if (overflow)
			return false;

		std::swap(prev, cur);
		nprev = ncur;
	}

	/* Compact the roots, in order of their first pixel in raster order. */
	std::size_t n = 0;
	for (std::size_t i = 0; i < labels; ++i) {
		if (par[i] == i)
			mom[n++] = mom[i];
	}
	components = n;
	return true;
}

BlobDetector::BlobDetector(int max_width, int max_height, const ThresholdConfig &threshold,
			   const BlobFilterConfig &filter)
	: thresholder_(max_width, max_height, threshold),
	  filter_(filter),
	  impl_(new Impl(thresholder_.maxWidth(), thresholder_.maxHeight()))
{
	filter_.fill_gap_px = std::clamp(filter_.fill_gap_px, 0, kMaxFrameSide);
	filter_.clip_level = std::clamp(filter_.clip_level, 1, 256);
	/* (256: nothing clips, and no core is looked for: Dropped::clipped needs a clipped pixel.) */
	peak_map_ = ThresholdMap(thresholder_.maxWidth(), thresholder_.maxHeight(), 1);
	clip_map_ =
		ThresholdMap::uniform(static_cast<std::uint8_t>(std::min(filter_.clip_level, 255)));
}

BlobDetector::~BlobDetector()
{
	delete impl_;
}

bool BlobDetector::labelImpl(const ImageView &image, const ThresholdMap &map)
{
	impl_->labels = 0;
	impl_->components = 0;
	impl_->overflow = false;
	if (!image.valid() || image.width > impl_->max_width || image.height > impl_->max_height)
		return false;
	return impl_->label(image, map, filter_.fill_gap_px, filter_.clip_level,
			    PixelWindow{ 0, 0, image.width, image.height });
}

std::size_t BlobDetector::componentCount() const
{
	return impl_->components;
}

const BlobMoments *BlobDetector::components() const
{
	return impl_->acc.data();
}

Blob BlobDetector::measure(const BlobMoments &m, double noise_sigma, double noise_gain,
			   double level_over_background)
{
	__extension__ using Int128 = __int128;

	Blob b;
	b.area_px = static_cast<double>(m.area);
	b.weight = static_cast<double>(m.sum_w);
	b.peak = m.peak;
	b.x_min = m.x_min;
	b.x_max = m.x_max;
	b.y_min = m.y_min;
	b.y_max = m.y_max;

	if (m.sum_w == 0) {
		/* Not produced by the labeller (every component has a segmented pixel). */
		b.u_px = 0.5 * (m.x_min + m.x_max);
		b.v_px = 0.5 * (m.y_min + m.y_max);
		b.sigma_major_px = b.sigma_minor_px = std::sqrt(1.0 / 12.0);
		b.elongation = 1.0;
		b.fill = b.area_px / (std::numbers::pi * 4.0 * (1.0 / 12.0));
		return b;
	}

	const double sw = static_cast<double>(m.sum_w);
	b.u_px = static_cast<double>(m.sum_wx) / sw;
	b.v_px = static_cast<double>(m.sum_wy) / sw;
	{
		/*
		 * The centroid with one level for the whole spot, its lowest:
		 * w' = v - T_min + 1 = w + (T - T_min). A spot across tiles of
		 * different levels is otherwise weighted unevenly (a step of one
		 * level over half a small spot moves it by ~0.01 px).
		 */
		const std::uint64_t n_seg = std::uint64_t{ m.noisy } + m.saturated;
		const std::uint64_t t0 = m.level_min;
		const std::uint64_t sw1 = m.sum_w + m.sum_t - t0 * n_seg;
		if (n_seg > 0 && sw1 > 0) {
			const double d = static_cast<double>(sw1);
			b.u_px = static_cast<double>(m.sum_wx + m.sum_tx -
						     t0 * (m.sum_x + m.sat_x)) /
				 d;
			b.v_px = static_cast<double>(m.sum_wy + m.sum_ty -
						     t0 * (m.sum_y + m.sat_y)) /
				 d;
		}
	}

	/*
	 * Central second moments, exact in 128-bit integers:
	 * mu_xx * sw^2 = sw * sum_wxx - sum_wx^2, etc. Pixels are unit squares,
	 * so each one adds 1/12 to the variance along x and along y.
	 */
	const Int128 w = static_cast<Int128>(m.sum_w);
	const Int128 cxx = w * static_cast<Int128>(m.sum_wxx) -
			   static_cast<Int128>(m.sum_wx) * static_cast<Int128>(m.sum_wx);
	const Int128 cyy = w * static_cast<Int128>(m.sum_wyy) -
			   static_cast<Int128>(m.sum_wy) * static_cast<Int128>(m.sum_wy);
	const Int128 cxy = w * static_cast<Int128>(m.sum_wxy) -
			   static_cast<Int128>(m.sum_wx) * static_cast<Int128>(m.sum_wy);
	const double sw2 = sw * sw;
	const double mxx = static_cast<double>(cxx) / sw2 + 1.0 / 12.0;
	const double myy = static_cast<double>(cyy) / sw2 + 1.0 / 12.0;
	const double mxy = static_cast<double>(cxy) / sw2;

	const double mean = 0.5 * (mxx + myy);
	const double half_diff = 0.5 * (mxx - myy);
	const double root = std::sqrt(half_diff * half_diff + mxy * mxy);
	const double l_major = mean + root;
	const double l_minor = std::max(mean - root, 1.0 / 12.0 * 1e-6);

	b.sigma_major_px = std::sqrt(l_major);
	b.sigma_minor_px = std::sqrt(l_minor);
	b.elongation = b.sigma_major_px / b.sigma_minor_px;
	b.fill = b.area_px / (std::numbers::pi * 4.0 * b.sigma_major_px * b.sigma_minor_px);
	b.saturated_px = static_cast<int>(m.saturated);
	if (noise_sigma >= 0.0) {
		/* sum w (x - u_w)^2 etc. about the weighted centroid u_w, for the shot noise. */
		const WeightedSpread spread{ static_cast<double>(cxx) / sw,
					     static_cast<double>(cyy) / sw,
					     static_cast<double>(cxy) / sw };
		centroidCovariance(m, noise_sigma, noise_gain, level_over_background, spread, &b);
	}
	return b;
}

void BlobDetector::centroidCovariance(const BlobMoments &m, double noise_sigma, double noise_gain,
				      double level_over_background, const WeightedSpread &spread,
				      Blob *b)
{
	__extension__ using Int128 = __int128;

	/*
	 * u = sum w x / W with w = v - T + 1: du = sum (x - u) dv / W, so with
	 * independent pixel noise of variance s2, var(u) = s2 sum (x - u)^2 / W^2
	 * over the pixels whose value is noisy (clipped pixels are not). The
	 * sums about (u, v) from the unweighted moments, exact in integers:
	 * sum (x - u)^2 = (n sum_xx - sum_x^2) / n + n (mean_x - u)^2.
	 */
	const double s2 = std::max(noise_sigma * noise_sigma, kQuantisationVar);
	const std::uint64_t n_seg = std::uint64_t{ m.noisy } + m.saturated;
	const double sw = n_seg > 0 ? static_cast<double>(m.sum_w + m.sum_t -
							  std::uint64_t{ m.level_min } * n_seg)
				    : static_cast<double>(m.sum_w);
	double sxx = 0.0, syy = 0.0, sxy = 0.0;
	if (m.noisy > 0) {
		const Int128 n = m.noisy;
		const double dn = static_cast<double>(m.noisy);
		const Int128 cxx = n * static_cast<Int128>(m.sum_xx) -
				   static_cast<Int128>(m.sum_x) * static_cast<Int128>(m.sum_x);
		const Int128 cyy = n * static_cast<Int128>(m.sum_yy) -
				   static_cast<Int128>(m.sum_y) * static_cast<Int128>(m.sum_y);
		const Int128 cxy = n * static_cast<Int128>(m.sum_xy) -
				   static_cast<Int128>(m.sum_x) * static_cast<Int128>(m.sum_y);
		const double dx = static_cast<double>(m.sum_x) / dn - b->u_px;
		const double dy = static_cast<double>(m.sum_y) / dn - b->v_px;
		sxx = static_cast<double>(cxx) / dn + dn * dx * dx;
		syy = static_cast<double>(cyy) / dn + dn * dy * dy;
		sxy = static_cast<double>(cxy) / dn + dn * dx * dy;
	}
	const double k = s2 / (sw * sw);
	b->cov_uu_px2 = k * sxx;
	b->cov_vv_px2 = k * syy;
	b->cov_uv_px2 = k * sxy;

	/*
	 * Shot noise: a pixel's variance grows by g (v - B) = g (w - 1 + c)
	 * over the background's (c: the level's height over it), so var(u)
	 * gains g (sum w (x - u)^2 + (c - 1) sum (x - u)^2) / W^2 over the
	 * noisy pixels. sum w (x - u)^2 from the weighted spread about the
	 * weighted centroid, shifted to u, less the clipped pixels' share at
	 * the clip weight.
	 */
	if (noise_gain > 0.0 && m.sum_w > 0) {
		const double dw = static_cast<double>(m.sum_w);
		const double ux = static_cast<double>(m.sum_wx) / dw - b->u_px;
		const double uy = static_cast<double>(m.sum_wy) / dw - b->v_px;
		double wxx = spread.xx + dw * ux * ux;
		double wyy = spread.yy + dw * uy * uy;
		double wxy = spread.xy + dw * ux * uy;
		if (m.saturated > 0) {
			const double ns = static_cast<double>(m.saturated);
			const double clip_w = static_cast<double>(m.peak) -
					      static_cast<double>(m.level_min) + 1.0;
			const double mx = static_cast<double>(m.sat_x) / ns - b->u_px;
			const double my = static_cast<double>(m.sat_y) / ns - b->v_px;
			const double sx = static_cast<double>(m.sat_x);
			const double sy = static_cast<double>(m.sat_y);
			wxx -= clip_w *
			       ((static_cast<double>(m.sat_xx) - sx * sx / ns) + ns * mx * mx);
			wyy -= clip_w *
			       ((static_cast<double>(m.sat_yy) - sy * sy / ns) + ns * my * my);
			wxy -= clip_w *
			       ((static_cast<double>(m.sat_xy) - sx * sy / ns) + ns * mx * my);
		}
		const double c1 = level_over_background - 1.0;
		const double kg = noise_gain / (sw * sw);
		const double gxx = std::max(0.0, wxx + c1 * sxx);
		const double gyy = std::max(0.0, wyy + c1 * syy);
		/* (A sum of variances times an outer product: positive semi-definite.) */
		const double lim = std::sqrt(gxx * gyy);
		const double gxy = std::clamp(wxy + c1 * sxy, -lim, lim);
		b->cov_uu_px2 += kg * gxx;
		b->cov_vv_px2 += kg * gyy;
		b->cov_uv_px2 += kg * gxy;
	}

	/*
	 * Pixel locking, isotropic. For a disc of radius R the ring of one pixel
	 * at its edge holds 4 / R of sum (x - u)^2; the plateau's edge ring of
	 * radius R_s (from its pixel count) holds pi R_s^3 per axis.
	 */
	const double n_all = static_cast<double>(n_seg);
	if (n_all > 0.0) {
		const double radius = std::max(1.0, std::sqrt(n_all / std::numbers::pi));
		const double ring = 0.5 * (sxx + syy) * 4.0 / radius;
		double sys = kThresholdRingVar * ring;
		if (m.saturated > 0) {
			const double clip_w = static_cast<double>(m.peak) -
					      static_cast<double>(m.level_min) + 1.0;
			const double r_s =
				std::max(0.5, std::sqrt(static_cast<double>(m.saturated) /
							std::numbers::pi));
			sys += kPlateauEdgeFraction2 * clip_w * clip_w * std::numbers::pi * r_s *
			       r_s * r_s;
		}
		b->cov_uu_px2 += sys / (sw * sw);
		b->cov_vv_px2 += sys / (sw * sw);
	}
}

namespace {

/* a before b in the output: more weight, then top to bottom, then left to right. */
bool stronger(const Blob &a, const Blob &b)
{
	if (a.weight != b.weight)
		return a.weight > b.weight;
	if (a.v_px != b.v_px)
		return a.v_px < b.v_px;
	return a.u_px < b.u_px;
}

} /* namespace */

bool BlobDetector::detect(const ImageView &image, StaticVector<Blob, kMaxCandidates> *blobs,
			  BlobStats *stats)
{
	BlobStats local;
	BlobStats *st = stats ? stats : &local;
	*st = BlobStats{};
	reference_ = false;
	if (!blobs)
		return false;
	blobs->clear();

	if (!image.valid() || image.width > impl_->max_width || image.height > impl_->max_height) {
		st->threshold.valid = false;
		return false;
	}

	const ThresholdMap &map = thresholder_.compute(image, &st->threshold);
	if (!labelImpl(image, map)) {
		st->component_overflow = impl_->overflow;
		st->components = static_cast<int>(impl_->labels);
		return false;
	}
	st->components = static_cast<int>(impl_->components);
	dropped_.clear();
	collect(image, st, blobs, Look::First);
	/*
	 * On a steep background the cells' finer levels (Thresholder::cellMap())
	 * find spots below their tile's level: a second labelling at those
	 * levels, of which only the components none of whose pixels reached the
	 * tiles' levels are new (the others were found, or dropped, above; a
	 * flank that the cells' levels segment as one large component no longer
	 * swallows the spots on it).
	 */
	if (thresholder_.hasSteepTiles()) {
		const PixelWindow &w = thresholder_.steepBox();
		/*
		 * More components than the labelling holds, there only: the
		 * frame keeps the first look's blobs, without the second's.
		 */
		if (impl_->label(image, thresholder_.cellMap(), filter_.fill_gap_px,
				 filter_.clip_level, w)) {
			const std::size_t before =
				blobs->size() + static_cast<std::size_t>(st->dropped_capacity);
			collect(image, st, blobs, Look::BelowTiles, &w);
			st->below_tile_level =
				static_cast<int>(blobs->size() + st->dropped_capacity - before);
		} else {
			st->below_tile_overflow = true;
		}
	}
	/*
	 * A third look, at the clip level, in the box of each component that
	 * clipped but was dropped (too large, or not spot-shaped): an LED driven
	 * to clip and merged with a bright surrounding keeps a clipped core of its
	 * own. Cores that overlap a blob found already, or reach the box's side,
	 * are not new.
	 */
	for (const Dropped &d : dropped_)
		if (d.clipped &&
		    impl_->label(image, clip_map_, filter_.fill_gap_px, filter_.clip_level, d.box))
			collect(image, st, blobs, Look::Cores, &d.box);
	/*
	 * A fourth look in the same boxes: spots that do not clip, on a
	 * surrounding above their tile's level (lookForPeaks()).
	 */
	int peaks = 0;
	for (const Dropped &d : dropped_)
		lookForPeaks(image, d.box, st, blobs, &peaks);
	std::sort_heap(blobs->begin(), blobs->end(), stronger);
	reference_ = st->threshold.valid;
	reference_threshold_ = st->threshold;
	reference_width_ = image.width;
	reference_height_ = image.height;
	return true;
}

bool BlobDetector::detectWindows(const ImageView &image, const PixelWindow *windows,
				 std::size_t count, StaticVector<Blob, kMaxCandidates> *blobs,
				 BlobStats *stats)
{
	BlobStats local;
	BlobStats *st = stats ? stats : &local;
	*st = BlobStats{};
	if (!blobs)
		return false;
	blobs->clear();
	if (!reference_ || !image.valid() || image.width != reference_width_ ||
	    image.height != reference_height_)
		return false;
	st->threshold = reference_threshold_;

	const ThresholdMap &map = thresholder_.map();
	auto inside = [&image](const PixelWindow &w) {
		return w.x0 >= 0 && w.y0 >= 0 && w.x1 <= image.width && w.y1 <= image.height &&
		       w.x0 < w.x1 && w.y0 < w.y1;
	};
	for (std::size_t i = 0; i < count; ++i) {
		const PixelWindow &w = windows[i];
		if (!inside(w))
			return false;
		/* The next window's first rows follow this one's last into the cache. */
		const PixelWindow *next = i + 1 < count && inside(windows[i + 1]) ? &windows[i + 1]
										  : nullptr;
		if (!impl_->label(image, map, filter_.fill_gap_px, filter_.clip_level, w, next)) {
			st->component_overflow = impl_->overflow;
			return false;
		}
		const BlobMoments *comps = impl_->acc.data();
		for (std::size_t c = 0; c < impl_->components; ++c)
			if (cutByWindow(comps[c], w, image)) {
				st->window_cut = true;
				st->cut_reach = cutReach(comps[c], &w, image);
				return false;
			}
		st->components += static_cast<int>(impl_->components);
		collect(image, st, blobs, Look::Windows, &w);
		if (st->window_cut)
			return false;
	}
	std::sort_heap(blobs->begin(), blobs->end(), stronger);
	return true;
}

BlobDetector::Grow BlobDetector::grow(const ImageView &image, const BlobMoments &m, double noise,
				      const PixelWindow *window, BlobMoments *out)
{
	const int low = growContrast(noise);
	const int delta = thresholder_.contrast() - low;
	if (delta <= 0 || m.saturated > 0 || m.x_max - m.x_min + 1 > kGrowMaxBox ||
	    m.y_max - m.y_min + 1 > kGrowMaxBox)
		return Grow::Kept;
	const ThresholdMap &map = thresholder_.map();
	/* The grown spot stays inside [x0, x1) x [y0, y1): the margin, the frame, the window. */
	int x0 = std::max(0, m.x_min - kGrowMargin), y0 = std::max(0, m.y_min - kGrowMargin);
	int x1 = std::min(image.width, m.x_max + 1 + kGrowMargin);
	int y1 = std::min(image.height, m.y_max + 1 + kGrowMargin);
	/* A side of the search area that is the window's, not the margin's nor the frame's. */
	bool window_side[4] = { false, false, false, false };
	if (window) {
		window_side[0] = window->x0 > x0;
		window_side[1] = window->x1 < x1;
		window_side[2] = window->y0 > y0;
		window_side[3] = window->y1 < y1;
		x0 = std::max(x0, window->x0);
		x1 = std::min(x1, window->x1);
		y0 = std::max(y0, window->y0);
		y1 = std::min(y1, window->y1);
	}
	const int side_x = x1 - x0;
	const bool any_window_side = window_side[0] || window_side[1] || window_side[2] ||
				     window_side[3];
	/* A side of the search area that is the margin's (neither the frame's nor a window's). */
	const bool margin_side[4] = { x0 > 0 && !window_side[0],
				      x1 < image.width && !window_side[1],
				      y0 > 0 && !window_side[2],
				      y1 < image.height && !window_side[3] };
	auto margin_reached = [&](const bool reached[4]) {
		return (reached[0] && margin_side[0]) || (reached[1] && margin_side[1]) ||
		       (reached[2] && margin_side[2]) || (reached[3] && margin_side[3]);
	};
	/*
	 * Each pixel's low level, per tile row of the area: a tile row's levels
	 * written once, tile by tile, when the flood first reaches it.
	 */
	const bool tiled = map.cols() > 0;
	const int tile = tiled ? map.tilePx() : kMaxFrameSide;
	const int first_tile_row = tiled ? std::min(y0 / tile, map.rows() - 1) : 0;
	/* Per row of the area: its tile row, counted from the area's first. */
	std::array<int, kGrowSide> row_tile;
	for (int y = y0, r = first_tile_row; y < y1; ++y) {
		if (tiled && r < map.rows() - 1 && y >= (r + 1) * tile)
			++r;
		row_tile[static_cast<std::size_t>(y - y0)] = r - first_tile_row;
	}
	std::uint8_t *low_levels = impl_->grow_low.data(); /* kGrowSide per tile row */
	std::uint64_t low_written = 0; /* bit r: tile row r's low levels written */
	auto low_row = [&](int y) {
		const int r = row_tile[static_cast<std::size_t>(y - y0)];
		std::uint8_t *lows = low_levels + static_cast<std::size_t>(r) * kGrowSide;
		if (low_written >> r & 1U)
			return lows;
		low_written |= std::uint64_t{ 1 } << r;
		auto low_of = [&](int level) {
			return static_cast<std::uint8_t>(std::max(0, level - delta));
		};
		if (!tiled) {
			std::memset(lows, low_of(map.levelAt(0, 0)),
				    static_cast<std::size_t>(side_x));
			return lows;
		}
		const std::uint8_t *levels = map.rowLevels(first_tile_row + r);
		for (int c = std::min(x0 / tile, map.cols() - 1), xa = x0; xa < x1; ++c) {
			const int xb = c == map.cols() - 1 ? x1 : std::min(x1, (c + 1) * tile);
			std::memset(lows + (xa - x0), low_of(levels[c]),
				    static_cast<std::size_t>(xb - xa));
			xa = xb;
		}
		return lows;
	};
	/*
	 * Per row of the area (at most kGrowSide wide: one bit per column), its
	 * pixels at or above the low level, computed when the flood first reads
	 * the row (16 at a time), and those the flood has taken.
	 */
	std::array<std::uint64_t, kGrowSide> above;
	std::array<std::uint64_t, kGrowSide> taken;
	std::fill_n(taken.begin(), y1 - y0, std::uint64_t{ 0 });
	std::uint64_t above_read = 0; /* bit y - y0: that row's `above` computed */
	auto above_low = [&](int y) {
		const auto i = static_cast<std::size_t>(y - y0);
		if (above_read >> i & 1U)
			return above[i];
		const std::uint8_t *row = image.row(y) + x0;
		const std::uint8_t *lows = low_row(y);
		auto bits16 = [&](int d) {
			return std::uint64_t{ atLeastMask(load16(row + d), load16(lows + d)) } << d;
		};
		std::uint64_t bits = 0;
		int d = 0;
		for (; d + 16 <= side_x; d += 16)
			bits |= bits16(d);
		if (d < side_x && side_x >= 16) /* the last 16, overlapping those read */
			bits |= bits16(side_x - 16);
		else
			for (; d < side_x; ++d)
				bits |= std::uint64_t{ row[d] >= lows[d] } << d;
		above[i] = bits;
		above_read |= std::uint64_t{ 1 } << i;
		return bits;
	};

	/* The seed: the component's peak pixel (the first at its value, at or above its level). */
	int seed_x = -1, seed_y = -1;
	for (int y = m.y_min; y <= m.y_max && seed_x < 0; ++y) {
		const std::uint8_t *row = image.row(y);
		for (int x = m.x_min; x <= m.x_max; ++x)
			if (row[x] == m.peak && row[x] >= map.levelAt(x, y)) {
				seed_x = x;
				seed_y = y;
				break;
			}
	}
	if (seed_x < 0)
		return Grow::Kept;

	/*
	 * A span fill: each row's run of pixels at or above the low level is
	 * taken whole, and the runs of the rows above and below that touch it
	 * (8-connected: one pixel beyond each end) are seeded, a row's pixels
	 * compared with their levels once, 16 at a time, into a bit per pixel.
	 */
	std::uint32_t *stack = impl_->grow_stack.data();
	const std::size_t stack_capacity = impl_->grow_stack.size();
	std::size_t top = 0;
	auto push = [&](int x, int y) {
		stack[top++] = static_cast<std::uint32_t>(x) | static_cast<std::uint32_t>(y) << 16;
	};
	push(seed_x, seed_y);

	BlobMoments g;
	g.x_min = g.y_min = 0xffff;
	bool edge[4] = { false, false, false, false }; /* reached x0, x1 - 1, y0, y1 - 1 */
	while (top > 0) {
		const std::uint32_t p = stack[--top];
		const int sx = static_cast<int>(p & 0xffff), y = static_cast<int>(p >> 16);
		const auto yi = static_cast<std::size_t>(y - y0);
		const int b = sx - x0;
		if (taken[yi] >> b & 1U)
			continue;
		/* The run through the seed (at or above the low level; none of it taken yet). */
		const std::uint64_t bits = above_low(y);
		const int xr = sx + std::countr_one(bits >> b) - 1;
		const int xl = sx - std::countl_one(bits << (63 - b)) + 1;
		const int run_px = xr - xl + 1;
		taken[yi] |=
			(run_px == 64 ? ~std::uint64_t{ 0 } : ((std::uint64_t{ 1 } << run_px) - 1U))
			<< (xl - x0);
		/*
		 * The run's sums about its first pixel in 32 bits (a run is at most
		 * kGrowSide long: w dx^2 <= 256 * 63^2 per pixel), moved to the frame's
		 * origin once per run: the same integers as summing x, x^2 per pixel.
		 */
		const std::uint8_t *row = image.row(y) + xl;
		const std::uint8_t *lows = low_row(y) + (xl - x0);
		std::uint32_t rw = 0, rwd = 0, rwdd = 0, rt = 0, rtd = 0;
		std::uint8_t rpeak = 0;
		std::uint8_t rlmin = 255;
		for (int di = 0; di < run_px; ++di) {
			const auto d = static_cast<std::uint32_t>(di);
			const std::uint8_t v = row[di];
			const std::uint8_t t = lows[di];
			const std::uint32_t w = std::uint32_t{ v } + 1U - t;
			rw += w;
			rwd += w * d;
			rwdd += w * d * d;
			rt += t;
			rtd += std::uint32_t{ t } * d;
			rpeak = std::max(rpeak, v);
			rlmin = std::min(rlmin, t);
		}
		const auto n64 = static_cast<std::uint64_t>(run_px);
		const std::uint64_t ux = static_cast<std::uint64_t>(xl),
				    uy = static_cast<std::uint64_t>(y);
		/* sum w x = xl sum w + sum w d; sum w x^2 = xl^2 sum w + 2 xl sum w d + sum w d^2 */
		const std::uint64_t swx = ux * rw + rwd;
		g.sum_w += rw;
		g.sum_wx += swx;
		g.sum_wy += uy * rw;
		g.sum_wxx += ux * ux * rw + 2U * ux * rwd + rwdd;
		g.sum_wyy += uy * uy * rw;
		g.sum_wxy += uy * swx;
		/* sum d = n (n - 1) / 2, sum d^2 = (n - 1) n (2n - 1) / 6 over d = 0 .. n - 1 */
		const std::uint64_t sd = n64 * (n64 - 1U) / 2U;
		const std::uint64_t sdd = (n64 - 1U) * n64 * (2U * n64 - 1U) / 6U;
		const std::uint64_t run_x = ux * n64 + sd;
		g.sum_x += run_x;
		g.sum_y += uy * n64;
		g.sum_xx += ux * ux * n64 + 2U * ux * sd + sdd;
		g.sum_yy += uy * uy * n64;
		g.sum_xy += uy * run_x;
		g.sum_t += rt;
		g.sum_tx += ux * rt + rtd;
		g.sum_ty += uy * rt;
		g.level_min = std::min(g.level_min, rlmin);
		g.peak = std::max(g.peak, rpeak);
		const auto n = static_cast<std::uint32_t>(run_px);
		g.area += n;
		g.noisy += n;
		g.x_min = std::min<std::uint16_t>(g.x_min, static_cast<std::uint16_t>(xl));
		g.x_max = std::max<std::uint16_t>(g.x_max, static_cast<std::uint16_t>(xr));
		g.y_min = std::min<std::uint16_t>(g.y_min, static_cast<std::uint16_t>(y));
		g.y_max = std::max<std::uint16_t>(g.y_max, static_cast<std::uint16_t>(y));
		edge[0] = edge[0] || xl == x0;
		edge[1] = edge[1] || xr == x1 - 1;
		edge[2] = edge[2] || y == y0;
		edge[3] = edge[3] || y == y1 - 1;
		/*
		 * A margin reached where no window side can be (a spot on a brighter
		 * surrounding): kept as it was, whatever else the flood would reach,
		 * so the flood stops (a sunlit patch's spots would flood their whole
		 * area first).
		 */
		if (!any_window_side && margin_reached(edge))
			return Grow::Kept;
		/*
		 * Seed each run of the rows above and below that touches this one:
		 * the first pixel of each run of untaken pixels at or above the low
		 * level in [xl - 1, xr + 1], left to right.
		 */
		const int lo = std::max(0, xl - 1 - x0), hi = std::min(side_x - 1, xr + 1 - x0);
		const std::uint64_t span = (~std::uint64_t{ 0 } >> (63 - hi)) &
					   (~std::uint64_t{ 0 } << lo);
		for (int ny = y - 1; ny <= y + 1; ny += 2) {
			if (ny < y0 || ny >= y1)
				continue;
			const std::uint64_t open = above_low(ny) &
						   ~taken[static_cast<std::size_t>(ny - y0)] & span;
			for (std::uint64_t starts = open & ~(open << 1); starts != 0;
			     starts &= starts - 1) {
				/*
				 * Seeds: a few per run at most (its rows' neighbouring
				 * runs), the stack four per pixel of the area; a pattern
				 * that would need more keeps the component's measurement.
				 */
				if (top == stack_capacity)
					return Grow::Kept;
				push(x0 + std::countr_zero(starts), ny);
			}
		}
	}
	/* A window's side reached inside the frame: the spot may go on beyond it. */
	for (int i = 0; i < 4; ++i)
		if (edge[i] && window_side[i])
			return Grow::Cut;
	/*
	 * Kept as it was: a spot that reaches its margin (it stands on a
	 * brighter surrounding, not on the background), or that does not hold
	 * the whole component (its gaps filled by the labeller fall below the
	 * low level). One that holds other components at the detecting level
	 * is one spot the noise broke up at that level (a blurred streak):
	 * each of them grows into the same spot, which collect() keeps once.
	 */
	if (margin_reached(edge) || g.x_min > m.x_min || g.x_max < m.x_max || g.y_min > m.y_min ||
	    g.y_max < m.y_max)
		return Grow::Kept;
	*out = g;
	return Grow::Grown;
}

/*
 * The background's slope under a spot tilts its weights w = v - T + 1: with
 * B = B(u) + g . (p - u), the centroid moves by M g / W, M the unweighted
 * second moments of its segmented pixels about the centroid, W its weight.
 * Small for a sharp spot; ~0.02 px for a halo of 15 px radius on a gradient
 * of 0.007 levels/px. The slope comes from the tile backgrounds around the
 * spot (Thresholder::backgroundSlope); its uncertainty is added to the
 * covariance. Spots for which no plausible slope matters are left alone.
 */
void BlobDetector::correctBackgroundSlope(const BlobMoments &m, Blob *b) const
{
	const SpotMoments s = spotMoments(m, b->u_px, b->v_px);
	/* A slope of 0.05 levels/px (70 levels across a 1456 px frame) moves it by less than 0.002 px. */
	if (!(s.w > 0.0) || (s.mxx + s.myy) / s.w < 0.04)
		return;
	double gx = 0.0, gy = 0.0, sg = 0.0;
	if (!thresholder_.backgroundSlope(b->u_px, b->v_px, &gx, &gy, &sg))
		return;
	b->u_px -= (s.mxx * gx + s.mxy * gy) / s.w;
	b->v_px -= (s.mxy * gx + s.myy * gy) / s.w;
	addSlopeVariance(s, sg, b);
}

BlobDetector::SpotMoments BlobDetector::spotMoments(const BlobMoments &m, double u, double v)
{
	SpotMoments s;
	const std::uint64_t n_seg = std::uint64_t{ m.noisy } + m.saturated;
	const double w =
		static_cast<double>(m.sum_w + m.sum_t - std::uint64_t{ m.level_min } * n_seg);
	if (n_seg == 0 || !(w > 0.0))
		return s;
	const double n = static_cast<double>(n_seg);
	const double sx = static_cast<double>(m.sum_x + m.sat_x),
		     sy = static_cast<double>(m.sum_y + m.sat_y);
	s.w = w;
	s.mxx = static_cast<double>(m.sum_xx + m.sat_xx) - 2.0 * u * sx + n * u * u;
	s.myy = static_cast<double>(m.sum_yy + m.sat_yy) - 2.0 * v * sy + n * v * v;
	s.mxy = static_cast<double>(m.sum_xy + m.sat_xy) - u * sy - v * sx + n * u * v;
	return s;
}

void BlobDetector::addSlopeVariance(const SpotMoments &s, double sigma_slope, Blob *b)
{
	if (!(s.w > 0.0))
		return;
	const double k = sigma_slope * sigma_slope / (s.w * s.w);
	b->cov_uu_px2 += k * (s.mxx * s.mxx + s.mxy * s.mxy);
	b->cov_vv_px2 += k * (s.mxy * s.mxy + s.myy * s.myy);
	b->cov_uv_px2 += k * (s.mxx * s.mxy + s.mxy * s.myy);
}

/*
 * Are a component's clipped pixels, taken alone, shaped like a spot (or a
 * few: LEDs whose blooms merged) rather than a streak: their second moments
 * within the filter's max_elongation? A glint's clipped line, broken by the
 * noise into specks, is not. Allocates: never.
 */
bool BlobDetector::clippedLikeASpot(const BlobMoments &m) const
{
	if (m.saturated == 0)
		return false;
	const double n = static_cast<double>(m.saturated);
	const double mx = static_cast<double>(m.sat_x) / n, my = static_cast<double>(m.sat_y) / n;
	const double vxx = static_cast<double>(m.sat_xx) / n - mx * mx + 1.0 / 12.0;
	const double vyy = static_cast<double>(m.sat_yy) / n - my * my + 1.0 / 12.0;
	const double vxy = static_cast<double>(m.sat_xy) / n - mx * my;
	const double mean = 0.5 * (vxx + vyy);
	const double root = std::sqrt(0.25 * (vxx - vyy) * (vxx - vyy) + vxy * vxy);
	const double minor = std::max(mean - root, 1.0 / 12.0 * 1e-6);
	return (mean + root) <= filter_.max_elongation * filter_.max_elongation * minor;
}

/*
 * Is a component labelled at the clip level a plateau, not noise: does it
 * hold a pixel whose 3 x 3 neighbourhood clips whole? An LED driven beyond
 * the clip level clips solidly; where a surrounding's brightest part only
 * reaches the clip level, the noise clips a scatter of specks, and a 3 x 3
 * block of them is rare. Allocates: never.
 */
bool BlobDetector::solidCore(const ImageView &image, const BlobMoments &m) const
{
	const int clip = filter_.clip_level;
	for (int y = m.y_min + 1; y < m.y_max; ++y)
		for (int x = m.x_min + 1; x < m.x_max; ++x) {
			bool solid = true;
			for (int dy = -1; dy <= 1 && solid; ++dy)
				for (int dx = -1; dx <= 1 && solid; ++dx)
					solid = image.at(x + dx, y + dy) >= clip;
			if (solid)
				return true;
		}
	return false;
}

namespace {

/* The ring round a peak (BlobDetector::peakAt()): kPeakRing offsets, evenly round, radius kPeakRingPx. */
constexpr std::size_t kPeakRing = 16;
const std::array<std::array<int, 2>, kPeakRing> &peakRing()
{
	static const auto ring = [] {
		std::array<std::array<int, 2>, kPeakRing> o{};
		for (std::size_t k = 0; k < kPeakRing; ++k) {
			const double a = 2.0 * std::numbers::pi * static_cast<double>(k) /
					 static_cast<double>(kPeakRing);
			o[k] = { static_cast<int>(std::lround(kPeakRingPx * std::cos(a))),
				 static_cast<int>(std::lround(kPeakRingPx * std::sin(a))) };
		}
		return o;
	}();
	return ring;
}

} /* namespace */

/*
 * Inside `box` (a dropped component's), every local maximum that does not
 * clip and stands the contrast above the median of a ring of radius
 * kPeakRingPx round it, where the ring departs from its plane (its median,
 * and the slopes of its opposite samples) by no more than the contrast: the
 * plane plus the contrast is the level, pixel by pixel, of a labelling of
 * the square window that the ring bounds (peakAt()); the
 * component holding the maximum is a new blob when it passes the filter,
 * stays inside the window and overlaps no blob found already. At most
 * kMaxInnerPeaks labellings per frame (*peaks counts them). Allocates: never.
 */
void BlobDetector::lookForPeaks(const ImageView &image, const PixelWindow &box, BlobStats *st,
				StaticVector<Blob, kMaxCandidates> *blobs, int *peaks)
{
	constexpr int kR = kPeakRingPx;
	constexpr int kPeakScan = 64;
	/* The highest unclipped level (clip_level 1..256). */
	const auto top = static_cast<std::uint8_t>(filter_.clip_level - 1);
	const int x0 = std::max(box.x0, kR), x1 = std::min(box.x1, image.width - kR);
	const int y0 = std::max(box.y0, kR), y1 = std::min(box.y1, image.height - kR);
	const ThresholdMap &tiles = thresholder_.map();
	const int tile = tiles.tilePx();
	for (int y = y0; y < y1; ++y) {
		const std::uint8_t *up = image.row(y - 1), *row = image.row(y),
				   *down = image.row(y + 1);
		for (int x = x0; x < x1;) {
			/* Tile by tile along the row, so the level is looked up once per tile. */
			const int end = std::min(x1, (x / tile + 1) * tile);
			const auto level = static_cast<std::uint8_t>(tiles.levelAt(x, y));
			/*
			 * Only where the first look segmented (the dropped
			 * component's pixels are there); a maximum: above the
			 * neighbours before it in scan order, not below those after.
			 * Marked branch-free 64 pixels at a time (the compiler
			 * vectorises it: a sunlit patch's box holds ~10^5 pixels),
			 * then visited in order.
			 */
			for (int n = 0; x < end; x += n) {
				n = std::min(kPeakScan, end - x);
				std::array<std::uint8_t, kPeakScan> mark{};
				for (int k = 0; k < n; ++k) {
					const int c = x + k;
					const std::uint8_t v = row[c];
					mark[static_cast<std::size_t>(k)] =
						static_cast<std::uint8_t>(
							(v >= level) & (v <= top) &
							(v > row[c - 1]) & (v > up[c - 1]) &
							(v > up[c]) & (v > up[c + 1]) &
							(v >= row[c + 1]) & (v >= down[c - 1]) &
							(v >= down[c]) & (v >= down[c + 1]));
				}
				for (int k = 0; k < n; ++k) {
					if (!mark[static_cast<std::size_t>(k)])
						continue;
					peakAt(image, x + k, y, row[x + k], st, blobs, peaks);
					if (*peaks >= static_cast<int>(kMaxInnerPeaks))
						return;
				}
			}
		}
	}
}

/*
 * lookForPeaks()'s test and labelling of one local maximum v at (x, y), at
 * least kPeakRingPx inside the frame. Allocates: never.
 */
void BlobDetector::peakAt(const ImageView &image, int x, int y, int v, BlobStats *st,
			  StaticVector<Blob, kMaxCandidates> *blobs, int *peaks)
{
	constexpr int kR = kPeakRingPx;
	constexpr std::size_t kRing = kPeakRing;
	const auto &ring = peakRing();
	const int contrast = thresholder_.contrast();
	/*
	 * The test below, v >= median(ring) + contrast, holds exactly when more
	 * than kRing / 2 samples lie at or below v - contrast: counted first, so
	 * that the noise's many local maxima on a bright patch cost no sort.
	 */
	std::array<int, kRing> s{};
	std::size_t at_or_below = 0;
	for (std::size_t k = 0; k < kRing; ++k) {
		s[k] = image.at(x + ring[k][0], y + ring[k][1]);
		at_or_below += s[k] <= v - contrast ? 1U : 0U;
	}
	if (at_or_below <= kRing / 2)
		return;
	std::array<int, kRing> sorted = s;
	std::nth_element(sorted.begin(), sorted.begin() + kRing / 2, sorted.end());
	const int base = sorted[kRing / 2];
	if (v < base + contrast)
		return;
	/* The slopes: s_k - s_(k+8) = 2 (gx dx_k + gy dy_k), least squares over the 8 pairs. */
	double sxx = 0.0, syy = 0.0, sxy = 0.0, bx = 0.0, by = 0.0;
	for (std::size_t k = 0; k < kRing / 2; ++k) {
		const double dx = ring[k][0], dy = ring[k][1];
		const double d = 0.5 * (s[k] - s[k + kRing / 2]);
		sxx += dx * dx;
		syy += dy * dy;
		sxy += dx * dy;
		bx += dx * d;
		by += dy * d;
	}
	const double det = sxx * syy - sxy * sxy;
	const double gx = (syy * bx - sxy * by) / det;
	const double gy = (sxx * by - sxy * bx) / det;
	/* The ring's rms departure from the plane, at least the noise's. */
	double misfit2 = 0.0;
	for (std::size_t k = 0; k < kRing; ++k) {
		const double e = s[k] - (base + gx * ring[k][0] + gy * ring[k][1]);
		misfit2 += e * e;
	}
	peak_misfit_ = std::max(std::sqrt(misfit2 / kRing), st->threshold.noise_sigma);
	/*
	 * The plane is the peak's background only where the ring lies on
	 * one smooth surface: departing from it by more than the
	 * contrast, the ring straddles an edge (a patch's side, another
	 * spot), where the peak is not a spot's.
	 */
	if (peak_misfit_ > contrast)
		return;
	if (*peaks >= static_cast<int>(kMaxInnerPeaks))
		return;
	++*peaks;
	const PixelWindow w{ x - kR, y - kR, x + kR + 1, y + kR + 1 };
	for (int py = w.y0; py < w.y1; ++py)
		for (int px = w.x0; px < w.x1; ++px) {
			const double level = base + gx * (px - x) + gy * (py - y) + contrast;
			peak_map_.setLevel(px, py,
					   static_cast<std::uint8_t>(
						   std::clamp(std::lround(level), 1L, 255L)));
		}
	peak_x_ = x;
	peak_y_ = y;
	if (impl_->label(image, peak_map_, filter_.fill_gap_px, filter_.clip_level, w))
		collect(image, st, blobs, Look::Peaks, &w);
}

/* Does a component's box overlap the box of one of `blobs`? Allocates: never. */
bool BlobDetector::overlapsBlob(const BlobMoments &m,
				const StaticVector<Blob, kMaxCandidates> &blobs)
{
	for (const Blob &b : blobs)
		if (m.x_min <= b.x_max && b.x_min <= m.x_max && m.y_min <= b.y_max &&
		    b.y_min <= m.y_max)
			return true;
	return false;
}

/*
 * BlobStats::cut_reach of a component: grow()'s search box around it, and
 * where `window` (when the labelling cut it, not grow()) has a side through
 * it, as far again as the largest spot grow() measures. Allocates: never.
 */
PixelWindow BlobDetector::cutReach(const BlobMoments &m, const PixelWindow *window,
				   const ImageView &image)
{
	auto beyond = [](bool side_cut) {
		return kGrowMargin + (side_cut ? kGrowMaxBox : 0);
	};
	const bool cut_x0 = window && m.x_min == window->x0;
	const bool cut_x1 = window && m.x_max + 1 == window->x1;
	const bool cut_y0 = window && m.y_min == window->y0;
	const bool cut_y1 = window && m.y_max + 1 == window->y1;
	return PixelWindow{ std::max(0, m.x_min - beyond(cut_x0)),
			    std::max(0, m.y_min - beyond(cut_y0)),
			    std::min(image.width, m.x_max + 1 + beyond(cut_x1)),
			    std::min(image.height, m.y_max + 1 + beyond(cut_y1)) };
}

/*
 * Does a component touch a side of `window` that lies inside the frame (so
 * that it may go on beyond the window)? Allocates: never.
 */
bool BlobDetector::cutByWindow(const BlobMoments &m, const PixelWindow &window,
			       const ImageView &image)
{
	return (window.x0 > 0 && m.x_min == window.x0) ||
	       (window.x1 < image.width && m.x_max + 1 == window.x1) ||
	       (window.y0 > 0 && m.y_min == window.y0) ||
	       (window.y1 < image.height && m.y_max + 1 == window.y1);
}

/*
 * Does a component stand out of its own surroundings: its peak at least
 * `contrast` above the median of a ring 2 px outside its box (up to 64
 * samples spread round it)? A spot does; where a bright background bulges
 * above the interpolation of the tile backgrounds, its noise does not.
 * Allocates: never.
 */
bool BlobDetector::standsOut(const ImageView &image, const BlobMoments &m, int contrast)
{
	constexpr int kGap = 2;
	constexpr int kSamples = 64;
	const int x0 = std::max(m.x_min - kGap, 0), x1 = std::min(m.x_max + kGap, image.width - 1);
	const int y0 = std::max(m.y_min - kGap, 0), y1 = std::min(m.y_max + kGap, image.height - 1);
	const int w = x1 - x0, h = y1 - y0;
	const int perimeter = 2 * (w + h);
	if (w < 1 || h < 1)
		return false;
	const int step = (perimeter + kSamples - 1) / kSamples;
	std::array<std::uint8_t, kSamples> ring{};
	std::size_t n = 0;
	for (int k = 0; k < perimeter && n < ring.size(); k += step) {
		int x = 0, y = 0;
		if (k < w) {
			x = x0 + k;
			y = y0;
		} else if (k < w + h) {
			x = x1;
			y = y0 + (k - w);
		} else if (k < 2 * w + h) {
			x = x1 - (k - w - h);
			y = y1;
		} else {
			x = x0;
			y = y1 - (k - 2 * w - h);
		}
		ring[n++] = image.at(x, y);
	}
	const auto mid = ring.begin() + static_cast<std::ptrdiff_t>(n / 2);
	std::nth_element(ring.begin(), mid, ring.begin() + static_cast<std::ptrdiff_t>(n));
	return static_cast<int>(m.peak) >= static_cast<int>(*mid) + contrast;
}

/* Filter and measure the components of the last labelling into the heap `blobs`. */
void BlobDetector::collect(const ImageView &image, BlobStats *st,
			   StaticVector<Blob, kMaxCandidates> *blobs, Look look,
			   const PixelWindow *window)
{
	const ThresholdMap *below = look == Look::BelowTiles ? &thresholder_.map() : nullptr;
	/* The lowest level of `below` over the tiles a component's box touches. */
	auto lowest = [below](const BlobMoments &m) {
		const int tile = below->tilePx();
		const int c0 = std::min<int>(m.x_min / tile, below->cols() - 1),
			  c1 = std::min<int>(m.x_max / tile, below->cols() - 1);
		const int r0 = std::min<int>(m.y_min / tile, below->rows() - 1),
			  r1 = std::min<int>(m.y_max / tile, below->rows() - 1);
		int level = 255;
		for (int r = r0; r <= r1; ++r)
			for (int c = c0; c <= c1; ++c)
				level = std::min<int>(level, below->level(c, r));
		return level;
	};
	const std::int64_t frame_px = static_cast<std::int64_t>(image.width) * image.height;
	const std::int64_t max_area = filter_.max_area_px > 0
					      ? filter_.max_area_px
					      : std::max<std::int64_t>(1, frame_px / 200);
	const std::int64_t min_area = filter_.min_area_px;

	const double noise = st->threshold.noise_sigma;
	const double gain = st->threshold.noise_gain;
	/* The spots grown so far: one that several components grow into is kept once. */
	struct GrownKey {
		std::uint32_t area;
		std::uint64_t sum_w;
		std::uint16_t x_min, y_min;
	};
	StaticVector<GrownKey, 2 * kMaxCandidates> grown_keys;
	/* Keep the strongest kMaxCandidates in a heap whose top is the weakest. */
	const BlobMoments *comps = impl_->acc.data();
	const std::size_t n = impl_->components;
	for (std::size_t i = 0; i < n; ++i) {
		const BlobMoments &m = comps[i];
		if (below && (below->cols() == 0 || m.peak >= lowest(m) ||
			      (window && cutByWindow(m, *window, image)) ||
			      !standsOut(image, m, thresholder_.contrast())))
			continue;
		if (look == Look::Cores && ((window && cutByWindow(m, *window, image)) ||
					    overlapsBlob(m, *blobs) || !solidCore(image, m)))
			continue;
		if (look == Look::Peaks &&
		    (!window || cutByWindow(m, *window, image) || m.x_min > peak_x_ ||
		     m.x_max < peak_x_ || m.y_min > peak_y_ || m.y_max < peak_y_ ||
		     overlapsBlob(m, *blobs)))
			continue;
		/*
		 * A component that the filter drops may hold an LED merged with a
		 * bright surrounding (a sunlit patch, a reflection, another LED's
		 * bloom): its box is looked at again, for clipped cores of their own
		 * where it clipped, and for peaks that stand out of the
		 * surrounding's own level.
		 */
		auto merged = [&] {
			if (look == Look::First && !dropped_.full())
				dropped_.push_back(Dropped{
					PixelWindow{ m.x_min, m.y_min, m.x_max + 1, m.y_max + 1 },
					m.saturated > 0 && m.saturated < m.area &&
						clippedLikeASpot(m) });
		};
		if (static_cast<std::int64_t>(m.area) < min_area) {
			++st->dropped_small;
			continue;
		}
		if (static_cast<std::int64_t>(m.area) > max_area) {
			++st->dropped_large;
			merged();
			continue;
		}
		/* The spot's measurement reaches below the detecting level (grow()). */
		BlobMoments grown;
		const BlobMoments *spot = &m;
		if (look == Look::First || look == Look::Windows) {
			const Grow g = grow(image, m, noise,
					    look == Look::Windows ? window : nullptr, &grown);
			if (g == Grow::Cut) {
				st->window_cut = true;
				st->cut_reach = cutReach(m, nullptr, image);
				return;
			}
			if (g == Grow::Grown) {
				const GrownKey key{ grown.area, grown.sum_w, grown.x_min,
						    grown.y_min };
				const bool seen = std::any_of(grown_keys.begin(), grown_keys.end(),
							      [&](const GrownKey &k) {
								      return k.area == key.area &&
									     k.sum_w == key.sum_w &&
									     k.x_min == key.x_min &&
									     k.y_min == key.y_min;
							      });
				if (seen)
					continue;
				if (!grown_keys.full()) {
					grown_keys.push_back(key);
					spot = &grown;
				}
			}
		}
		const BlobMoments &ms = *spot;
		Blob b = measure(ms, noise, gain,
				 spot == &grown ? growContrast(noise) : thresholder_.contrast());
		if (look == Look::Cores) {
			/*
			 * The core's centroid is its clipped plateau's; a brighter
			 * surrounding on one side (what merged it) pushes the plateau's
			 * edge out there. One pixel along half the edge of a disc moves
			 * its centroid by 4 / pi^2 px, whatever its radius: that, per axis.
			 */
			constexpr double kHalfEdgeShift =
				4.0 / (std::numbers::pi * std::numbers::pi);
			b.cov_uu_px2 += kHalfEdgeShift * kHalfEdgeShift;
			b.cov_vv_px2 += kHalfEdgeShift * kHalfEdgeShift;
		} else if (look == Look::Peaks) {
			/*
			 * The level followed a plane through the ring round the peak;
			 * where the surrounding bends, the background under the spot
			 * may depart from the plane by as much as the ring does, across
			 * the spot's own rms radius: a slope that tilts the weights
			 * (correctBackgroundSlope()).
			 */
			const SpotMoments sm = spotMoments(ms, b.u_px, b.v_px);
			const double n_px = static_cast<double>(ms.noisy) + ms.saturated;
			const double rms_radius =
				std::sqrt((sm.mxx + sm.myy) / std::max(n_px, 1.0));
			addSlopeVariance(sm, peak_misfit_ / std::max(rms_radius, 0.5), &b);
		} else if (b.cov_uu_px2 > 0.0) {
			correctBackgroundSlope(ms, &b);
		}
		/* (Its model's background is the tiles'; a peak's is the plane round it.) */
		if (b.cov_uu_px2 > 0.0 && m.saturated == 0 && look != Look::Peaks)
			fitSmallSpot(image, std::max(noise * noise, kQuantisationVar), gain, &b);
		/*
		 * A spot cut by the frame's edge lost an unknown part: its centroid
		 * may be off by up to half its visible extent along that axis.
		 */
		if (b.cov_uu_px2 > 0.0 && (ms.x_min == 0 || ms.x_max == image.width - 1)) {
			const double half = 0.5 * (ms.x_max - ms.x_min + 1);
			b.cov_uu_px2 += half * half;
		}
		if (b.cov_vv_px2 > 0.0 && (ms.y_min == 0 || ms.y_max == image.height - 1)) {
			const double half = 0.5 * (ms.y_max - ms.y_min + 1);
			b.cov_vv_px2 += half * half;
		}
		if (b.elongation > filter_.max_elongation || b.fill < filter_.min_fill) {
			++st->dropped_shape;
			merged();
			continue;
		}
		st->clipped_cores += look == Look::Cores ? 1 : 0;
		st->inner_peaks += look == Look::Peaks ? 1 : 0;
		if (!blobs->full()) {
			blobs->push_back(b);
			std::push_heap(blobs->begin(), blobs->end(), stronger);
		} else {
			++st->dropped_capacity;
			if (stronger(b, *blobs->begin())) {
				std::pop_heap(blobs->begin(), blobs->end(), stronger);
				blobs->back() = b;
				std::push_heap(blobs->begin(), blobs->end(), stronger);
			}
		}
	}
}

} /* namespace dockpose */

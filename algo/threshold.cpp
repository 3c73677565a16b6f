/* SPDX-License-Identifier: MIT */
/*
 * Fixed and automatic segmentation levels, see threshold.h.
 */
#include "algo/threshold.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <numbers>

namespace dockpose {

namespace {

/*
 * The guarded background of tile (c, r) in a grid `cols` wide, padded by one
 * tile of extrapolation on every side (c in [-1, cols], r in [-1, rows]): its
 * index in Thresholder::padded_.
 */
std::size_t paddedIndex(int cols, int c, int r)
{
	return static_cast<std::size_t>(r + 1) * static_cast<std::size_t>(cols + 2) +
	       static_cast<std::size_t>(c + 1);
}

/* 1.4826 / sqrt(2): from the MAD of a difference of two pixels to one pixel's sigma. */
constexpr UQ16_16 kMadToSigma{ 1.4826 * 0.70710678118654752440 };

/*
 * The threshold's cells: a quarter of a tile where that divides it, else a
 * half, else the tile itself (each tile holds whole cells, and the cells
 * cover the frame as the tiles do).
 */
int cellPx(int tile)
{
	return tile % 4 == 0 ? tile / 4 : tile % 2 == 0 ? tile / 2 : tile;
}

int clampInt(int v, int lo, int hi)
{
	return v < lo ? lo : (v > hi ? hi : v);
}

/* Number of tiles of `tile` pixels covering `size` pixels. */
int tilesFor(int size, int tile)
{
	return (size + tile - 1) / tile;
}

/*
 * Sample positions in one tile [a, a + length): n = ceil(length / step)
 * positions `step` apart, centred in the tile.
 */
void samplePositions(int a, int length, int step, int *start, int *count)
{
	const int n = (length + step - 1) / step;
	*count = n;
	*start = a + (length - 1 - (n - 1) * step) / 2;
}

} /* namespace */

ThresholdMap::ThresholdMap(int width, int height, int tile_px, std::uint8_t level)
{
	tile_px_ = clampInt(tile_px, 1, kMaxFrameSide);
	cols_ = std::max(1, tilesFor(std::max(width, 1), tile_px_));
	rows_ = std::max(1, tilesFor(std::max(height, 1), tile_px_));
	levels_.assign(static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_), level);
}

ThresholdMap ThresholdMap::uniform(std::uint8_t level)
{
	ThresholdMap map(1, 1, kMaxFrameSide, level);
	return map;
}

void ThresholdMap::setUniform(std::uint8_t level)
{
	if (levels_.empty()) {
		/* no storage: the map stays without tiles and reads `level` everywhere */
		empty_level_ = level;
		return;
	}
	tile_px_ = kMaxFrameSide;
	cols_ = 1;
	rows_ = 1;
	levels_[0] = level;
}

bool ThresholdMap::reshape(int width, int height, int tile_px)
{
	if (width < 1 || height < 1 || tile_px < 1)
		return false;
	const int cols = tilesFor(width, tile_px);
	const int rows = tilesFor(height, tile_px);
	if (static_cast<std::size_t>(cols) * static_cast<std::size_t>(rows) > levels_.size())
		return false;
	tile_px_ = tile_px;
	cols_ = cols;
	rows_ = rows;
	return true;
}

void ThresholdMap::fill(std::uint8_t level)
{
	std::fill(levels_.begin(), levels_.begin() + static_cast<std::ptrdiff_t>(cols_) * rows_,
		  level);
}

Thresholder::Thresholder(int max_width, int max_height, const ThresholdConfig &config)
	: config_(config)
{
	max_width_ = clampInt(max_width, 1, kMaxFrameSide);
	max_height_ = clampInt(max_height, 1, kMaxFrameSide);

	config_.fixed_level = clampInt(config.fixed_level, 0, 255);
	config_.min_contrast = clampInt(config.min_contrast, 0, 255);
	config_.k_sigma = std::clamp(config.k_sigma, 0.0, 255.0);
	if (!(config_.k_sigma == config_.k_sigma))
		config_.k_sigma = 0.0;
	tile_px_ = clampInt(config.tile_px, 8, kMaxFrameSide);
	/* at least 4 x 4 and at most 64 x 64 samples per tile */
	step_px_ = clampInt(config.sample_step_px, 1, std::max(1, tile_px_ / 4));
	step_px_ = std::max(step_px_, (tile_px_ + 63) / 64);
	config_.tile_px = tile_px_;
	config_.sample_step_px = step_px_;

	k_sigma_ = UQ8_8(config_.k_sigma);
	min_contrast_ = UQ16_16(config_.min_contrast);

	const int cols = tilesFor(max_width_, tile_px_);
	const int rows = tilesFor(max_height_, tile_px_);
	map_ = ThresholdMap(max_width_, max_height_, tile_px_);
	cell_map_ = ThresholdMap(max_width_, max_height_, cellPx(tile_px_));
	col_start_.assign(static_cast<std::size_t>(cols), 0);
	col_count_.assign(static_cast<std::size_t>(cols), 0);
	row_start_.assign(static_cast<std::size_t>(rows), 0);
	row_count_.assign(static_cast<std::size_t>(rows), 0);
	hist_.assign(static_cast<std::size_t>(cols) * 256, 0);
	col_min_.assign(static_cast<std::size_t>(cols), 255);
	medians_.assign(static_cast<std::size_t>(cols) * static_cast<std::size_t>(rows), 0);
	padded_.assign(static_cast<std::size_t>(cols + 2) * static_cast<std::size_t>(rows + 2), 0);
	corners_.assign(static_cast<std::size_t>(cols + 1) * static_cast<std::size_t>(rows + 1), 0);
	steep_.assign(static_cast<std::size_t>(cols) * static_cast<std::size_t>(rows), 0);
	slopes_.assign(static_cast<std::size_t>(cols) * static_cast<std::size_t>(rows), SlopeFit{});
}

const ThresholdMap &Thresholder::compute(const ImageView &image, ThresholdStats *stats)
{
	ThresholdStats local;
	ThresholdStats *st = stats ? stats : &local;
	*st = ThresholdStats{};

	cols_ = rows_ = 0;
	steep_tiles_ = false;
	cell_map_.setUniform(255);
	/* Every kept slope fit is of an earlier map (0: none; at the wrap, after 2^32 maps, all cleared). */
	if (++generation_ == 0) {
		for (SlopeFit &fit : slopes_)
			fit.generation = 0;
		generation_ = 1;
	}
	if (!image.valid() || image.width > max_width_ || image.height > max_height_) {
		map_.setUniform(255);
		st->level_min = st->level_max = 255;
		st->tiles_x = st->tiles_y = 1;
		st->valid = false;
		return map_;
	}

	if (config_.mode == ThresholdMode::Fixed) {
		map_.setUniform(static_cast<std::uint8_t>(config_.fixed_level));
		st->level_min = st->level_max = config_.fixed_level;
		st->tiles_x = st->tiles_y = 1;
		st->valid = true;
		sampleNoise(image);
		st->noise_sigma = noiseSigma().toDouble();
		return map_; /* no tiles, no backgrounds: noise_gain stays 0 */
	}

	computeAuto(image, st);
	width_ = image.width;
	height_ = image.height;
	cols_ = st->tiles_x;
	rows_ = st->tiles_y;
	return map_;
}

void Thresholder::sampleGain(const ImageView &image, int cols, int rows)
{
	gain_hist_.fill(0);
	gain_level_sum_.fill(0);
	/*
	 * Pairs (x, x + 1) at the tiles' sample points, and at more points
	 * beside each, 2 px apart, until the frame has about kGainPairs; each
	 * goes to the band of its tile's median (its background: a pair's own
	 * value would cut its noise to the band).
	 */
	const int tile = tile_px_;
	const int step = step_px_;
	std::int64_t points = 0;
	for (int c = 0; c < cols; ++c)
		points += col_count_[static_cast<std::size_t>(c)];
	std::int64_t sample_rows = 0;
	for (int r = 0; r < rows; ++r)
		sample_rows += row_count_[static_cast<std::size_t>(r)];
	points *= sample_rows;
	const int per_point = static_cast<int>(std::clamp<std::int64_t>(
		(kGainPairs + points - 1) / std::max<std::int64_t>(points, 1), 1, step / 2));
	for (int r = 0; r < rows; ++r) {
		for (int j = 0; j < row_count_[static_cast<std::size_t>(r)]; ++j) {
			const int y = row_start_[static_cast<std::size_t>(r)] + j * step;
			const std::uint8_t *p = image.row(y);
			for (int c = 0; c < cols; ++c) {
				const int median = medians_[static_cast<std::size_t>(r) * cols + c];
				const std::size_t band =
					static_cast<std::size_t>(median) / kGainBandLevels;
				std::uint32_t *h = gain_hist_.data() + band * kGainDiffs;
				const int x_end = std::min(image.width, (c + 1) * tile);
				std::uint32_t n = 0;
				for (int i = 0; i < col_count_[static_cast<std::size_t>(c)]; ++i) {
					const int x0 =
						col_start_[static_cast<std::size_t>(c)] + i * step;
					for (int e = 0; e < per_point; ++e) {
						const int x = x0 + 2 * e;
						if (x + 1 >= x_end)
							break;
						const int d = static_cast<int>(p[x + 1]) -
							      static_cast<int>(p[x]);
						const int ad = d < 0 ? -d : d;
						++h[static_cast<std::size_t>(
							ad < static_cast<int>(kGainDiffs)
								? ad
								: kGainDiffs - 1)];
						++n;
					}
				}
				gain_level_sum_[band] += static_cast<std::uint32_t>(median) * n;
			}
		}
	}
}

void Thresholder::sampleTiles(const ImageView &image, int cols, int rows)
{
	const int width = image.width;
	const int height = image.height;
	const int step = step_px_;
	const int tile = tile_px_;

	for (auto &bank : diff_hist_)
		bank.fill(0);
	std::uint32_t *dh = diff_hist_[0].data(); /* the 4 banks are contiguous */
	static_assert(sizeof(diff_hist_) == sizeof(std::uint32_t[4][256]));

	/*
	 * The full tiles share one sample pattern (offset col_start_[0] in the
	 * tile, col_count_[0] samples). They are sampled with the tile loop
	 * innermost, so that consecutive increments go to different histograms
	 * (no store-to-load chains on a popular bin). The last tile column may be
	 * partial and sampled on its own.
	 */
	const int n_full = col_count_[0];
	const int off = col_start_[0];
	const std::ptrdiff_t tile_stride = tile;
	/* A pattern whose last pair reaches into the next tile must not do so at the frame's edge. */
	const bool pair_leaves_tile = off + (n_full - 1) * step + 1 >= tile;
	const int full = width % tile == 0 && !pair_leaves_tile ? cols : cols - 1;
	std::uint16_t *hist = hist_.data();
	std::uint8_t *col_min = col_min_.data();

	/*
	 * The sample rows lie step_px_ rows apart, each on pages of its own: in a
	 * frame fresh from the camera each would come at the memory's latency
	 * in turn. Prefetched all at once first (about a sixteenth of a 1456 x
	 * 1088 frame's lines), they come together: Thresholder::compute() on
	 * fresh heavy-clutter frames 71-78 -> 61-67 us (docs/accuracy.md).
	 */
	for (int r = 0; r < rows; ++r)
		for (int j = 0; j < row_count_[r]; ++j)
			prefetchRow(image.row(row_start_[r] + j * step), 0, width);

	for (int r = 0; r < rows; ++r) {
		std::fill(col_min, col_min + cols, std::uint8_t{ 255 });

		for (int j = 0; j < row_count_[r]; ++j) {
			const int y = row_start_[r] + j * step;
			const std::uint8_t *p = image.row(y);
			/* With a dense sample the noise comes from every other sample row (plenty of pairs). */
			const bool noise_row = step >= 12 || (j & 1) == 0;

			for (int i = 0; i < n_full; ++i) {
				const std::uint8_t *q =
					p + off + static_cast<std::ptrdiff_t>(i) * step;
				for (int c = 0; c < full; ++c) {
					const unsigned v = q[c * tile_stride];
					++hist[static_cast<std::size_t>(c) * 256 + v];
					col_min[c] = static_cast<std::uint8_t>(
						v < col_min[c] ? v : col_min[c]);
				}
				if (noise_row) {
					/* pairs (x, x + 1): x + 1 is inside the same full tile */
					for (int c = 0; c < full; ++c) {
						const int d =
							static_cast<int>(q[c * tile_stride + 1]) -
							static_cast<int>(q[c * tile_stride]);
						++dh[static_cast<std::size_t>(c & 3) * 256 +
						     static_cast<std::size_t>(d < 0 ? -d : d)];
					}
				}
			}

			/*
			 * The partial last tile. Its last sample may sit on the last pixel:
			 * it pairs with its left neighbour; a frame one pixel wide pairs
			 * vertically.
			 */
			for (int c = full; c < cols; ++c) {
				std::uint16_t *h = hist + static_cast<std::size_t>(c) * 256;
				unsigned m = col_min[c];
				for (int i = 0, x = col_start_[c]; i < col_count_[c];
				     ++i, x += step) {
					const unsigned v = p[x];
					++h[v];
					m = v < m ? v : m;
					if (!noise_row)
						continue;
					int d;
					if (x + 1 < width)
						d = static_cast<int>(p[x + 1]) -
						    static_cast<int>(v);
					else if (x >= 1)
						d = static_cast<int>(p[x - 1]) -
						    static_cast<int>(v);
					else if (y + 1 < height)
						d = static_cast<int>(image.row(y + 1)[x]) -
						    static_cast<int>(v);
					else if (y >= 1)
						d = static_cast<int>(image.row(y - 1)[x]) -
						    static_cast<int>(v);
					else
						continue; /* a 1 x 1 frame: no pair */
					++dh[static_cast<std::size_t>(i & 3) * 256 +
					     static_cast<std::size_t>(d < 0 ? -d : d)];
				}
				col_min[c] = static_cast<std::uint8_t>(m);
			}
		}

		/* Lower median of each tile: walk up from its smallest sample, clearing behind. */
		for (int c = 0; c < cols; ++c) {
			std::uint16_t *h = hist + static_cast<std::size_t>(c) * 256;
			const int n = col_count_[c] * row_count_[r];
			const int half = (n + 1) / 2;
			int v = col_min[c];
			int cum = h[v];
			while (cum < half && v < 255)
				cum += h[++v];
			medians_[static_cast<std::size_t>(r) * cols + c] =
				static_cast<std::uint8_t>(v);
			/* clear what is left above the median, then what the walk passed */
			int rest = n - cum;
			for (int u = v + 1; rest > 0 && u < 256; ++u) {
				rest -= h[u];
				h[u] = 0;
			}
			for (int u = col_min[c]; u <= v; ++u)
				h[u] = 0;
		}
	}
}

void Thresholder::sampleNoise(const ImageView &image)
{
	for (auto &bank : diff_hist_)
		bank.fill(0);
	const int step = step_px_;
	const int width = image.width;
	/* The pairs (x, x + 1) on the sample grid that Auto mode uses, vertical in a 1-wide frame. */
	int x0 = 0, nx = 0, y0 = 0, ny = 0;
	samplePositions(0, std::max(1, width - 1), step, &x0, &nx);
	samplePositions(0, image.height, step, &y0, &ny);
	for (int j = 0; j < ny; ++j) {
		const int y = y0 + j * step;
		const std::uint8_t *p = image.row(y);
		for (int i = 0; i < nx; ++i) {
			const int x = x0 + i * step;
			int d;
			if (width > 1)
				d = static_cast<int>(p[x + 1]) - static_cast<int>(p[x]);
			else if (y + 1 < image.height)
				d = static_cast<int>(image.row(y + 1)[x]) - static_cast<int>(p[x]);
			else
				continue;
			++diff_hist_[static_cast<std::size_t>(i & 3)]
				    [static_cast<std::size_t>(d < 0 ? -d : d)];
		}
	}
}

namespace {

/*
 * The median of |d| over a histogram of `bins` bins of n > 0 counts,
 * interpolated within its bin: value 0 stands for |d| in [0, 0.5), value
 * b >= 1 for [b - 0.5, b + 0.5). In Q16.16; `bins` (past the last bin) when
 * the median is not found.
 */
UQ16_16 medianAbsDiff(const std::uint32_t *h, std::size_t bins, std::uint64_t n)
{
	std::uint64_t below = 0;
	for (std::size_t b = 0; b < bins; ++b) {
		const std::uint64_t count = h[b];
		if (2 * (below + count) >= n && count > 0) {
			const std::uint64_t lo = b == 0 ? 0 : (2 * b - 1) << 15;
			const std::uint64_t width = b == 0 ? (1u << 15) : (1u << 16);
			/* fraction of the bin below the median: (n/2 - below) / count */
			const std::uint64_t within =
				((n - 2 * below) * width + count) / (2 * count);
			return UQ16_16::fromWideRaw(lo + within);
		}
		below += count;
	}
	return UQ16_16(static_cast<int>(bins));
}

} /* namespace */

UQ16_16 Thresholder::noiseSigma() const
{
	std::uint64_t n = 0;
	std::array<std::uint32_t, 256> h{};
	for (std::size_t d = 0; d < 256; ++d) {
		h[d] = diff_hist_[0][d] + diff_hist_[1][d] + diff_hist_[2][d] + diff_hist_[3][d];
		n += h[d];
	}
	if (n == 0)
		return UQ16_16(0);

	return fixedMul<UQ16_16>(medianAbsDiff(h.data(), h.size(), n), kMadToSigma);
}

double Thresholder::noiseGain() const
{
	/*
	 * Photon transfer within the frame: per band of kGainBandLevels levels
	 * of the tiles' backgrounds with at least kGainMinPairs pairs, the pixel
	 * variance from the median |d| (medianAbsDiff(), as noiseSigma(); spots'
	 * edges are outliers there too) against the band's mean level; a
	 * straight line through them, each weighted by the inverse of its
	 * variance's own variance (a MAD-based variance of n Gaussian pairs:
	 * ~kMadVarOfVar var^2 / n). The slope is the gain when it stands out of
	 * its standard error (kGainSignificance times it, that error scaled up
	 * by the fit's reduced chi^2 when the bands scatter more than that):
	 * a frame whose backgrounds span too little, or carry no shot noise,
	 * gives 0 instead of its noise.
	 */
	constexpr double kMadVarOfVar = 5.4;
	constexpr double kGainSignificance = 2.0;
	std::array<double, kGainBands> lv{}, vr{}, wt{};
	int bands = 0;
	double level_lo = 256.0, level_hi = -1.0;
	for (std::size_t b = 0; b < kGainBands; ++b) {
		const std::uint32_t *h = gain_hist_.data() + b * kGainDiffs;
		std::uint64_t n = 0;
		for (std::size_t d = 0; d < kGainDiffs; ++d)
			n += h[d];
		if (n < kGainMinPairs)
			continue;
		const double mad = medianAbsDiff(h, kGainDiffs, n).toDouble();
		if (mad >= static_cast<double>(kGainDiffs) - 1.0)
			continue; /* not a background's band: mostly edges */
		const double sigma = 1.4826 * mad / std::numbers::sqrt2;
		const double var = std::max(sigma * sigma, 1.0 / 12.0);
		const double level =
			static_cast<double>(gain_level_sum_[b]) / static_cast<double>(n);
		/* Levels clipped at 0 or 255 within two sigma: their spread is cut. */
		if (level < 2.0 * sigma || level > 255.0 - 2.0 * sigma)
			continue;
		lv[static_cast<std::size_t>(bands)] = level;
		vr[static_cast<std::size_t>(bands)] = var;
		wt[static_cast<std::size_t>(bands)] =
			static_cast<double>(n) / (kMadVarOfVar * var * var);
		++bands;
		level_lo = std::min(level_lo, level);
		level_hi = std::max(level_hi, level);
	}
	if (bands < kGainMinBands || level_hi - level_lo < kGainMinSpanLevels)
		return 0.0;
	double sw = 0.0, swx = 0.0, swy = 0.0, swxx = 0.0, swxy = 0.0;
	for (std::size_t i = 0; i < static_cast<std::size_t>(bands); ++i) {
		sw += wt[i];
		swx += wt[i] * lv[i];
		swy += wt[i] * vr[i];
		swxx += wt[i] * lv[i] * lv[i];
		swxy += wt[i] * lv[i] * vr[i];
	}
	const double det = sw * swxx - swx * swx;
	if (!(det > 0.0))
		return 0.0;
	const double slope = (sw * swxy - swx * swy) / det;
	const double offset = (swy - slope * swx) / sw;
	double chi2 = 0.0;
	for (std::size_t i = 0; i < static_cast<std::size_t>(bands); ++i) {
		const double r = vr[i] - offset - slope * lv[i];
		chi2 += wt[i] * r * r;
	}
	const double reduced = bands > 2 ? chi2 / (bands - 2) : 1.0;
	const double slope_se = std::sqrt(sw / det * std::max(1.0, reduced));
	if (!(slope > kGainSignificance * slope_se))
		return 0.0;
	return std::min(slope, kGainMax);
}

void Thresholder::computeAuto(const ImageView &image, ThresholdStats *stats)
{
	const int width = image.width;
	const int height = image.height;
	const int tile = tile_px_;
	const int cols = tilesFor(width, tile);
	const int rows = tilesFor(height, tile);
	/* always fits: the frame is within the constructor's size */
	map_.reshape(width, height, tile);

	for (int c = 0; c < cols; ++c)
		samplePositions(c * tile, std::min(tile, width - c * tile), step_px_,
				&col_start_[c], &col_count_[c]);
	for (int r = 0; r < rows; ++r)
		samplePositions(r * tile, std::min(tile, height - r * tile), step_px_,
				&row_start_[r], &row_count_[r]);

	sampleTiles(image, cols, rows);
	sampleGain(image, cols, rows);

	const UQ16_16 sigma = noiseSigma();
	const UQ16_16 contrast = std::max(fixedMul<UQ16_16>(k_sigma_, sigma), min_contrast_);

	/*
	 * Guard against spots: a tile whose own median lies more than a quarter
	 * of the contrast above the median of its 3x3 neighbourhood (the upper
	 * one of an even count at the borders, so that one raised tile among
	 * four or six never moves it) takes the neighbourhood median instead.
	 * On a planar background the two agree (up to the step of the gradient
	 * between tiles at the borders), so the guard leaves it alone. The
	 * guarded backgrounds go into a grid padded by one tile of linear
	 * extrapolation.
	 */
	const std::int64_t margin = std::max<std::int64_t>(1, contrast.toIntFloor() / 4);
	auto P = [&](int c, int r) -> std::int32_t & {
		return padded_[paddedIndex(cols, c, r)];
	};
	auto median = [&](int c, int r) -> int {
		return medians_[static_cast<std::size_t>(r) * cols + c];
	};
	std::uint64_t background_sum = 0;
	for (int r = 0; r < rows; ++r) {
		const int r0 = std::max(r - 1, 0), r1 = std::min(r + 1, rows - 1);
		for (int c = 0; c < cols; ++c) {
			const int c0 = std::max(c - 1, 0), c1 = std::min(c + 1, cols - 1);
			const int own = median(c, r);
			int g = own;
			/* The median is at least the minimum: only a tile above its lowest neighbour can be an outlier. */
			int lowest = own;
			for (int rr = r0; rr <= r1; ++rr)
				for (int cc = c0; cc <= c1; ++cc)
					lowest = std::min(lowest, median(cc, rr));
			if (own > lowest + margin) {
				int nb[9];
				int n = 0;
				for (int rr = r0; rr <= r1; ++rr) {
					for (int cc = c0; cc <= c1; ++cc) {
						/* insertion into the sorted nb[0..n) */
						const int v = median(cc, rr);
						int k = n++;
						while (k > 0 && nb[k - 1] > v) {
							nb[k] = nb[k - 1];
							--k;
						}
						nb[k] = v;
					}
				}
				const int nbr = nb[n / 2];
				if (own > nbr + margin)
					g = nbr;
			}
			P(c, r) = g;
			background_sum += static_cast<std::uint64_t>(g);
		}
	}
	for (int r = 0; r < rows; ++r) {
		P(-1, r) = cols >= 2 ? 2 * P(0, r) - P(1, r) : P(0, r);
		P(cols, r) = cols >= 2 ? 2 * P(cols - 1, r) - P(cols - 2, r) : P(cols - 1, r);
	}
	for (int c = -1; c <= cols; ++c) {
		P(c, -1) = rows >= 2 ? 2 * P(c, 0) - P(c, 1) : P(c, 0);
		P(c, rows) = rows >= 2 ? 2 * P(c, rows - 1) - P(c, rows - 2) : P(c, rows - 1);
	}

	/*
	 * Corner (i, j) of the tile grid (i in [0, cols], j in [0, rows]) is the
	 * mean of the four tiles that meet there, kept as their sum (quarter
	 * levels).
	 */
	const int ccols = cols + 1;
	for (int j = 0; j <= rows; ++j) {
		std::int32_t *corner_row = corners_.data() + static_cast<std::size_t>(j) * ccols;
		std::int32_t left = P(-1, j - 1) + P(-1, j);
		for (int i = 0; i <= cols; ++i) {
			const std::int32_t right = P(i, j - 1) + P(i, j);
			corner_row[i] = left + right;
			left = right;
		}
	}

	/*
	 * The level of a tile: the largest value of the bilinear interpolation
	 * of the backgrounds over the tile (its largest corner), at least its own
	 * background, plus the contrast.
	 */
	int level_min = 255;
	int level_max = 0;
	for (int r = 0; r < rows; ++r) {
		const std::int32_t *top = corners_.data() + static_cast<std::size_t>(r) * ccols;
		const std::int32_t *bottom = top + ccols;
		for (int c = 0; c < cols; ++c) {
			const std::int32_t hi4 =
				std::max(std::max(4 * P(c, r), std::max(top[c], top[c + 1])),
					 std::max(bottom[c], bottom[c + 1]));
			/* background in Q16.16 (quarter levels << 14) + contrast, rounded */
			const UQ16_16 bg = UQ16_16::fromWideRaw(
				static_cast<std::uint64_t>(std::max(hi4, 0)) << 14);
			const int level = static_cast<int>(
				std::min<std::int64_t>((bg + contrast).toIntRound(), 255));
			map_.setLevel(c, r, static_cast<std::uint8_t>(level));
			level_min = std::min(level_min, level);
			level_max = std::max(level_max, level);
		}
	}

	contrast_ = static_cast<int>(std::min<std::int64_t>(contrast.toIntRound(), 255));
	computeCells(width, height, cols, rows, contrast);

	stats->level_min = level_min;
	stats->level_max = level_max;
	stats->background = static_cast<double>(background_sum) / static_cast<double>(cols * rows);
	stats->noise_sigma = sigma.toDouble();
	stats->noise_gain = noiseGain();
	stats->tiles_x = cols;
	stats->tiles_y = rows;
	stats->valid = true;
}

void Thresholder::computeCells(int width, int height, int cols, int rows, UQ16_16 contrast)
{
	const int tile = tile_px_;
	const int cell = cellPx(tile);
	steep_box_ = PixelWindow{};
	auto P = [&](int c, int r) -> std::int64_t {
		return padded_[paddedIndex(cols, c, r)];
	};
	const int ccols = corners_.empty() ? 0 : cols + 1;
	auto corner = [&](int i, int j) -> std::int64_t {
		return corners_[static_cast<std::size_t>(j) * ccols + static_cast<std::size_t>(i)];
	};
	/*
	 * A tile is steep when the interpolation over it (its centre and
	 * corners, quarter levels) spans the contrast or more: only there can a
	 * cell lie that far below the tile's level, and a spot that the tile's
	 * level misses by less stands out of its background by less than twice
	 * the contrast. The others' cells take the tile's level.
	 */
	const std::int64_t steep4 = 4 * contrast.toIntRound();
	int c_lo = cols, c_hi = -1, r_lo = rows, r_hi = -1;
	for (int r = 0; r < rows; ++r)
		for (int c = 0; c < cols; ++c) {
			const std::int64_t v[5] = { 4 * P(c, r), corner(c, r), corner(c + 1, r),
						    corner(c, r + 1), corner(c + 1, r + 1) };
			const auto [lo, hi] = std::minmax_element(v, v + 5);
			const bool steep = *hi - *lo >= steep4;
			steep_[static_cast<std::size_t>(r) * cols + c] = steep ? 1 : 0;
			if (steep) {
				c_lo = std::min(c_lo, c);
				c_hi = std::max(c_hi, c);
				r_lo = std::min(r_lo, r);
				r_hi = std::max(r_hi, r);
			}
		}
	steep_tiles_ = c_hi >= 0;
	/* No steep tile (most frames): the cells are the tiles. */
	const int per_tile = steep_tiles_ ? tile / cell : 1;
	if (!cell_map_.reshape(width, height, steep_tiles_ ? cell : tile)) {
		steep_tiles_ = false;
		return;
	}
	for (int r = 0; r < rows; ++r)
		for (int c = 0; c < cols; ++c) {
			const bool steep = steep_[static_cast<std::size_t>(r) * cols + c] != 0;
			const std::uint8_t level = map_.level(c, r);
			for (int j = r * per_tile;
			     j < std::min((r + 1) * per_tile, cell_map_.rows()); ++j)
				for (int i = c * per_tile;
				     i < std::min((c + 1) * per_tile, cell_map_.cols()); ++i)
					cell_map_.setLevel(i, j, steep ? 0 : level);
		}
	if (!steep_tiles_)
		return;

	/*
	 * The interpolation at pixel (x, y) times (2 tile)^2: tile c's centre is
	 * at x = c tile + (tile - 1) / 2, in doubled coordinates 2 c tile + tile - 1.
	 */
	const std::int64_t span = 2 * static_cast<std::int64_t>(tile);
	auto interpolated = [&](int x, int y) -> std::int64_t {
		auto axis = [&](int v, int n, int *k, std::int64_t *w) {
			const std::int64_t d = 2 * static_cast<std::int64_t>(v) - (tile - 1);
			*k = static_cast<int>(std::clamp<std::int64_t>(
				d >= 0 ? d / span : -1, -1, static_cast<std::int64_t>(n) - 1));
			*w = std::clamp<std::int64_t>(d - *k * span, 0, span);
		};
		int c = 0, r = 0;
		std::int64_t wx = 0, wy = 0;
		axis(x, cols, &c, &wx);
		axis(y, rows, &r, &wy);
		const int c1 = std::min(c + 1, cols), r1 = std::min(r + 1, rows);
		return P(c, r) * (span - wx) * (span - wy) + P(c1, r) * wx * (span - wy) +
		       P(c, r1) * (span - wx) * wy + P(c1, r1) * wx * wy;
	};
	const std::int64_t scale = span * span;
	for (int r = r_lo; r <= r_hi; ++r)
		for (int c = c_lo; c <= c_hi; ++c) {
			const int tile_level = map_.level(c, r);
			/*
			 * Never below the lowest background of the tiles around plus the
			 * contrast: at the frame's edge the interpolation extrapolates, and
			 * beside a bright patch it can fall below any background there.
			 */
			std::int64_t floor_bg = P(c, r);
			for (int rr = std::max(r - 1, 0); rr <= std::min(r + 1, rows - 1); ++rr)
				for (int cc = std::max(c - 1, 0); cc <= std::min(c + 1, cols - 1);
				     ++cc)
					floor_bg = std::min(floor_bg, P(cc, rr));
			const int floor_level = static_cast<int>(std::min<std::int64_t>(
				(UQ16_16(static_cast<int>(std::max<std::int64_t>(floor_bg, 0))) +
				 contrast)
					.toIntRound(),
				tile_level));
			/* Where the backgrounds bend down the interpolation falls short by up to 1/8 of the bend. */
			const std::int64_t bend_x =
				std::max<std::int64_t>(0, 2 * P(c, r) - P(c - 1, r) - P(c + 1, r));
			const std::int64_t bend_y =
				std::max<std::int64_t>(0, 2 * P(c, r) - P(c, r - 1) - P(c, r + 1));
			for (int j = r * per_tile;
			     j < std::min((r + 1) * per_tile, cell_map_.rows()); ++j) {
				const int y0 = j * cell, y1 = std::min(y0 + cell, height) - 1;
				for (int i = c * per_tile;
				     i < std::min((c + 1) * per_tile, cell_map_.cols()); ++i) {
					if (cell_map_.level(i, j) != 0)
						continue; /* not a steep tile's */
					const int x0 = i * cell,
						  x1 = std::min(x0 + cell, width) - 1;
					std::int64_t hi = std::max(
						{ interpolated(x0, y0), interpolated(x1, y0),
						  interpolated(x0, y1), interpolated(x1, y1) });
					hi += (bend_x + bend_y) * scale / 8;
					/* In Q16.16, plus the contrast, rounded; never above the tile's. */
					const std::int64_t raw =
						(std::max<std::int64_t>(hi, 0) << 16) / scale;
					const UQ16_16 bg = UQ16_16::fromWideRaw(
						static_cast<std::uint64_t>(raw));
					const int level = static_cast<int>(std::clamp<std::int64_t>(
						(bg + contrast).toIntRound(), floor_level,
						tile_level));
					cell_map_.setLevel(i, j, static_cast<std::uint8_t>(level));
				}
			}
		}
	/* What a second labelling must read: the steep tiles and one tile round them. */
	steep_box_ = PixelWindow{ std::max(c_lo - 1, 0) * tile, std::max(r_lo - 1, 0) * tile,
				  std::min((c_hi + 2) * tile, width),
				  std::min((r_hi + 2) * tile, height) };
}

bool Thresholder::backgroundSlope(double u_px, double v_px, double *gx, double *gy,
				  double *sigma) const
{
	if (cols_ < 2 || rows_ < 2)
		return false;
	const int tile = tile_px_;
	const int c_at = std::clamp(static_cast<int>(u_px) / tile, 0, cols_ - 1);
	const int r_at = std::clamp(static_cast<int>(v_px) / tile, 0, rows_ - 1);
	SlopeFit &fit = slopes_[static_cast<std::size_t>(r_at) * cols_ + c_at];
	if (fit.generation == generation_) {
		*gx = fit.gx;
		*gy = fit.gy;
		*sigma = fit.sigma;
		return fit.ok;
	}
	fit = SlopeFit{};
	fit.generation = generation_;
	/* The centre of tile k along an extent (the last tile may be cut short), pixels. */
	auto centre = [tile](int k, int extent) {
		return k * tile + 0.5 * (std::min(tile, extent - k * tile) - 1);
	};
	/* The slope and its variance do not depend on the pixel: the plane about the tile's centre. */
	const double u0_px = centre(c_at, width_);
	const double v0_px = centre(r_at, height_);
	const int c0 = std::max(c_at - 2, 0), c1 = std::min(c_at + 2, cols_ - 1);
	const int r0 = std::max(r_at - 2, 0), r1 = std::min(r_at + 2, rows_ - 1);
	/* Least squares b = a + gx (x - u0) + gy (y - v0) over the tiles' centres. */
	double s[3][3] = {}, t[3] = {};
	double b2sum = 0.0;
	int n = 0;
	for (int r = r0; r <= r1; ++r) {
		const double y = centre(r, height_);
		for (int c = c0; c <= c1; ++c) {
			const double x = centre(c, width_);
			const double b = padded_[paddedIndex(cols_, c, r)];
			const double f[3] = { 1.0, x - u0_px, y - v0_px };
			for (int i = 0; i < 3; ++i) {
				for (int j = 0; j < 3; ++j)
					s[i][j] += f[i] * f[j];
				t[i] += f[i] * b;
			}
			b2sum += b * b;
			++n;
		}
	}
	/* Solve the 3 x 3 normal equations (symmetric, positive definite for 2 x 2 tiles or more). */
	const double a00 = s[0][0], a01 = s[0][1], a02 = s[0][2], a11 = s[1][1], a12 = s[1][2],
		     a22 = s[2][2];
	const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22,
		     c02 = a01 * a12 - a02 * a11;
	const double det = a00 * c00 + a01 * c01 + a02 * c02;
	if (!(det > 0.0))
		return false;
	const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12,
		     c22 = a00 * a11 - a01 * a01;
	const double p0 = (c00 * t[0] + c01 * t[1] + c02 * t[2]) / det;
	const double p1 = (c01 * t[0] + c11 * t[1] + c12 * t[2]) / det;
	const double p2 = (c02 * t[0] + c12 * t[1] + c22 * t[2]) / det;
	/* Residual variance of one tile's background, at least its rounding to a level. */
	const double ssr = b2sum - (p0 * t[0] + p1 * t[1] + p2 * t[2]);
	const double var_b = std::max(n > 3 ? ssr / (n - 3) : 0.0, 1.0 / 12.0);
	fit.gx = *gx = p1;
	fit.gy = *gy = p2;
	/* The larger of the two slopes' variances: var_b (A^-1)_kk. */
	fit.sigma = *sigma = std::sqrt(var_b * std::max(c11, c22) / det);
	fit.ok = true;
	return true;
}

} /* namespace dockpose */

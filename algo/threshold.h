/* SPDX-License-Identifier: MIT */
/*
 * The segmentation level of a frame (method.md section 1, step 2).
 *
 * A pixel of value v is segmented when v >= T, where T is the level of the
 * tile the pixel lies in. The level is either one fixed value or an automatic
 * level per tile computed from the frame's own statistics:
 *
 *   level = background(tile) + max(k_sigma * noise_sigma, min_contrast)
 *
 *  - background: the median of a sparse sample of the tile (every
 *    sample_step_px-th pixel of every sample_step_px-th row); a tile whose
 *    median lies more than a quarter of the contrast above the median of its
 *    3x3 neighbourhood of tiles takes that instead (a bright spot covering
 *    most of a tile does not raise the tile's level); then raised to the
 *    largest value that the bilinear interpolation between tile centres
 *    takes inside the tile (an ambient gradient does not eat the margin at
 *    the bright side of a tile);
 *  - noise_sigma: one robust figure for the whole frame, from the median
 *    absolute difference of horizontally adjacent pixels at the sample points,
 *    sigma = 1.4826 * MAD / sqrt(2) (a difference has sqrt(2) the noise of a
 *    pixel; gradients cancel in the difference, spots are outliers). The
 *    median is interpolated within its histogram bin, so noise below one
 *    level is still measured (pixel quantisation adds 1/12 level^2).
 *    Fixed mode measures it too, from pairs on the same sample grid (the
 *    blobs' centroid covariance needs it);
 *  - noise_gain (Auto only): the sensor's shot noise, levels^2 of variance
 *    per level, from the noise against the level of the tiles' backgrounds
 *    (photon transfer within the frame, noiseGain(); docs/vision.md).
 *
 * The arithmetic on levels is fixed point (algo/fixed_point.h). The sample
 * reads about 1/sample_step_px^2 of the pixels (1/256 by default: 16
 * samples in a 64-pixel tile, a tile median good to about 0.3 sigma, and
 * some 6000 pixel pairs for the noise of a 1456 x 1088 frame).
 *
 * Units: levels of the 8-bit frame; pixels.
 */
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "algo/capacities.h"
#include "algo/fixed_point.h"
#include "algo/image.h"

namespace dockpose {

enum class ThresholdMode : std::uint8_t {
	Fixed = 0, /* one level for the whole frame: fixed_level */
	Auto, /* per tile, from background and noise */
};

struct ThresholdConfig {
	using Mode = ThresholdMode;

	Mode mode = Mode::Auto;
	/* Fixed: pixels >= fixed_level are segmented, 0..255. */
	int fixed_level = 100;
	/* Auto: level = background + max(k_sigma * noise_sigma, min_contrast). */
	double k_sigma = 6.0; /* 0..255, used as UQ8_8 */
	int min_contrast = 12; /* levels, 0..255 */
	/*
	 * Auto: tile side (8..kMaxFrameSide) and sampling step (1..tile_px / 4,
	 * so a tile has at least 4 x 4 samples), pixels. The step is raised when
	 * a tile would have more than 64 x 64 samples.
	 */
	int tile_px = 64;
	int sample_step_px = 16;
};

struct ThresholdStats {
	int level_min = 0; /* smallest and largest tile level of the frame */
	int level_max = 0;
	double background = 0.0; /* mean of the tile backgrounds, levels (Auto only, else 0) */
	double noise_sigma = 0.0; /* robust noise estimate, levels (both modes) */
	/*
	 * Shot noise: the pixel variance grows by this many levels^2 per level
	 * of signal, var(v) = noise_sigma^2 + noise_gain * (v - background)
	 * (the sensor's levels per electron), fitted to the noise against the
	 * level over the frame's own sample (Thresholder::noiseGain()); 0 when
	 * the sample's levels span too little to show it (Auto only: 0 in Fixed mode).
	 */
	double noise_gain = 0.0;
	int tiles_x = 0; /* the tile grid */
	int tiles_y = 0;
	bool valid = false; /* false: invalid view or frame larger than the Thresholder's */
};

/*
 * Per-tile levels. Tile (c, r) covers pixels x in [c * tile_px, (c + 1) * tile_px)
 * and y in [r * tile_px, (r + 1) * tile_px); pixels beyond the grid take the
 * level of the last column / row, so a map answers for any pixel.
 */
class ThresholdMap
{
public:
	/* No tiles: every pixel reads level 255 (or what setUniform() set). Allocates: never. */
	ThresholdMap() = default;

	/*
	 * A grid of ceil(width / tile_px) x ceil(height / tile_px) tiles, all at
	 * `level`. Allocates: here (the grid).
	 */
	ThresholdMap(int width, int height, int tile_px, std::uint8_t level = 255);

	/* One tile, `level` everywhere. Allocates: here (one byte). */
	static ThresholdMap uniform(std::uint8_t level);

	/* Turn this map into one tile at `level`, keeping its storage. Allocates: never. */
	void setUniform(std::uint8_t level);

	/*
	 * Re-grid for a width x height frame with tiles of tile_px, within the
	 * storage allocated at construction (levels unspecified until set).
	 * Returns false, leaving the map unchanged, when the grid does not fit.
	 * Allocates: never.
	 */
	bool reshape(int width, int height, int tile_px);

	void fill(std::uint8_t level);

	int tilePx() const { return tile_px_; }
	int cols() const { return cols_; }
	int rows() const { return rows_; }
	/* Tiles the storage holds. */
	int capacity() const { return static_cast<int>(levels_.size()); }

	std::uint8_t level(int col, int row) const { return levels_[index(col, row)]; }
	void setLevel(int col, int row, std::uint8_t level) { levels_[index(col, row)] = level; }

	/* The cols() levels of tile row `row` (row in [0, rows())). */
	const std::uint8_t *rowLevels(int row) const
	{
		return levels_.data() + static_cast<std::size_t>(row) * cols_;
	}

	/* Level of pixel (x, y), x, y >= 0. */
	std::uint8_t levelAt(int x, int y) const
	{
		if (cols_ == 0)
			return empty_level_;
		int c = x / tile_px_;
		int r = y / tile_px_;
		c = c < cols_ ? c : cols_ - 1;
		r = r < rows_ ? r : rows_ - 1;
		return levels_[index(c, r)];
	}

private:
	std::size_t index(int col, int row) const
	{
		return static_cast<std::size_t>(row) * static_cast<std::size_t>(cols_) +
		       static_cast<std::size_t>(col);
	}

	int tile_px_ = kMaxFrameSide;
	int cols_ = 0;
	int rows_ = 0;
	std::uint8_t empty_level_ = 255; /* the level of a map without tiles */
	std::vector<std::uint8_t> levels_;
};

class Thresholder
{
public:
	/*
	 * For frames up to max_width x max_height. Out-of-range configuration
	 * values are clamped (see ThresholdConfig). Allocates: here only.
	 */
	Thresholder(int max_width, int max_height, const ThresholdConfig &config);

	/*
	 * The level map of one frame. An invalid view or a frame larger than the
	 * constructor's size gives a uniform map at 255 with stats->valid false.
	 * stats may be null. The map stays valid until the next call.
	 * Allocates: never.
	 */
	const ThresholdMap &compute(const ImageView &image, ThresholdStats *stats = nullptr);

	const ThresholdMap &map() const { return map_; }

	/*
	 * The last Auto compute()'s levels on cells a quarter of a tile across
	 * (a half, or the tile, when a quarter does not divide it): each the largest value that the bilinear interpolation
	 * of the tile backgrounds takes in the cell (plus an eighth of the
	 * backgrounds' second difference where they bend down, the most the
	 * interpolation can fall short of a smooth background there) plus the
	 * contrast, never above its tile's level. On a steep background (the
	 * flank of a sunlit patch) the tile's level is its brightest corner's,
	 * and a faint LED at the foot of the flank lies below it; the cell's
	 * level follows the flank. Only steep tiles (the interpolation spans the
	 * contrast or more over them) get cells of their own; the others' cells
	 * keep the tile's level. hasSteepTiles(): there is one; without, the
	 * cells are the tiles (the map equals map()).
	 * Allocates: never.
	 */
	const ThresholdMap &cellMap() const { return cell_map_; }
	bool hasSteepTiles() const { return steep_tiles_; }
	/* The last Auto compute()'s contrast, levels: a level is a background plus this. */
	int contrast() const { return contrast_; }
	/* The steep tiles and one tile round them (empty: none). */
	const PixelWindow &steepBox() const { return steep_box_; }

	/*
	 * The background's slope around pixel (u_px, v_px) in the last Auto
	 * compute(): a plane fitted to the guarded tile backgrounds of the 5 x 5
	 * tiles around it, its gradient (gx, gy) in levels per pixel, and the
	 * 1-sigma of each component from the fit's residuals (at least the
	 * backgrounds' quantisation). False when there is no such background
	 * (Fixed mode, an invalid frame, fewer than 2 x 2 tiles). The fit
	 * depends only on the tile holding the pixel: it is made once per tile
	 * and compute(), and kept (so: the frame thread only).
	 * Allocates: never.
	 */
	bool backgroundSlope(double u_px, double v_px, double *gx, double *gy, double *sigma) const;
	const ThresholdConfig &config() const { return config_; }
	int maxWidth() const { return max_width_; }
	int maxHeight() const { return max_height_; }

private:
	void computeAuto(const ImageView &image, ThresholdStats *stats);
	/* Tile medians (medians_) and the difference histogram from the sparse sample. */
	void sampleTiles(const ImageView &image, int cols, int rows);
	/* Fixed mode: only the difference histogram, from pairs on the same sparse grid. */
	void sampleNoise(const ImageView &image);
	/* Robust noise sigma from the difference histogram, levels. */
	UQ16_16 noiseSigma() const;
	/* ThresholdStats::noise_gain from gain_hist_, levels^2 per level. */
	double noiseGain() const;
	/* The pairs of noiseGain(), after sampleTiles() (its medians). Allocates: never. */
	void sampleGain(const ImageView &image, int cols, int rows);
	/*
	 * The noise against the level (sampleGain()): about kGainPairs pairs, by
	 * band of kGainBandLevels levels of their tile's median and by
	 * |difference| (up to kGainDiffs - 1); a band counts with kGainMinPairs
	 * pairs, the fit with kGainMinBands bands spanning kGainMinSpanLevels
	 * levels; the gain is at most kGainMax.
	 */
	static constexpr std::size_t kGainBandLevels = 4;
	static constexpr std::int64_t kGainPairs = 8192;
	static constexpr std::size_t kGainBands = 256 / kGainBandLevels;
	static constexpr std::size_t kGainDiffs = 64;
	static constexpr std::uint64_t kGainMinPairs = 48;
	static constexpr int kGainMinBands = 2;
	static constexpr double kGainMinSpanLevels = 4.0;
	static constexpr double kGainMax = 4.0;
	std::array<std::uint32_t, kGainBands * kGainDiffs> gain_hist_{};
	std::array<std::uint32_t, kGainBands> gain_level_sum_{};

	ThresholdConfig config_;
	int max_width_ = 0;
	int max_height_ = 0;
	int tile_px_ = 64;
	int step_px_ = 8;
	/* The last Auto compute(): its frame and tile grid (0: none, backgrounds in padded_). */
	int width_ = 0, height_ = 0, cols_ = 0, rows_ = 0;
	UQ8_8 k_sigma_;
	UQ16_16 min_contrast_;

	ThresholdMap map_;
	ThresholdMap cell_map_;
	bool steep_tiles_ = false;
	int contrast_ = 0;
	PixelWindow steep_box_;
	/* Levels on the cells of cell_map_ (computeAuto()'s last step). */
	void computeCells(int width, int height, int cols, int rows, UQ16_16 contrast);
	/* Sample positions of the current frame's tile columns / rows. */
	std::vector<int> col_start_, col_count_, row_start_, row_count_;
	/* One histogram and the minimum sample per tile column of the current tile row. */
	std::vector<std::uint16_t> hist_;
	std::vector<std::uint8_t> col_min_;
	/* Tile medians; guarded backgrounds padded by one tile; corner sums of four tiles. */
	std::vector<std::uint8_t> medians_;
	std::vector<std::int32_t> padded_;
	std::vector<std::int32_t> corners_;
	std::vector<std::uint8_t> steep_; /* per tile of the last Auto compute(): 1 when steep */
	/* backgroundSlope()'s fit by tile, valid while its generation is compute()'s. */
	struct SlopeFit {
		double gx = 0.0, gy = 0.0, sigma = 0.0;
		std::uint32_t generation = 0;
		bool ok = false;
	};
	mutable std::vector<SlopeFit> slopes_;
	std::uint32_t generation_ = 1;
	/* Histograms of absolute differences (4 banks to break store dependencies). */
	std::array<std::array<std::uint32_t, 256>, 4> diff_hist_{};
};

} /* namespace dockpose */

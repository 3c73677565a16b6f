/* SPDX-License-Identifier: MIT */
/*
 * From an 8-bit frame to LED candidate blobs (method.md section 1, steps 2-4):
 *  - integer thresholding, a fixed level or an automatic level per tile from
 *    the frame's own statistics (background and noise), see threshold.h;
 *  - ONE streaming pass over the frame that thresholds, builds runs, merges
 *    them into components with union-find and accumulates integer,
 *    intensity-weighted moments; no label image;
 *  - clean-up (single pixels and specks dropped, gaps inside a row filled) and
 *    the shape filter (too elongated, too large, too small, too sparse);
 *  - for small unsaturated spots, a model-based sub-pixel centre (a
 *    three-point Gaussian fit on the 3 x 3 core, which the pixel grid does not
 *    lock) when its covariance is smaller than the centroid's.
 *
 * Weights: a segmented pixel of value v in a tile of level T weighs
 * w = v - T + 1 (>= 1), so a spot's centroid is not biased by the pixels that
 * just cross the threshold. Coordinates are integer pixel indices (x, y);
 * centroids are in pixels with (0, 0) at the centre of the top-left pixel.
 */
#pragma once

#include <cstddef>
#include <cstdint>

#include "algo/capacities.h"
#include "algo/image.h"
#include "algo/static_vector.h"
#include "algo/threshold.h"

namespace dockpose {

/* Raw integer moments of one connected component. */
struct BlobMoments {
	std::uint32_t area = 0; /* segmented pixels */
	std::uint64_t sum_w = 0; /* sum of weights */
	std::uint64_t sum_wx = 0, sum_wy = 0;
	std::uint64_t sum_wxx = 0, sum_wyy = 0, sum_wxy = 0;
	std::uint16_t x_min = 0, x_max = 0, y_min = 0, y_max = 0;
	std::uint8_t peak = 0; /* largest pixel value */
	/*
	 * Unweighted moments of the segmented pixels below the clip level (the
	 * ones whose value carries the frame's noise): count, sums of x, y and
	 * of their products. For the centroid's covariance.
	 */
	std::uint32_t noisy = 0;
	std::uint64_t sum_x = 0, sum_y = 0;
	std::uint64_t sum_xx = 0, sum_yy = 0, sum_xy = 0;
	/* Pixels at or above the clip level, their sums of x, y and of their products, their bounding box. */
	std::uint32_t saturated = 0;
	std::uint64_t sat_x = 0, sat_y = 0;
	std::uint64_t sat_xx = 0, sat_yy = 0, sat_xy = 0;
	std::uint16_t sat_x_min = 0xffff, sat_x_max = 0, sat_y_min = 0xffff, sat_y_max = 0;
	/*
	 * The levels T of the segmented pixels: their sum, sums of T x and T y,
	 * and the lowest. A spot that straddles tiles of different levels is
	 * re-weighted to one level, its lowest (see measure()).
	 */
	std::uint64_t sum_t = 0, sum_tx = 0, sum_ty = 0;
	std::uint8_t level_min = 255;
};

/* A blob that passed the clean-up and shape filter. */
struct Blob {
	/*
	 * Centre: the intensity-weighted centroid, or for a small unsaturated
	 * spot the grid undersamples a three-point Gaussian fit (detect() only,
	 * not measure(); see docs/vision.md).
	 */
	double u_px = 0.0, v_px = 0.0;
	double area_px = 0.0; /* segmented pixels (gaps filled) */
	double weight = 0.0; /* sum of weights */
	double sigma_major_px = 0.0; /* weighted std-dev along the major axis */
	double sigma_minor_px = 0.0; /* ... and the minor axis */
	double elongation = 1.0; /* sigma_major / sigma_minor */
	double fill = 1.0; /* area / (pi * 4 sigma_major sigma_minor), ~1 for a disc */
	std::uint8_t peak = 0;
	std::uint16_t x_min = 0, x_max = 0, y_min = 0, y_max = 0;
	/*
	 * Covariance of the centroid (u, v) in px^2, from the frame's measured
	 * noise, the blob's intensity moments and its saturation (0 when unknown:
	 * consumers then fall back to RefineOptions::sigma_px).
	 */
	double cov_uu_px2 = 0.0, cov_uv_px2 = 0.0, cov_vv_px2 = 0.0;
	int saturated_px = 0; /* pixels at the sensor's clip level */
};

struct BlobFilterConfig {
	/* Smaller components are specks or hot pixels (1 drops single pixels). */
	int min_area_px = 2;
	/* Larger components are not LED spots; 0 = 1/200 of the frame. */
	int max_area_px = 0;
	/*
	 * sigma_major / sigma_minor above this is a glint, not an LED. A spot of
	 * PSF sigma s drawn out by a motion of L px during the exposure has
	 * sqrt(L^2 / 12 + s^2) / s: 12 keeps streaks of up to ~41 s (33 px at
	 * s = 0.8 px), whose centroid is still the LED's mid-exposure place. The
	 * paper's 4 dropped every streak longer than ~13 s (11 px). A glint kept as a
	 * candidate costs search time, never safety: the false-alarm bound
	 * counts every candidate.
	 */
	double max_elongation = 12.0;
	/* Fill ratio below this is too sparse for an LED spot. */
	double min_fill = 0.25;
	/* Gaps of up to this many pixels inside a row are filled (closing). */
	int fill_gap_px = 1;
	/*
	 * Pixels at or above this level are clipped by the sensor (1..256; 256:
	 * none is): they carry no noise, and a spot with clipped pixels gets the
	 * saturated treatment of its centroid (see measure()).
	 */
	int clip_level = 255;
};

/*
 * The dropped counts cover every look of detect() (the first, then on steep
 * tiles, clipped cores and peaks inside dropped components).
 */
struct BlobStats {
	int components = 0; /* connected components found (detect(): by its first look) */
	int dropped_small = 0; /* specks, single pixels */
	int dropped_large = 0;
	int dropped_shape = 0; /* elongated or sparse */
	int dropped_capacity = 0; /* valid blobs beyond kMaxCandidates (weakest dropped) */
	bool component_overflow = false; /* more than kMaxComponents: frame too cluttered */
	bool window_cut = false; /* detectWindows(): a component reaches beyond a window */
	/*
	 * detectWindows(), with window_cut: the box (frame coordinates, inside
	 * the frame) the cutting window must also cover for that component to be
	 * read whole, as far as the cut shows: the box grow() searches around
	 * it, and beyond a side the window cut, room for the largest spot grown.
	 */
	PixelWindow cut_reach;
	/* detect(): spots found on the threshold's cells below their tile's level (Thresholder::cellMap()) */
	int below_tile_level = 0;
	/*
	 * detect(): the second look overflowed the labelling (more than
	 * kMaxComponents in the steep tiles' box); the frame keeps the first
	 * look's blobs and no spot below the tile level was looked for
	 */
	bool below_tile_overflow = false;
	/*
	 * detect(): clipped cores found at the clip level inside components that
	 * clipped but were dropped (an LED merged with a bright surrounding)
	 */
	int clipped_cores = 0;
	/* detect(): spots round peaks inside dropped components (BlobDetector::lookForPeaks()) */
	int inner_peaks = 0;
	ThresholdStats threshold;
};

class BlobDetector
{
public:
	/* Buffers sized for frames up to max_width x max_height. Allocates: here only. */
	BlobDetector(int max_width, int max_height, const ThresholdConfig &threshold,
		     const BlobFilterConfig &filter);
	~BlobDetector();
	BlobDetector(const BlobDetector &) = delete;
	BlobDetector &operator=(const BlobDetector &) = delete;

	/*
	 * Threshold, label, measure and filter one frame. Blobs come out sorted by
	 * weight, strongest first, at most kMaxCandidates. Returns false when the
	 * frame cannot be processed (larger than the buffers, invalid view,
	 * component overflow of its first look); stats says why. Allocates: never.
	 */
	bool detect(const ImageView &image, StaticVector<Blob, kMaxCandidates> *blobs,
		    BlobStats *stats);

	/*
	 * Tracking with regions of interest: the same as detect(), but reading
	 * only the pixels of `count` windows (frame coordinates, inside the frame,
	 * not overlapping), against the level map and noise figure of the last
	 * successful detect() on a frame of the same size (the background is not
	 * re-measured: a full detect() now and then refreshes it). A blob comes
	 * out exactly as detect() would give it on the same map. Returns false,
	 * and the caller runs detect(), when there is no such map, a window is
	 * outside the frame, or a component touches a side of its window that
	 * lies inside the frame (stats->window_cut: it may go on beyond, its
	 * moments would be partial). Allocates: never.
	 */
	bool detectWindows(const ImageView &image, const PixelWindow *windows, std::size_t count,
			   StaticVector<Blob, kMaxCandidates> *blobs, BlobStats *stats);

	/*
	 * Lower level, for tests and tools: label `image` against `map` and call
	 * sink(const BlobMoments &) once per connected component (8-connected,
	 * after gap filling), before any filtering. Returns false on overflow.
	 * Allocates: never.
	 */
	template<typename Sink>
	bool label(const ImageView &image, const ThresholdMap &map, Sink &&sink);

	Thresholder &thresholder() { return thresholder_; }

	/*
	 * From raw moments to a Blob (centroid, axes, fill). With the frame's
	 * pixel noise (levels, >= 0; ThresholdStats::noise_sigma) also the
	 * centroid's covariance; without (< 0) it stays 0 (unknown). Its shot
	 * noise: noise_gain (ThresholdStats::noise_gain, levels^2 per level) and
	 * the segmenting level's height over the background (levels; 0 when
	 * unknown, e.g. a fixed level): a pixel of weight w = v - T + 1 has the
	 * variance noise_sigma^2 + noise_gain (w - 1 + level_over_background).
	 * Allocates: never.
	 */
	static Blob measure(const BlobMoments &m, double noise_sigma = -1.0,
			    double noise_gain = 0.0, double level_over_background = 0.0);

private:
	struct Impl;
	/* sum w (x - u_w)^2, sum w (y - v_w)^2, sum w (x - u_w)(y - v_w) about the weighted centroid. */
	struct WeightedSpread {
		double xx = 0.0, yy = 0.0, xy = 0.0;
	};
	static void centroidCovariance(const BlobMoments &m, double noise_sigma, double noise_gain,
				       double level_over_background, const WeightedSpread &spread,
				       Blob *b);
	/* Label into the component list of impl_ (componentCount() entries). */
	bool labelImpl(const ImageView &image, const ThresholdMap &map);
	std::size_t componentCount() const;
	const BlobMoments *components() const;
	/*
	 * The last labelling's components that pass the filter, into the heap
	 * `blobs`. First: every one; the boxes of those dropped go to dropped_.
	 * Windows: every one. BelowTiles: only those whose peak lies below every
	 * tile level around them (none of their pixels reaches the tiles' map),
	 * that stand out of their surroundings (standsOut()) and do not reach
	 * `window`'s sides inside the frame. Cores: only those that do not reach
	 * `window`'s sides inside the frame nor overlap a blob's box, and are
	 * plateaus (solidCore()). Peaks: only the one holding (peak_x_, peak_y_),
	 * if it does not reach `window`'s sides nor overlap a blob's box.
	 */
	enum class Look {
		First, /* detect(): the tiles' levels */
		Windows, /* detectWindows(): the tiles' levels in a window */
		BelowTiles, /* detect(): the steep tiles' cells, below the tiles' levels */
		Cores, /* detect(): the clip level, in the box of a dropped component that clipped */
		Peaks, /* detect(): a plane round a peak in a dropped component's box (lookForPeaks()) */
	};
	void lookForPeaks(const ImageView &image, const PixelWindow &box, BlobStats *st,
			  StaticVector<Blob, kMaxCandidates> *blobs, int *peaks);
	void peakAt(const ImageView &image, int x, int y, int v, BlobStats *st,
		    StaticVector<Blob, kMaxCandidates> *blobs, int *peaks);
	void collect(const ImageView &image, BlobStats *stats,
		     StaticVector<Blob, kMaxCandidates> *blobs, Look look,
		     const PixelWindow *window = nullptr);
	void correctBackgroundSlope(const BlobMoments &m, Blob *b) const;
	/*
	 * Hysteresis: the spot whose core the component `m` (of the tiles'
	 * levels, unsaturated, its box small) is, measured down to a lower level
	 * -- 3 sigma of the frame's noise `noise` over the background -- from
	 * its peak pixel, 8-connected, within a margin of its box (and inside
	 * `window`, when given). A faint spot drawn out by motion blur shows
	 * only the few pixels the noise lifts above the detecting level, whose
	 * centroid then lies anywhere along it: its moments over the whole
	 * spot put it back, and the covariance follows (docs/vision.md). Grown:
	 * *out holds them (several components of one spot grow into the same
	 * moments: collect() keeps it once). Kept: none (the spot reaches its
	 * margin, does not hold the whole component, or is not such a spot).
	 * Cut: it reaches a side of `window` inside the frame. Allocates: never.
	 */
	enum class Grow {
		Kept,
		Grown,
		Cut
	};
	Grow grow(const ImageView &image, const BlobMoments &m, double noise,
		  const PixelWindow *window, BlobMoments *out);
	/* A component's weight W and the unweighted second moments of its pixels about (u, v). */
	struct SpotMoments {
		double w = 0.0, mxx = 0.0, myy = 0.0, mxy = 0.0;
	};
	static SpotMoments spotMoments(const BlobMoments &m, double u, double v);
	/* The centroid's covariance from a background slope uncertain by sigma_slope (levels/px). */
	static void addSlopeVariance(const SpotMoments &s, double sigma_slope, Blob *b);
	static bool standsOut(const ImageView &image, const BlobMoments &m, int contrast);
	static bool cutByWindow(const BlobMoments &m, const PixelWindow &window,
				const ImageView &image);
	static PixelWindow cutReach(const BlobMoments &m, const PixelWindow *window,
				    const ImageView &image);
	bool clippedLikeASpot(const BlobMoments &m) const;
	bool solidCore(const ImageView &image, const BlobMoments &m) const;
	static bool overlapsBlob(const BlobMoments &m,
				 const StaticVector<Blob, kMaxCandidates> &blobs);

	Thresholder thresholder_;
	BlobFilterConfig filter_;
	Impl *impl_;
	/* Every pixel at the clip level: the third look's map. */
	ThresholdMap clip_map_;
	/* Pixel by pixel: the fourth look's levels (lookForPeaks()), set in each window before it is labelled. */
	ThresholdMap peak_map_;
	int peak_x_ = 0, peak_y_ = 0; /* the peak lookForPeaks() labels round */
	double peak_misfit_ = 0.0; /* its ring's rms departure from their plane, levels */
	/* The first look's dropped components: the third and fourth looks' boxes. */
	struct Dropped {
		PixelWindow box;
		/* It clipped, and its clipped pixels, alone, are spot-shaped (clippedLikeASpot()). */
		bool clipped = false;
	};
	StaticVector<Dropped, kMaxDropped> dropped_;
	/* The last successful detect(): its map is thresholder_.map(). */
	bool reference_ = false;
	ThresholdStats reference_threshold_;
	int reference_width_ = 0, reference_height_ = 0;
};

template<typename Sink>
bool BlobDetector::label(const ImageView &image, const ThresholdMap &map, Sink &&sink)
{
	if (!labelImpl(image, map))
		return false;
	const BlobMoments *c = components();
	const std::size_t n = componentCount();
	for (std::size_t i = 0; i < n; ++i)
		sink(c[i]);
	return true;
}

} /* namespace dockpose */

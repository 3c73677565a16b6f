/* SPDX-License-Identifier: MIT */
/*
 * Annotated debug frames for `dockpose solve --annotate DIR`: the frame in
 * grey, every candidate blob as a small yellow cross and, when a pose was
 * found, every model LED reprojected (green circle when matched, red circle
 * when predicted in view but not matched) and the faces' outlines (green;
 * dark green for faces turned away); a red border when no pose was found.
 *
 * A host-tool helper only: never part of algo/ or of the frame path. Drawing
 * is plain integer raster work (Bresenham lines, midpoint circles) with a
 * square brush for thick strokes; everything outside the image is clipped.
 * Pixel convention as in method.md: (0, 0) is the centre of the top-left
 * pixel, so a point (u, v) in pixels is drawn at (round(u), round(v)).
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "algo/blob_detector.h"
#include "algo/camera_model.h"
#include "algo/capacities.h"
#include "algo/image.h"
#include "algo/pipeline.h"
#include "algo/static_vector.h"
#include "algo/target_model.h"

namespace dockpose::annotate {

struct Rgb {
	std::uint8_t r = 0, g = 0, b = 0;
};

inline constexpr Rgb kYellow{ 255, 255, 0 };
inline constexpr Rgb kGreen{ 0, 255, 0 };
inline constexpr Rgb kDarkGreen{ 0, 120, 0 };
inline constexpr Rgb kRed{ 255, 0, 0 };

/* An 8-bit RGB image, rows top to bottom, 3 bytes per pixel. Allocates: in the constructor. */
class RgbImage
{
public:
	RgbImage() = default;
	RgbImage(int width, int height);

	/* The grey frame as RGB (r = g = b = the pixel's level). Allocates: the image. */
	static RgbImage fromGrey(const ImageView &grey);

	int width() const { return width_; }
	int height() const { return height_; }
	const std::vector<std::uint8_t> &bytes() const { return bytes_; }

	/* Set one pixel; pixels outside the image are ignored. */
	void set(int x, int y, Rgb colour);
	/* The pixel at (x, y), which must be inside the image. */
	Rgb at(int x, int y) const;

private:
	int width_ = 0;
	int height_ = 0;
	std::vector<std::uint8_t> bytes_;
};

/* A square brush of side thickness_px centred on (x, y). */
void stamp(RgbImage *image, int x, int y, Rgb colour, int thickness_px = 1);

/* Bresenham line from (x0, y0) to (x1, y1), both ends included. */
void drawLine(RgbImage *image, int x0, int y0, int x1, int y1, Rgb colour, int thickness_px = 1);

/* Midpoint circle of radius_px (>= 1) around (cx, cy). */
void drawCircle(RgbImage *image, int cx, int cy, int radius_px, Rgb colour, int thickness_px = 1);

/* An upright cross with arms of arm_px pixels either side of (cx, cy). */
void drawCross(RgbImage *image, int cx, int cy, int arm_px, Rgb colour, int thickness_px = 1);

/* A frame of width_px pixels along all four edges. */
void drawBorder(RgbImage *image, int width_px, Rgb colour);

/* Marker sizes in pixels; fromWidth() scales them with the frame. */
struct Style {
	int stroke_px = 1; /* line and circle thickness */
	int led_radius_px = 6; /* circle around a reprojected LED */
	int cross_arm_px = 4; /* blob cross, each arm */
	int border_px = 5; /* the "not found" border */
	int edge_segments = 16; /* each face edge is projected as this many segments (distortion) */

	static Style fromWidth(int width_px);
};

/*
 * Draw the annotation of one solved frame onto *image (which holds the frame):
 * the blobs, and the reprojected model when result.found, else the red border.
 * An LED counts as predicted in view when it projects inside the image and
 * lies on a face turned towards the camera.
 */
void annotateFrame(RgbImage *image, const CameraModel &camera, const TargetModel &target,
		   const StaticVector<Blob, kMaxCandidates> &blobs, const PoseResult &result,
		   const Style &style);

/* Write a binary PPM (P6, maxval 255). Returns an empty string, else the problem. */
std::string writePpm(const std::string &path, const RgbImage &image);

} /* namespace dockpose::annotate */

/* SPDX-License-Identifier: MIT */
/*
 * dockpose calibrate --grid GRID.json -o CAMERA.json IMAGE...
 *
 * Intrinsics (fx, fy, cx, cy, k1, k2, p1, p2: algo/camera_model.h's Brown-Conrady model,
 * OpenCV's with k3 fixed to 0) from frames of a planar grid of bright dots on a dark
 * background (docs/calibration.md):
 *  - GRID.json: {"rows": R, "cols": C, "spacing_mm": s, "layout": "symmetric"|"asymmetric"},
 *    rows != cols for the symmetric layout (else the grid's orientation is ambiguous);
 *    "asymmetric" is OpenCV's asymmetric circle grid: every other row shifted by half a
 *    pitch, spacing_mm between consecutive rows and half the pitch along a row;
 *  - the dots are the product's blobs (algo/blob_detector.h: automatic threshold,
 *    subpixel intensity-weighted centroids), ordered into the grid by OpenCV's
 *    findCirclesGrid fed those centroids as keypoints (extra blobs and perspective
 *    are tolerated); a frame without the whole grid is skipped with a line on stderr;
 *  - OpenCV's calibrateCamera solves the intrinsics and every frame's extrinsics; frames
 *    whose rms exceeds kOutlierFactor x the median are dropped and it solves again (until
 *    none is dropped, at most kMaxOutlierRounds times);
 *  - the report (stdout): per-frame rms, dropped frames, each parameter with its 1 sigma,
 *    and a warning when the dots leave corners or edges of the image uncovered;
 *  - CAMERA.json: the camera file (algo/io/model_json.h) with "rms_px", "sigma",
 *    "frames" and "date".
 *
 * Exit status: 0 written; 1 an image could not be read (the others are used and the file is
 * still written), or no calibration (too few frames with the grid, a solution that fails the
 * camera file's checks, the file not written); 2 a bad command line or grid file.
 *
 * Host only (OpenCV: this file is built only where OpenCV is found). Allocates freely;
 * one thread.
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "algo/status.h"

namespace dockpose::tool {

struct GridSpec {
	enum class Layout {
		Symmetric,
		Asymmetric
	};
	int rows = 0;
	int cols = 0;
	double spacing_mm = 0.0;
	Layout layout = Layout::Symmetric;

	int count() const { return rows * cols; }
	/* The dot centres (mm, z = 0) in the order findCirclesGrid returns them: row by row. */
	std::vector<Eigen::Vector3d> points() const;
	/* The smallest distance between two dots, mm. */
	double pitchMm() const;
};

/* Parse and validate a grid file's text; errors name `source` and the key. */
Result<GridSpec> parseGridSpec(const std::string &json_text, const std::string &source);
Result<GridSpec> loadGridSpec(const std::string &path);

struct CalibrateArgs {
	std::string grid_path;
	std::string output_path;
	std::vector<std::string> images;
};

/* A frame whose reprojection rms exceeds this many times the median frame's is dropped. */
inline constexpr double kOutlierFactor = 3.0;
/* Dropping and solving again stops after this many rounds (each drops at least a frame). */
inline constexpr int kMaxOutlierRounds = 5;
/* Fewer frames with the grid than this: no calibration (exit 1). */
inline constexpr int kMinFrames = 4;

/* The whole command; the exit status. Report on stdout, skips and errors on stderr. */
int runCalibrate(const CalibrateArgs &args);

} /* namespace dockpose::tool */

/* SPDX-License-Identifier: MIT */
/*
 * Target model and camera intrinsics from JSON files (method.md section 3).
 *
 * Target:  { "name": "wedge", "units": "mm",
 *            "points": [[x, y, z], ...],        LED centres in the target frame, mm
 *            "faces": [[i, j, k, l], ...] }      convex planar quads, cyclic order
 *   "name" is optional (default: the file's stem), "units" is optional but
 *   must be "mm" when present. At most kMaxLeds points and kMaxFaces faces.
 *   Optional: "led_sigma_mm": s (>= 0, the 1-sigma tolerance of each LED's
 *   position, isotropic) and "approach": {"axis": [x, y, z] (non-zero,
 *   normalised on reading), "max_deg": a (0 < a <= 180)}.
 *
 * Camera:  { "width": W, "height": H, "fx": .., "fy": .., "cx": .., "cy": ..,
 *            "k1": .., "k2": .., "p1": .., "p2": .. }
 *   width/height are integers (pixels); fx, fy, cx, cy in pixels are required;
 *   the distortion coefficients default to 0 when absent. A non-zero "k3"
 *   (or higher) is refused: dockpose's lens model has k1, k2, p1, p2 only.
 *   Optional: "sigma": {"fx": .., "fy": .., "cx": .., "cy": .., "k1": ..,
 *   "k2": .., "p1": .., "p2": ..}, the calibration's 1-sigma uncertainty of
 *   any subset of the parameters (>= 0; CameraIntrinsics::sigma), and what a
 *   calibration tool writes beside them (dockpose calibrate; not used, but
 *   validated): "rms_px" (>= 0 px), "frames" (an integer >= 1) and "date"
 *   (ISO 8601: "2026-12-03" or "2026-12-03T18:40:00Z", or with a UTC offset).
 *
 * Unknown keys are ignored. Nothing here throws: every failure comes back as
 * a Result whose message names the file (or "<text>") and the problem.
 *
 * Host and start-up only. Allocates: yes (strings, the parsed document).
 */
#pragma once

#include <cstddef>
#include <string>

#include "algo/camera_model.h"
#include "algo/status.h"
#include "algo/target_model.h"

namespace dockpose {

/*
 * Parse a target model from JSON text. `source` names the text in error
 * messages (a path, or "<text>"); it also gives the default name.
 */
Result<TargetModel> parseTargetModel(const std::string &json_text,
				     const std::string &source = "<text>");

/* Read and parse a target model file. */
Result<TargetModel> loadTargetModel(const std::string &path);

/* Parse camera intrinsics from JSON text; `source` as above. */
Result<CameraIntrinsics> parseCameraIntrinsics(const std::string &json_text,
					       const std::string &source = "<text>");

/* Read and parse a camera file. */
Result<CameraIntrinsics> loadCameraIntrinsics(const std::string &path);

/* The largest target, camera or board file read (bytes); they are a few kB. */
constexpr std::size_t kMaxTextFileBytes = std::size_t{ 1 } << 20;

/*
 * Read a whole file. Errors say "<path>: <reason>": it cannot be opened, is a
 * directory, is not a regular file (a device such as /dev/zero, a FIFO: never
 * waited on), or is larger than kMaxTextFileBytes. Used by the loaders above
 * and by the board file reader. Allocates: the text.
 */
Result<std::string> readFileContents(const std::string &path);

} /* namespace dockpose */

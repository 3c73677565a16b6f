/* SPDX-License-Identifier: MIT */
/*
 * Frames of a planar calibration grid of bright dots with known intrinsics, for
 * `dockpose calibrate` (tools/dockpose/calibrate.h): the dots are discs on the grid's
 * plane z = 0, drawn by casting 4 x 4 rays per pixel through the camera model (distortion
 * included) onto the plane, so a pixel's level is the fraction of its area a dot covers;
 * then Gaussian read noise. The same rendering as tests/algo/test_calibrate_cv.cpp's, for
 * tools that need a calibration made the product's way (tools/paper-study).
 *
 * Allocates: freely (the image, a level buffer). Host tools and tests only.
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "algo/camera_model.h"
#include "algo/image.h"
#include "algo/pose.h"
#include "algo/synth/rng.h"

namespace dockpose {

struct DotGrid {
	int rows = 7;
	int cols = 10;
	double spacing_mm = 20.0;
	/* Dots at most a quarter of the pitch across (docs/calibration.md). */
	double dot_radius_mm = 2.5;

	/* OpenCV's asymmetric circle grid: row i shifted by i % 2 spacings, 2 spacings apart
	 * along a row (tools/dockpose/calibrate.h). */
	bool asymmetric = false;

	Eigen::Vector3d point(int i, int j) const
	{
		const double x = asymmetric ? (2 * j + i % 2) * spacing_mm : j * spacing_mm;
		return { x, i * spacing_mm, 0.0 };
	}
	/* Width of the grid along its rows, mm. */
	double widthMm() const
	{
		return asymmetric ? (2 * (cols - 1) + 1) * spacing_mm : (cols - 1) * spacing_mm;
	}
	Eigen::Vector3d centre() const
	{
		return { 0.5 * widthMm(), 0.5 * (rows - 1) * spacing_mm, 0.0 };
	}
	/* The grid file of `dockpose calibrate`. */
	std::string json() const;
};

/*
 * The grid seen from `pose` (grid plane -> camera), background 15 levels, dots 200 above
 * it, Gaussian read noise of noise_sigma levels; `extras`: more dots beside the grid, at
 * these grid-plane points (mm). An empty image when a dot's rim is behind the camera or
 * outside the lens's valid field. Allocates: the image.
 */
Image renderDotGrid(const CameraModel &camera, const DotGrid &grid, const Pose &pose,
		    double noise_sigma, std::uint64_t seed,
		    const std::vector<Eigen::Vector3d> &extras = {});

/* Every dot in front of the camera and at least margin_px inside the frame. */
bool dotGridInFrame(const CameraModel &camera, const DotGrid &grid, const Pose &pose,
		    double margin_px);

/*
 * View n of a calibration set: the grid tilted by 30-45 degrees from facing the camera
 * (about an axis in its plane that turns from view to view), rolled, its centre aimed at
 * one of nine places of the frame (corners, edges, centre) at a range where it spans about
 * 45 % of the frame; pulled towards the centre until every dot is 10 px inside the frame.
 * centre_only: aimed at the centre whatever n. False when no placement fits.
 */
bool dotGridView(const CameraModel &camera, const DotGrid &grid, int n, synth::Rng *rng, Pose *pose,
		 bool centre_only = false);

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
/*
 * The frame path: one 8-bit frame in, one PoseResult out.
 *
 * Pipeline owns every buffer, sized at construction from the camera and the
 * target model; process() never allocates (proved by tests/algo/test_no_alloc).
 */
#pragma once

#include <algorithm>
#include <cstdint>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "algo/blob_detector.h"
#include "algo/camera_model.h"
#include "algo/correspondence.h"
#include "algo/pose.h"
#include "algo/target_model.h"

namespace dockpose {

enum class PoseStatus : std::uint8_t {
	Found = 0,
	NoFrame, /* invalid view or wrong size */
	TooCluttered, /* component overflow */
	TooFewBlobs, /* fewer than 4 candidates */
	NoMatch, /* no hypothesis passed verification */
	Ambiguous, /* two different poses explain the image equally well */
	RefineFailed, /* refinement diverged or left a large error */
	Imprecise, /* the pose's own covariance puts its error beyond the precision required */
};

const char *poseStatusName(PoseStatus status);

struct PoseResult {
	bool found = false;
	PoseStatus status = PoseStatus::NoFrame;
	Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
	Eigen::Vector3d t_mm = Eigen::Vector3d::Zero();
	Eigen::Quaterniond q = Eigen::Quaterniond::Identity(); /* w >= 0 */
	Eigen::Vector3d rpy_deg = Eigen::Vector3d::Zero(); /* roll, pan, tilt */
	double rms_px = 0.0;
	/*
	 * log10 of the number of false alarms of the accepted match: the expected
	 * number of equally good chance matches in this frame (a-contrario; see
	 * algo/correspondence.h). Accepted poses have log10_nfa <= the configured
	 * bound (default -4); more negative is more certain.
	 */
	double log10_nfa = 0.0;
	int leds_used = 0;
	std::uint32_t led_mask = 0; /* bit i: model LED i matched */
	Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
	Eigen::Vector3d sigma_t_mm = Eigen::Vector3d::Zero();
	Eigen::Vector3d sigma_rpy_deg = Eigen::Vector3d::Zero();
	bool tracked = false; /* found by the tracking path (prediction from the last pose) */
	int windows = 0; /* regions of interest read (0: the whole frame was read) */
	int blobs = 0; /* candidates after the shape filter */
	int hypotheses = 0; /* hypotheses scored */
	int verified = 0; /* of them, verified against every predicted LED */
	BlobStats blob_stats;
};

struct PipelineConfig {
	ThresholdConfig threshold;
	BlobFilterConfig blob_filter;
	CorrespondenceConfig correspondence;
	RefineOptions refine;
	bool tracking = true; /* predict from the last pose, full search when lost */
	/*
	 * Tracking with regions of interest: while a pose is tracked, only
	 * windows around the predicted LEDs are read, and every
	 * full_frame_every-th frame the whole frame, to re-measure the
	 * background, the noise and the clutter density that acceptance uses.
	 * A window whose side cuts a spot (clutter at its edge, a seam between
	 * two) is widened to hold that spot and read again, a few times
	 * (Pipeline::kMaxWidenings); a frame whose windows still fail (a spot
	 * cut, too few blobs, no tracked match) is read whole at once, as
	 * without windows.
	 * 1: the whole frame every frame.
	 *
	 * A window is centred where the LED's last image motion carries it
	 * (constant velocity in the image) and reaches beyond the LEDs' last spot
	 * radius by twice that motion plus roi_margin_px (pixels): a change of
	 * speed up to the speed itself stays inside. After the first pose of a
	 * track (no motion measured yet) it covers the tracked match's gate.
	 */
	int full_frame_every = 30;
	double roi_margin_px = 6.0;
	/*
	 * The precision a reported pose must have: the 99 % bound of its error,
	 * from its own covariance (3.37 sigma, the 99 % point of chi^2 with 3
	 * degrees of freedom, along the worst axis of the rotation's and of the
	 * translation's block), within max_rotation_error_deg (degrees) and
	 * max(min_translation_error_mm, max_translation_error_frac x range).
	 * A pose the image determines less well (far, few LEDs, blurred spots)
	 * is refused as Imprecise: right or not, it could be off by more than the
	 * arm may be told. Defaults: issue 8's bar for a correct pose.
	 * max_rotation_error_deg 0, max_translation_error_frac 0: no such limit.
	 */
	double max_rotation_error_deg = 2.0;
	double max_translation_error_frac = 0.02;
	double min_translation_error_mm = 5.0;
};

class Pipeline
{
public:
	/* Allocates: here, every buffer the frame path needs. */
	Pipeline(const TargetModel &target, const CameraIntrinsics &camera,
		 const PipelineConfig &config = {});

	/* One frame -> one pose. Allocates: never. */
	const PoseResult &process(const ImageView &frame);

	/* Forget the tracked pose (next frame runs the full search). */
	void reset();

	/*
	 * Read the next `frames` frames whole, not through windows: the light
	 * changed (exposure, gain, strobe mode), so the last whole frame's
	 * background and noise no longer hold. Allocates: never.
	 */
	void readWhole(int frames) { whole_frames_ = std::max(whole_frames_, frames); }

	const CameraModel &camera() const { return camera_; }
	const TargetModel &target() const { return target_; }
	const StaticVector<Blob, kMaxCandidates> &blobs() const { return blobs_; }
	const PoseResult &last() const { return result_; }

private:
	/* The regions-of-interest pass of one tracked frame; false: read the whole frame. */
	bool processWindows(const ImageView &frame);
	void mergeWindows();
	/* A window that cuts a spot is widened at most this often a frame (processWindows()). */
	static constexpr int kMaxWidenings = 3;
	void setFound(const CorrespondenceResult &match);
	bool preciseEnough(const CorrespondenceResult &match) const;

	TargetModel target_;
	CameraModel camera_;
	PipelineConfig config_;
	BlobDetector detector_;
	Correspondence correspondence_;
	StaticVector<Blob, kMaxCandidates> blobs_;
	PoseResult result_;
	bool have_track_ = false;
	Pose track_pose_;
	bool have_previous_ = false; /* the pose of the frame before track_pose_'s */
	Pose previous_pose_;
	/* The pose the next frame should show (constant velocity when it was measured). */
	Pose predictedPose() const;
	/* Regions of interest: this frame's windows, the last whole-frame pass, the spots' radius. */
	StaticVector<PixelWindow, kMaxLeds> windows_;
	int frames_since_full_ = 0;
	int whole_frames_ = 0; /* readWhole(): frames still to read whole */
	int frame_candidates_ = 0;
	double spot_radius_px_ = 0.0;
};

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
#include "algo/pipeline.h"

#include <cmath>
#include <numbers>

#include <Eigen/Eigenvalues>

namespace dockpose {

const char *poseStatusName(PoseStatus status)
{
	switch (status) {
	case PoseStatus::Found:
		return "found";
	case PoseStatus::NoFrame:
		return "no_frame";
	case PoseStatus::TooCluttered:
		return "too_cluttered";
	case PoseStatus::TooFewBlobs:
		return "too_few_blobs";
	case PoseStatus::NoMatch:
		return "no_match";
	case PoseStatus::Ambiguous:
		return "ambiguous";
	case PoseStatus::RefineFailed:
		return "error_too_large";
	case PoseStatus::Imprecise:
		return "imprecise";
	}
	return "unknown";
}

Pipeline::Pipeline(const TargetModel &target, const CameraIntrinsics &camera,
		   const PipelineConfig &config)
	: target_(target),
	  camera_(camera),
	  config_(config),
	  detector_(camera.width, camera.height, config.threshold, config.blob_filter),
	  correspondence_(target, camera_, [&config] {
		  CorrespondenceConfig c = config.correspondence;
		  c.refine = config.refine;
		  return c;
	  }())
{
}

void Pipeline::reset()
{
	have_track_ = false;
}

namespace {

bool overlapOrTouch(const PixelWindow &a, const PixelWindow &b)
{
	return a.x0 <= b.x1 && b.x0 <= a.x1 && a.y0 <= b.y1 && b.y0 <= a.y1;
}

PixelWindow boundingBox(const PixelWindow &a, const PixelWindow &b)
{
	return PixelWindow{ std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1),
			    std::max(a.y1, b.y1) };
}

} /* namespace */

/*
 * PipelineConfig::max_rotation_error_deg and the translation's limit, against
 * the 99 % bound of the pose's error along the worst axis of each block of its
 * covariance ((tx, ty, tz) mm, (rx, ry, rz) rad).
 */
bool Pipeline::preciseEnough(const CorrespondenceResult &match) const
{
	/* sqrt of the 99 % point of chi^2 with 3 degrees of freedom (11.345). */
	constexpr double kBound99 = 3.3682;
	const Eigen::Matrix<double, 6, 6> &c = match.refined.covariance;
	/*
	 * Is k sigma along the worst axis of the block within the limit? The
	 * trace bounds the largest eigenvalue from above, so a pose well inside
	 * (every tracked frame, mostly) needs no eigen-decomposition.
	 */
	auto within = [](const Eigen::Matrix3d &block, double limit) {
		const double var_limit = limit * limit / (kBound99 * kBound99);
		if (block.trace() <= var_limit)
			return true;
		const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(block,
									Eigen::EigenvaluesOnly);
		return es.eigenvalues().maxCoeff() <= var_limit;
	};
	if (config_.max_rotation_error_deg > 0.0 &&
	    !within(c.block<3, 3>(3, 3), config_.max_rotation_error_deg * std::numbers::pi / 180.0))
		return false;
	if (config_.max_translation_error_frac > 0.0 &&
	    !within(c.block<3, 3>(0, 0),
		    std::max(config_.min_translation_error_mm,
			     config_.max_translation_error_frac * match.refined.pose.t_mm.norm())))
		return false;
	return true;
}

void Pipeline::setFound(const CorrespondenceResult &match)
{
	const Pose &pose = match.refined.pose;
	result_.found = true;
	result_.status = PoseStatus::Found;
	result_.tracked = match.tracked;
	result_.R = pose.R;
	result_.t_mm = pose.t_mm;
	result_.q = quaternionFromRotation(pose.R);
	result_.rpy_deg = rollPanTiltDegFromRotation(pose.R);
	result_.rms_px = match.refined.rms_px;
	result_.log10_nfa = match.log10_nfa;
	result_.leds_used = static_cast<int>(match.match.pairs.size());
	result_.led_mask = match.match.led_mask;
	result_.covariance = match.refined.covariance;
	for (int i = 0; i < 3; ++i)
		result_.sigma_t_mm[i] = std::sqrt(std::max(0.0, result_.covariance(i, i)));
	result_.sigma_rpy_deg = rollPanTiltSigmaDeg(pose.R, result_.covariance);

	/* The largest matched spot: the windows of the next frames must hold it whole. */
	spot_radius_px_ = 0.0;
	for (const auto &pair : match.match.pairs) {
		const Blob &b = blobs_[static_cast<std::size_t>(pair[1])];
		const int extent = std::max(b.x_max - b.x_min + 1, b.y_max - b.y_min + 1);
		spot_radius_px_ = std::max(spot_radius_px_, 0.5 * extent);
	}
	/* Consecutive poses measure the image motion the next windows follow. */
	have_previous_ = have_track_;
	previous_pose_ = track_pose_;
	track_pose_ = pose;
	have_track_ = true;
}

/*
 * The last pose moved on by the last frame-to-frame motion, in the camera's
 * frame (x' = turn x + shift from the frame before to the last): the tracked
 * match's start, so that its refinement starts where the windows are centred.
 */
Pose Pipeline::predictedPose() const
{
	if (!have_previous_)
		return track_pose_;
	/* The last frame-to-frame rotation, applied once more. */
	const Eigen::Matrix3d turn = track_pose_.R * previous_pose_.R.transpose();
	Pose next;
	next.R = turn * track_pose_.R;
	next.t_mm = track_pose_.t_mm + turn * (track_pose_.t_mm - previous_pose_.t_mm);
	return next;
}

/* Windows that overlap or touch become their bounding box (a spot on the seam stays whole). */
void Pipeline::mergeWindows()
{
	for (bool merged = true; merged;) {
		merged = false;
		for (std::size_t a = 0; a < windows_.size() && !merged; ++a) {
			for (std::size_t b = a + 1; b < windows_.size(); ++b) {
				if (!overlapOrTouch(windows_[a], windows_[b]))
					continue;
				windows_[a] = boundingBox(windows_[a], windows_[b]);
				windows_[b] = windows_.back();
				windows_.pop_back();
				merged = true;
				break;
			}
		}
	}
}

bool Pipeline::processWindows(const ImageView &frame)
{
	const CameraIntrinsics &k = camera_.intrinsics();
	const std::uint32_t leds = correspondence_.trackedLeds(track_pose_);
	/* Without measured motion: the gate, a spot reaching over its edge still whole inside. */
	const double gate_half = correspondence_.trackGatePx(track_pose_) + spot_radius_px_ + 2.0;
	windows_.clear();
	for (std::size_t i = 0; i < target_.points_mm.size(); ++i) {
		if (!(leds & (1u << i)))
			continue;
		Eigen::Vector2d uv, before;
		if (!camera_.project(track_pose_.apply(target_.points_mm[i]), &uv))
			continue;
		double half = gate_half;
		if (have_previous_ &&
		    camera_.project(previous_pose_.apply(target_.points_mm[i]), &before)) {
			const Eigen::Vector2d motion = uv - before;
			uv += motion;
			half = std::min(half, spot_radius_px_ + 2.0 * motion.norm() +
						      config_.roi_margin_px);
		}
		const int h = static_cast<int>(std::ceil(half));
		const int u = static_cast<int>(std::lround(uv.x()));
		const int v = static_cast<int>(std::lround(uv.y()));
		PixelWindow w{ std::max(u - h, 0), std::max(v - h, 0), std::min(u + h + 1, k.width),
			       std::min(v + h + 1, k.height) };
		if (w.x0 < w.x1 && w.y0 < w.y1)
			windows_.push_back(w);
	}
	mergeWindows();
	if (windows_.size() == 0)
		return false;

	/*
	 * A spot a window's side cuts (clutter at a window's edge or on the seam
	 * between two): that window widened to the spot's reach
	 * (BlobStats::cut_reach), merged with any it now touches, and read again;
	 * after kMaxWidenings, the whole frame.
	 */
	BlobStats stats;
	bool ok = false;
	for (int widenings = 0;; ++widenings) {
		ok = detector_.detectWindows(frame, windows_.data(), windows_.size(), &blobs_,
					     &stats);
		if (ok || !stats.window_cut || widenings == kMaxWidenings)
			break;
		/* The cut component lies inside its window, so some window touches its reach. */
		for (PixelWindow &w : windows_)
			if (overlapOrTouch(w, stats.cut_reach)) {
				w = boundingBox(w, stats.cut_reach);
				break;
			}
		mergeWindows();
	}
	if (!ok || blobs_.size() < 4)
		return false;
	double area = 0.0;
	for (const PixelWindow &w : windows_)
		area += static_cast<double>(w.x1 - w.x0) * (w.y1 - w.y0);
	CorrespondenceResult match;
	const Pose prediction = predictedPose();
	if (!correspondence_.solve(blobs_, &prediction, &match,
				   SolveContext{ area, frame_candidates_ }) ||
	    !match.found)
		return false;
	result_.blob_stats = stats;
	result_.blobs = static_cast<int>(blobs_.size());
	result_.hypotheses = match.hypotheses;
	result_.verified = match.verified;
	result_.windows = static_cast<int>(windows_.size());
	if (!preciseEnough(match))
		return false;
	setFound(match);
	return true;
}

const PoseResult &Pipeline::process(const ImageView &frame)
{
	result_ = PoseResult{};
	const CameraIntrinsics &k = camera_.intrinsics();
	if (!frame.valid() || frame.width != k.width || frame.height != k.height) {
		result_.status = PoseStatus::NoFrame;
		have_track_ = false;
		return result_;
	}

	const bool whole = whole_frames_ > 0;
	whole_frames_ = std::max(whole_frames_ - 1, 0);
	if (config_.tracking && have_track_ && !whole &&
	    frames_since_full_ + 1 < config_.full_frame_every) {
		if (processWindows(frame)) {
			++frames_since_full_;
			return result_;
		}
		result_ = PoseResult{};
	}

	frames_since_full_ = 0;
	blobs_.clear();
	if (!detector_.detect(frame, &blobs_, &result_.blob_stats)) {
		result_.status = result_.blob_stats.component_overflow ? PoseStatus::TooCluttered
								       : PoseStatus::NoFrame;
		have_track_ = false;
		return result_;
	}
	result_.blobs = static_cast<int>(blobs_.size());
	frame_candidates_ = result_.blobs;
	if (blobs_.size() < 4) {
		result_.status = PoseStatus::TooFewBlobs;
		have_track_ = false;
		return result_;
	}

	CorrespondenceResult match;
	const bool tracking = config_.tracking && have_track_;
	const Pose predicted = tracking ? predictedPose() : Pose{};
	const Pose *prediction = tracking ? &predicted : nullptr;
	correspondence_.solve(blobs_, prediction, &match);
	result_.hypotheses = match.hypotheses;
	result_.verified = match.verified;
	if (!match.found) {
		result_.status = match.ambiguous	 ? PoseStatus::Ambiguous
				 : match.error_too_large ? PoseStatus::RefineFailed
							 : PoseStatus::NoMatch;
		have_track_ = false;
		return result_;
	}
	if (!preciseEnough(match)) {
		result_.status = PoseStatus::Imprecise;
		have_track_ = false;
		return result_;
	}
	setFound(match);
	return result_;
}

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
#include "algo/pipeline.h"

#include <cmath>

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
	}
	return "unknown";
}

Pipeline::Pipeline(const TargetModel &target, const CameraIntrinsics &camera, const PipelineConfig &config)
	: target_(target), camera_(camera), config_(config),
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

const PoseResult &Pipeline::process(const ImageView &frame)
{
	result_ = PoseResult{};
	const CameraIntrinsics &k = camera_.intrinsics();
	if (!frame.valid() || frame.width != k.width || frame.height != k.height) {
		result_.status = PoseStatus::NoFrame;
		have_track_ = false;
		return result_;
	}

	blobs_.clear();
	if (!detector_.detect(frame, &blobs_, &result_.blob_stats)) {
		result_.status = result_.blob_stats.component_overflow ? PoseStatus::TooCluttered : PoseStatus::NoFrame;
		have_track_ = false;
		return result_;
	}
	result_.blobs = static_cast<int>(blobs_.size());
	if (blobs_.size() < 4) {
		result_.status = PoseStatus::TooFewBlobs;
		have_track_ = false;
		return result_;
	}

	CorrespondenceResult match;
	const Pose *prediction = (config_.tracking && have_track_) ? &track_pose_ : nullptr;
	correspondence_.solve(blobs_, prediction, &match);
	result_.hypotheses = match.hypotheses;
	if (!match.found) {
		result_.status = match.ambiguous	   ? PoseStatus::Ambiguous
				 : match.error_too_large ? PoseStatus::RefineFailed
							 : PoseStatus::NoMatch;
		have_track_ = false;
		return result_;
	}

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

	track_pose_ = pose;
	have_track_ = true;
	return result_;
}

} /* namespace dockpose */

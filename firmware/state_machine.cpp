/* SPDX-License-Identifier: MIT */
#include "firmware/state_machine.h"

namespace dockpose::firmware {

namespace {

int saturatingIncrement(int v)
{
	return v < (1 << 30) ? v + 1 : v;
}

} /* namespace */

SensorState StateMachine::update(const StateInputs &in)
{
	if (state_ == SensorState::Shutdown)
		return state_;

	frames_since_valid_ = in.pose_valid ? 0 : saturatingIncrement(frames_since_valid_);
	frames_since_degrading_ =
		(in.faults & kDegradingFaults) ? 0 : saturatingIncrement(frames_since_degrading_);

	if (in.faults & kFatalFaults) {
		state_ = SensorState::Fault;
		return state_;
	}

	const bool lost = frames_since_valid_ >= lost_after_frames_;
	const bool recently_degraded = frames_since_degrading_ <= degraded_hold_frames_;
	if (lost) {
		state_ = SensorState::Searching;
	} else if (in.pose_valid) {
		state_ = recently_degraded ? SensorState::Degraded : SensorState::Tracking;
	} else {
		/* Lost for fewer than lost_after_frames frames: coasting. From searching or
		 * fault a single miss keeps searching. */
		if (state_ == SensorState::Tracking || state_ == SensorState::Degraded)
			state_ = SensorState::Degraded;
		else
			state_ = SensorState::Searching;
	}
	return state_;
}

} /* namespace dockpose::firmware */

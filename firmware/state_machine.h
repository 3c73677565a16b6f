/* SPDX-License-Identifier: MIT */
/*
 * The sensor's state, as the arm controller sees it in every status frame:
 *
 *   startup ──► searching ◄──► tracking ◄──► degraded
 *                  ▲  │            │            │
 *                  │  └──────► fault ◄──────────┘
 *                  └────────────┘ (frames return)
 *
 *  - startup:   backends opening, before the first frame.
 *  - searching: no valid pose for `lost_after_frames` frames or more (or never).
 *  - tracking:  a valid pose this frame and nothing wrong.
 *  - degraded:  poses come (or were lost only for a few frames), but something
 *               is not right: camera frames dropped, the CAN queue overflowed,
 *               a strobe error, pose lost for < lost_after_frames frames; held
 *               for `degraded_hold_frames` frames after the last such event.
 *  - fault:     no usable frames: the camera stalls or fails, or the strobe
 *               dead-man switch tripped. No pose is valid in fault.
 *  - shutdown:  the last status frame before the daemon exits.
 *
 * Allocates: never.
 */
#pragma once

#include <cstdint>

#include "firmware/protocol/dockpose_can.h"

namespace dockpose::firmware {

using SensorState = can::SensorState;

struct StateInputs {
	bool pose_valid = false; /* this frame gave a valid pose */
	std::uint8_t faults = 0; /* can::fault bits active now */
};

class StateMachine
{
public:
	StateMachine(int lost_after_frames, int degraded_hold_frames)
		: lost_after_frames_(lost_after_frames),
		  degraded_hold_frames_(degraded_hold_frames)
	{
	}

	/* One processed frame (or one stall interval, with fault bits set). Returns the new state. */
	SensorState update(const StateInputs &in);
	/* The daemon is going down. */
	void shutdown() { state_ = SensorState::Shutdown; }

	SensorState state() const { return state_; }
	int framesSinceValid() const { return frames_since_valid_; }

	/* Faults that put the sensor into fault (no usable frames). */
	static constexpr std::uint8_t kFatalFaults = can::fault::kCameraStall |
						     can::fault::kCameraError;
	/* Faults that degrade an otherwise tracking sensor. */
	static constexpr std::uint8_t kDegradingFaults =
		can::fault::kStrobeError | can::fault::kCanTxOverflow | can::fault::kCanBusOff |
		can::fault::kFramesDropped | can::fault::kLoopOverrun;

private:
	int lost_after_frames_;
	int degraded_hold_frames_;
	SensorState state_ = SensorState::Startup;
	int frames_since_valid_ = 1 << 30;
	int frames_since_degrading_ = 1 << 30;
};

} /* namespace dockpose::firmware */

/* SPDX-License-Identifier: MIT */
/*
 * The sim board: the whole firmware on the host, for demos, tests and CI.
 * Frames come from the synthetic camera (the target rendered along a docking
 * approach, lit or unlit as the strobe really was during each exposure) or
 * from a folder of PGM frames; the strobe is recorded; CAN frames go to a
 * candump log (`dockposed --can-log FILE`) that can-utils and python-can read.
 */
#include <memory>

#include "board/board.h"
#include "board/sim/sim_board.h"
#include "hal/sim/file_can_bus.h"
#include "hal/sim/recording_strobe.h"
#include "hal/sim/replay_camera.h"
#include "hal/sim/synthetic_camera.h"

namespace dockpose::board {

namespace {

constexpr const char *kCameras[] = { "synthetic", "replay" };
constexpr const char *kStrobes[] = { "recording" };
constexpr const char *kCans[] = { "file" };

hal::Status wire(const BoardConfig &config, Backends *out)
{
	if (config.can.log_file.empty())
		return hal::Status::error(
			"can.log_file: the sim board writes CAN frames to a candump log; "
			"name one in the board file or with --can-log FILE");
	return wireSimulated(config, std::make_unique<hal::FileCanBus>(config.can.log_file), out);
}

} /* namespace */

hal::Status wireSimulated(const BoardConfig &config, std::unique_ptr<hal::CanBus> can,
			  Backends *out)
{
	auto strobe = std::make_unique<hal::RecordingStrobe>();
	out->strobe_control = std::make_unique<hal::StrobeController>(
		strobe.get(), config.camera.stall_timeout_ms);
	out->strobe = std::move(strobe);

	if (config.camera.backend == "synthetic") {
		out->camera = std::make_unique<hal::SyntheticCamera>(config.target_model,
								     config.camera_model,
								     config.camera.synthetic,
								     out->strobe_control.get());
	} else {
		out->camera = std::make_unique<hal::ReplayCamera>(config.camera.replay.folder,
								  config.camera.replay.loop);
	}

	out->can = std::move(can);
	return hal::Status::ok();
}

extern const BoardInfo kSimBoard;
const BoardInfo kSimBoard{
	"sim",
	"host simulation: synthetic or replayed frames, recording strobe, candump-log CAN",
	wire,
	kCameras,
	kStrobes,
	kCans
};

} /* namespace dockpose::board */

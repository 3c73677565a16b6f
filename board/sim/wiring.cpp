/* SPDX-License-Identifier: MIT */
/*
 * The sim board: the whole firmware on the host, for demos, tests and CI.
 * Frames come from the synthetic camera (the target rendered along a docking
 * approach, lit or unlit as the strobe really was during each exposure) or
 * from a folder of PGM frames; the strobe is recorded; CAN frames go to a
 * candump log (`dockposed --can-log FILE`) that can-utils and python-can read.
 */
#include <memory>

#include "algo/io/model_json.h"
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

/* The synthetic camera's scene from the board file's camera.synthetic section. */
hal::SyntheticScene syntheticScene(const firmware::SyntheticCameraConfig &s)
{
	hal::SyntheticScene scene{};
	for (int i = 0; i < 6; ++i) {
		scene.from[i] = s.from[i];
		scene.to[i] = s.to[i];
	}
	scene.duration_s = s.duration_s;
	scene.loop = s.loop;
	scene.reflections = s.reflections;
	scene.glints = s.glints;
	scene.hot_pixels = s.hot_pixels;
	scene.noise_sigma = s.noise_sigma;
	scene.seed = s.seed;
	return scene;
}

hal::Status wire(const firmware::BoardConfig &config, Backends *out)
{
	if (config.can.log_file.empty())
		return hal::Status::error(
			"can.log_file: the sim board writes CAN frames to a candump log; "
			"name one in the board file or with --can-log FILE");
	return wireSimulated(config, std::make_unique<hal::FileCanBus>(config.can.log_file), out);
}

} /* namespace */

hal::Status wireSimulated(const firmware::BoardConfig &config, std::unique_ptr<hal::CanBus> can,
			  Backends *out)
{
	auto strobe = std::make_unique<hal::RecordingStrobe>();
	out->strobe_control = std::make_unique<hal::StrobeController>(
		strobe.get(), config.camera.stall_timeout_ms);
	out->strobe = std::move(strobe);

	if (config.camera.backend == "synthetic") {
		auto target = loadTargetModel(config.pipeline.target);
		if (!target.ok())
			return hal::Status::error(target.error);
		auto intrinsics = loadCameraIntrinsics(config.camera.intrinsics);
		if (!intrinsics.ok())
			return hal::Status::error(intrinsics.error);
		const hal::SyntheticScene scene = syntheticScene(config.camera.synthetic);
		out->camera = std::make_unique<hal::SyntheticCamera>(
			target.value, intrinsics.value, scene, out->strobe_control.get());
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

/* SPDX-License-Identifier: MIT */
/*
 * The vm board: the real backends against the kernel's virtual drivers in a
 * QEMU guest (scripts/vm, docs/vm-tests.md): libcamera on vimc, libgpiod on a
 * gpio-sim chip labelled "dockpose-sim", SocketCAN on vcan0. The camera may
 * also be the replay camera, so a cross-built dockposed can be fed frames that
 * show the target while everything else stays real.
 */
#include <memory>

#include "board/board.h"
#include "hal/gpiod/gpiod_strobe.h"
#include "hal/libcamera/libcamera_camera.h"
#include "hal/sim/replay_camera.h"
#include "hal/socketcan/socketcan_bus.h"

namespace dockpose::board {

namespace {

constexpr const char *kCameras[] = { "libcamera", "replay" };
constexpr const char *kStrobes[] = { "gpiod" };
constexpr const char *kCans[] = { "socketcan" };

hal::Status wire(const BoardConfig &config, Backends *out)
{
	auto strobe = std::make_unique<hal::GpiodStrobe>(config.strobe);
	out->strobe_control = std::make_unique<hal::StrobeController>(
		strobe.get(), config.camera.stall_timeout_ms);
	out->strobe = std::move(strobe);
	if (config.camera.backend == "replay")
		out->camera = std::make_unique<hal::ReplayCamera>(config.camera.replay.folder,
								  config.camera.replay.loop);
	else
		out->camera = std::make_unique<hal::LibcameraCamera>();
	out->can = std::make_unique<hal::SocketCanBus>(config.can.interface, config.can.bitrate);
	return hal::Status::ok();
}

} /* namespace */

extern const BoardInfo kVmBoard;
const BoardInfo kVmBoard{
	"vm",	  "QEMU test board: libcamera on vimc (or replayed frames), gpio-sim strobe, vcan0",
	wire,	  kCameras,
	kStrobes, kCans
};

} /* namespace dockpose::board */

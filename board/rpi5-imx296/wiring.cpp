/* SPDX-License-Identifier: MIT */
/*
 * The reference board: Raspberry Pi 5, Raspberry Pi Global Shutter Camera
 * (Sony IMX296) through libcamera, the IR LED driver on a GPIO line through
 * libgpiod, and can0 (MCP2518FD HAT) through SocketCAN. Wiring notes:
 * board/rpi5-imx296/README.md.
 */
#include <memory>

#include "board/board.h"
#include "hal/gpiod/gpiod_strobe.h"
#include "hal/libcamera/libcamera_camera.h"
#include "hal/socketcan/socketcan_bus.h"

namespace dockpose::board {

namespace {

constexpr const char *kCameras[] = { "libcamera" };
constexpr const char *kStrobes[] = { "gpiod" };
constexpr const char *kCans[] = { "socketcan" };

hal::Status wire(const BoardConfig &config, Backends *out)
{
	auto strobe = std::make_unique<hal::GpiodStrobe>(config.strobe);
	out->strobe_control = std::make_unique<hal::StrobeController>(
		strobe.get(), config.camera.stall_timeout_ms);
	out->strobe = std::move(strobe);
	out->camera = std::make_unique<hal::LibcameraCamera>();
	out->can = std::make_unique<hal::SocketCanBus>(config.can.interface, config.can.bitrate);
	return hal::Status::ok();
}

} /* namespace */

extern const BoardInfo kRpi5Imx296Board;
const BoardInfo kRpi5Imx296Board{
	"rpi5-imx296",
	"Raspberry Pi 5 + IMX296 global-shutter camera, GPIO LED strobe, MCP2518FD can0",
	wire,
	kCameras,
	kStrobes,
	kCans
};

} /* namespace dockpose::board */

/* SPDX-License-Identifier: MIT */
/* The sim board's pieces that tests reuse when they wire simulated backends themselves. */
#pragma once

#include <memory>

#include "board/board.h"
#include "board/board_config.h"
#include "hal/can_bus.h"

namespace dockpose::board {

/*
 * The sim board's wiring with a CAN bus of the caller's choosing (the board itself uses the
 * candump-log bus; tests use the loopback bus): a RecordingStrobe with its controller, and the
 * synthetic or replay camera of camera.backend. Allocates: the backends.
 */
hal::Status wireSimulated(const BoardConfig &config, std::unique_ptr<hal::CanBus> can,
			  Backends *out);

} /* namespace dockpose::board */

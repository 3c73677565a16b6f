/* SPDX-License-Identifier: MIT */
/*
 * Boards: which backends a board uses, wired in one place per board
 * (board/<name>/wiring.cpp), chosen at build time (DOCKPOSE_BOARDS in CMake).
 * A board file (board/<name>/board.json) names its board; dockposed refuses a
 * file for a board it was not built with.
 *
 * Allocates: wiring allocates the backends (start-up only).
 */
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "board/board_config.h"
#include "hal/camera.h"
#include "hal/can_bus.h"
#include "hal/status.h"
#include "hal/strobe.h"

namespace dockpose::board {

/* Everything hardware-facing the daemon runs on; destroyed in reverse order. */
struct Backends {
	std::unique_ptr<hal::Strobe> strobe;
	std::unique_ptr<hal::StrobeController> strobe_control; /* drives `strobe` */
	std::unique_ptr<hal::Camera> camera;
	std::unique_ptr<hal::CanBus> can;
};

struct BoardInfo {
	const char *name;
	const char *description;
	/* Build the board's backends from a validated configuration (not yet opened). */
	hal::Status (*wire)(const BoardConfig &config, Backends *out);
	/* Backends the board accepts in its file, per section (checked by validation). */
	std::span<const char *const> cameras;
	std::span<const char *const> strobes;
	std::span<const char *const> cans;
};

/* The boards built into this binary. */
std::span<const BoardInfo> boards();
const BoardInfo *findBoard(const std::string &name);

/*
 * Every backend name a built board accepts in one section, in the boards'
 * order, each once: what a board file may name at all (firmware/config.cpp
 * validates with it); the named board's own list then decides (dockposed).
 * The boards' lists are the one place backend names are written.
 */
enum class BackendKind {
	Camera,
	Strobe,
	Can
};
std::vector<const char *> backendNames(BackendKind kind);

} /* namespace dockpose::board */

/* SPDX-License-Identifier: MIT */
/*
 * The board configuration: one JSON file per board, board/<name>/board.json,
 * read and validated before anything starts (docs/configuration.md documents
 * every key). Every bad value is reported with its JSON path and what was
 * expected ("camera.exposure_us: 0 is out of range [10, 1000000]"); all errors
 * are collected, not only the first.
 *
 * Relative file paths in the file (target, intrinsics, replay folder, CAN log)
 * are resolved against the directory of the configuration file.
 *
 * Allocates: freely (start-up only).
 */
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "board/board_config.h"

namespace dockpose::firmware {

/* The structs live in the board layer (board/board_config.h); validation here. */
using board::BoardConfig;
using board::CameraSection;
using board::CanSection;
using board::PipelineSection;
using board::ReplayCameraConfig;
using board::StrobeMode;
using board::strobeModeName;
using board::StrobeSection;
using board::SystemdSection;
using board::TrackMode;

struct ConfigResult {
	BoardConfig config;
	std::vector<std::string> errors; /* empty: valid */
	bool ok() const { return errors.empty(); }
};

/* Read, parse and validate a board file (checks referenced files exist and load). */
ConfigResult loadBoardConfig(const std::string &path);
/* Parse and validate JSON text; base_dir resolves relative paths. */
ConfigResult parseBoardConfig(const std::string &json_text, const std::string &base_dir);

/* The worst-case share of the bus (0..1, 1 = full) the sensor takes with this configuration:
 * a report with pose per camera frame (one DP_ReportFd with can.fd), the heartbeats, their MAC
 * frames when authenticated; at can.bitrate, worst-case stuffing. Allocates: never. */
double canBusLoad(const BoardConfig &config);

} /* namespace dockpose::firmware */

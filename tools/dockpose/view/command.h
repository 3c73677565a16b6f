/* SPDX-License-Identifier: MIT */
/*
 * The page's command (POST /api/command) as a DP_Command: the JSON object
 * {"enable": bool, "mode": "TRACK" | "SEARCH_ONLY", "strobe": "OFF" | "CONSTANT" |
 * "ALTERNATE" | "UNCHANGED", "exposure_us": 0..65535, "gain": 0..25.5}, every field
 * optional (absent: the CommandData default: enabled, track, strobe and exposure and
 * gain unchanged). The mode and strobe names are the header's (trackModeName(),
 * strobeModeName()). The view encodes the result with can::Encoder.
 *
 * Allocates: the error sentence only. Any thread.
 */
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "firmware/protocol/dockpose_can.h"

namespace dockpose::tool {

/* Fill *cmd from body; "" when it is a command, else what is wrong (cmd partly filled). */
std::string commandFromJson(const nlohmann::json &body, can::CommandData *cmd);

} /* namespace dockpose::tool */

/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/view/command.h"

#include <cstdint>

namespace dockpose::tool {

std::string commandFromJson(const nlohmann::json &body, can::CommandData *cmd)
{
	if (!body.is_object())
		return "the body is not a JSON object";
	if (body.contains("enable")) {
		if (!body["enable"].is_boolean())
			return "enable: not true or false";
		cmd->enable = body["enable"].get<bool>();
	}
	if (body.contains("mode")) {
		const std::string m = body["mode"].is_string() ? body["mode"].get<std::string>()
							       : "";
		bool known = false;
		for (int i = 0; i <= static_cast<int>(can::TrackMode::SearchOnly); ++i)
			if (m == can::trackModeName(static_cast<can::TrackMode>(i))) {
				cmd->mode = static_cast<can::TrackMode>(i);
				known = true;
			}
		if (!known)
			return "mode: not one of the DBC's track modes";
	}
	if (body.contains("strobe")) {
		const std::string m = body["strobe"].is_string() ? body["strobe"].get<std::string>()
								 : "";
		bool known = false;
		for (int i = 0; i <= static_cast<int>(can::StrobeMode::Unchanged); ++i)
			if (m == can::strobeModeName(static_cast<can::StrobeMode>(i))) {
				cmd->strobe = static_cast<can::StrobeMode>(i);
				known = true;
			}
		if (!known)
			return "strobe: not one of the DBC's strobe modes";
	}
	if (body.contains("exposure_us")) {
		if (!body["exposure_us"].is_number_integer())
			return "exposure_us: not an integer";
		const std::int64_t e = body["exposure_us"].get<std::int64_t>();
		if (e < 0 || e > 65535)
			return "exposure_us: outside 0..65535 (0: unchanged)";
		cmd->exposure_us = static_cast<std::uint16_t>(e);
	}
	if (body.contains("gain")) {
		if (!body["gain"].is_number())
			return "gain: not a number";
		const double g = body["gain"].get<double>();
		if (!(g >= 0.0 && g <= 25.5))
			return "gain: outside 0..25.5 (0: unchanged)";
		cmd->gain = g;
	}
	return "";
}

} /* namespace dockpose::tool */

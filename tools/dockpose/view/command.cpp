/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/view/command.h"

#include <cstdint>

#include "firmware/can_auth.h"
#include "tools/dockpose/view/view_state.h"

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

CommandSender::CommandSender(std::uint32_t base_id)
	: encoder_(base_id)
{
}

Status CommandSender::setKey(const std::array<std::uint8_t, can::kKeyBytes> &key)
{
	const std::lock_guard<std::mutex> lock(mutex_);
	if (!cmac_.setKey(key)) {
		encoder_.setAuthenticator(nullptr);
		return Status::error("OpenSSL has no AES-128 CMAC: commands cannot be signed");
	}
	/* Commands never advance the encoder's own freshness value (only a sensor's DP_Auth
	 * does): what a command carries is the sensor's value it answers. */
	encoder_.setAuthenticator(&cmac_);
	return Status::ok();
}

bool CommandSender::signing() const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	return encoder_.authenticating();
}

std::string CommandSender::encode(const can::CommandData &cmd, std::uint64_t sensor_freshness,
				  BusAlive bus_alive, can::RawFrame (&out)[can::kMaxCommandFrames],
				  int *count)
{
	const std::lock_guard<std::mutex> lock(mutex_);
	*count = 0;
	if (encoder_.authenticating()) {
		if (sensor_freshness == 0)
			return "no authenticated sensor frame verified yet (the sensor's key is "
			       "another, the sensor is keyless, or no heartbeat came yet)";
		if (sensor_freshness <= last_freshness_)
			return "the sensor's freshness value has not moved since the last command "
			       "(it takes one command per DP_Auth)";
	}
	if (bus_alive.command >= 0)
		encoder_.continueAliveAfter(can::kCommand,
					    static_cast<std::uint8_t>(bus_alive.command));
	if (bus_alive.command_auth >= 0)
		encoder_.continueAliveAfter(can::kCommandAuth,
					    static_cast<std::uint8_t>(bus_alive.command_auth));
	*count = encoder_.encodeCommand(cmd, sensor_freshness, out);
	if (encoder_.authenticating()) {
		if (encoder_.macFailed()) {
			*count = 0;
			return "the command's MAC could not be computed (OpenSSL)";
		}
		last_freshness_ = sensor_freshness;
	}
	return "";
}

Status useCanKey(const std::string &path, ViewState *state, CommandSender *sender)
{
	std::array<std::uint8_t, can::kKeyBytes> key{};
	Status result = firmware::loadCanKey(path, &key);
	if (result)
		result = state->setKey(key);
	if (result)
		result = sender->setKey(key);
	key.fill(0);
	return result;
}

} /* namespace dockpose::tool */

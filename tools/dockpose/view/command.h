/* SPDX-License-Identifier: MIT */
/*
 * The page's command (POST /api/command) as a DP_Command: the JSON object
 * {"enable": bool, "mode": "TRACK" | "SEARCH_ONLY", "strobe": "OFF" | "CONSTANT" |
 * "ALTERNATE" | "UNCHANGED", "exposure_us": 0..65535, "gain": 0..25.5}, every field
 * optional (absent: the CommandData default: enabled, track, strobe and exposure and
 * gain unchanged). The mode and strobe names are the header's (trackModeName(),
 * strobeModeName()). The view encodes the result with a CommandSender.
 *
 * CommandSender: the view's sending path, a can::Encoder whose alive counters
 * go on from the last DP_Command and DP_CommandAuth on the bus, whoever sent
 * them (ViewState::commandAliveOnBus(): the arm controller may command the
 * sensor too, and the sensor refuses a repeated counter). Without a key a command is the bare
 * DP_Command, which a keyed sensor refuses. With one (useCanKey: `dockpose
 * view --key FILE`) it is DP_Command and DP_CommandAuth, whose MAC covers
 * the command and the newest sensor freshness value the view verified
 * (ViewState::sensorFreshness(); docs/can-protocol.md, "Authentication").
 * The sensor takes a signed command only if that value is one of its own
 * last 256 and newer than its last command's, so the sender signs nothing
 * before a value was verified and answers each value once: at most one
 * command per sensor DP_Auth (10 to 60 a second).
 *
 * Allocates: commandFromJson() and encode() their error sentences only;
 * setKey() OpenSSL's context (once). Threads: commandFromJson() any;
 * CommandSender's calls any (one mutex).
 */
#pragma once

#include <array>
#include <cstdint>
#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "algo/status.h"
#include "firmware/protocol/dockpose_can.h"
#include "firmware/protocol/dockpose_can_cmac.h"
#include "tools/dockpose/view/view_state.h"

namespace dockpose::tool {

/* Fill *cmd from body; "" when it is a command, else what is wrong (cmd partly filled). */
std::string commandFromJson(const nlohmann::json &body, can::CommandData *cmd);

class CommandSender
{
public:
	explicit CommandSender(std::uint32_t base_id);
	CommandSender(const CommandSender &) = delete;
	CommandSender &operator=(const CommandSender &) = delete;

	/* Sign every command from now on with this key; an error when OpenSSL has no
	 * AES-128 CMAC (then nothing is signed). */
	Status setKey(const std::array<std::uint8_t, can::kKeyBytes> &key);
	bool signing() const;

	/*
	 * cmd's frames into out[0..*count): DP_Command, and with a key DP_CommandAuth
	 * answering sensor_freshness (ViewState::sensorFreshness()), their alive
	 * counters after bus_alive's (ViewState::commandAliveOnBus()). "" when they are
	 * ready to send, else why not (nothing written, no counter moved): with a key, no
	 * sensor value verified yet (0), or one not newer than the last command's (the
	 * sensor would refuse it as a replay: wait for its next DP_Auth).
	 */
	std::string encode(const can::CommandData &cmd, std::uint64_t sensor_freshness,
			   BusAlive bus_alive, can::RawFrame (&out)[can::kMaxCommandFrames],
			   int *count);

private:
	mutable std::mutex mutex_;
	can::Encoder encoder_;
	can::OpensslCmac cmac_;
	std::uint64_t last_freshness_ = 0; /* the value the last signed command answered */
};

/*
 * `dockpose view --key FILE`: the CAN key read with the sensor's own reader
 * (firmware::loadCanKey: 32 hex digits, a regular file of mode 0600/0400
 * owned by root or this user), given to the view's state (it verifies the
 * sensor's frames, which is where the freshness values come from) and to the
 * sender (it signs commands). The key bytes are wiped here once both have
 * it. An error names the file and the problem.
 */
Status useCanKey(const std::string &path, ViewState *state, CommandSender *sender);

} /* namespace dockpose::tool */

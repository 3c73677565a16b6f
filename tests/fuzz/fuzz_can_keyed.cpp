/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the keyed decoders (protocol 3 authentication) fed sequences
 * of frames — the controller's can::Decoder with a key, and the sensor's
 * command decoder checking commands against a keyed sensor encoder that the
 * input makes send reports and heartbeats in between. Frames are our ids with
 * valid CRCs unless the input says otherwise, so only the MAC and freshness
 * rules stand in the way.
 *
 * Oracle (docs/can-protocol.md, "Authentication"):
 *  - no crash, no sanitizer report, whatever arrives;
 *  - the controller takes a report or heartbeat only at a DP_Auth frame, and
 *    every one it takes has a freshness value above the one before (nothing
 *    is taken twice), whose low 16 bits are the DP_Auth's;
 *  - the sensor takes a command only at a DP_CommandAuth frame, answering a
 *    freshness value the sensor has sent, at most 256 DP_Auth back, and above
 *    the previous command's; and every genuine command (the harness's own
 *    encoder, with the key) that answers the sensor's latest value is taken.
 * libFuzzer may learn a MAC from the decoder's comparison (its compare
 * tracing sees both sides): that is why the oracle checks the rules of what is
 * taken rather than "nothing is taken".
 */
#include <cstddef>
#include <cstdint>

#include "firmware/protocol/dockpose_can_cmac.h"
#include "tests/fuzz/can_fuzz.h"

namespace {

using namespace dockpose;
using Event = can::Decoder::Event;

constexpr std::array<std::uint8_t, can::kKeyBytes> kKey = { 0x10, 0x32, 0x54, 0x76, 0x98, 0xba,
							    0xdc, 0xfe, 0x01, 0x23, 0x45, 0x67,
							    0x89, 0xab, 0xcd, 0xef };

can::OpensslCmac &mac()
{
	static can::OpensslCmac cmac;
	static const bool keyed = cmac.setKey(kKey);
	FUZZ_CHECK(keyed, "OpenSSL has AES-128 CMAC");
	return cmac;
}

} /* namespace */

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	fuzz::FuzzInput in(data, size);
	const std::uint32_t base_id = fuzz::readBaseId(in);
	can::Encoder sensor(base_id);
	sensor.setAuthenticator(&mac(), std::uint64_t{ in.u16() } << 32);
	can::Decoder controller(base_id);
	controller.setAuthenticator(&mac());
	can::Decoder command_side(base_id);
	command_side.setAuthenticator(&mac());
	command_side.setCommandFreshness(&sensor, 256);
	can::Encoder arm(base_id);
	arm.setAuthenticator(&mac());

	std::uint64_t last_taken = 0;
	std::uint64_t last_command = 0;
	bool command_taken = false;
	while (!in.empty()) {
		const std::uint8_t op = in.u8();
		if ((op & 0x0f) == 0) {
			/* The sensor sends: a heartbeat group or a report, fed to the controller. */
			can::RawFrame out[can::kMaxReportFrames];
			int n;
			if (op & 0x10) {
				n = sensor.encodeHeartbeat(can::HeartbeatData{}, out);
			} else {
				can::StatusData st;
				st.pose_valid = (op & 0x20) != 0;
				can::PoseData pose;
				pose.t_mm[2] = 500;
				n = sensor.encodeReport(st, &pose, out);
			}
			for (int i = 0; i < n; ++i)
				(void)controller.feed(out[i]);
			continue;
		}
		if ((op & 0x0f) == 1) {
			/* A genuine command answering the sensor's latest value. */
			can::RawFrame out[can::kMaxCommandFrames];
			const int n =
				arm.encodeCommand(can::CommandData{}, sensor.freshness(), out);
			FUZZ_CHECK(n == 2, "a keyed command has its MAC frame");
			/* An attacker's frame with the next alive counter can spoil it (refused as
			 * stale): a denial of service the protocol does not claim to prevent. */
			const Event e0 = command_side.feed(out[0]);
			const Event e = command_side.feed(out[1]);
			const bool spoiled =
				e0 == Event::Rejected ||
				(e == Event::Rejected &&
				 command_side.lastError() == can::FrameError::StaleAlive);
			const bool fresh = !command_taken || sensor.freshness() > last_command;
			if (fresh && !spoiled) {
				FUZZ_CHECK(e == Event::Command,
					   "a genuine, fresh command is taken");
			}
			if (e == Event::Command) {
				last_command = sensor.freshness();
				command_taken = true;
			}
			continue;
		}
		/* An attacker's frame, to both decoders. */
		const can::RawFrame f = fuzz::readFrame<fuzz::CrcProtocol>(in, base_id);
		const Event to_controller = controller.feed(f);
		if (to_controller == Event::Report || to_controller == Event::Heartbeat) {
			FUZZ_CHECK(f.id == base_id + can::kAuth, "taken only at a DP_Auth");
			FUZZ_CHECK(controller.freshness() > last_taken,
				   "a freshness value is taken once");
			FUZZ_CHECK((controller.freshness() & 0xffff) ==
					   can::detail::getRaw(f.data, can::layout::kAuthFreshness),
				   "the DP_Auth's low 16 bits are the value taken");
			last_taken = controller.freshness();
		}
		FUZZ_CHECK(to_controller != Event::Command, "the controller takes no command");
		const Event to_sensor = command_side.feed(f);
		if (to_sensor == Event::Command) {
			FUZZ_CHECK(f.id == base_id + can::kCommandAuth,
				   "taken only at a DP_CommandAuth");
			const std::uint64_t current = sensor.freshness();
			std::uint64_t echo =
				(current & ~std::uint64_t{ 0xffff }) |
				can::detail::getRaw(f.data, can::layout::kCommandFreshness);
			if (echo > current)
				echo -= 0x10000;
			FUZZ_CHECK(current - echo < 256,
				   "the command answers one of the last 256 values");
			FUZZ_CHECK(!command_taken || echo > last_command,
				   "each command answers a newer value");
			last_command = echo;
			command_taken = true;
		}
	}
	return 0;
}

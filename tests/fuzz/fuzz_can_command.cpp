/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the sensor's side of the CAN protocol, command frames as
 * dockposed receives them (firmware/daemon.cpp, Daemon::handleCommands and
 * applyCommand), from a hostile bus.
 *
 * Each frame is a hal::CanFrame of any shape a bus can deliver (standard or
 * extended id, FD or classic, 0..64 bytes: what hal::canFrameProblem()
 * accepts); it reaches the daemon only when it passes the
 * daemon's one receive filter (base id + kCommand, mask 0x7ff, standard
 * frames: hal::canFilterPasses, the kernel's CAN_RAW rule that every backend
 * applies), is copied into a can::RawFrame as handleCommands copies it (id,
 * len, at most 8 data bytes) and fed to the daemon's can::Decoder. A Command
 * event is mapped to board modes with fromCan() (firmware/modes.h), as
 * applyCommand does.
 *
 * Input: base id (u16), then frames: ctrl (u8; bit 0 extended, bit 1 FD, bit 2
 * id = base + kCommand (else any id: u32), bit 3 len = u8 % 65 (else 8), bit 4
 * CRC byte as given (else sealed)), the id, the len, 8 data bytes.
 *
 * Oracle, for every frame:
 *  - only a standard frame with the command id, 8 bytes, a good CRC and a fresh
 *    alive counter is a command (the verdict of the protocol model,
 *    tests/fuzz/can_fuzz.h); every other frame the daemon can receive is
 *    Rejected with the model's reason, and a frame the filter stops is never
 *    seen;
 *  - the decoded command is lossless (encoded again, the same signal bits)
 *    and within its signals' ranges: gain 0..25.5, the mode a board mode, the
 *    strobe a board mode or "unchanged" exactly when its raw value is 3.
 */
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>

#include "firmware/can_frames.h"
#include "firmware/modes.h"
#include "hal/can_bus.h"
#include "hal/sim/sim_can.h"
#include "tests/fuzz/can_fuzz.h"

using namespace dockpose;
using namespace dockpose::fuzz;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	using Event = can::Decoder::Event;
	FuzzInput in(data, size);
	const std::uint32_t base_id = readBaseId(in);
	const hal::CanFilter commands{ base_id + can::kCommand, 0x7ff, false };
	can::Decoder decoder(base_id);
	AcceptModel<CrcProtocol> model(base_id);

	while (!in.empty()) {
		hal::CanFrame frame;
		const std::uint8_t ctrl = in.u8();
		frame.extended = (ctrl & 0x01) != 0;
		frame.fd = (ctrl & 0x02) != 0;
		frame.id = (ctrl & 0x04) ? base_id + can::kCommand : in.u32();
		frame.len = (ctrl & 0x08) ? static_cast<std::uint8_t>(in.u8() % 65) : 8;
		for (std::size_t i = 0; i < 8; ++i)
			frame.data[i] = in.u8();
		if (!(ctrl & 0x10)) {
			can::RawFrame sealed;
			sealed.id = frame.id;
			std::copy_n(frame.data.begin(), 8, sealed.data.begin());
			frame.data[7] = can::frameCrc(sealed.id, sealed.data);
		}

		/* No bus delivers a frame canFrameProblem() refuses (an id wider than its format,
		 * a classic frame over 8 bytes): the backends' one validator. */
		if (hal::canFrameProblem(frame, true) != nullptr)
			continue;
		if (!hal::canFilterPasses(std::span<const hal::CanFilter>(&commands, 1), frame))
			continue;
		FUZZ_CHECK(!frame.extended && frame.id == base_id + can::kCommand,
			   "only standard frames with the command id pass the daemon's filter");

		/* As Daemon::handleCommands copies a received frame. */
		const can::RawFrame raw = firmware::toRawFrame(frame);

		const Verdict v = model.judge(raw);
		const Event event = decoder.feed(raw);
		FUZZ_CHECK(event == v.event, "the decoder's event is the protocol's verdict");
		FUZZ_CHECK(decoder.lastError() == v.error, "lastError() is the protocol's verdict");
		FUZZ_CHECK(event == Event::Command || event == Event::Rejected,
			   "a frame through the command filter is a command or rejected");
		if (event != Event::Command)
			continue;

		FUZZ_CHECK(frame.len == 8, "a command has 8 bytes");
		const can::CommandData &cmd = decoder.command();
		can::Encoder encoder(base_id);
		FUZZ_CHECK(samePayload(encoder.encodeCommand(cmd), raw, kCommandUnused),
			   "the command decodes losslessly");
		FUZZ_CHECK(cmd.gain >= 0.0 && cmd.gain <= 25.5 + 1e-9, "gain within its signal");

		/* As Daemon::applyCommand maps it. */
		const board::TrackMode mode = firmware::fromCan(cmd.mode);
		FUZZ_CHECK(mode == ((raw.data[0] & 0x02) ? board::TrackMode::SearchOnly
							 : board::TrackMode::Track),
			   "the mode bit maps to its board mode");
		const auto strobe = firmware::fromCan(cmd.strobe);
		const unsigned int strobe_raw = (raw.data[0] >> 2) & 0x03u;
		FUZZ_CHECK(strobe.has_value() == (strobe_raw != 3),
			   "the strobe is unchanged exactly for raw value 3");
		if (strobe)
			FUZZ_CHECK(static_cast<unsigned int>(*strobe) == strobe_raw &&
					   static_cast<std::size_t>(*strobe) <
						   board::kStrobeModeNames.size(),
				   "a commanded strobe is a board mode with a name");
		FUZZ_CHECK(static_cast<unsigned int>(cmd.preview) == ((raw.data[0] >> 4) & 0x03u),
			   "the preview switch is bits 4-5 (3, reserved, the daemon refuses)");
	}
	return 0;
}

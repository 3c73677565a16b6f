/* SPDX-License-Identifier: MIT */
/*
 * The CAN harnesses' shared part: frames read off the fuzz input, and a
 * reference model of what the protocol (firmware/protocol/dockpose_can.h,
 * docs/can-protocol.md) says a receiver must do with each frame.
 *
 * A Protocol trait says how a frame is made intact and checked: CrcProtocol
 * is today's (the CRC-8 in byte 7) with can::Decoder. A keyed variant (a
 * MAC) is another trait of the same shape with its own decoder, and one more
 * harness file that calls runController<ThatProtocol>() — the frame reading,
 * the model and the oracle below stay as they are.
 *
 * Input layout (every field zero past the end, fuzz_check.h): base id (u16,
 * reduced to a valid base), then frames, each
 *   ctrl (u8): bit 0: id = base + (u8 % 0x11), else any id (u16);
 *              bit 1: len = u8, else 8;
 *              bit 2: the integrity byte as given, else sealed (Protocol::seal),
 *                     so most frames get past the CRC to the decoding;
 *   then the id byte(s), the len byte, 8 data bytes.
 */
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "firmware/protocol/dockpose_can.h"
#include "tests/fuzz/fuzz_check.h"

namespace dockpose::fuzz {

/* Today's protocol: CRC-8 SAE J1850 over id and bytes 0..6, in byte 7. */
struct CrcProtocol {
	using Decoder = can::Decoder;
	static constexpr can::FrameError kIntegrityError = can::FrameError::BadCrc;

	static Decoder makeDecoder(std::uint32_t base_id) { return Decoder(base_id); }
	static void seal(can::RawFrame *frame)
	{
		frame->data[7] = can::frameCrc(frame->id, frame->data);
	}
	static bool intact(const can::RawFrame &frame)
	{
		return can::frameCrc(frame.id, frame.data) == frame.data[7];
	}
};

inline std::uint32_t readBaseId(FuzzInput &in)
{
	return in.u16() % (can::kMaxBaseId + 1);
}

template<typename Protocol>
can::RawFrame readFrame(FuzzInput &in, std::uint32_t base_id)
{
	can::RawFrame f;
	const std::uint8_t ctrl = in.u8();
	f.id = (ctrl & 0x01) ? base_id + in.u8() % (can::kCommandAuth + 1) : in.u16();
	f.len = (ctrl & 0x02) ? in.u8() : can::kFrameLength;
	for (std::uint8_t &b : f.data)
		b = in.u8();
	if (!(ctrl & 0x04))
		Protocol::seal(&f);
	return f;
}

/* What the protocol says a receiver does with one frame. */
struct Verdict {
	can::Decoder::Event event = can::Decoder::Event::None;
	can::FrameError error = can::FrameError::None;
	bool accepted = false; /* intact, fresh and ours: its alive counter counts */
	std::uint32_t offset = 0;
	unsigned int alive_gap = 0; /* alive counts skipped before this frame */
};

/*
 * The acceptance rules of docs/can-protocol.md, written from the document, not
 * from the decoder: a frame not ours is ignored; ours is refused for a length
 * other than 8, a failed integrity check, or an alive counter equal to the
 * last accepted one of its identifier.
 */
template<typename Protocol>
class AcceptModel
{
public:
	explicit AcceptModel(std::uint32_t base_id)
		: base_id_(base_id)
	{
	}

	Verdict judge(const can::RawFrame &f)
	{
		using Event = can::Decoder::Event;
		Verdict v;
		/* Protocol 3: offsets 0x0..0x9 (0x8, 0x9: authentication), the command's 0x10, 0x11. */
		const std::uint32_t o = f.id - base_id_;
		const bool ours = f.id >= base_id_ && (o <= can::kFreshness || o == can::kCommand ||
						       o == can::kCommandAuth);
		if (!ours) {
			v.error = can::FrameError::UnknownId;
			return v;
		}
		v.offset = f.id - base_id_;
		v.event = Event::Rejected;
		if (f.len != can::kFrameLength) {
			v.error = can::FrameError::WrongLength;
			return v;
		}
		if (!Protocol::intact(f)) {
			v.error = Protocol::kIntegrityError;
			return v;
		}
		const std::size_t slot = v.offset >= can::kCommand ? v.offset - can::kCommand + 10
								   : v.offset;
		const unsigned int alive = f.data[6] & 0x0fu;
		if (seen_[slot]) {
			if (alive == alive_[slot]) {
				v.error = can::FrameError::StaleAlive;
				return v;
			}
			v.alive_gap = ((alive - alive_[slot]) & 0x0fu) - 1;
		}
		seen_[slot] = true;
		alive_[slot] = static_cast<std::uint8_t>(alive);
		v.accepted = true;
		switch (v.offset) {
		case can::kStatus:
			v.event = Event::Report;
			break;
		case can::kHeartbeat:
			v.event = Event::Heartbeat;
			break;
		case can::kCommand:
			v.event = Event::Command;
			break;
		default: /* pose frames; and the MAC frames, which a keyless receiver only counts */
			v.event = Event::None;
			break;
		}
		return v;
	}

private:
	std::uint32_t base_id_;
	std::array<bool, 12> seen_{};
	std::array<std::uint8_t, 12> alive_{};
};

/* Bytes 0..5 (the signals) of two frames agree outside the bits in `unused`. */
inline bool samePayload(const can::RawFrame &a, const can::RawFrame &b, std::uint64_t unused = 0)
{
	std::uint64_t wa = 0, wb = 0;
	for (int i = 5; i >= 0; --i) {
		wa = (wa << 8) | a.data[static_cast<std::size_t>(i)];
		wb = (wb << 8) | b.data[static_cast<std::size_t>(i)];
	}
	return ((wa ^ wb) & ~unused) == 0;
}

/* Bits no signal uses (docs/can-protocol.md): command bits 6..7, 32..47. The heartbeat's bit 31
 * (Authenticated) is the encoder's own state, not a decoded value: left out too. */
constexpr std::uint64_t kHeartbeatUnused = std::uint64_t{ 1 } << 31;
constexpr std::uint64_t kCommandUnused = (std::uint64_t{ 0x3 } << 6) |
					 (std::uint64_t{ 0xffff } << 32);

/*
 * The controller's side: Protocol's decoder fed a sequence of frames.
 *
 * Oracle, after every frame:
 *  - the decoder's event and lastError() are the AcceptModel's verdict, and its
 *    counters add up the verdicts (frames, unknown ids, length, integrity and
 *    stale errors, alive gaps, reports);
 *  - a report has a valid pose exactly when its status says PoseValid and the
 *    six pose frames were accepted with the status's sequence since the
 *    previous status (or since a pose frame of another sequence): a pose is
 *    never valid from a partial or mixed set of frames;
 *  - decoding is lossless: the decoded status, heartbeat, command and pose,
 *    encoded again by can::Encoder, give the payload bits that arrived (the
 *    latest accepted frame of each pose offset), and a decoded pose is always
 *    one the encoder can send.
 */
template<typename Protocol>
void runController(FuzzInput &in)
{
	using Event = can::Decoder::Event;
	const std::uint32_t base_id = readBaseId(in);
	typename Protocol::Decoder decoder = Protocol::makeDecoder(base_id);
	AcceptModel<Protocol> model(base_id);

	can::Decoder::Counters expected;
	std::array<can::RawFrame, 8> held{}; /* the latest accepted frame of each pose offset */
	std::uint8_t held_mask = 0;
	std::uint8_t held_seq = 0;

	while (!in.empty()) {
		const can::RawFrame f = readFrame<Protocol>(in, base_id);
		const Verdict v = model.judge(f);
		const Event event = decoder.feed(f);

		++expected.frames;
		switch (v.error) {
		case can::FrameError::UnknownId:
			++expected.unknown_ids;
			break;
		case can::FrameError::WrongLength:
			++expected.length_errors;
			break;
		case can::FrameError::BadCrc:
			++expected.crc_errors;
			break;
		case can::FrameError::StaleAlive:
			++expected.stale_frames;
			break;
		default: /* None; the authentication errors are a keyed decoder's */
			break;
		}
		expected.alive_gaps += v.alive_gap;

		FUZZ_CHECK(event == v.event, "the decoder's event is the protocol's verdict");
		FUZZ_CHECK(decoder.lastError() == v.error, "lastError() is the protocol's verdict");

		const std::uint8_t seq = static_cast<std::uint8_t>(f.data[6] >> 4);
		const bool pose_frame = v.accepted &&
					(v.offset <= can::kSigma || v.offset == can::kQuality);
		if (pose_frame) {
			if (held_mask != 0 && held_seq != seq)
				held_mask = 0;
			held_seq = seq;
			held_mask = static_cast<std::uint8_t>(held_mask | (1u << v.offset));
			held[v.offset] = f;
		}

		can::Encoder encoder(base_id);
		can::RawFrame out[can::kReportFrames];
		if (event == Event::Report) {
			const bool status_valid = (f.data[0] & 0x10) != 0;
			const bool complete = held_mask == can::detail::kPoseFrameMask &&
					      held_seq == seq;
			const bool pose_valid = status_valid && complete;
			++expected.reports;
			if (pose_valid)
				++expected.valid_poses;
			else if (status_valid)
				++expected.incomplete_poses;
			held_mask = 0;

			FUZZ_CHECK(
				decoder.poseValid() == pose_valid,
				"a pose is valid exactly when its six frames and the status agree");
			FUZZ_CHECK(decoder.sequence() == seq,
				   "the report's sequence is its status's");
			FUZZ_CHECK(decoder.status().pose_valid == status_valid,
				   "status().pose_valid is the sender's flag");
			const can::PoseData &pose = decoder.pose();
			FUZZ_CHECK(can::Encoder::poseEncodable(pose),
				   "a decoded pose can be sent again");
			const int n = encoder.encodeReport(decoder.status(), &pose, out);
			FUZZ_CHECK(n == (status_valid ? can::kReportFrames : 1),
				   "the decoded status encodes to a report of its kind");
			FUZZ_CHECK(samePayload(out[n - 1], f), "the status decodes losslessly");
			if (pose_valid) {
				const std::uint32_t offsets[6] = {
					can::kTranslation, can::kQuatA, can::kQuatB,
					can::kAngles,	   can::kSigma, can::kQuality
				};
				for (int i = 0; i < 6; ++i) {
					const std::uint32_t o = offsets[i];
					FUZZ_CHECK(out[i].id == held[o].id,
						   "pose frames in the DBC's order");
					FUZZ_CHECK(samePayload(out[i], held[o]),
						   "the pose decodes losslessly");
				}
			}
		} else if (event == Event::Heartbeat) {
			const can::RawFrame hb = encoder.encodeHeartbeat(decoder.heartbeat());
			FUZZ_CHECK(samePayload(hb, f, kHeartbeatUnused),
				   "the heartbeat decodes losslessly");
		} else if (event == Event::Command) {
			const can::RawFrame cmd = encoder.encodeCommand(decoder.command());
			FUZZ_CHECK(samePayload(cmd, f, kCommandUnused),
				   "the command decodes losslessly");
		}

		const can::Decoder::Counters &c = decoder.counters();
		FUZZ_CHECK(c.frames == expected.frames && c.unknown_ids == expected.unknown_ids &&
				   c.length_errors == expected.length_errors &&
				   c.crc_errors == expected.crc_errors &&
				   c.stale_frames == expected.stale_frames &&
				   c.alive_gaps == expected.alive_gaps &&
				   c.reports == expected.reports &&
				   c.valid_poses == expected.valid_poses &&
				   c.incomplete_poses == expected.incomplete_poses,
			   "the decoder's counters add up the verdicts");
	}
}

} /* namespace dockpose::fuzz */

/* SPDX-License-Identifier: MIT */
/*
 * The dockpose CAN protocol: encoder and decoder of the frames a dockpose
 * sensor sends (pose, status, heartbeat) and receives (command).
 *
 * The contract is firmware/protocol/dockpose.dbc; docs/can-protocol.md
 * explains it. This header is shared with the arm controller: header-only,
 * C++17 or later, the C++ standard library only, and it never allocates.
 *
 * Classic CAN, 11-bit identifiers, 8 data bytes, Intel (little-endian) signals.
 * Identifier = base id + Offset; the DBC is written for base 0x300.
 *
 *   byte 6   AliveCounter (bits 48..51): per identifier, +1 mod 16 per frame
 *            Sequence (bits 52..55): one value for all frames of one camera
 *            frame's report (0 in heartbeat and command)
 *   byte 7   CRC-8 SAE J1850 over [id & 0xff, (id >> 8) & 0x07, data[0..6]]
 *
 * A report is the six pose frames (only when the pose is valid: translation,
 * quaternion A and B, angles, sigma, quality, in that order) followed by the
 * status frame; the status frame completes the report.
 *
 * CAN FD (optional, the sensor's can.fd): a report's frames go packed in one
 * 64-byte FD frame, DP_ReportFd (base + kReportFd): slot k, bytes 8k..8k+7,
 * holds the classic frame kFdSlots[k] byte for byte (counter, sequence and CRC
 * as computed for its classic id), or eight zero bytes when the report has no
 * such frame. packFd() and Decoder::feedFd() are the two ends.
 *
 * Units: millimetres, degrees, pixels, milliseconds, hertz, microseconds, as
 * in the field names. Threads: an Encoder or Decoder belongs to one thread.
 */
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace dockpose::can {

constexpr std::uint32_t kDefaultBaseId = 0x300;
/* The base id the DBC is written for: tools subtract (base - kDbcBaseId). */
constexpr std::uint32_t kDbcBaseId = 0x300;
constexpr std::uint8_t kFrameLength = 8;
/* Frames in a report with a pose: six pose frames and the status. */
constexpr int kReportFrames = 7;
/* With authentication each report, heartbeat and command is followed by its
 * MAC frame (and a heartbeat by the freshness frame before it): the most
 * frames encodeReport(), encodeHeartbeat() and encodeCommand() write. */
constexpr int kMaxReportFrames = kReportFrames + 1;
constexpr int kMaxHeartbeatFrames = 3;
constexpr int kMaxCommandFrames = 2;

enum Offset : std::uint32_t {
	kTranslation = 0x0,
	kQuatA = 0x1,
	kQuatB = 0x2,
	kAngles = 0x3,
	kSigma = 0x4,
	kStatus = 0x5,
	kHeartbeat = 0x6,
	kQuality = 0x7, /* a pose frame, sent before the status */
	kAuth = 0x8, /* the MAC of the sensor's frames since the previous one */
	kFreshness = 0x9, /* the sensor's freshness value, high bits (before a heartbeat's MAC) */
	kReportFd = 0xa, /* CAN FD only: a whole report in one 64-byte frame (packFd) */
	kCommand = 0x10,
	kCommandAuth = 0x11, /* the MAC of the command before it */
};

/* base .. base + kCommandAuth must stay 11-bit. */
constexpr std::uint32_t kMaxBaseId = 0x7ff - kCommandAuth;

constexpr bool validBaseId(std::uint32_t base_id)
{
	return base_id <= kMaxBaseId;
}

/*
 * Where a scaled signal sits, as its SG_ line in the DBC declares it: the
 * message (base id + offset), start bit (Intel byte order, bit 0 = LSB of
 * byte 0), length, sign and factor (offset 0). The encoder and decoder use
 * these and nothing else for the signal; tests/firmware/test_can_protocol.cpp
 * checks each against the DBC.
 */
struct SignalLayout {
	std::uint32_t offset;
	unsigned int start_bit;
	unsigned int length_bits;
	bool is_signed;
	double factor;

	constexpr std::int64_t rawMin() const
	{
		return is_signed ? -(std::int64_t{ 1 } << (length_bits - 1)) : 0;
	}
	constexpr std::int64_t rawMax() const
	{
		return is_signed ? (std::int64_t{ 1 } << (length_bits - 1)) - 1
				 : (std::int64_t{ 1 } << length_bits) - 1;
	}
};

namespace layout {
/* DP_Quality Log10Nfa: -3276.8 .. 3276.7 in steps of 0.1. */
constexpr SignalLayout kLog10Nfa{ kQuality, 0, 16, true, 0.1 };
/* DP_Quality SensorTimeUs: the sensor's CLOCK_MONOTONIC when it encoded the
 * report, in microseconds modulo 2^32 (it wraps every 71.6 minutes). */
constexpr SignalLayout kSensorTime{ kQuality, 16, 32, false, 1.0 };
/* DP_Heartbeat Authenticated: 1 when the sensor authenticates its frames. */
constexpr SignalLayout kAuthenticated{ kHeartbeat, 31, 1, false, 1.0 };
/* DP_Auth: the low 16 bits of the freshness value the MAC covers, and the MAC
 * (the first four bytes of the AES-128-CMAC, the first byte most significant). */
constexpr SignalLayout kAuthFreshness{ kAuth, 0, 16, false, 1.0 };
constexpr SignalLayout kAuthMac{ kAuth, 16, 32, false, 1.0 };
/* DP_Freshness: the freshness value's bits 16..63 (the next DP_Auth's). */
constexpr SignalLayout kFreshnessHigh{ kFreshness, 0, 48, false, 1.0 };
/* DP_CommandAuth: the low 16 bits of the sensor freshness value the command
 * answers to, and the MAC. */
constexpr SignalLayout kCommandFreshness{ kCommandAuth, 0, 16, false, 1.0 };
constexpr SignalLayout kCommandMac{ kCommandAuth, 16, 32, false, 1.0 };
} /* namespace layout */

enum class SensorState : std::uint8_t {
	Startup = 0,
	Searching,
	Tracking,
	Degraded,
	Fault,
	Shutdown
};
enum class StrobeMode : std::uint8_t {
	Off = 0,
	Constant = 1,
	Alternate = 2,
	Unchanged = 3
};
/* DP_Command Preview: the operator preview (dockposed's shared-memory ring). */
enum class PreviewSwitch : std::uint8_t {
	Unchanged = 0,
	Off = 1,
	On = 2,
	Reserved = 3 /* refused: COMMAND_REJECTED */
};
enum class TrackMode : std::uint8_t {
	Track = 0,
	SearchOnly = 1
};

/* The names are the DBC's value-table names. A decoded value outside the
 * enumeration (State 6 or 7) is kept as it came and named "UNKNOWN". */
inline const char *sensorStateName(SensorState state)
{
	switch (state) {
	case SensorState::Startup:
		return "STARTUP";
	case SensorState::Searching:
		return "SEARCHING";
	case SensorState::Tracking:
		return "TRACKING";
	case SensorState::Degraded:
		return "DEGRADED";
	case SensorState::Fault:
		return "FAULT";
	case SensorState::Shutdown:
		return "SHUTDOWN";
	}
	return "UNKNOWN";
}

inline const char *strobeModeName(StrobeMode mode)
{
	switch (mode) {
	case StrobeMode::Off:
		return "OFF";
	case StrobeMode::Constant:
		return "CONSTANT";
	case StrobeMode::Alternate:
		return "ALTERNATE";
	case StrobeMode::Unchanged:
		return "UNCHANGED";
	}
	return "UNKNOWN";
}

inline const char *trackModeName(TrackMode mode)
{
	switch (mode) {
	case TrackMode::Track:
		return "TRACK";
	case TrackMode::SearchOnly:
		return "SEARCH_ONLY";
	}
	return "UNKNOWN";
}

namespace fault {
constexpr std::uint8_t kCameraStall = 1u << 0;
constexpr std::uint8_t kCameraError = 1u << 1;
constexpr std::uint8_t kStrobeError = 1u << 2;
constexpr std::uint8_t kCanTxOverflow = 1u << 3;
constexpr std::uint8_t kCanBusOff = 1u << 4;
constexpr std::uint8_t kFramesDropped = 1u << 5;
constexpr std::uint8_t kLoopOverrun = 1u << 6;
constexpr std::uint8_t kCommandRejected = 1u << 7;
} /* namespace fault */

/* Name of fault bit `bit` (0..7), "CAMERA_STALL" etc.; "UNKNOWN" otherwise. */
inline const char *faultBitName(unsigned int bit)
{
	static constexpr const char *kNames[8] = {
		"CAMERA_STALL", "CAMERA_ERROR",	  "STROBE_ERROR", "CAN_TX_OVERFLOW",
		"CAN_BUS_OFF",	"FRAMES_DROPPED", "LOOP_OVERRUN", "COMMAND_REJECTED",
	};
	return bit < 8 ? kNames[bit] : "UNKNOWN";
}

/* CRC-8 SAE J1850: polynomial 0x1d, init 0xff, final xor 0xff
 * (check value of "123456789": 0x4b). */
constexpr std::uint8_t crc8J1850(const std::uint8_t *data, std::size_t len)
{
	std::uint8_t crc = 0xff;
	for (std::size_t i = 0; i < len; ++i) {
		crc = static_cast<std::uint8_t>(crc ^ data[i]);
		for (int b = 0; b < 8; ++b)
			crc = (crc & 0x80) ? static_cast<std::uint8_t>((crc << 1) ^ 0x1d)
					   : static_cast<std::uint8_t>(crc << 1);
	}
	return static_cast<std::uint8_t>(crc ^ 0xff);
}

struct RawFrame {
	std::uint32_t id = 0;
	std::uint8_t len = 0;
	std::array<std::uint8_t, 8> data{};
};

/* The CRC byte of a frame with identifier `id` (the real one on the bus) and
 * data bytes 0..6. */
constexpr std::uint8_t frameCrc(std::uint32_t id, const std::array<std::uint8_t, 8> &data)
{
	std::uint8_t bytes[9] = {
		static_cast<std::uint8_t>(id & 0xff),
		static_cast<std::uint8_t>((id >> 8) & 0x07),
		data[0],
		data[1],
		data[2],
		data[3],
		data[4],
		data[5],
		data[6],
	};
	return crc8J1850(bytes, sizeof(bytes));
}

/* Byte 6 of every frame: the alive counter (bits 0-3) and the sequence (bits 4-7). */
constexpr std::uint8_t aliveSeqByte(std::uint8_t alive, std::uint8_t seq)
{
	return static_cast<std::uint8_t>((alive & 0x0f) | ((seq & 0x0f) << 4));
}
constexpr std::uint8_t frameAlive(const std::array<std::uint8_t, 8> &data)
{
	return data[6] & 0x0f;
}
constexpr std::uint8_t frameSeq(const std::array<std::uint8_t, 8> &data)
{
	return static_cast<std::uint8_t>(data[6] >> 4);
}

/* A frame of the protocol's length whose byte 7 is its CRC (the identifier not checked). */
constexpr bool frameIntact(const RawFrame &frame)
{
	return frame.len == kFrameLength && frameCrc(frame.id, frame.data) == frame.data[7];
}

/* Bits on the wire of a classic standard-id data frame with `data_bytes` bytes
 * and worst-case bit stuffing, interframe space included (135 for 8 bytes). */
constexpr int worstCaseFrameBits(int data_bytes)
{
	return 34 + 8 * data_bytes + 13 + (34 + 8 * data_bytes - 1) / 4;
}

/* Fraction of the bus (0..1) the sensor takes at `frames_hz` camera frames per
 * second (every one a report with pose: kReportFrames frames), `heartbeat_hz`
 * heartbeats and `command_hz` commands per second, at `bitrate` bit/s,
 * worst-case stuffing; `authenticated` adds each group's MAC frame (and the
 * heartbeat's DP_Freshness). 60 / 10 / 500 kbit/s: 0.1161, authenticated 0.1377. */
constexpr double worstCaseBusLoad(double frames_hz, double heartbeat_hz, double bitrate,
				  double command_hz = 0.0, bool authenticated = false)
{
	const double report = authenticated ? kMaxReportFrames : kReportFrames;
	const double heartbeat = authenticated ? kMaxHeartbeatFrames : 1;
	const double command = authenticated ? kMaxCommandFrames : 1;
	return (report * frames_hz + heartbeat * heartbeat_hz + command * command_hz) *
	       worstCaseFrameBits(kFrameLength) / bitrate;
}

/* Bits on the wire of a CAN FD standard-id data frame of `data_bytes` bytes (a CAN FD length)
 * sent without bit-rate switching, worst-case stuffing, interframe space included: 22 bits
 * SOF..DLC and the data with their dynamic stuff bits, the stuff count and CRC (17 bits up to
 * 16 bytes, 21 beyond) with their fixed stuff bits, 13 bits of delimiters, ACK, EOF and IFS.
 * 712 for 64 bytes. */
constexpr int worstCaseFdFrameBits(int data_bytes)
{
	const int head = 22 + 8 * data_bytes;
	const int crc = 4 + (data_bytes <= 16 ? 17 : 21);
	return head + (head - 1) / 4 + crc + (crc + 3) / 4 + 13;
}

/* Bytes of DP_ReportFd: eight classic frames of eight bytes. */
constexpr std::uint8_t kFdReportLength = 64;

/* The same as worstCaseBusLoad() with `fd`: every report one DP_ReportFd (its data phase at
 * the arbitration bit rate: no bit-rate switching), heartbeats and commands classic.
 * 60 / 10 / 500 kbit/s, authenticated: 0.0938. */
constexpr double worstCaseFdBusLoad(double frames_hz, double heartbeat_hz, double bitrate,
				    double command_hz = 0.0, bool authenticated = false)
{
	const double heartbeat = authenticated ? kMaxHeartbeatFrames : 1;
	const double command = authenticated ? kMaxCommandFrames : 1;
	return (frames_hz * worstCaseFdFrameBits(kFdReportLength) +
		(heartbeat * heartbeat_hz + command * command_hz) *
			worstCaseFrameBits(kFrameLength)) /
	       bitrate;
}

/* DP_ReportFd's slots: the classic frame each carries, in the order they are sent. */
constexpr std::array<std::uint32_t, 8> kFdSlots = { kTranslation, kQuatA,   kQuatB,  kAngles,
						    kSigma,	  kQuality, kStatus, kAuth };

/* A CAN FD frame of the protocol (DP_ReportFd). */
struct FdFrame {
	std::uint32_t id = 0;
	std::uint8_t len = 0;
	std::array<std::uint8_t, 64> data{};
};

/* The slot of DP_ReportFd that carries the classic frame at `offset`, -1 for none. */
constexpr int fdSlot(std::uint32_t offset)
{
	for (std::size_t k = 0; k < kFdSlots.size(); ++k)
		if (kFdSlots[k] == offset)
			return static_cast<int>(k);
	return -1;
}

/*
 * Packs one report's frames (Encoder::encodeReport()'s, base id base_id) into
 * DP_ReportFd. False, with out untouched, when a frame is not one a report has
 * (another id, a length other than 8) or two frames want the same slot.
 * Allocates: never.
 */
inline bool packFd(const RawFrame *frames, int count, std::uint32_t base_id, FdFrame *out)
{
	FdFrame fd;
	fd.id = (base_id + kReportFd) & 0x7ff;
	fd.len = kFdReportLength;
	std::uint8_t used = 0;
	for (int i = 0; i < count; ++i) {
		const RawFrame &f = frames[i];
		const int k = f.id < base_id ? -1 : fdSlot(f.id - base_id);
		if (k < 0 || f.len != kFrameLength || (used & (1u << k)))
			return false;
		used = static_cast<std::uint8_t>(used | (1u << k));
		for (std::size_t b = 0; b < kFrameLength; ++b)
			fd.data[static_cast<std::size_t>(k) * kFrameLength + b] = f.data[b];
	}
	*out = fd;
	return true;
}

/*
 * The classic frames DP_ReportFd carries, in slot order, an all-zero slot left
 * out (no frame: the frame's own CRC and counter make an all-zero classic frame
 * of ours a 1-in-256 accident, and missing it only makes that report
 * incomplete). Returns how many were written to out (at most 8). Allocates: never.
 */
inline int unpackFd(const FdFrame &fd, std::uint32_t base_id, RawFrame *out)
{
	int n = 0;
	for (std::size_t k = 0; k < kFdSlots.size(); ++k) {
		RawFrame f;
		f.id = (base_id + kFdSlots[k]) & 0x7ff;
		f.len = kFrameLength;
		bool any = false;
		for (std::size_t b = 0; b < kFrameLength; ++b) {
			f.data[b] = fd.data[k * kFrameLength + b];
			any = any || f.data[b] != 0;
		}
		if (any)
			out[n++] = f;
	}
	return n;
}

struct PoseData {
	std::uint32_t frame_counter = 0; /* the camera frame's sequence number */
	double t_mm[3]{}; /* X_c = R X_t + t; Tx, Ty: +-3276.7, Tz: 0..6553.5 */
	double q[4]{ 1, 0, 0, 0 }; /* w x y z */
	double rpy_deg[3]{}; /* roll, pan, tilt */
	double sigma_t_mm[3]{}; /* 1-sigma, sent rounded up; >= 25.5 is sent as 25.5 (saturated) */
	double sigma_rpy_deg[3]{}; /* 1-sigma, sent rounded up; >= 2.55 is sent as 2.55 (saturated) */
	/* log10 of the match's number of false alarms (<= -4 when accepted, more
	 * negative is more certain); resolution 0.1, saturates at -3276.8 and
	 * 3276.7; NaN is sent as 3276.7 (unknown: no evidence). */
	double log10_nfa = 0.0;
	/* The sensor's clock when the report was encoded (CLOCK_MONOTONIC, us modulo 2^32);
	 * the decoder dates reports with it (Decoder::setMaxAgeUs). */
	std::uint32_t sensor_time_us = 0;
};

struct StatusData {
	SensorState state = SensorState::Startup;
	bool enabled = true;
	bool pose_valid = false;
	bool tracked = false;
	StrobeMode strobe = StrobeMode::Off;
	int leds_used = 0;
	double rms_px = 0; /* >= 2.55 is sent as 2.55 (saturated) */
	std::uint8_t faults = 0; /* fault:: bits */
	double latency_ms = 0; /* sensor timestamp to CAN send; >= 655.35 saturated */
};

struct HeartbeatData {
	std::uint32_t uptime_s = 0; /* saturates at 2^24 - 1 */
	bool authenticated = false; /* set by the encoder: it has an authenticator */
	SensorState state = SensorState::Startup;
	TrackMode mode = TrackMode::Track;
	StrobeMode strobe = StrobeMode::Off;
	bool enabled = true;
	std::uint8_t faults = 0;
	double frame_rate_hz = 0; /* resolution 0.5, up to 127.5 */
};

struct CommandData {
	bool enable = true;
	TrackMode mode = TrackMode::Track;
	StrobeMode strobe = StrobeMode::Unchanged;
	std::uint16_t exposure_us = 0; /* 0: unchanged */
	double gain = 0; /* resolution 0.1, up to 25.5; 0: unchanged */
	PreviewSwitch preview = PreviewSwitch::Unchanged;
};

namespace detail {

/* Resolution (factor) of each scaled signal. */
constexpr double kTranslationRes = 0.1;
constexpr double kQuatRes = 0.0001;
constexpr double kAngleRes = 0.01;
constexpr double kSigmaTRes = 0.1;
constexpr double kSigmaRpyRes = 0.01;
constexpr double kRmsRes = 0.01;
constexpr double kLatencyRes = 0.01;
constexpr double kFrameRateRes = 0.5;
constexpr double kGainRes = 0.1;

/* A rounded raw value saturated into [lo, hi]. */
inline std::int64_t clampRaw(double r, std::int64_t lo, std::int64_t hi)
{
	if (r <= static_cast<double>(lo))
		return lo;
	if (r >= static_cast<double>(hi))
		return hi;
	return static_cast<std::int64_t>(r);
}

/* value / res rounded to the nearest integer and clamped to [lo, hi]; NaN
 * gives `nan_raw`. */
inline std::int64_t toRaw(double value, double res, std::int64_t lo, std::int64_t hi,
			  std::int64_t nan_raw)
{
	if (std::isnan(value))
		return nan_raw;
	return clampRaw(std::round(value / res), lo, hi);
}

/* As toRaw, but rounded up: for a sigma, whose sent value must never claim more
 * certainty than the estimate has (a sigma of 0.03 mm goes out as 0.1, not 0). The
 * 1e-9 step keeps an exact multiple (0.1 / 0.1) on its own step. NaN and a
 * negative value (no sigma at all) go out as nan_raw: unknown, never "certain". */
inline std::int64_t toRawUp(double value, double res, std::int64_t lo, std::int64_t hi,
			    std::int64_t nan_raw)
{
	if (!(value >= 0.0))
		return nan_raw;
	return clampRaw(std::ceil(value / res - 1e-9), lo, hi);
}

/* True when value / res rounds into [lo, hi] (false for NaN and infinities). */
inline bool encodable(double value, double res, std::int64_t lo, std::int64_t hi)
{
	if (!std::isfinite(value))
		return false;
	const double r = std::round(value / res);
	return r >= static_cast<double>(lo) && r <= static_cast<double>(hi);
}

constexpr std::uint64_t field(std::uint64_t raw, unsigned int start, unsigned int length)
{
	return (raw & ((std::uint64_t{ 1 } << length) - 1)) << start;
}

constexpr std::uint64_t signedField(std::int64_t raw, unsigned int start, unsigned int length)
{
	return field(static_cast<std::uint64_t>(raw), start, length);
}

constexpr std::uint64_t bits(const std::array<std::uint8_t, 8> &data, unsigned int start,
			     unsigned int length)
{
	std::uint64_t word = 0;
	for (int i = 7; i >= 0; --i)
		word = (word << 8) | data[static_cast<std::size_t>(i)];
	return (word >> start) & ((std::uint64_t{ 1 } << length) - 1);
}

/* Sign-extended field of `length` bits. */
constexpr std::int64_t signedBits(const std::array<std::uint8_t, 8> &data, unsigned int start,
				  unsigned int length)
{
	const std::uint64_t raw = bits(data, start, length);
	const std::uint64_t sign = std::uint64_t{ 1 } << (length - 1);
	return (raw & sign) ? static_cast<std::int64_t>(raw) - static_cast<std::int64_t>(sign << 1)
			    : static_cast<std::int64_t>(raw);
}

constexpr std::uint64_t flag(bool value, unsigned int bit)
{
	return value ? std::uint64_t{ 1 } << bit : 0;
}

/* A scaled signal placed in its field: rounded, clamped to its raw range, NaN as nan_raw. */
inline std::uint64_t put(const SignalLayout &s, double value, std::int64_t nan_raw)
{
	return signedField(toRaw(value, s.factor, s.rawMin(), s.rawMax(), nan_raw), s.start_bit,
			   s.length_bits);
}

/* A scaled signal's value. */
constexpr double get(const std::array<std::uint8_t, 8> &data, const SignalLayout &s)
{
	const std::int64_t raw =
		s.is_signed ? signedBits(data, s.start_bit, s.length_bits)
			    : static_cast<std::int64_t>(bits(data, s.start_bit, s.length_bits));
	return static_cast<double>(raw) * s.factor;
}

constexpr std::uint64_t putRaw(const SignalLayout &s, std::uint64_t raw)
{
	return field(raw, s.start_bit, s.length_bits);
}
constexpr std::uint64_t getRaw(const std::array<std::uint8_t, 8> &data, const SignalLayout &s)
{
	return bits(data, s.start_bit, s.length_bits);
}

/*
 * What a MAC covers (protocol 3): "DPA3", the base id (2 bytes), then for
 * each frame of the group its identifier (2 bytes) and its 8 data bytes, then
 * the 64-bit freshness value and byte 6 of the MAC frame itself (its alive
 * counter and sequence); integers little-endian. A group is at most a report
 * (kReportFrames frames).
 */
class MacInput
{
public:
	static constexpr std::size_t kMaxFrames = kReportFrames;

	void reset(std::uint32_t base_id)
	{
		len_ = 0;
		frames_ = 0;
		overflow_ = false;
		for (char c : { 'D', 'P', 'A', '3' })
			bytes_[len_++] = static_cast<std::uint8_t>(c);
		put(base_id, 2);
	}
	void add(const RawFrame &frame)
	{
		if (frames_ == kMaxFrames) {
			overflow_ = true;
			return;
		}
		put(frame.id, 2);
		for (std::uint8_t b : frame.data)
			bytes_[len_++] = b;
		++frames_;
	}
	std::size_t frames() const { return frames_; }
	bool overflow() const { return overflow_; }
	/* The bytes with the freshness value and the MAC frame's byte 6 appended (the group
	 * itself is kept). */
	const std::uint8_t *finish(std::uint64_t freshness, std::uint8_t mac_byte6,
				   std::size_t *len)
	{
		std::size_t n = len_;
		for (int i = 0; i < 8; ++i)
			bytes_[n++] = static_cast<std::uint8_t>(freshness >> (8 * i));
		bytes_[n++] = mac_byte6;
		*len = n;
		return bytes_.data();
	}

private:
	void put(std::uint64_t v, int n)
	{
		for (int i = 0; i < n; ++i)
			bytes_[len_++] = static_cast<std::uint8_t>(v >> (8 * i));
	}

	std::array<std::uint8_t, 4 + 2 + kMaxFrames * 10 + 8 + 1> bytes_{};
	std::size_t len_ = 0;
	std::size_t frames_ = 0;
	bool overflow_ = false;
};

/* The pose frames a valid report needs, one bit per offset. */
constexpr std::uint8_t kPoseFrameMask = (1u << kTranslation) | (1u << kQuatA) | (1u << kQuatB) |
					(1u << kAngles) | (1u << kSigma) | (1u << kQuality);

constexpr std::size_t slot(std::uint32_t offset)
{
	return offset >= kCommand ? offset - kCommand + 10 : offset;
}

constexpr std::size_t kSlots = 12;

/* One of ours: base .. base + 0x9 and the command's two. */
constexpr bool knownOffset(std::uint32_t offset)
{
	return offset <= kFreshness || offset == kCommand || offset == kCommandAuth;
}

} /* namespace detail */

/*
 * The MAC behind authentication (protocol 3, SecOC-style): AES-128-CMAC with
 * the shared key, truncated to its first four bytes. This header has no
 * crypto of its own; dockpose_can_cmac.h implements it with OpenSSL, and a
 * controller may use its HSM instead. mac32() is called for every
 * authenticated group (from the owner's thread).
 */
class MacFunction
{
public:
	virtual ~MacFunction() = default;
	/* The first four bytes of the CMAC of data[0..len), the first byte in bits 24..31.
	 * False when it could not be computed (the group is then refused). */
	virtual bool mac32(const std::uint8_t *data, std::size_t len, std::uint32_t *mac) = 0;
};

/*
 * Encoder: turns one camera frame's results into frames, keeping the alive
 * counters (per identifier) and the report sequence. Never allocates.
 *
 * With an authenticator (setAuthenticator) every group of frames the sensor
 * sends — a report, or a heartbeat with the freshness frame — is followed by
 * a DP_Auth frame: the low 16 bits of the sensor's freshness value (+1 per
 * DP_Auth) and the truncated MAC of the group and the whole value. A
 * command is followed by DP_CommandAuth, whose MAC covers the command and
 * the latest sensor freshness value the controller verified.
 */
class Encoder
{
public:
	/* base_id must satisfy validBaseId(); identifiers are masked to 11 bits. */
	explicit Encoder(std::uint32_t base_id = kDefaultBaseId)
		: base_id_(base_id)
	{
	}

	/*
	 * One camera frame's report: the six pose frames (when status.pose_valid,
	 * pose != nullptr and the pose is encodable) and then the status frame,
	 * all with the next sequence number. Returns the number of frames written
	 * to out: kReportFrames (7) with a pose, 1 without. When a pose was asked for but cannot
	 * be sent (pose == nullptr, a translation outside Tx/Ty +-3276.7 mm or
	 * Tz 0..6553.5 mm, or a non-finite value in t, q or rpy), the status goes
	 * out with PoseValid cleared and poseDropped() is true until the next
	 * report. Other fields saturate at their ranges. With an authenticator
	 * the DP_Auth frame follows (kMaxReportFrames in all: out must hold them).
	 */
	int encodeReport(const StatusData &status, const PoseData *pose, RawFrame *out)
	{
		using namespace detail;
		const std::uint8_t seq = sequence_;
		sequence_ = static_cast<std::uint8_t>((sequence_ + 1) & 0x0f);

		pose_dropped_ = false;
		bool send_pose = status.pose_valid;
		if (send_pose && (pose == nullptr || !poseEncodable(*pose))) {
			send_pose = false;
			pose_dropped_ = true;
		}

		int n = 0;
		if (send_pose) {
			const PoseData &p = *pose;
			out[n++] = finish(
				kTranslation, seq,
				signedField(toRaw(p.t_mm[0], kTranslationRes, -32768, 32767, 0), 0,
					    16) |
					signedField(toRaw(p.t_mm[1], kTranslationRes, -32768, 32767,
							  0),
						    16, 16) |
					field(static_cast<std::uint64_t>(toRaw(
						      p.t_mm[2], kTranslationRes, 0, 65535, 0)),
					      32, 16));
			out[n++] = finish(
				kQuatA, seq,
				signedField(toRaw(p.q[0], kQuatRes, -32768, 32767, 0), 0, 16) |
					signedField(toRaw(p.q[1], kQuatRes, -32768, 32767, 0), 16,
						    16) |
					signedField(toRaw(p.q[2], kQuatRes, -32768, 32767, 0), 32,
						    16));
			out[n++] = finish(kQuatB, seq,
					  signedField(toRaw(p.q[3], kQuatRes, -32768, 32767, 0), 0,
						      16) |
						  field(p.frame_counter, 16, 32));
			out[n++] =
				finish(kAngles, seq,
				       signedField(toRaw(p.rpy_deg[0], kAngleRes, -32768, 32767, 0),
						   0, 16) |
					       signedField(toRaw(p.rpy_deg[1], kAngleRes, -32768,
								 32767, 0),
							   16, 16) |
					       signedField(toRaw(p.rpy_deg[2], kAngleRes, -32768,
								 32767, 0),
							   32, 16));
			std::uint64_t sigma = 0;
			for (unsigned int i = 0; i < 3; ++i) {
				sigma |= signedField(toRawUp(p.sigma_t_mm[i], kSigmaTRes, 0, 255,
							     255),
						     8 * i, 8);
				sigma |= signedField(toRawUp(p.sigma_rpy_deg[i], kSigmaRpyRes, 0,
							     255, 255),
						     24 + 8 * i, 8);
			}
			out[n++] = finish(kSigma, seq, sigma);
			out[n++] = finish(kQuality, seq,
					  put(layout::kLog10Nfa, p.log10_nfa,
					      layout::kLog10Nfa.rawMax()) |
						  put(layout::kSensorTime, p.sensor_time_us, 0));
		}

		const std::uint64_t st =
			field(static_cast<std::uint64_t>(status.state), 0, 3) |
			flag(status.enabled, 3) | flag(send_pose, 4) | flag(status.tracked, 5) |
			field(static_cast<std::uint64_t>(status.strobe), 6, 2) |
			signedField(status.leds_used < 0
					    ? 0
					    : (status.leds_used > 255 ? 255 : status.leds_used),
				    8, 8) |
			signedField(toRaw(status.rms_px, kRmsRes, 0, 255, 255), 16, 8) |
			field(status.faults, 24, 8) |
			signedField(toRaw(status.latency_ms, kLatencyRes, 0, 65535, 65535), 32, 16);
		out[n++] = finish(kStatus, seq, st);
		if (mac_)
			n = authenticate(out, n, seq);
		return n;
	}

	/* The heartbeat frame alone (no authenticator: with one, use the other overload). */
	RawFrame encodeHeartbeat(const HeartbeatData &hb) { return heartbeatFrame(hb); }

	/* The heartbeat and, with an authenticator, DP_Freshness (the freshness
	 * value's high bits) and DP_Auth over both. Returns the frames written
	 * (1 or kMaxHeartbeatFrames). */
	int encodeHeartbeat(const HeartbeatData &hb, RawFrame *out)
	{
		out[0] = heartbeatFrame(hb);
		if (!mac_)
			return 1;
		out[1] = finish(kFreshness, 0,
				detail::putRaw(layout::kFreshnessHigh, (freshness_ + 1) >> 16));
		return authenticate(out, 2, 0);
	}

	/* For the controller side (and tests): a keyless command. */
	RawFrame encodeCommand(const CommandData &cmd) { return commandFrame(cmd); }

	/* A command and, with an authenticator, DP_CommandAuth: its MAC over the
	 * command and sensor_freshness (Decoder::freshness(): the latest value
	 * the controller verified). Returns the frames written (1 or 2). */
	int encodeCommand(const CommandData &cmd, std::uint64_t sensor_freshness, RawFrame *out)
	{
		out[0] = commandFrame(cmd);
		if (!mac_)
			return 1;
		detail::MacInput input;
		input.reset(base_id_);
		input.add(out[0]);
		std::size_t len = 0;
		const std::uint8_t *bytes =
			input.finish(sensor_freshness, nextByte6(kCommandAuth, 0), &len);
		std::uint32_t mac = 0;
		mac_failed_ = !mac_->mac32(bytes, len, &mac);
		out[1] = finish(kCommandAuth, 0,
				detail::putRaw(layout::kCommandFreshness,
					       sensor_freshness & 0xffff) |
					detail::putRaw(layout::kCommandMac, mac));
		return 2;
	}

	/*
	 * Authenticate from now on with mac (nullptr: no more). first_freshness:
	 * the freshness value before the first DP_Auth; it must never repeat for
	 * a key, so the sensor starts each run at (a persisted run counter) << 32.
	 */
	void setAuthenticator(MacFunction *mac, std::uint64_t first_freshness = 0)
	{
		mac_ = mac;
		freshness_ = first_freshness;
	}
	bool authenticating() const { return mac_ != nullptr; }
	/* The freshness value of the last DP_Auth sent (first_freshness before any). */
	std::uint64_t freshness() const { return freshness_; }
	/* The last MAC could not be computed (its frame carries 0: receivers refuse it). */
	bool macFailed() const { return mac_failed_; }
	/*
	 * The next frame at offset continues after alive counter `last`: for a
	 * sender that shares an identifier with another (two command senders on
	 * one bus: an arm controller and an operator's view). A receiver keeps one
	 * alive counter per identifier and refuses a repeated one (StaleAlive).
	 */
	void continueAliveAfter(std::uint32_t offset, std::uint8_t last)
	{
		alive_[detail::slot(offset)] = static_cast<std::uint8_t>((last + 1) & 0x0f);
	}

	std::uint32_t baseId() const { return base_id_; }
	/* The last encodeReport() was asked for a pose it could not send. */
	bool poseDropped() const { return pose_dropped_; }
	/* The sequence the next report will carry (0..15). */
	std::uint8_t nextSequence() const { return sequence_; }

	/* True when the pose fits the fields that must not saturate (translation)
	 * and t, q, rpy are finite. */
	static bool poseEncodable(const PoseData &p)
	{
		using namespace detail;
		if (!encodable(p.t_mm[0], kTranslationRes, -32768, 32767) ||
		    !encodable(p.t_mm[1], kTranslationRes, -32768, 32767) ||
		    !encodable(p.t_mm[2], kTranslationRes, 0, 65535))
			return false;
		for (double v : p.q)
			if (!std::isfinite(v))
				return false;
		for (double v : p.rpy_deg)
			if (!std::isfinite(v))
				return false;
		return true;
	}

private:
	RawFrame heartbeatFrame(const HeartbeatData &hb)
	{
		using namespace detail;
		const std::uint64_t uptime = hb.uptime_s > 0xffffffu ? 0xffffffu : hb.uptime_s;
		return finish(kHeartbeat, 0,
			      field(uptime, 0, 24) |
				      field(static_cast<std::uint64_t>(hb.state), 24, 3) |
				      field(static_cast<std::uint64_t>(hb.mode), 27, 1) |
				      field(static_cast<std::uint64_t>(hb.strobe), 28, 2) |
				      flag(hb.enabled, 30) | flag(mac_ != nullptr, 31) |
				      field(hb.faults, 32, 8) |
				      signedField(toRaw(hb.frame_rate_hz, kFrameRateRes, 0, 255, 0),
						  40, 8));
	}

	RawFrame commandFrame(const CommandData &cmd)
	{
		using namespace detail;
		return finish(kCommand, 0,
			      flag(cmd.enable, 0) |
				      field(static_cast<std::uint64_t>(cmd.mode), 1, 1) |
				      field(static_cast<std::uint64_t>(cmd.strobe), 2, 2) |
				      field(static_cast<std::uint64_t>(cmd.preview), 4, 2) |
				      field(cmd.exposure_us, 8, 16) |
				      signedField(toRaw(cmd.gain, kGainRes, 0, 255, 0), 24, 8));
	}

	/* Append DP_Auth over out[0..n) with the next freshness value; returns n + 1. */
	int authenticate(RawFrame *out, int n, std::uint8_t seq)
	{
		detail::MacInput input;
		input.reset(base_id_);
		for (int i = 0; i < n; ++i)
			input.add(out[i]);
		++freshness_;
		std::size_t len = 0;
		const std::uint8_t *bytes = input.finish(freshness_, nextByte6(kAuth, seq), &len);
		std::uint32_t mac = 0;
		mac_failed_ = !mac_->mac32(bytes, len, &mac);
		out[n] = finish(kAuth, seq,
				detail::putRaw(layout::kAuthFreshness, freshness_ & 0xffff) |
					detail::putRaw(layout::kAuthMac, mac_failed_ ? 0 : mac));
		return n + 1;
	}

	/* Byte 6 (alive counter, sequence) of the next frame at offset. */
	std::uint8_t nextByte6(std::uint32_t offset, std::uint8_t seq) const
	{
		return aliveSeqByte(alive_[detail::slot(offset)], seq);
	}

	RawFrame finish(std::uint32_t offset, std::uint8_t seq, std::uint64_t payload)
	{
		RawFrame f;
		f.id = (base_id_ + offset) & 0x7ff;
		f.len = kFrameLength;
		std::uint8_t &alive = alive_[detail::slot(offset)];
		for (std::size_t i = 0; i < 6; ++i)
			f.data[i] = static_cast<std::uint8_t>(payload >> (8 * i));
		f.data[6] = aliveSeqByte(alive, seq);
		f.data[7] = frameCrc(f.id, f.data);
		alive = static_cast<std::uint8_t>((alive + 1) & 0x0f);
		return f;
	}

	std::uint32_t base_id_;
	std::array<std::uint8_t, detail::kSlots> alive_{};
	std::uint8_t sequence_ = 0;
	bool pose_dropped_ = false;
	MacFunction *mac_ = nullptr;
	std::uint64_t freshness_ = 0;
	bool mac_failed_ = false;
};

enum class FrameError : std::uint8_t {
	None,
	UnknownId,
	WrongLength,
	BadCrc,
	StaleAlive, /* repeated alive counter */
	BadMac, /* authentication: the MAC does not match */
	Replayed, /* authentication: a freshness value not newer than the last accepted (or too old) */
	Unsynced, /* authentication: no DP_Freshness seen yet, the value cannot be rebuilt */
	Unauthenticated, /* authentication: a MAC frame with nothing to cover, or a group whose MAC never came */
};

inline const char *frameErrorName(FrameError error)
{
	switch (error) {
	case FrameError::None:
		return "none";
	case FrameError::UnknownId:
		return "unknown id";
	case FrameError::WrongLength:
		return "wrong length";
	case FrameError::BadCrc:
		return "bad CRC";
	case FrameError::StaleAlive:
		return "stale alive counter";
	case FrameError::BadMac:
		return "bad MAC";
	case FrameError::Replayed:
		return "replayed or outdated freshness value";
	case FrameError::Unsynced:
		return "no freshness value yet";
	case FrameError::Unauthenticated:
		return "not authenticated";
	}
	return "unknown error";
}

/*
 * Decoder: checks and decodes frames from the bus and assembles reports.
 * Never allocates.
 *
 * A frame is Rejected for a length other than 8 (WrongLength), a CRC that does
 * not match its identifier and data (BadCrc), or an alive counter equal to the
 * previous accepted one of its identifier (StaleAlive: repeated or stuck data).
 * An alive counter that jumps by more than 1 is accepted and the skipped
 * counts are added to alive_gaps (frames lost). Identifiers that are not ours
 * (outside base .. base + 0x11, or an unused offset) are normal on a shared
 * bus: Event::None, lastError() UnknownId, counted in unknown_ids only.
 *
 * Pose frames are held until the status frame of the same sequence arrives;
 * that status completes a Report. poseValid() is true when the status says
 * PoseValid and all six pose frames of that sequence arrived intact since
 * the previous status; otherwise a PoseValid status counts in
 * incomplete_poses.
 *
 * Freshness: feed(frame, arrival_us) dates every report with a pose. The
 * sensor stamps its clock into the report (SensorTimeUs, at encoding) and
 * how long the pose had been on its way by then (LatencyMs, from the start of
 * the exposure); the decoder cannot read the sensor's clock directly, so it
 * takes the least-delayed report of the last kClockSamples as the reference:
 *
 *   delay(report) = arrival_us - SensorTimeUs          (clock offset + transit)
 *   age(report)   = delay - min(delay over the last kClockSamples) + LatencyMs
 *
 * A report whose age is above maxAgeUs() (default kDefaultMaxAgeUs) is not a
 * valid pose and counts in stale_poses: a report that sat in a queue during a
 * bus stall arrives with its old SensorTimeUs and shows its wait. Until
 * kMinClockSamples reports have been dated there is no reference yet, and the
 * pose is not valid either (undated_poses); so are reports of a sensor that
 * restarted (its heartbeat's uptime went back) until the reference is built
 * again. A delay the whole stream shares since before the first report cannot
 * be seen this way; the sensor never lets a report wait in its own queue
 * beyond can.max_report_age_us, and the kernel's queue is txqueuelen frames.
 * feed(frame) without an arrival time dates nothing (poseAgeUs() is -1).
 *
 * Authentication (setAuthenticator): nothing counts until its MAC has been
 * checked. The frames the sensor sends since its previous DP_Auth are held;
 * DP_Auth completes them: its freshness value is rebuilt (from the preceding
 * DP_Freshness, or from the last accepted value and the 16 bits it carries),
 * must be newer than the last accepted one, and the MAC over the group and
 * that value must match; only then is the report (Event::Report) or the
 * heartbeat (Event::Heartbeat) taken. A group whose DP_Auth never came is
 * dropped when the next group starts (unauthenticated); a MAC that does not
 * match, a value not newer (replays) or one that cannot be rebuilt yet
 * (unsynced: no DP_Freshness since the decoder started, up to one heartbeat
 * period) is Rejected. The sensor side checks commands the same way, with
 * DP_CommandAuth: its value must be one of the sensor's own last
 * setCommandFreshness() window values, and newer than the last command's.
 */
class Decoder
{
public:
	enum class Event : std::uint8_t {
		None, /* frame taken (or not ours), nothing completed */
		Report,
		Heartbeat,
		Command,
		Rejected,
	};

	struct Counters {
		std::uint64_t frames = 0; /* every frame fed */
		std::uint64_t reports = 0;
		std::uint64_t valid_poses = 0;
		std::uint64_t incomplete_poses = 0;
		std::uint64_t crc_errors = 0;
		std::uint64_t length_errors = 0;
		std::uint64_t unknown_ids = 0;
		std::uint64_t alive_gaps = 0; /* skipped counters: frames lost */
		std::uint64_t stale_frames = 0;
		std::uint64_t stale_poses = 0; /* complete, but older than maxAgeUs() */
		std::uint64_t undated_poses = 0; /* complete, but no clock reference yet */
		std::uint64_t auth_failures = 0; /* MAC mismatch */
		std::uint64_t replays = 0; /* freshness value not newer, or outside the window */
		std::uint64_t unsynced = 0; /* MAC frames before any DP_Freshness */
		std::uint64_t unauthenticated =
			0; /* groups without their MAC, MACs without a group */
	};

	/* Reports dated against the least-delayed of this many. */
	static constexpr std::size_t kClockSamples = 64;
	/* Reports needed before a pose can be dated (and so be valid). */
	static constexpr std::size_t kMinClockSamples = 4;
	/* The default bound on a pose's age at arrival: 50 ms. */
	static constexpr std::int64_t kDefaultMaxAgeUs = 50000;

	explicit Decoder(std::uint32_t base_id = kDefaultBaseId)
		: base_id_(base_id)
	{
		resetGroup();
	}

	/* A frame from the bus, undated (no freshness check). */
	Event feed(const RawFrame &frame)
	{
		timed_ = false;
		return take(frame);
	}

	/* A frame from the bus and the receiver's clock when it arrived (us, any
	 * monotonic clock): reports with a pose are dated (see above). */
	Event feed(const RawFrame &frame, std::int64_t arrival_us)
	{
		timed_ = true;
		arrival_us_ = arrival_us;
		return take(frame);
	}

	/*
	 * A DP_ReportFd from the bus (CAN FD), and its arrival time: its classic
	 * frames are taken one by one as if they had come in that order (the same
	 * counters, CRCs, MAC and dating). Report when they completed a report;
	 * Rejected when the frame is not a 64-byte DP_ReportFd (length_errors,
	 * unknown_ids) or one of its frames was refused (the first refusal is
	 * lastError()); the report is then not valid.
	 */
	Event feedFd(const FdFrame &frame, std::int64_t arrival_us)
	{
		timed_ = true;
		arrival_us_ = arrival_us;
		return takeFd(frame);
	}
	/* The same, undated. */
	Event feedFd(const FdFrame &frame)
	{
		timed_ = false;
		return takeFd(frame);
	}

	/* Check MACs from now on (nullptr: accept unauthenticated frames again). */
	void setAuthenticator(MacFunction *mac)
	{
		mac_ = mac;
		dropGroup();
		command_held_ = false;
	}
	bool authenticating() const { return mac_ != nullptr; }
	/* Controller side: the newest sensor freshness value accepted (0: none yet). Persist it
	 * across restarts with restoreFreshness(), so that no recorded traffic is accepted before
	 * the sensor's next DP_Freshness. */
	std::uint64_t freshness() const { return last_fv_; }
	void restoreFreshness(std::uint64_t freshness)
	{
		last_fv_ = freshness;
		synced_ = freshness != 0;
	}
	/* Sensor side: commands must answer one of the last `window` freshness values `sensor`
	 * sent (its own encoder) and be newer than the last command's. */
	void setCommandFreshness(const Encoder *sensor, std::uint64_t window)
	{
		sensor_ = sensor;
		command_window_ = window;
	}

	/* Sensor side, with a key: a DP_Command is held until its DP_CommandAuth. */
	bool commandPending() const { return command_held_; }
	/*
	 * Sensor side: the held DP_Command whose DP_CommandAuth did not come (the
	 * caller's bound: a sender sends the two back to back) is dropped,
	 * Rejected (Unauthenticated, counted in unauthenticated); None when none
	 * is held. A later DP_Command also rejects the one held before it.
	 */
	Event dropPendingCommand()
	{
		if (!command_held_)
			return Event::None;
		command_held_ = false;
		return reject(FrameError::Unauthenticated, &counters_.unauthenticated);
	}

	/* Poses older than this at arrival are not valid (feed with arrival_us). */
	void setMaxAgeUs(std::int64_t max_age_us) { max_age_us_ = max_age_us; }
	std::int64_t maxAgeUs() const { return max_age_us_; }
	/* The last dated report's age at arrival (us), -1 when it was not dated. */
	std::int64_t poseAgeUs() const { return pose_age_us_; }

private:
	Event takeFd(const FdFrame &frame)
	{
		if (frame.id != ((base_id_ + kReportFd) & 0x7ff)) {
			++counters_.frames;
			++counters_.unknown_ids;
			last_error_ = FrameError::UnknownId;
			return Event::None;
		}
		if (frame.len != kFdReportLength) {
			++counters_.frames;
			++counters_.length_errors;
			last_error_ = FrameError::WrongLength;
			return Event::Rejected;
		}
		std::array<RawFrame, kFdSlots.size()> frames;
		const int n = unpackFd(frame, base_id_, frames.data());
		Event result = Event::None;
		FrameError first = FrameError::None;
		for (int i = 0; i < n; ++i) {
			const RawFrame &f = frames[static_cast<std::size_t>(i)];
			/* A keyless receiver ignores the MAC slot: the status is then the last
			 * frame taken, so a report completes only after every other part. */
			if (!mac_ && f.id == ((base_id_ + kAuth) & 0x7ff))
				continue;
			const Event e = take(f);
			if (e == Event::Rejected && first == FrameError::None)
				first = last_error_;
			if (e != Event::None)
				result = e;
		}
		if (first != FrameError::None) {
			/* A refused part leaves the report incomplete (its status, when it
			 * came, already said so); nothing of it is held for later frames. */
			dropGroup();
			pending_mask_ = 0;
			pose_valid_ = false;
			last_error_ = first;
			return Event::Rejected;
		}
		return result;
	}

	Event take(const RawFrame &frame)
	{
		using namespace detail;
		++counters_.frames;
		last_error_ = FrameError::None;

		if (frame.id < base_id_ || !knownOffset(frame.id - base_id_)) {
			++counters_.unknown_ids;
			last_error_ = FrameError::UnknownId;
			return Event::None;
		}
		const std::uint32_t offset = frame.id - base_id_;
		if (frame.len != kFrameLength) {
			++counters_.length_errors;
			last_error_ = FrameError::WrongLength;
			return Event::Rejected;
		}
		if (frameCrc(frame.id, frame.data) != frame.data[7]) {
			++counters_.crc_errors;
			last_error_ = FrameError::BadCrc;
			return Event::Rejected;
		}

		const std::uint8_t alive = frameAlive(frame.data);
		const std::uint8_t seq = frameSeq(frame.data);
		const std::size_t s = slot(offset);
		if (alive_seen_[s]) {
			const unsigned int step = (alive - alive_[s]) & 0x0fu;
			if (step == 0) {
				++counters_.stale_frames;
				last_error_ = FrameError::StaleAlive;
				return Event::Rejected;
			}
			counters_.alive_gaps += step - 1;
		}
		alive_seen_[s] = true;
		alive_[s] = alive;

		const std::array<std::uint8_t, 8> &d = frame.data;
		if (mac_ && offset <= kFreshness && offset != kAuth) {
			/* A sensor frame after a closed group (its status or heartbeat came) that
			 * is not the heartbeat's DP_Freshness: that group's MAC was lost. */
			if (held_ != Held::None &&
			    !(offset == kFreshness && held_ == Held::Heartbeat))
				dropGroup();
			/*
			 * A frame that cannot belong to the open group: the rest of that
			 * group never came (the sensor drops what misses its deadline,
			 * and a report cut short leaves its first frames on the bus), so
			 * its frames must not spoil the next group's MAC.
			 */
			else if (group_kind_ != GroupKind::None && !continuesGroup(offset, seq)) {
				++counters_.unauthenticated;
				resetGroup();
			}
			group_.add(frame);
			group_kind_ = offset == kHeartbeat || offset == kFreshness
					      ? GroupKind::Heartbeat
					      : GroupKind::Report;
			group_seq_ = seq;
		}
		if (!mac_ && (offset == kAuth || offset == kFreshness || offset == kCommandAuth))
			return Event::None; /* a keyless receiver ignores the MACs */
		switch (offset) {
		case kTranslation:
			takePose(kTranslation, seq);
			pending_.t_mm[0] =
				static_cast<double>(signedBits(d, 0, 16)) * kTranslationRes;
			pending_.t_mm[1] =
				static_cast<double>(signedBits(d, 16, 16)) * kTranslationRes;
			pending_.t_mm[2] = static_cast<double>(bits(d, 32, 16)) * kTranslationRes;
			return Event::None;
		case kQuatA:
			takePose(kQuatA, seq);
			for (unsigned int i = 0; i < 3; ++i)
				pending_.q[i] =
					static_cast<double>(signedBits(d, 16 * i, 16)) * kQuatRes;
			return Event::None;
		case kQuatB:
			takePose(kQuatB, seq);
			pending_.q[3] = static_cast<double>(signedBits(d, 0, 16)) * kQuatRes;
			pending_.frame_counter = static_cast<std::uint32_t>(bits(d, 16, 32));
			return Event::None;
		case kAngles:
			takePose(kAngles, seq);
			for (unsigned int i = 0; i < 3; ++i)
				pending_.rpy_deg[i] =
					static_cast<double>(signedBits(d, 16 * i, 16)) * kAngleRes;
			return Event::None;
		case kSigma:
			takePose(kSigma, seq);
			for (unsigned int i = 0; i < 3; ++i) {
				pending_.sigma_t_mm[i] =
					static_cast<double>(bits(d, 8 * i, 8)) * kSigmaTRes;
				pending_.sigma_rpy_deg[i] =
					static_cast<double>(bits(d, 24 + 8 * i, 8)) * kSigmaRpyRes;
			}
			return Event::None;
		case kQuality:
			takePose(kQuality, seq);
			pending_.log10_nfa = get(d, layout::kLog10Nfa);
			pending_.sensor_time_us =
				static_cast<std::uint32_t>(get(d, layout::kSensorTime));
			return Event::None;
		case kStatus:
			if (!mac_)
				return completeReport(parseStatus(d), seq);
			held_ = Held::Report;
			held_status_ = parseStatus(d);
			held_seq_ = seq;
			return Event::None;
		case kHeartbeat:
			if (!mac_)
				return commitHeartbeat(parseHeartbeat(d));
			held_ = Held::Heartbeat;
			held_heartbeat_ = parseHeartbeat(d);
			have_high_ = false;
			return Event::None;
		case kFreshness:
			if (held_ == Held::Heartbeat) {
				held_high_ = getRaw(d, layout::kFreshnessHigh);
				have_high_ = true;
			}
			return Event::None;
		case kAuth:
			return verifyGroup(d);
		case kCommand:
			if (!mac_) {
				command_ = parseCommand(d);
				return Event::Command;
			}
			{
				/* The command held before this one never got its DP_CommandAuth. */
				const bool orphan = command_held_;
				command_held_ = true;
				held_command_ = parseCommand(d);
				command_frame_ = frame;
				if (orphan)
					return reject(FrameError::Unauthenticated,
						      &counters_.unauthenticated);
				return Event::None;
			}
		default: /* kCommandAuth */
			return verifyCommand(d);
		}
	}

	static StatusData parseStatus(const std::array<std::uint8_t, 8> &d)
	{
		using namespace detail;
		StatusData st;
		st.state = static_cast<SensorState>(bits(d, 0, 3));
		st.enabled = bits(d, 3, 1) != 0;
		st.pose_valid = bits(d, 4, 1) != 0;
		st.tracked = bits(d, 5, 1) != 0;
		st.strobe = static_cast<StrobeMode>(bits(d, 6, 2));
		st.leds_used = static_cast<int>(bits(d, 8, 8));
		st.rms_px = static_cast<double>(bits(d, 16, 8)) * kRmsRes;
		st.faults = static_cast<std::uint8_t>(bits(d, 24, 8));
		st.latency_ms = static_cast<double>(bits(d, 32, 16)) * kLatencyRes;
		return st;
	}

	static HeartbeatData parseHeartbeat(const std::array<std::uint8_t, 8> &d)
	{
		using namespace detail;
		HeartbeatData hb;
		hb.uptime_s = static_cast<std::uint32_t>(bits(d, 0, 24));
		hb.state = static_cast<SensorState>(bits(d, 24, 3));
		hb.mode = static_cast<TrackMode>(bits(d, 27, 1));
		hb.strobe = static_cast<StrobeMode>(bits(d, 28, 2));
		hb.enabled = bits(d, 30, 1) != 0;
		hb.authenticated = getRaw(d, layout::kAuthenticated) != 0;
		hb.faults = static_cast<std::uint8_t>(bits(d, 32, 8));
		hb.frame_rate_hz = static_cast<double>(bits(d, 40, 8)) * kFrameRateRes;
		return hb;
	}

	static CommandData parseCommand(const std::array<std::uint8_t, 8> &d)
	{
		using namespace detail;
		CommandData cmd;
		cmd.enable = bits(d, 0, 1) != 0;
		cmd.mode = static_cast<TrackMode>(bits(d, 1, 1));
		cmd.strobe = static_cast<StrobeMode>(bits(d, 2, 2));
		cmd.preview = static_cast<PreviewSwitch>(bits(d, 4, 2));
		cmd.exposure_us = static_cast<std::uint16_t>(bits(d, 8, 16));
		cmd.gain = static_cast<double>(bits(d, 24, 8)) * kGainRes;
		return cmd;
	}

	Event commitHeartbeat(const HeartbeatData &hb)
	{
		if (hb.uptime_s < heartbeat_.uptime_s)
			resetClock(); /* the sensor restarted: its clock did too */
		heartbeat_ = hb;
		return Event::Heartbeat;
	}

	Event reject(FrameError error, std::uint64_t *counter)
	{
		++*counter;
		last_error_ = error;
		return Event::Rejected;
	}

	/* The MAC's truncated value over `input`, `freshness` and the MAC frame's byte 6 is
	 * the MAC frame's. */
	bool macMatches(detail::MacInput &input, std::uint64_t freshness,
			const std::array<std::uint8_t, 8> &mac_frame,
			const SignalLayout &mac_signal)
	{
		const std::uint64_t mac = detail::getRaw(mac_frame, mac_signal);
		std::size_t len = 0;
		const std::uint8_t *bytes = input.finish(freshness, mac_frame[6], &len);
		std::uint32_t expected = 0;
		return mac_->mac32(bytes, len, &expected) && expected == mac;
	}

	/* DP_Auth: check the held group and take it. */
	Event verifyGroup(const std::array<std::uint8_t, 8> &d)
	{
		using namespace detail;
		const Held held = held_;
		const bool overflow = group_.overflow();
		const bool have_high = have_high_;
		const std::uint64_t high = held_high_;
		held_ = Held::None;
		have_high_ = false;
		/* The group is checked as it is now; the next one starts empty. */
		detail::MacInput input = group_;
		resetGroup();
		if (held == Held::None || overflow)
			return reject(FrameError::Unauthenticated, &counters_.unauthenticated);

		const std::uint64_t low = getRaw(d, layout::kAuthFreshness);
		std::uint64_t fv;
		if (have_high) {
			fv = (high << 16) | low;
		} else if (synced_) {
			fv = (last_fv_ & ~std::uint64_t{ 0xffff }) | low;
			if (fv <= last_fv_)
				fv += 0x10000;
		} else {
			return reject(FrameError::Unsynced, &counters_.unsynced);
		}
		if (synced_ && fv <= last_fv_)
			return reject(FrameError::Replayed, &counters_.replays);
		if (!macMatches(input, fv, d, layout::kAuthMac))
			return reject(FrameError::BadMac, &counters_.auth_failures);
		last_fv_ = fv;
		synced_ = true;
		if (held == Held::Report)
			return completeReport(held_status_, held_seq_);
		return commitHeartbeat(held_heartbeat_);
	}

	/* DP_CommandAuth: check the held command against the sensor's own freshness. */
	Event verifyCommand(const std::array<std::uint8_t, 8> &d)
	{
		using namespace detail;
		const bool held = command_held_;
		command_held_ = false;
		if (!held || !sensor_)
			return reject(FrameError::Unauthenticated, &counters_.unauthenticated);
		const std::uint64_t current = sensor_->freshness();
		const std::uint64_t low = getRaw(d, layout::kCommandFreshness);
		std::uint64_t echo = (current & ~std::uint64_t{ 0xffff }) | low;
		if (echo > current) {
			if (echo < 0x10000)
				return reject(FrameError::Replayed, &counters_.replays);
			echo -= 0x10000;
		}
		if (current - echo >= command_window_ ||
		    (command_synced_ && echo <= last_command_fv_))
			return reject(FrameError::Replayed, &counters_.replays);
		detail::MacInput input;
		input.reset(base_id_);
		input.add(command_frame_);
		if (!macMatches(input, echo, d, layout::kCommandMac))
			return reject(FrameError::BadMac, &counters_.auth_failures);
		last_command_fv_ = echo;
		command_synced_ = true;
		command_ = held_command_;
		return Event::Command;
	}

	/*
	 * Can a sensor frame continue the open group? A heartbeat starts one (its
	 * DP_Freshness continues it); a report's frames share its sequence.
	 */
	bool continuesGroup(std::uint32_t offset, std::uint8_t seq) const
	{
		if (offset == kHeartbeat)
			return false;
		if (offset == kFreshness)
			return group_kind_ == GroupKind::Heartbeat;
		return group_kind_ == GroupKind::Report && seq == group_seq_;
	}

	void resetGroup()
	{
		group_.reset(base_id_);
		group_kind_ = GroupKind::None;
	}

	void dropGroup()
	{
		if (held_ != Held::None)
			++counters_.unauthenticated;
		held_ = Held::None;
		have_high_ = false;
		resetGroup();
	}

public:
	/* The last report's status, as sent (pose_valid is the sender's flag). */
	const StatusData &status() const { return status_; }
	/* After a Report: status().pose_valid and all six pose frames of its
	 * sequence arrived intact. */
	bool poseValid() const { return pose_valid_; }
	/* The last valid pose (current when poseValid()). */
	const PoseData &pose() const { return pose_; }
	/* The sequence of the last report (0..15). */
	std::uint8_t sequence() const { return sequence_; }
	const HeartbeatData &heartbeat() const { return heartbeat_; }
	const CommandData &command() const { return command_; }
	FrameError lastError() const { return last_error_; }
	const Counters &counters() const { return counters_; }
	std::uint32_t baseId() const { return base_id_; }

private:
	void takePose(std::uint32_t offset, std::uint8_t seq)
	{
		/* A pose frame of another sequence: what was held belongs to a
		 * report whose status never came. */
		if (pending_mask_ != 0 && pending_seq_ != seq)
			pending_mask_ = 0;
		pending_seq_ = seq;
		pending_mask_ = static_cast<std::uint8_t>(pending_mask_ | (1u << offset));
	}

	/* A status (verified, with authentication) completes the report of its sequence. */
	Event completeReport(const StatusData &status, std::uint8_t seq)
	{
		using namespace detail;
		status_ = status;
		sequence_ = seq;

		const bool complete = pending_mask_ == kPoseFrameMask && pending_seq_ == seq;
		pose_valid_ = status_.pose_valid && complete;
		pose_age_us_ = -1;
		if (pose_valid_ && timed_)
			pose_valid_ = datePose();
		if (pose_valid_) {
			pose_ = pending_;
			++counters_.valid_poses;
		} else if (status_.pose_valid && !complete) {
			++counters_.incomplete_poses;
		}
		pending_mask_ = 0;
		++counters_.reports;
		return Event::Report;
	}

	/* The complete report in pending_ arrived at arrival_us_: its age, and
	 * whether it is young enough (counting the ones that are not). */
	bool datePose()
	{
		/* SensorTimeUs wraps every 2^32 us: unwrap against the previous one. */
		const std::uint32_t raw = pending_.sensor_time_us;
		if (clock_count_ == 0)
			sensor_us_ = raw;
		else
			sensor_us_ += static_cast<std::int32_t>(
				raw - static_cast<std::uint32_t>(sensor_us_));
		const std::int64_t delay_us = arrival_us_ - sensor_us_;
		clock_[clock_next_] = delay_us;
		clock_next_ = (clock_next_ + 1) % kClockSamples;
		if (clock_count_ < kClockSamples)
			++clock_count_;
		std::int64_t min_us = delay_us;
		for (std::size_t i = 0; i < clock_count_; ++i)
			min_us = clock_[i] < min_us ? clock_[i] : min_us;

		pose_age_us_ = delay_us - min_us +
			       static_cast<std::int64_t>(std::llround(status_.latency_ms * 1000.0));
		if (clock_count_ < kMinClockSamples) {
			++counters_.undated_poses;
			return false;
		}
		if (pose_age_us_ > max_age_us_) {
			++counters_.stale_poses;
			return false;
		}
		return true;
	}

	void resetClock()
	{
		clock_count_ = 0;
		clock_next_ = 0;
	}

	std::uint32_t base_id_;
	std::array<std::uint8_t, detail::kSlots> alive_{};
	std::array<bool, detail::kSlots> alive_seen_{};
	enum class Held : std::uint8_t {
		None,
		Report,
		Heartbeat
	};

	bool timed_ = false;
	std::int64_t arrival_us_ = 0;
	/* Authentication. */
	MacFunction *mac_ = nullptr;
	detail::MacInput group_;
	/* What the open group holds: nothing yet, a report's frames (of group_seq_), a heartbeat's. */
	enum class GroupKind : std::uint8_t {
		None,
		Report,
		Heartbeat
	};
	GroupKind group_kind_ = GroupKind::None;
	std::uint8_t group_seq_ = 0;
	Held held_ = Held::None;
	StatusData held_status_;
	std::uint8_t held_seq_ = 0;
	HeartbeatData held_heartbeat_;
	bool have_high_ = false;
	std::uint64_t held_high_ = 0;
	std::uint64_t last_fv_ = 0;
	bool synced_ = false;
	const Encoder *sensor_ = nullptr;
	std::uint64_t command_window_ = 0;
	bool command_held_ = false;
	CommandData held_command_;
	RawFrame command_frame_;
	std::uint64_t last_command_fv_ = 0;
	bool command_synced_ = false;
	std::int64_t max_age_us_ = kDefaultMaxAgeUs;
	std::int64_t pose_age_us_ = -1;
	std::array<std::int64_t, kClockSamples> clock_{};
	std::size_t clock_count_ = 0;
	std::size_t clock_next_ = 0;
	std::int64_t sensor_us_ = 0;
	PoseData pending_;
	std::uint8_t pending_mask_ = 0; /* bit per pose offset held */
	std::uint8_t pending_seq_ = 0;
	StatusData status_;
	PoseData pose_;
	bool pose_valid_ = false;
	std::uint8_t sequence_ = 0;
	HeartbeatData heartbeat_;
	CommandData command_;
	FrameError last_error_ = FrameError::None;
	Counters counters_;
};

} /* namespace dockpose::can */

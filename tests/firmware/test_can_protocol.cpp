/* SPDX-License-Identifier: MIT */
/*
 * The CAN protocol (firmware/protocol/dockpose_can.h): CRC, encoder/decoder
 * round trips, saturation, rejections, bus load, and an independent check of
 * the DBC: reports encoded here are written as a candump log and decoded by
 * canmatrix alone (tests/firmware/canmatrix_decode.py) and by
 * scripts/candecode, and every signal is compared with the C++ input.
 */
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "firmware/protocol/dockpose_can.h"

using namespace dockpose::can;
using Event = Decoder::Event;

namespace {

/* Half a resolution step, plus room for the decimal factors' rounding. */
constexpr double kTolT = 0.05 + 1e-9;
constexpr double kTolQ = 5e-5 + 1e-12;
constexpr double kTolDeg = 0.005 + 1e-9;
/* A sigma's steps (it goes out rounded up, see expectSigmaSent). */
constexpr double kStepSigmaT = 0.1;
constexpr double kStepSigmaDeg = 0.01;
constexpr double kTolRms = 0.005 + 1e-9;
constexpr double kTolLatency = 0.005 + 1e-9;
constexpr double kTolNfa = 0.05 + 1e-9;

constexpr std::uint8_t crcOf(const char *s, std::size_t n)
{
	std::uint8_t b[16]{};
	for (std::size_t i = 0; i < n; ++i)
		b[i] = static_cast<std::uint8_t>(s[i]);
	return crc8J1850(b, n);
}
static_assert(crcOf("123456789", 9) == 0x4b, "CRC-8 J1850 check value");
static_assert(worstCaseFrameBits(8) == 135, "8-byte standard frame, worst-case stuffing");

struct Report {
	StatusData status;
	PoseData pose;
	bool with_pose = false;
};

class RandomReports
{
public:
	explicit RandomReports(unsigned int seed)
		: rng_(seed)
	{
	}

	double uniform(double lo, double hi)
	{
		return std::uniform_real_distribution<double>(lo, hi)(rng_);
	}
	int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }

	PoseData pose()
	{
		PoseData p;
		p.frame_counter = std::uniform_int_distribution<std::uint32_t>()(rng_);
		p.t_mm[0] = uniform(-3270, 3270);
		p.t_mm[1] = uniform(-3270, 3270);
		p.t_mm[2] = uniform(0, 6550);
		/* A random unit quaternion, w >= 0. */
		double q[4], n = 0;
		for (double &v : q) {
			v = std::normal_distribution<double>()(rng_);
			n += v * v;
		}
		n = std::sqrt(n) * (q[0] < 0 ? -1 : 1);
		for (int i = 0; i < 4; ++i)
			p.q[i] = q[i] / n;
		for (int i = 0; i < 3; ++i) {
			p.rpy_deg[i] = uniform(-180, 180);
			p.sigma_t_mm[i] = uniform(0, 25.5);
			p.sigma_rpy_deg[i] = uniform(0, 2.55);
		}
		p.log10_nfa = uniform(-300, 0);
		p.sensor_time_us = std::uniform_int_distribution<std::uint32_t>()(rng_);
		return p;
	}

	StatusData status(bool pose_valid)
	{
		StatusData s;
		s.state = pose_valid
				  ? (integer(0, 1) ? SensorState::Tracking : SensorState::Degraded)
				  : static_cast<SensorState>(integer(0, 5));
		s.enabled = integer(0, 1) != 0;
		s.pose_valid = pose_valid;
		s.tracked = integer(0, 1) != 0;
		s.strobe = static_cast<StrobeMode>(integer(0, 2));
		s.leds_used = integer(0, 255);
		s.rms_px = uniform(0, 2.55);
		s.faults = static_cast<std::uint8_t>(integer(0, 255));
		s.latency_ms = uniform(0, 655.35);
		return s;
	}

private:
	std::mt19937 rng_;
};

unsigned int sequenceOf(const RawFrame &f)
{
	return f.data[6] >> 4;
}
unsigned int aliveOf(const RawFrame &f)
{
	return f.data[6] & 0x0f;
}

/* A sigma goes out rounded up: decoded, it is at least what was sent (never more
 * certain) and less than one step above it (room for the decimal factor's rounding). */
void expectSigmaSent(double got, double sent, double step)
{
	EXPECT_GE(got, sent - 1e-9) << "sigma sent " << sent;
	EXPECT_LT(got, sent + step + 1e-9) << "sigma sent " << sent;
}

void expectPoseNear(const PoseData &got, const PoseData &want)
{
	EXPECT_EQ(got.frame_counter, want.frame_counter);
	for (int i = 0; i < 3; ++i) {
		EXPECT_NEAR(got.t_mm[i], want.t_mm[i], kTolT) << "t " << i;
		EXPECT_NEAR(got.rpy_deg[i], want.rpy_deg[i], kTolDeg) << "rpy " << i;
		expectSigmaSent(got.sigma_t_mm[i], want.sigma_t_mm[i], kStepSigmaT);
		expectSigmaSent(got.sigma_rpy_deg[i], want.sigma_rpy_deg[i], kStepSigmaDeg);
	}
	for (int i = 0; i < 4; ++i)
		EXPECT_NEAR(got.q[i], want.q[i], kTolQ) << "q " << i;
	EXPECT_NEAR(got.log10_nfa, want.log10_nfa, kTolNfa);
}

void expectStatusNear(const StatusData &got, const StatusData &want)
{
	EXPECT_EQ(got.state, want.state);
	EXPECT_EQ(got.enabled, want.enabled);
	EXPECT_EQ(got.pose_valid, want.pose_valid);
	EXPECT_EQ(got.tracked, want.tracked);
	EXPECT_EQ(got.strobe, want.strobe);
	EXPECT_EQ(got.leds_used, want.leds_used);
	EXPECT_NEAR(got.rms_px, want.rms_px, kTolRms);
	EXPECT_EQ(got.faults, want.faults);
	EXPECT_NEAR(got.latency_ms, want.latency_ms, kTolLatency);
}

/* Feed a report's frames; returns the event of the last one. */
Event feedAll(Decoder &dec, const RawFrame *frames, int n)
{
	Event ev = Event::Rejected;
	for (int i = 0; i < n; ++i)
		ev = dec.feed(frames[i]);
	return ev;
}

} /* namespace */

/* ---- CRC ---- */

TEST(Crc8J1850, CheckValueAndKnownVectors)
{
	const std::string check = "123456789";
	EXPECT_EQ(crc8J1850(reinterpret_cast<const std::uint8_t *>(check.data()), check.size()),
		  0x4b);

	/* AUTOSAR SWS CRC Library's SAE J1850 table, recomputed independently
	 * with a bitwise polynomial division in Python. */
	struct Vector {
		std::vector<std::uint8_t> data;
		std::uint8_t crc;
	};
	const Vector vectors[] = {
		{ { 0x00, 0x00, 0x00, 0x00 }, 0x59 },
		{ { 0xf2, 0x01, 0x83 }, 0x37 },
		{ { 0x0f, 0xaa, 0x00, 0x55 }, 0x79 },
		{ { 0x00, 0xff, 0x55, 0x11 }, 0xb8 },
		{ { 0x33, 0x22, 0x55, 0xaa, 0xbb, 0xcc, 0xdd, 0xee, 0xff }, 0xcb },
		{ { 0x92, 0x6b, 0x55 }, 0x8c },
		{ { 0xff, 0xff, 0xff, 0xff }, 0x74 },
		{ {}, 0x00 },
	};
	for (const Vector &v : vectors)
		EXPECT_EQ(crc8J1850(v.data.data(), v.data.size()), v.crc)
			<< "vector of " << v.data.size() << " bytes";
}

TEST(Crc8J1850, CoversTheIdentifier)
{
	std::array<std::uint8_t, 8> data{ 1, 2, 3, 4, 5, 6, 7, 0 };
	/* [id & 0xff, (id >> 8) & 0x07, data0..6]: all three high id bits count. */
	const std::uint8_t bytes[9] = { 0x05, 0x06, 1, 2, 3, 4, 5, 6, 7 };
	EXPECT_EQ(frameCrc(0x605, data), crc8J1850(bytes, 9));
	EXPECT_NE(frameCrc(0x605, data), frameCrc(0x606, data));
	EXPECT_NE(frameCrc(0x605, data), frameCrc(0x205, data));
	data[7] = 0xaa; /* the CRC byte itself is not covered */
	EXPECT_EQ(frameCrc(0x605, data), crc8J1850(bytes, 9));
}

/* ---- Encoder -> Decoder ---- */

TEST(CanProtocol, FrameLayout)
{
	Encoder enc(0x300);
	StatusData st;
	st.pose_valid = true;
	st.state = SensorState::Tracking;
	PoseData pose;
	pose.t_mm[0] = -1234.5; /* raw -12345 = 0xcfc7 */
	pose.t_mm[1] = 0.1; /* raw 1 */
	pose.t_mm[2] = 6553.5; /* raw 65535 */
	pose.frame_counter = 0x12345678;
	pose.log10_nfa = -12.34; /* raw -123 = 0xff85 */
	RawFrame out[kReportFrames];
	ASSERT_EQ(enc.encodeReport(st, &pose, out), kReportFrames);

	/* The pose frames, DP_Quality last, then the status. */
	const std::uint32_t ids[kReportFrames] = { 0x300, 0x301, 0x302, 0x303, 0x304, 0x307, 0x305 };
	for (int i = 0; i < kReportFrames; ++i) {
		EXPECT_EQ(out[i].id, ids[i]);
		EXPECT_EQ(out[i].len, 8);
		EXPECT_EQ(sequenceOf(out[i]), 0u);
		EXPECT_EQ(aliveOf(out[i]), 0u);
		EXPECT_EQ(out[i].data[7], frameCrc(out[i].id, out[i].data));
	}
	const std::array<std::uint8_t, 6> translation{ 0xc7, 0xcf, 0x01, 0x00, 0xff, 0xff };
	EXPECT_TRUE(std::equal(translation.begin(), translation.end(), out[0].data.begin()));
	/* Qw 1.0 = raw 10000 = 0x2710 */
	EXPECT_EQ(out[1].data[0], 0x10);
	EXPECT_EQ(out[1].data[1], 0x27);
	/* FrameCounter in bits 16..47, little-endian */
	EXPECT_EQ(out[2].data[2], 0x78);
	EXPECT_EQ(out[2].data[5], 0x12);
	/* Log10Nfa in bits 0..15, the rest of the payload spare (0) */
	const std::array<std::uint8_t, 6> quality{ 0x85, 0xff, 0, 0, 0, 0 };
	EXPECT_TRUE(std::equal(quality.begin(), quality.end(), out[5].data.begin()));
	/* Status: State 2, Enabled, PoseValid: 0b00011010 */
	EXPECT_EQ(out[6].data[0], 0x1a);

	/* Second report: sequence 1, alive 1 everywhere. */
	ASSERT_EQ(enc.encodeReport(st, &pose, out), kReportFrames);
	for (int i = 0; i < kReportFrames; ++i) {
		EXPECT_EQ(sequenceOf(out[i]), 1u);
		EXPECT_EQ(aliveOf(out[i]), 1u);
	}
	/* Heartbeat and command carry sequence 0 and their own alive counters. */
	EXPECT_EQ(sequenceOf(enc.encodeHeartbeat(HeartbeatData{})), 0u);
	const RawFrame hb = enc.encodeHeartbeat(HeartbeatData{});
	EXPECT_EQ(hb.id, 0x306u);
	EXPECT_EQ(aliveOf(hb), 1u);
	const RawFrame cmd = enc.encodeCommand(CommandData{});
	EXPECT_EQ(cmd.id, 0x310u);
	EXPECT_EQ(aliveOf(cmd), 0u);
	EXPECT_EQ(sequenceOf(cmd), 0u);
}

TEST(CanProtocol, RandomRoundTrip)
{
	for (std::uint32_t base : { kDefaultBaseId, 0x120u, kMaxBaseId }) {
		SCOPED_TRACE(base);
		RandomReports gen(1234 + base);
		Encoder enc(base);
		Decoder dec(base);
		RawFrame out[kReportFrames];
		int valid = 0;
		for (int i = 0; i < 2000; ++i) {
			const bool with_pose = i % 5 != 4;
			const PoseData pose = gen.pose();
			const StatusData st = gen.status(with_pose);
			const int n = enc.encodeReport(st, &pose, out);
			ASSERT_EQ(n, with_pose ? kReportFrames : 1);
			EXPECT_FALSE(enc.poseDropped());
			for (int k = 0; k < n; ++k) {
				EXPECT_EQ(sequenceOf(out[k]), static_cast<unsigned int>(i) & 0x0f);
				const Event ev = dec.feed(out[k]);
				ASSERT_EQ(ev, k == n - 1 ? Event::Report : Event::None)
					<< "frame " << k << " error "
					<< frameErrorName(dec.lastError());
			}
			EXPECT_EQ(dec.sequence(), static_cast<unsigned int>(i) & 0x0f);
			expectStatusNear(dec.status(), st);
			ASSERT_EQ(dec.poseValid(), with_pose);
			if (with_pose) {
				expectPoseNear(dec.pose(), pose);
				EXPECT_EQ(dec.pose().sensor_time_us, pose.sensor_time_us);
				++valid;
			}
			if (::testing::Test::HasFailure())
				return;
		}
		const Decoder::Counters &c = dec.counters();
		EXPECT_EQ(c.reports, 2000u);
		EXPECT_EQ(c.valid_poses, static_cast<std::uint64_t>(valid));
		EXPECT_EQ(c.incomplete_poses + c.crc_errors + c.length_errors + c.alive_gaps +
				  c.stale_frames + c.unknown_ids,
			  0u);
	}
}

TEST(CanProtocol, SignedFields)
{
	Encoder enc;
	Decoder dec;
	RawFrame out[kReportFrames];
	StatusData st;
	st.pose_valid = true;
	const double cases[][3] = {
		{ -0.1, 0.1, 0.0 },
		{ -3276.8, 3276.7, 0.1 },
		{ 3276.7, -3276.8, 6553.5 },
		{ -1.0, -2000.05, 1500.2 },
	};
	for (const auto &t : cases) {
		PoseData p;
		for (int i = 0; i < 3; ++i)
			p.t_mm[i] = t[i];
		p.q[0] = 0.0001;
		p.q[1] = -1.0;
		p.q[2] = -0.0001;
		p.q[3] = -3.2768;
		p.rpy_deg[0] = -180.0;
		p.rpy_deg[1] = -0.01;
		p.rpy_deg[2] = 327.67;
		ASSERT_EQ(enc.encodeReport(st, &p, out), kReportFrames);
		ASSERT_EQ(feedAll(dec, out, kReportFrames), Event::Report);
		ASSERT_TRUE(dec.poseValid());
		expectPoseNear(dec.pose(), p);
		EXPECT_LT(dec.pose().q[1], 0.0);
	}
}

TEST(CanProtocol, Saturation)
{
	Encoder enc;
	Decoder dec;
	RawFrame out[kReportFrames];
	StatusData st;
	st.pose_valid = true;
	st.leds_used = 300;
	st.rms_px = 3.0;
	st.latency_ms = 1000.0;
	PoseData p;
	p.t_mm[2] = 1000;
	p.sigma_t_mm[0] = 30.0;
	p.sigma_t_mm[1] = std::numeric_limits<double>::quiet_NaN();
	p.sigma_t_mm[2] = -1.0;
	p.sigma_rpy_deg[0] = 5.0;
	p.sigma_rpy_deg[1] = std::numeric_limits<double>::infinity();
	p.sigma_rpy_deg[2] = 2.55;
	p.rpy_deg[0] = 400.0;
	p.rpy_deg[1] = -400.0;
	p.log10_nfa = -5000.0;
	ASSERT_EQ(enc.encodeReport(st, &p, out), kReportFrames);
	ASSERT_EQ(feedAll(dec, out, kReportFrames), Event::Report);
	ASSERT_TRUE(dec.poseValid());
	EXPECT_DOUBLE_EQ(dec.pose().log10_nfa, -3276.8); /* at most that */
	EXPECT_DOUBLE_EQ(dec.pose().sigma_t_mm[0], 25.5);
	EXPECT_DOUBLE_EQ(dec.pose().sigma_t_mm[1], 25.5); /* NaN: unknown, sent as saturated */
	EXPECT_DOUBLE_EQ(dec.pose().sigma_t_mm[2], 25.5); /* negative: no sigma, unknown */
	EXPECT_DOUBLE_EQ(dec.pose().sigma_rpy_deg[0], 2.55);
	EXPECT_DOUBLE_EQ(dec.pose().sigma_rpy_deg[1], 2.55);
	EXPECT_DOUBLE_EQ(dec.pose().sigma_rpy_deg[2], 2.55);
	EXPECT_DOUBLE_EQ(dec.pose().rpy_deg[0], 327.67);
	EXPECT_DOUBLE_EQ(dec.pose().rpy_deg[1], -327.68);
	EXPECT_EQ(dec.status().leds_used, 255);
	EXPECT_DOUBLE_EQ(dec.status().rms_px, 2.55);
	EXPECT_DOUBLE_EQ(dec.status().latency_ms, 655.35);

	/* log10 NFA: NaN is unknown, sent as the top of the range (no evidence); +inf too. */
	for (const double nfa : { std::numeric_limits<double>::quiet_NaN(),
				  std::numeric_limits<double>::infinity(), 4000.0 }) {
		p.log10_nfa = nfa;
		ASSERT_EQ(enc.encodeReport(st, &p, out), kReportFrames);
		ASSERT_EQ(feedAll(dec, out, kReportFrames), Event::Report);
		ASSERT_TRUE(dec.poseValid());
		EXPECT_DOUBLE_EQ(dec.pose().log10_nfa, 3276.7) << nfa;
	}
	p.log10_nfa = -std::numeric_limits<double>::infinity();
	ASSERT_EQ(enc.encodeReport(st, &p, out), kReportFrames);
	ASSERT_EQ(feedAll(dec, out, kReportFrames), Event::Report);
	EXPECT_DOUBLE_EQ(dec.pose().log10_nfa, -3276.8);

	st.pose_valid = false;
	st.leds_used = -3;
	st.rms_px = -1;
	st.latency_ms = -2;
	ASSERT_EQ(enc.encodeReport(st, nullptr, out), 1);
	ASSERT_EQ(dec.feed(out[0]), Event::Report);
	EXPECT_EQ(dec.status().leds_used, 0);
	EXPECT_DOUBLE_EQ(dec.status().rms_px, 0.0);
	EXPECT_DOUBLE_EQ(dec.status().latency_ms, 0.0);

	HeartbeatData hb;
	hb.uptime_s = 20000000;
	hb.frame_rate_hz = 200;
	ASSERT_EQ(dec.feed(enc.encodeHeartbeat(hb)), Event::Heartbeat);
	EXPECT_EQ(dec.heartbeat().uptime_s, 16777215u);
	EXPECT_DOUBLE_EQ(dec.heartbeat().frame_rate_hz, 127.5);
}

TEST(CanProtocol, UnencodablePoseIsNotSentAsValid)
{
	const double nan = std::numeric_limits<double>::quiet_NaN();
	struct Case {
		const char *what;
		double t[3];
		double qw;
		double roll;
		bool ok;
	};
	const Case cases[] = {
		{ "in range", { 3276.74, -3276.84, 6553.54 }, 1, 0, true },
		{ "Tx too large", { 3276.76, 0, 1000 }, 1, 0, false },
		{ "Ty too small", { 0, -3276.86, 1000 }, 1, 0, false },
		{ "Tz negative", { 0, 0, -0.1 }, 1, 0, false },
		{ "Tz too large", { 0, 0, 6553.6 }, 1, 0, false },
		{ "Tz NaN", { 0, 0, nan }, 1, 0, false },
		{ "q NaN", { 0, 0, 1000 }, nan, 0, false },
		{ "roll infinite",
		  { 0, 0, 1000 },
		  1,
		  std::numeric_limits<double>::infinity(),
		  false },
	};
	Encoder enc;
	Decoder dec;
	RawFrame out[kReportFrames];
	for (const Case &c : cases) {
		SCOPED_TRACE(c.what);
		StatusData st;
		st.pose_valid = true;
		PoseData p;
		std::copy(std::begin(c.t), std::end(c.t), p.t_mm);
		p.q[0] = c.qw;
		p.rpy_deg[0] = c.roll;
		const int n = enc.encodeReport(st, &p, out);
		EXPECT_EQ(n, c.ok ? kReportFrames : 1);
		EXPECT_EQ(enc.poseDropped(), !c.ok);
		EXPECT_EQ(Encoder::poseEncodable(p), c.ok);
		EXPECT_EQ(out[n - 1].id, kDefaultBaseId + kStatus);
		EXPECT_EQ((out[n - 1].data[0] >> 4) & 1, c.ok ? 1 : 0) << "PoseValid bit";
		ASSERT_EQ(feedAll(dec, out, n), Event::Report);
		EXPECT_EQ(dec.poseValid(), c.ok);
		EXPECT_EQ(dec.status().pose_valid, c.ok);
	}
	EXPECT_EQ(dec.counters().incomplete_poses, 0u);

	/* pose_valid without a pose */
	StatusData st;
	st.pose_valid = true;
	EXPECT_EQ(enc.encodeReport(st, nullptr, out), 1);
	EXPECT_TRUE(enc.poseDropped());
	EXPECT_EQ((out[0].data[0] >> 4) & 1, 0);
	PoseData p;
	p.t_mm[2] = 100;
	EXPECT_EQ(enc.encodeReport(st, &p, out), kReportFrames);
	EXPECT_FALSE(enc.poseDropped());
}

TEST(CanProtocol, HeartbeatAndCommandRoundTrip)
{
	Encoder enc(0x410);
	Decoder dec(0x410);
	HeartbeatData hb;
	hb.uptime_s = 123456;
	hb.state = SensorState::Degraded;
	hb.mode = TrackMode::SearchOnly;
	hb.strobe = StrobeMode::Alternate;
	hb.enabled = false;
	hb.faults = fault::kCameraStall | fault::kCommandRejected;
	hb.frame_rate_hz = 59.5;
	ASSERT_EQ(dec.feed(enc.encodeHeartbeat(hb)), Event::Heartbeat);
	EXPECT_EQ(dec.heartbeat().uptime_s, hb.uptime_s);
	EXPECT_EQ(dec.heartbeat().state, hb.state);
	EXPECT_EQ(dec.heartbeat().mode, hb.mode);
	EXPECT_EQ(dec.heartbeat().strobe, hb.strobe);
	EXPECT_EQ(dec.heartbeat().enabled, hb.enabled);
	EXPECT_EQ(dec.heartbeat().faults, hb.faults);
	EXPECT_DOUBLE_EQ(dec.heartbeat().frame_rate_hz, 59.5);

	CommandData cmd;
	cmd.enable = false;
	cmd.mode = TrackMode::SearchOnly;
	cmd.strobe = StrobeMode::Unchanged;
	cmd.exposure_us = 54321;
	cmd.gain = 12.3;
	cmd.preview = PreviewSwitch::On;
	ASSERT_EQ(dec.feed(enc.encodeCommand(cmd)), Event::Command);
	EXPECT_EQ(dec.command().preview, PreviewSwitch::On);
	EXPECT_EQ(dec.command().enable, false);
	EXPECT_EQ(dec.command().mode, TrackMode::SearchOnly);
	EXPECT_EQ(dec.command().strobe, StrobeMode::Unchanged);
	EXPECT_EQ(dec.command().exposure_us, 54321);
	EXPECT_NEAR(dec.command().gain, 12.3, 0.05 + 1e-9);
	cmd.enable = true;
	cmd.mode = TrackMode::Track;
	cmd.strobe = StrobeMode::Constant;
	cmd.gain = 0;
	cmd.preview = PreviewSwitch::Reserved; /* decoded as sent: the daemon refuses it */
	ASSERT_EQ(dec.feed(enc.encodeCommand(cmd)), Event::Command);
	EXPECT_EQ(dec.command().preview, PreviewSwitch::Reserved);
	EXPECT_EQ(dec.command().enable, true);
	EXPECT_EQ(dec.command().mode, TrackMode::Track);
	EXPECT_EQ(dec.command().strobe, StrobeMode::Constant);
	EXPECT_DOUBLE_EQ(dec.command().gain, 0.0);

	EXPECT_STREQ(sensorStateName(SensorState::Tracking), "TRACKING");
	EXPECT_STREQ(sensorStateName(static_cast<SensorState>(7)), "UNKNOWN");
	EXPECT_STREQ(strobeModeName(StrobeMode::Alternate), "ALTERNATE");
	EXPECT_STREQ(trackModeName(TrackMode::SearchOnly), "SEARCH_ONLY");
	EXPECT_STREQ(faultBitName(4), "CAN_BUS_OFF");
}

/* ---- Rejections ---- */

class CanRejection : public ::testing::Test
{
protected:
	void SetUp() override
	{
		st_.pose_valid = true;
		st_.state = SensorState::Tracking;
		pose_.t_mm[2] = 800;
		pose_.frame_counter = 77;
		ASSERT_EQ(enc_.encodeReport(st_, &pose_, frames_), kReportFrames);
	}

	Encoder enc_;
	Decoder dec_;
	StatusData st_;
	PoseData pose_;
	RawFrame frames_[kReportFrames];
};

TEST_F(CanRejection, TruncatedFrame)
{
	RawFrame f = frames_[0];
	f.len = 5;
	EXPECT_EQ(dec_.feed(f), Event::Rejected);
	EXPECT_EQ(dec_.lastError(), FrameError::WrongLength);
	EXPECT_EQ(dec_.counters().length_errors, 1u);
	/* The rest of the report arrives: the status completes it, without a pose. */
	EXPECT_EQ(feedAll(dec_, frames_ + 1, kReportFrames - 1), Event::Report);
	EXPECT_EQ(dec_.lastError(), FrameError::None);
	EXPECT_FALSE(dec_.poseValid());
	EXPECT_TRUE(dec_.status().pose_valid);
	EXPECT_EQ(dec_.counters().incomplete_poses, 1u);
	EXPECT_EQ(dec_.counters().valid_poses, 0u);
}

TEST_F(CanRejection, EveryFlippedBitFailsTheCrc)
{
	for (int frame = 0; frame < kReportFrames; ++frame) {
		for (int bit = 0; bit < 64; ++bit) {
			RawFrame f = frames_[frame];
			f.data[static_cast<std::size_t>(bit / 8)] ^=
				static_cast<std::uint8_t>(1u << (bit % 8));
			ASSERT_EQ(dec_.feed(f), Event::Rejected)
				<< "frame " << frame << " bit " << bit;
			ASSERT_EQ(dec_.lastError(), FrameError::BadCrc);
		}
	}
	EXPECT_EQ(dec_.counters().crc_errors, kReportFrames * 64u);
	/* Nothing was taken from them: the intact report still decodes. */
	EXPECT_EQ(feedAll(dec_, frames_, kReportFrames), Event::Report);
	EXPECT_TRUE(dec_.poseValid());
	EXPECT_EQ(dec_.pose().frame_counter, 77u);
}

TEST_F(CanRejection, WrongIdWithRightDataFailsTheCrc)
{
	for (std::uint32_t offset :
	     { kTranslation, kQuatA, kQuatB, kAngles, kSigma, kQuality, kStatus }) {
		RawFrame f = frames_[0];
		if (offset == kTranslation)
			f = frames_[1];
		f.id = kDefaultBaseId + offset;
		EXPECT_EQ(dec_.feed(f), Event::Rejected) << offset;
		EXPECT_EQ(dec_.lastError(), FrameError::BadCrc);
	}
	/* The same frames from a sensor at another base on the same bus. */
	Decoder other(0x400);
	RawFrame f = frames_[kReportFrames - 1];
	f.id = 0x405;
	EXPECT_EQ(other.feed(f), Event::Rejected);
	EXPECT_EQ(other.lastError(), FrameError::BadCrc);
}

TEST_F(CanRejection, RepeatedFrameIsStale)
{
	EXPECT_EQ(feedAll(dec_, frames_, kReportFrames), Event::Report);
	EXPECT_TRUE(dec_.poseValid());
	EXPECT_EQ(dec_.feed(frames_[kReportFrames - 1]), Event::Rejected);
	EXPECT_EQ(dec_.lastError(), FrameError::StaleAlive);
	EXPECT_EQ(dec_.feed(frames_[2]), Event::Rejected);
	EXPECT_EQ(dec_.counters().stale_frames, 2u);
	EXPECT_EQ(dec_.counters().reports, 1u);

	/* A stuck sender: a new pose with the alive counters not advanced. */
	RawFrame next[kReportFrames];
	ASSERT_EQ(enc_.encodeReport(st_, &pose_, next), kReportFrames);
	for (RawFrame &f : next) {
		f.data[6] =
			static_cast<std::uint8_t>((f.data[6] & 0xf0) | (frames_[0].data[6] & 0x0f));
		f.data[7] = frameCrc(f.id, f.data);
	}
	for (const RawFrame &f : next)
		EXPECT_EQ(dec_.feed(f), Event::Rejected);
	EXPECT_EQ(dec_.counters().reports, 1u);
}

TEST_F(CanRejection, AliveGapsCountLostFrames)
{
	RawFrame hb[5];
	for (RawFrame &f : hb)
		f = enc_.encodeHeartbeat(HeartbeatData{});
	EXPECT_EQ(dec_.feed(hb[0]), Event::Heartbeat);
	EXPECT_EQ(dec_.feed(hb[1]), Event::Heartbeat);
	EXPECT_EQ(dec_.feed(hb[4]), Event::Heartbeat); /* two lost */
	EXPECT_EQ(dec_.counters().alive_gaps, 2u);
	EXPECT_EQ(dec_.lastError(), FrameError::None);

	/* Wrap-around 15 -> 0 is no gap. */
	Encoder enc;
	Decoder dec;
	for (int i = 0; i < 40; ++i)
		ASSERT_EQ(dec.feed(enc.encodeHeartbeat(HeartbeatData{})), Event::Heartbeat);
	EXPECT_EQ(dec.counters().alive_gaps, 0u);
}

TEST_F(CanRejection, MissingPoseFrameMakesTheReportIncomplete)
{
	for (int missing = 0; missing < kReportFrames - 1; ++missing) {
		SCOPED_TRACE(missing);
		RawFrame report[kReportFrames];
		ASSERT_EQ(enc_.encodeReport(st_, &pose_, report), kReportFrames);
		Decoder dec;
		for (int i = 0; i < kReportFrames; ++i)
			if (i != missing)
				dec.feed(report[i]);
		EXPECT_EQ(dec.lastError(), FrameError::None);
		EXPECT_FALSE(dec.poseValid());
		EXPECT_TRUE(dec.status().pose_valid);
		EXPECT_EQ(dec.counters().reports, 1u);
		EXPECT_EQ(dec.counters().incomplete_poses, 1u);
		EXPECT_EQ(dec.counters().valid_poses, 0u);
	}
}

TEST_F(CanRejection, PoseFramesOfAnotherSequenceDoNotComplete)
{
	/* Report A's status is lost, report B's QuatB is lost: A's QuatB must
	 * not stand in for it. */
	RawFrame b[kReportFrames];
	PoseData other = pose_;
	other.frame_counter = 78;
	ASSERT_EQ(enc_.encodeReport(st_, &other, b), kReportFrames);
	feedAll(dec_, frames_, kReportFrames - 1);
	for (int i : { 0, 1, 3, 4, 5, 6 })
		dec_.feed(b[i]);
	EXPECT_FALSE(dec_.poseValid());
	EXPECT_EQ(dec_.counters().incomplete_poses, 1u);

	/* A status whose sequence differs from the pose frames held. */
	RawFrame c[kReportFrames], d[kReportFrames];
	ASSERT_EQ(enc_.encodeReport(st_, &pose_, c), kReportFrames);
	ASSERT_EQ(enc_.encodeReport(st_, &pose_, d), kReportFrames);
	feedAll(dec_, c, kReportFrames - 1);
	EXPECT_EQ(dec_.feed(d[kReportFrames - 1]), Event::Report);
	EXPECT_FALSE(dec_.poseValid());
	EXPECT_EQ(dec_.counters().incomplete_poses, 2u);

	/* The next complete report is valid again. */
	RawFrame e[kReportFrames];
	ASSERT_EQ(enc_.encodeReport(st_, &other, e), kReportFrames);
	EXPECT_EQ(feedAll(dec_, e, kReportFrames), Event::Report);
	EXPECT_TRUE(dec_.poseValid());
	EXPECT_EQ(dec_.pose().frame_counter, 78u);
	/* Frames lost on the way, as the alive counters see them: b's QuatB (1),
	 * c's status (1), d's six pose frames (6). */
	EXPECT_EQ(dec_.counters().alive_gaps, 8u);
}

TEST_F(CanRejection, OtherIdsAreNotOurs)
{
	for (std::uint32_t id : { kDefaultBaseId - 1, kDefaultBaseId + 0xa, kDefaultBaseId + 0xf,
				  kDefaultBaseId + 0x12, 0x7ffu, 0u }) {
		RawFrame f = frames_[0];
		f.id = id;
		f.data[7] = frameCrc(id, f.data);
		EXPECT_EQ(dec_.feed(f), Event::None) << id;
		EXPECT_EQ(dec_.lastError(), FrameError::UnknownId);
	}
	EXPECT_EQ(dec_.counters().unknown_ids, 6u);
	EXPECT_EQ(dec_.counters().crc_errors, 0u);
	/* Our frames seen by a decoder for another base are not its own. */
	Decoder other(0x320);
	for (const RawFrame &f : frames_)
		EXPECT_EQ(other.feed(f), Event::None);
	EXPECT_EQ(other.counters().unknown_ids, static_cast<std::uint64_t>(kReportFrames));
	EXPECT_EQ(other.counters().reports, 0u);
}

/* ---- Bus load ---- */

TEST(CanProtocol, BusLoad)
{
	EXPECT_EQ(worstCaseFrameBits(8), 135);
	EXPECT_EQ(worstCaseFrameBits(0), 34 + 13 + 8);
	const double load = worstCaseBusLoad(60, 10, 500000);
	EXPECT_LE(load, 0.30);
	EXPECT_NEAR(load, (7 * 60 + 10) * 135.0 / 500000.0, 1e-12);
	EXPECT_NEAR(load, 0.1161, 1e-4);
	/* The same traffic on a 125 kbit/s bus is over the 30 % budget. */
	EXPECT_GT(worstCaseBusLoad(60, 10, 125000), 0.30);
	/* Authenticated: a DP_Auth per report, DP_Freshness and DP_Auth per heartbeat. */
	const double auth = worstCaseBusLoad(60, 10, 500000, 0.0, true);
	EXPECT_NEAR(auth, (8 * 60 + 3 * 10) * 135.0 / 500000.0, 1e-12);
	EXPECT_NEAR(auth, 0.1377, 1e-4);
	EXPECT_LE(worstCaseBusLoad(60, 10, 250000, 0.0, true), 0.30);
}

/* ---- CAN FD: a report in one DP_ReportFd ---- */

TEST(CanFd, FrameBitsAndBusLoad)
{
	/* 22 + 512 bits, 133 stuff bits, 4 + 21 CRC bits with 7 fixed stuff bits, 13. */
	EXPECT_EQ(worstCaseFdFrameBits(64), 712);
	EXPECT_EQ(worstCaseFdFrameBits(8), 22 + 64 + 21 + 4 + 17 + 6 + 13);
	/* One FD frame carries eight classic frames' bytes in less than their bits. */
	EXPECT_LT(worstCaseFdFrameBits(64), kMaxReportFrames * worstCaseFrameBits(8));
	const double fd = worstCaseFdBusLoad(60, 10, 500000, 0.0, true);
	EXPECT_NEAR(fd, (60 * 712 + 3 * 10 * 135) / 500000.0, 1e-12);
	EXPECT_NEAR(fd, 0.0935, 1e-4);
	EXPECT_LT(fd, worstCaseBusLoad(60, 10, 500000, 0.0, true));
	EXPECT_NEAR(worstCaseFdBusLoad(60, 10, 500000), (60 * 712 + 10 * 135) / 500000.0, 1e-12);
}

TEST(CanFd, ReportsRoundTripThroughOneFrame)
{
	RandomReports gen(7);
	Encoder enc(0x520);
	Decoder classic(0x520);
	Decoder fd(0x520);
	for (int i = 0; i < 500; ++i) {
		const bool with_pose = i % 5 != 2;
		const PoseData pose = gen.pose();
		const StatusData status = gen.status(with_pose);
		RawFrame frames[kReportFrames];
		const int n = enc.encodeReport(status, &pose, frames);
		FdFrame packed;
		ASSERT_TRUE(packFd(frames, n, 0x520, &packed));
		EXPECT_EQ(packed.id, 0x520u + kReportFd);
		EXPECT_EQ(packed.len, kFdReportLength);
		/* A report without a pose leaves the pose slots zero. */
		for (std::size_t b = 0; !with_pose && b < 6 * 8; ++b)
			ASSERT_EQ(packed.data[b], 0) << b;
		ASSERT_EQ(feedAll(classic, frames, n), Event::Report);
		ASSERT_EQ(fd.feedFd(packed), Event::Report) << i;
		ASSERT_EQ(fd.poseValid(), with_pose);
		ASSERT_EQ(fd.poseValid(), classic.poseValid());
		expectStatusNear(fd.status(), classic.status());
		if (with_pose)
			expectPoseNear(fd.pose(), classic.pose());
		EXPECT_EQ(fd.sequence(), classic.sequence());
	}
	const Decoder::Counters &c = fd.counters();
	EXPECT_EQ(c.reports, 500u);
	EXPECT_EQ(c.valid_poses, 400u);
	EXPECT_EQ(c.crc_errors + c.length_errors + c.alive_gaps + c.incomplete_poses, 0u);
}

TEST(CanFd, BadFramesAreRefusedAndCounted)
{
	Encoder enc;
	Decoder dec;
	RandomReports gen(3);
	const PoseData pose = gen.pose();
	RawFrame frames[kReportFrames];
	const int n = enc.encodeReport(gen.status(true), &pose, frames);
	FdFrame packed;
	ASSERT_TRUE(packFd(frames, n, kDefaultBaseId, &packed));

	FdFrame short_frame = packed;
	short_frame.len = 48;
	EXPECT_EQ(dec.feedFd(short_frame), Event::Rejected);
	EXPECT_EQ(dec.lastError(), FrameError::WrongLength);
	EXPECT_EQ(dec.counters().length_errors, 1u);

	FdFrame other = packed;
	other.id = kDefaultBaseId + kReportFd + 1;
	EXPECT_EQ(dec.feedFd(other), Event::None);
	EXPECT_EQ(dec.lastError(), FrameError::UnknownId);

	/* A bit flipped in any pose slot: no valid pose, the frame refused by that slot's CRC. */
	for (std::size_t bit = 0; bit < 6 * 64; bit += 7) {
		Encoder e;
		Decoder d;
		RawFrame f[kReportFrames];
		const int m = e.encodeReport(gen.status(true), &pose, f);
		FdFrame p;
		ASSERT_TRUE(packFd(f, m, kDefaultBaseId, &p));
		p.data[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
		EXPECT_EQ(d.feedFd(p), Event::Rejected) << bit;
		EXPECT_FALSE(d.poseValid()) << bit;
		EXPECT_EQ(d.lastError(), FrameError::BadCrc) << bit;
	}

	/* The same frame twice: its frames' alive counters repeat. */
	Decoder twice;
	ASSERT_EQ(twice.feedFd(packed), Event::Report);
	EXPECT_TRUE(twice.poseValid());
	EXPECT_EQ(twice.feedFd(packed), Event::Rejected);
	EXPECT_FALSE(twice.poseValid());
	EXPECT_EQ(twice.lastError(), FrameError::StaleAlive);

	/* Frames that are not a report's do not pack. */
	FdFrame untouched;
	const RawFrame hb = enc.encodeHeartbeat(HeartbeatData{});
	EXPECT_FALSE(packFd(&hb, 1, kDefaultBaseId, &untouched));
	RawFrame two[2] = { frames[0], frames[0] };
	EXPECT_FALSE(packFd(two, 2, kDefaultBaseId, &untouched));
	EXPECT_EQ(untouched.len, 0);
}

/* ---- Freshness: the decoder dates reports (feed with an arrival time) ---- */

namespace {

/*
 * A sensor at 60 reports/s: report i is encoded at sensor time send_us(i)
 * (its exposure began latency_ms earlier); the receiver's clock is the
 * sensor's plus an unknown offset, and a frame arrives transit_us after it
 * was sent unless a test delays it.
 */
class FreshnessTest : public ::testing::Test
{
protected:
	static constexpr std::int64_t kPeriodUs = 16667;
	static constexpr std::int64_t kOffsetUs = 987654321; /* receiver clock - sensor clock */
	static constexpr std::int64_t kTransitUs = 300;
	static constexpr double kLatencyMs = 7.5;

	std::int64_t sendUs(int i) const { return start_us_ + i * kPeriodUs; }

	/* Encode report i (a pose at tz = 1000 - i mm) and feed it as arriving `delay_us` late. */
	Event deliver(int i, std::int64_t delay_us = 0)
	{
		StatusData st;
		st.state = SensorState::Tracking;
		st.pose_valid = true;
		st.latency_ms = kLatencyMs;
		PoseData pose;
		pose.t_mm[2] = 1000 - i;
		pose.frame_counter = static_cast<std::uint32_t>(i);
		pose.sensor_time_us = static_cast<std::uint32_t>(sendUs(i));
		RawFrame frames[kReportFrames];
		const int n = enc_.encodeReport(st, &pose, frames);
		Event ev = Event::None;
		for (int k = 0; k < n; ++k)
			ev = dec_.feed(frames[k], sendUs(i) + kOffsetUs + kTransitUs + delay_us);
		return ev;
	}

	std::int64_t start_us_ = 5000000;
	Encoder enc_;
	Decoder dec_;
};

} /* namespace */

TEST_F(FreshnessTest, OnTimeReportsAreValidOnceTheClockReferenceIsBuilt)
{
	for (int i = 0; i < 100; ++i) {
		ASSERT_EQ(deliver(i), Event::Report);
		const bool dated = static_cast<std::size_t>(i + 1) >= Decoder::kMinClockSamples;
		EXPECT_EQ(dec_.poseValid(), dated) << i;
		/* Age: the latency; the transit is the reference's own. */
		EXPECT_EQ(dec_.poseAgeUs(), static_cast<std::int64_t>(kLatencyMs * 1000)) << i;
	}
	EXPECT_EQ(dec_.counters().undated_poses, Decoder::kMinClockSamples - 1);
	EXPECT_EQ(dec_.counters().stale_poses, 0u);
	EXPECT_EQ(dec_.counters().valid_poses, 100 - (Decoder::kMinClockSamples - 1));
}

/* The probe of the issue: the bus stalls for 1 s with 60 reports queued, then
 * they all arrive at once. Only those young enough at arrival are poses. */
TEST_F(FreshnessTest, ReportsQueuedThroughAOneSecondStallAreStale)
{
	for (int i = 0; i < 20; ++i)
		deliver(i);
	ASSERT_TRUE(dec_.poseValid());
	const std::int64_t released_us = sendUs(80); /* the bus comes back at report 80 */
	int accepted = 0;
	for (int i = 20; i < 80; ++i) {
		ASSERT_EQ(deliver(i, released_us - sendUs(i)), Event::Report);
		const std::int64_t real_age_us = released_us - sendUs(i) + kTransitUs +
						 static_cast<std::int64_t>(kLatencyMs * 1000);
		EXPECT_EQ(dec_.poseAgeUs(), real_age_us - kTransitUs) << i;
		EXPECT_EQ(dec_.poseValid(), dec_.poseAgeUs() <= Decoder::kDefaultMaxAgeUs) << i;
		if (dec_.poseValid()) {
			++accepted;
			EXPECT_LE(real_age_us, Decoder::kDefaultMaxAgeUs + kTransitUs);
			EXPECT_LT(dec_.pose().t_mm[2], 1000 - 75 + 0.05) << "only the newest";
		}
	}
	/* 50 ms bound, 7.5 ms latency, 16.7 ms period: the newest two (ages 24.2 and 40.8 ms). */
	EXPECT_EQ(accepted, 2);
	EXPECT_EQ(dec_.counters().stale_poses, 58u);
	/* Reports on time again: valid at once (the reference survived the stall). */
	ASSERT_EQ(deliver(80), Event::Report);
	EXPECT_TRUE(dec_.poseValid());
}

TEST_F(FreshnessTest, OneLateReportAmongOnTimeOnesIsStale)
{
	for (int i = 0; i < 10; ++i)
		deliver(i);
	dec_.setMaxAgeUs(20000);
	ASSERT_EQ(deliver(10, 12501), Event::Report); /* 7.5 + 12.501 ms: just over */
	EXPECT_FALSE(dec_.poseValid());
	EXPECT_EQ(dec_.counters().stale_poses, 1u);
	ASSERT_EQ(deliver(11, 12500), Event::Report); /* exactly the bound */
	EXPECT_TRUE(dec_.poseValid());
	EXPECT_EQ(dec_.poseAgeUs(), 20000);
}

TEST_F(FreshnessTest, SensorTimeWrapsWithoutAStep)
{
	start_us_ = (std::int64_t{ 1 } << 32) - 10 * kPeriodUs; /* wraps at report 10 */
	for (int i = 0; i < 30; ++i) {
		ASSERT_EQ(deliver(i), Event::Report);
		if (static_cast<std::size_t>(i + 1) >= Decoder::kMinClockSamples) {
			EXPECT_TRUE(dec_.poseValid()) << i;
		}
	}
	EXPECT_EQ(dec_.counters().stale_poses, 0u);
}

/* A sensor that restarts has a new clock: its heartbeat's uptime goes back and
 * the decoder builds its reference again instead of judging by the old one. */
TEST_F(FreshnessTest, ASensorRestartRebuildsTheReference)
{
	HeartbeatData hb;
	hb.uptime_s = 500;
	dec_.feed(enc_.encodeHeartbeat(hb), 0);
	for (int i = 0; i < 10; ++i)
		deliver(i);
	ASSERT_TRUE(dec_.poseValid());
	/* Restarted: uptime 1 s, its clock far behind (every report would look an hour old). */
	hb.uptime_s = 1;
	dec_.feed(enc_.encodeHeartbeat(hb), 0);
	start_us_ -= 3600LL * 1000000;
	const std::uint64_t undated_before = dec_.counters().undated_poses;
	for (int i = 10; i < 20; ++i)
		deliver(i);
	EXPECT_TRUE(dec_.poseValid());
	EXPECT_EQ(dec_.counters().undated_poses - undated_before, Decoder::kMinClockSamples - 1);
	EXPECT_EQ(dec_.counters().stale_poses, 0u);
}

TEST_F(FreshnessTest, UndatedFeedChecksNoAge)
{
	StatusData st;
	st.pose_valid = true;
	PoseData pose;
	RawFrame frames[kReportFrames];
	const int n = enc_.encodeReport(st, &pose, frames);
	for (int k = 0; k < n; ++k)
		dec_.feed(frames[k]);
	EXPECT_TRUE(dec_.poseValid());
	EXPECT_EQ(dec_.poseAgeUs(), -1);
}

/* ---- Independent check of the DBC with canmatrix, and of scripts/candecode ---- */

namespace {

struct RunResult {
	int status = -1;
	std::string out;
	std::string err;
};

std::string readFile(const std::string &path)
{
	std::ifstream in(path);
	std::stringstream ss;
	ss << in.rdbuf();
	return ss.str();
}

std::string quote(const std::string &s)
{
	std::string q = "'";
	for (char c : s) {
		if (c == '\'')
			q += "'\\''";
		else
			q += c;
	}
	return q + "'";
}

RunResult run(const std::string &cmd, const std::string &dir)
{
	RunResult r;
	const std::string err_path = dir + "/stderr.txt";
	FILE *p = popen((cmd + " 2>" + quote(err_path)).c_str(), "r");
	if (!p)
		return r;
	char buf[4096];
	std::size_t n;
	while ((n = fread(buf, 1, sizeof(buf), p)) > 0)
		r.out.append(buf, n);
	const int st = pclose(p);
	r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
	r.err = readFile(err_path);
	return r;
}

std::vector<nlohmann::json> jsonLines(const std::string &text)
{
	std::vector<nlohmann::json> v;
	std::istringstream in(text);
	std::string line;
	while (std::getline(in, line))
		if (!line.empty())
			v.push_back(nlohmann::json::parse(line));
	return v;
}

std::string candumpLine(double t, const RawFrame &f)
{
	char buf[96];
	int n = std::snprintf(buf, sizeof(buf), "(%.6f) can0 %03X#", t, f.id);
	for (std::size_t i = 0; i < f.len; ++i)
		n += std::snprintf(buf + n, sizeof(buf) - static_cast<std::size_t>(n), "%02X",
				   f.data[i]);
	return std::string(buf) + "\n";
}

/* A CAN FD line as candump -l writes it: id##<flags><data>. */
std::string candumpLine(double t, const FdFrame &f)
{
	char buf[192];
	int n = std::snprintf(buf, sizeof(buf), "(%.6f) can0 %03X##0", t, f.id);
	for (std::size_t i = 0; i < f.len; ++i)
		n += std::snprintf(buf + n, sizeof(buf) - static_cast<std::size_t>(n), "%02X",
				   f.data[i]);
	return std::string(buf) + "\n";
}

double clampD(double v, double lo, double hi)
{
	return std::min(std::max(v, lo), hi);
}

/* What Log10Nfa carries for a value: clamped to its range, NaN as its top. */
double sentNfa(double v)
{
	const SignalLayout &s = layout::kLog10Nfa;
	const double lo = static_cast<double>(s.rawMin()) * s.factor,
		     hi = static_cast<double>(s.rawMax()) * s.factor;
	return std::isnan(v) ? hi : clampD(v, lo, hi);
}

class CanToolsTest : public ::testing::Test
{
protected:
	void SetUp() override
	{
		char tmpl[] = "/tmp/dockpose-can-XXXXXX";
		ASSERT_NE(mkdtemp(tmpl), nullptr) << "mkdtemp failed";
		dir_ = tmpl;
		source_ = DOCKPOSE_SOURCE_DIR;
		python_ = DOCKPOSE_PYTHON;
		dbc_ = source_ + "/firmware/protocol/dockpose.dbc";
		const RunResult mods = run(
			quote(python_) + " -c 'import can, canmatrix, canmatrix.formats'", dir_);
		ASSERT_EQ(mods.status, 0)
			<< python_
			<< " cannot import python-can and canmatrix (Debian packages python3-can and "
			<< "python3-canmatrix, installed by scripts/setup): " << mods.err;
	}

	void TearDown() override
	{
		std::error_code ec;
		if (!dir_.empty())
			std::filesystem::remove_all(dir_, ec);
	}

	/* Encode `n` reports (every 7th without a pose, some saturating) plus
	 * heartbeats and a command at `base`, write them as a candump log. */
	void writeLog(std::uint32_t base, int n)
	{
		RandomReports gen(99 + base);
		Encoder enc(base);
		Encoder arm(base);
		std::ofstream log(dir_ + "/log.log");
		double t = 1700000000.0;
		for (int i = 0; i < n; ++i) {
			Report r;
			r.with_pose = i % 7 != 3;
			r.pose = gen.pose();
			r.status = gen.status(r.with_pose);
			if (i % 10 == 5) {
				r.pose.sigma_t_mm[1] = 40.0;
				r.pose.sigma_rpy_deg[2] = 9.0;
				r.status.rms_px = 7.0;
				r.status.latency_ms = 900.0;
				r.pose.log10_nfa = -4000.0;
			}
			if (i % 10 == 8)
				r.pose.log10_nfa = std::numeric_limits<double>::quiet_NaN();
			RawFrame out[kReportFrames];
			const int k = enc.encodeReport(r.status, &r.pose, out);
			ASSERT_EQ(k, r.with_pose ? kReportFrames : 1);
			if (fd_) {
				FdFrame fd;
				ASSERT_TRUE(packFd(out, k, base, &fd));
				log << candumpLine(t, fd);
				report_times_.push_back(t);
			}
			for (int j = 0; j < k; ++j) {
				if (!fd_)
					log << candumpLine(t + 0.0001 * j, out[j]);
				frames_.push_back(out[j]);
			}
			if (!fd_)
				report_times_.push_back(t + 0.0001 * (k - 1));
			reports_.push_back(r);
			if (i % 6 == 0) {
				HeartbeatData hb;
				hb.uptime_s = static_cast<std::uint32_t>(i);
				hb.state = r.status.state;
				hb.mode = static_cast<TrackMode>(i % 2);
				hb.strobe = r.status.strobe;
				hb.enabled = r.status.enabled;
				hb.faults = r.status.faults;
				hb.frame_rate_hz = 60;
				heartbeats_.push_back(hb);
				const RawFrame f = enc.encodeHeartbeat(hb);
				log << candumpLine(t + 0.001, f);
				frames_.push_back(f);
			}
			if (i == n / 2) {
				CommandData cmd;
				cmd.mode = TrackMode::SearchOnly;
				cmd.strobe = StrobeMode::Alternate;
				cmd.exposure_us = 1500;
				cmd.gain = 4.5;
				cmd.preview = PreviewSwitch::Off;
				const RawFrame f = arm.encodeCommand(cmd);
				log << candumpLine(t + 0.002, f);
				frames_.push_back(f);
			}
			t += 1.0 / 60.0;
		}
		ASSERT_TRUE(log.good());
	}

	/* Every frame decoded by canmatrix alone against the C++ inputs. */
	void checkCanmatrix(std::uint32_t base)
	{
		char base_text[16];
		std::snprintf(base_text, sizeof(base_text), "0x%x", base);
		const RunResult r =
			run(quote(python_) + " " +
				    quote(source_ + "/tests/firmware/canmatrix_decode.py") +
				    " --dbc " + quote(dbc_) + " --base-id " + base_text + " " +
				    quote(dir_ + "/log.log"),
			    dir_);
		ASSERT_EQ(r.status, 0) << r.err;
		const std::vector<nlohmann::json> objs = fdSlotsAsFrames(jsonLines(r.out), base);
		ASSERT_EQ(objs.size(), frames_.size());

		std::size_t report = 0, hb = 0;
		for (std::size_t i = 0; i < objs.size(); ++i) {
			SCOPED_TRACE("frame " + std::to_string(i) + " " + objs[i].dump());
			const nlohmann::json &o = objs[i];
			const RawFrame &f = frames_[i];
			ASSERT_EQ(o["id"].get<std::uint32_t>(), f.id);
			ASSERT_FALSE(o["message"].is_null());
			const nlohmann::json &s = o["signals"];
			const nlohmann::json &raw = o["raw"];
			EXPECT_EQ(raw["AliveCounter"].get<unsigned int>(), aliveOf(f));
			EXPECT_EQ(raw["Sequence"].get<unsigned int>(), sequenceOf(f));
			EXPECT_EQ(raw["CRC"].get<unsigned int>(), f.data[7]);
			auto val = [&](const char *name) {
				return s.at(name).get<double>();
			};
			const std::string msg = o["message"].get<std::string>();
			const std::uint32_t offset = f.id - base;
			const Report &r_in = reports_[std::min(report, reports_.size() - 1)];
			const PoseData &p = r_in.pose;
			switch (offset) {
			case kTranslation:
				ASSERT_EQ(msg, "DP_Translation");
				EXPECT_NEAR(val("Tx"), p.t_mm[0], kTolT);
				EXPECT_NEAR(val("Ty"), p.t_mm[1], kTolT);
				EXPECT_NEAR(val("Tz"), p.t_mm[2], kTolT);
				EXPECT_EQ(sequenceOf(f), report & 0x0f);
				break;
			case kQuatA:
				ASSERT_EQ(msg, "DP_QuatA");
				EXPECT_NEAR(val("Qw"), p.q[0], kTolQ);
				EXPECT_NEAR(val("Qx"), p.q[1], kTolQ);
				EXPECT_NEAR(val("Qy"), p.q[2], kTolQ);
				break;
			case kQuatB:
				ASSERT_EQ(msg, "DP_QuatB");
				EXPECT_NEAR(val("Qz"), p.q[3], kTolQ);
				EXPECT_EQ(raw["FrameCounter"].get<std::uint32_t>(),
					  p.frame_counter);
				break;
			case kAngles:
				ASSERT_EQ(msg, "DP_Angles");
				EXPECT_NEAR(val("Roll"), p.rpy_deg[0], kTolDeg);
				EXPECT_NEAR(val("Pan"), p.rpy_deg[1], kTolDeg);
				EXPECT_NEAR(val("Tilt"), p.rpy_deg[2], kTolDeg);
				break;
			case kSigma: {
				ASSERT_EQ(msg, "DP_Sigma");
				const char *t_names[3] = { "SigmaTx", "SigmaTy", "SigmaTz" };
				const char *r_names[3] = { "SigmaRoll", "SigmaPan", "SigmaTilt" };
				for (int k = 0; k < 3; ++k) {
					expectSigmaSent(val(t_names[k]),
							clampD(p.sigma_t_mm[k], 0, 25.5),
							kStepSigmaT);
					expectSigmaSent(val(r_names[k]),
							clampD(p.sigma_rpy_deg[k], 0, 2.55),
							kStepSigmaDeg);
				}
				break;
			}
			case kQuality:
				ASSERT_EQ(msg, "DP_Quality");
				EXPECT_NEAR(val("Log10Nfa"), sentNfa(p.log10_nfa), kTolNfa);
				EXPECT_EQ(raw["SensorTimeUs"].get<std::uint32_t>(),
					  p.sensor_time_us);
				EXPECT_EQ(sequenceOf(f), report & 0x0f);
				break;
			case kStatus: {
				ASSERT_EQ(msg, "DP_Status");
				const StatusData &st = r_in.status;
				EXPECT_EQ(raw["State"].get<int>(), static_cast<int>(st.state));
				EXPECT_EQ((raw["Enabled"].get<int>() != 0), st.enabled);
				EXPECT_EQ((raw["PoseValid"].get<int>() != 0), r_in.with_pose);
				EXPECT_EQ((raw["Tracked"].get<int>() != 0), st.tracked);
				EXPECT_EQ(raw["StrobeMode"].get<int>(),
					  static_cast<int>(st.strobe));
				EXPECT_EQ(raw["LedsUsed"].get<int>(), st.leds_used);
				EXPECT_NEAR(val("RmsPx"), clampD(st.rms_px, 0, 2.55), kTolRms);
				EXPECT_EQ(raw["FaultBits"].get<int>(), st.faults);
				EXPECT_NEAR(val("LatencyMs"), clampD(st.latency_ms, 0, 655.35),
					    kTolLatency);
				EXPECT_EQ(sequenceOf(f), report & 0x0f);
				++report;
				break;
			}
			case kHeartbeat: {
				ASSERT_EQ(msg, "DP_Heartbeat");
				ASSERT_LT(hb, heartbeats_.size());
				const HeartbeatData &h = heartbeats_[hb++];
				EXPECT_EQ(raw["UptimeS"].get<std::uint32_t>(), h.uptime_s);
				EXPECT_EQ(raw["State"].get<int>(), static_cast<int>(h.state));
				EXPECT_EQ(raw["Mode"].get<int>(), static_cast<int>(h.mode));
				EXPECT_EQ(raw["StrobeMode"].get<int>(), static_cast<int>(h.strobe));
				EXPECT_EQ((raw["Enabled"].get<int>() != 0), h.enabled);
				EXPECT_EQ(raw["FaultBits"].get<int>(), h.faults);
				EXPECT_DOUBLE_EQ(val("FrameRate"), h.frame_rate_hz);
				EXPECT_EQ(sequenceOf(f), 0u);
				break;
			}
			case kCommand:
				ASSERT_EQ(msg, "DP_Command");
				EXPECT_EQ((raw["Enable"].get<int>() != 0), true);
				EXPECT_EQ(raw["Mode"].get<int>(), 1);
				EXPECT_EQ(raw["StrobeMode"].get<int>(), 2);
				EXPECT_EQ(raw["Preview"].get<int>(), 1);
				EXPECT_EQ(raw["ExposureUs"].get<int>(), 1500);
				EXPECT_NEAR(val("Gain"), 4.5, 0.05 + 1e-9);
				break;
			default:
				FAIL() << "unexpected id";
			}
			if (::testing::Test::HasFatalFailure())
				return;
		}
		EXPECT_EQ(report, reports_.size());
		EXPECT_EQ(hb, heartbeats_.size());
	}

	/* scripts/candecode --json on the same log against the C++ inputs. */
	void checkCandecode(std::uint32_t base)
	{
		char base_text[16];
		std::snprintf(base_text, sizeof(base_text), "0x%x", base);
		const RunResult r =
			run(quote(python_) + " " + quote(source_ + "/scripts/candecode") +
				    " --json --strict --base-id " + base_text + " --log " +
				    quote(dir_ + "/log.log"),
			    dir_);
		ASSERT_EQ(r.status, 0) << r.err;
		const std::vector<nlohmann::json> objs = jsonLines(r.out);
		ASSERT_EQ(objs.size(), reports_.size());
		for (std::size_t i = 0; i < objs.size(); ++i) {
			SCOPED_TRACE("report " + std::to_string(i) + " " + objs[i].dump());
			const nlohmann::json &o = objs[i];
			const Report &in = reports_[i];
			EXPECT_EQ(o["seq"].get<unsigned int>(), i & 0x0f);
			EXPECT_EQ(o["state"].get<std::string>(), sensorStateName(in.status.state));
			EXPECT_EQ(o["valid"].get<bool>(), in.with_pose);
			EXPECT_EQ(o["leds"].get<int>(), in.status.leds_used);
			EXPECT_NEAR(o["rms_px"].get<double>(), clampD(in.status.rms_px, 0, 2.55),
				    kTolRms);
			EXPECT_NEAR(o["latency_ms"].get<double>(),
				    clampD(in.status.latency_ms, 0, 655.35), kTolLatency);
			EXPECT_NEAR(o["timestamp"].get<double>(), report_times_[i], 1e-5);
			std::vector<std::string> faults;
			for (unsigned int b = 0; b < 8; ++b)
				if (in.status.faults & (1u << b))
					faults.push_back(faultBitName(b));
			EXPECT_EQ(o["faults"].get<std::vector<std::string>>(), faults);
			if (!in.with_pose) {
				EXPECT_TRUE(o["t_mm"].is_null());
				EXPECT_TRUE(o["log10_nfa"].is_null());
				EXPECT_TRUE(o["frame"].is_null());
				continue;
			}
			const PoseData &p = in.pose;
			EXPECT_EQ(o["frame"].get<std::uint32_t>(), p.frame_counter);
			for (std::size_t k = 0; k < 3; ++k) {
				EXPECT_NEAR(o["t_mm"][k].get<double>(), p.t_mm[k], kTolT);
				EXPECT_NEAR(o["rpy_deg"][k].get<double>(), p.rpy_deg[k], kTolDeg);
				expectSigmaSent(o["sigma_t_mm"][k].get<double>(),
						clampD(p.sigma_t_mm[k], 0, 25.5), kStepSigmaT);
				expectSigmaSent(o["sigma_rpy_deg"][k].get<double>(),
						clampD(p.sigma_rpy_deg[k], 0, 2.55), kStepSigmaDeg);
			}
			for (std::size_t k = 0; k < 4; ++k)
				EXPECT_NEAR(o["q"][k].get<double>(), p.q[k], kTolQ);
			EXPECT_NEAR(o["log10_nfa"].get<double>(), sentNfa(p.log10_nfa), kTolNfa);
			if (::testing::Test::HasFailure())
				return;
		}
		/* The summary (stderr with --json): the rate from the timestamps. */
		EXPECT_NE(r.err.find("at 60.0 Hz"), std::string::npos) << r.err;
		EXPECT_NE(r.err.find("CRC 0, length 0, alive gaps 0"), std::string::npos) << r.err;
	}

	/* canmatrix's DP_ReportFd objects as the classic frames of their slots: its signals
	 * "<Message>_<Signal>" grouped by message (DP_<Message>), a slot whose raw values are all
	 * zero left out (no frame), in slot order. Other objects as they are. */
	static std::vector<nlohmann::json> fdSlotsAsFrames(const std::vector<nlohmann::json> &objs,
							   std::uint32_t base)
	{
		static const std::pair<const char *, std::uint32_t> kSlotMessages[] = {
			{ "Translation", kTranslation },
			{ "QuatA", kQuatA },
			{ "QuatB", kQuatB },
			{ "Angles", kAngles },
			{ "Sigma", kSigma },
			{ "Quality", kQuality },
			{ "Status", kStatus },
			{ "Auth", kAuth },
		};
		std::vector<nlohmann::json> out;
		for (const nlohmann::json &o : objs) {
			if (o["message"] != "DP_ReportFd") {
				out.push_back(o);
				continue;
			}
			EXPECT_EQ(o["raw"].size(), 54u) << "DP_ReportFd's signals";
			for (std::size_t k = 0; k < kFdSlots.size(); ++k) {
				/* The slot order is the header's (kFdSlots); the names the DBC's. */
				const auto &[name, offset] = kSlotMessages[k];
				EXPECT_EQ(offset, kFdSlots[k]);
				nlohmann::json frame = { { "id", base + offset },
							 { "message", std::string("DP_") + name },
							 { "signals", nlohmann::json::object() },
							 { "raw", nlohmann::json::object() } };
				bool any = false;
				const std::string prefix = std::string(name) + "_";
				for (const auto &[sig, value] : o["raw"].items()) {
					if (sig.rfind(prefix, 0) != 0)
						continue;
					const std::string classic = sig.substr(prefix.size());
					frame["raw"][classic] = value;
					frame["signals"][classic] = o["signals"][sig];
					any = any || value.get<std::uint64_t>() != 0;
				}
				if (any)
					out.push_back(frame);
			}
		}
		return out;
	}

	bool fd_ = false;
	std::string dir_, source_, python_, dbc_;
	std::vector<Report> reports_;
	std::vector<double> report_times_;
	std::vector<HeartbeatData> heartbeats_;
	std::vector<RawFrame> frames_;
};

} /* namespace */

TEST_F(CanToolsTest, CanmatrixAndCandecodeAgreeWithTheEncoder)
{
	writeLog(kDefaultBaseId, 150);
	ASSERT_FALSE(HasFatalFailure());
	checkCanmatrix(kDefaultBaseId);
	checkCandecode(kDefaultBaseId);
}

/* Every SignalLayout of the header is its SG_ line in the DBC, in the message of its offset. */
TEST(CanProtocol, SignalLayoutsAreTheDbcs)
{
	const std::string dbc_path =
		std::string(DOCKPOSE_SOURCE_DIR) + "/firmware/protocol/dockpose.dbc";
	const std::string dbc = readFile(dbc_path);
	struct Named {
		const char *name;
		const SignalLayout &layout;
	};
	const Named layouts[] = {
		{ "Log10Nfa", layout::kLog10Nfa },
		{ "SensorTimeUs", layout::kSensorTime },
		{ "Authenticated", layout::kAuthenticated },
		{ "AuthFreshness", layout::kAuthFreshness },
		{ "AuthMac", layout::kAuthMac },
		{ "FreshnessHigh", layout::kFreshnessHigh },
		{ "CmdFreshness", layout::kCommandFreshness },
		{ "CmdMac", layout::kCommandMac },
	};
	for (const Named &n : layouts) {
		SCOPED_TRACE(n.name);
		/* The message that holds the signal: the last BO_ before its SG_ line. */
		const std::size_t at = dbc.find(std::string(" SG_ ") + n.name + " :");
		ASSERT_NE(at, std::string::npos) << "no SG_ " << n.name << " in " << dbc_path;
		const std::size_t bo = dbc.rfind("BO_ ", at);
		ASSERT_NE(bo, std::string::npos);
		unsigned int id = 0;
		ASSERT_EQ(std::sscanf(dbc.c_str() + bo, "BO_ %u", &id), 1);
		EXPECT_EQ(id, kDbcBaseId + n.layout.offset);
		unsigned int start = 0, length = 0;
		char sign = 0;
		double factor = 0, offset = 1, lo = 0, hi = 0;
		const std::string line = dbc.substr(at, dbc.find('\n', at) - at);
		ASSERT_EQ(std::sscanf(line.c_str() + line.find(':') + 1,
				      " %u|%u@1%c (%lf,%lf) [%lf|%lf]", &start, &length, &sign,
				      &factor, &offset, &lo, &hi),
			  7)
			<< line;
		EXPECT_EQ(start, n.layout.start_bit);
		EXPECT_EQ(length, n.layout.length_bits);
		EXPECT_EQ(sign == '-', n.layout.is_signed);
		EXPECT_DOUBLE_EQ(factor, n.layout.factor);
		EXPECT_EQ(offset, 0.0);
		EXPECT_NEAR(lo, static_cast<double>(n.layout.rawMin()) * n.layout.factor, 1e-9);
		EXPECT_NEAR(hi, static_cast<double>(n.layout.rawMax()) * n.layout.factor, 1e-9);
		/* Clear of bytes 6 and 7 (AliveCounter, Sequence, CRC). */
		EXPECT_LE(start + length, 48u);
	}
}

/* DP_ReportFd in the DBC is the classic messages of kFdSlots, slot k's signals named
 * <Message>_<Signal> at the classic start bit + 64 k, everything else on the line the same. */
TEST(CanFd, TheDbcsReportFdIsTheClassicMessagesInSlotOrder)
{
	const std::string dbc =
		readFile(std::string(DOCKPOSE_SOURCE_DIR) + "/firmware/protocol/dockpose.dbc");
	/* id -> (name, its SG_ lines) */
	struct Message {
		std::string name;
		std::vector<std::string> signals;
	};
	std::map<unsigned int, Message> messages;
	std::istringstream in(dbc);
	std::string line;
	unsigned int current = 0;
	while (std::getline(in, line)) {
		unsigned int id = 0, size = 0;
		char name[64] = {};
		if (std::sscanf(line.c_str(), "BO_ %u %63[^:]: %u", &id, name, &size) == 3) {
			current = id;
			messages[id].name = name;
		} else if (line.rfind(" SG_ ", 0) == 0) {
			messages[current].signals.push_back(line);
		}
	}
	const auto fd = messages.find(kDbcBaseId + kReportFd);
	ASSERT_NE(fd, messages.end()) << "no DP_ReportFd";
	EXPECT_EQ(fd->second.name, "DP_ReportFd");
	EXPECT_NE(dbc.find("BO_ 778 DP_ReportFd: 64 DOCKPOSE"), std::string::npos);
	EXPECT_NE(dbc.find("BA_ \"VFrameFormat\" BO_ 778 14;"), std::string::npos)
		<< "DP_ReportFd must be marked a CAN FD frame (StandardCAN_FD)";
	std::size_t expected = 0;
	for (std::size_t k = 0; k < kFdSlots.size(); ++k) {
		const Message &classic = messages.at(kDbcBaseId + kFdSlots[k]);
		const std::string prefix = classic.name.substr(3) + "_";
		for (const std::string &sg : classic.signals) {
			char sig[64] = {};
			unsigned int start = 0;
			ASSERT_EQ(std::sscanf(sg.c_str(), " SG_ %63s : %u|", sig, &start), 2) << sg;
			const std::string rest = sg.substr(sg.find('|'));
			const std::string want = " SG_ " + prefix + sig + " : " +
						 std::to_string(start + 64 * k) + rest;
			EXPECT_NE(std::find(fd->second.signals.begin(), fd->second.signals.end(),
					    want),
				  fd->second.signals.end())
				<< "DP_ReportFd lacks: " << want;
			++expected;
		}
	}
	EXPECT_EQ(fd->second.signals.size(), expected) << "DP_ReportFd has signals of no slot";
}

/* can.fd: each report one DP_ReportFd; canmatrix decodes its 54 signals with the DBC into
 * the same values as the classic frames, and scripts/candecode takes the same reports. */
TEST_F(CanToolsTest, CanFdReportsDecodeWithTheDbc)
{
	fd_ = true;
	writeLog(kDefaultBaseId, 150);
	ASSERT_FALSE(HasFatalFailure());
	checkCanmatrix(kDefaultBaseId);
	checkCandecode(kDefaultBaseId);
}

TEST_F(CanToolsTest, OtherBaseIdIsRemapped)
{
	writeLog(0x520, 60);
	ASSERT_FALSE(HasFatalFailure());
	checkCanmatrix(0x520);
	checkCandecode(0x520);
	/* Read as base 0x300 the frames are not ours: no report at all. */
	const RunResult r = run(quote(python_) + " " + quote(source_ + "/scripts/candecode") +
					" --json --log " + quote(dir_ + "/log.log"),
				dir_);
	EXPECT_EQ(r.status, 0) << r.err;
	EXPECT_TRUE(r.out.empty()) << r.out;
	EXPECT_NE(r.err.find("reports 0"), std::string::npos) << r.err;
}

TEST_F(CanToolsTest, CandecodeFindsCorruptionLikeTheDecoder)
{
	writeLog(kDefaultBaseId, 40);
	ASSERT_FALSE(HasFatalFailure());
	/* Corrupt the third QuatA frame, drop the 18th Angles frame, repeat the
	 * 11th status frame, and put a line that is not candump's first. */
	std::vector<std::string> lines;
	{
		std::ifstream in(dir_ + "/log.log");
		std::string line;
		while (std::getline(in, line))
			lines.push_back(line + "\n");
	}
	ASSERT_EQ(lines.size(), frames_.size());
	auto lineOf = [&](std::size_t report, std::uint32_t offset) {
		std::size_t seen = 0;
		for (std::size_t i = 0; i < frames_.size(); ++i) {
			if (frames_[i].id == kDefaultBaseId + offset && seen++ == report)
				return i;
		}
		return frames_.size();
	};
	const std::size_t quat = lineOf(2, kQuatA), angles = lineOf(17, kAngles),
			  status = lineOf(10, kStatus);
	ASSERT_LT(quat, lines.size());
	ASSERT_LT(angles, lines.size());
	ASSERT_LT(status, lines.size());
	lines[quat][lines[quat].size() - 4] = lines[quat][lines[quat].size() - 4] == '0' ? '1'
											 : '0';
	lines[angles] = "";
	lines.insert(lines.begin() + static_cast<std::ptrdiff_t>(status) + 1, lines[status]);
	lines.insert(lines.begin(), "this is not a candump line\n");
	{
		std::ofstream out(dir_ + "/bad.log");
		for (const std::string &l : lines)
			out << l;
	}

	/* The C++ decoder on the same frames. */
	Decoder dec;
	{
		std::ifstream in(dir_ + "/bad.log");
		std::string line;
		while (std::getline(in, line)) {
			unsigned int id;
			char data[17] = {};
			if (std::sscanf(line.c_str(), "(%*f) %*s %x#%16s", &id, data) != 2)
				continue;
			RawFrame f;
			f.id = id;
			f.len = 8;
			for (std::size_t k = 0; k < 8; ++k)
				f.data[k] = static_cast<std::uint8_t>(
					std::stoul(std::string(data + 2 * k, 2), nullptr, 16));
			dec.feed(f);
		}
	}
	EXPECT_EQ(dec.counters().crc_errors, 1u);
	EXPECT_EQ(dec.counters().stale_frames, 1u);
	EXPECT_EQ(dec.counters().alive_gaps, 2u); /* the corrupted and the dropped frame */
	EXPECT_EQ(dec.counters().incomplete_poses, 2u);

	const std::string cmd = quote(python_) + " " + quote(source_ + "/scripts/candecode") +
				" --json --log " + quote(dir_ + "/bad.log");
	RunResult r = run(cmd, dir_);
	ASSERT_EQ(r.status, 0) << r.err;
	const std::vector<nlohmann::json> objs = jsonLines(r.out);
	ASSERT_EQ(objs.size(), reports_.size());
	std::uint64_t valid = 0, incomplete = 0;
	for (const nlohmann::json &o : objs) {
		valid += o["valid"].get<bool>();
		incomplete += o["incomplete"].get<bool>();
	}
	EXPECT_EQ(valid, dec.counters().valid_poses);
	EXPECT_EQ(incomplete, dec.counters().incomplete_poses);
	EXPECT_NE(
		r.err.find(
			"CRC 1, length 0, alive gaps 2 (frames lost), stale 1, malformed log lines 1"),
		std::string::npos)
		<< r.err;
	EXPECT_NE(r.err.find(":1: not a candump -l line"), std::string::npos) << r.err;

	/* --strict turns the errors into exit status 1; --count stops early. */
	r = run(cmd + " --strict", dir_);
	EXPECT_EQ(r.status, 1) << r.err;
	r = run(cmd + " --count 5", dir_);
	EXPECT_EQ(r.status, 0) << r.err;
	EXPECT_EQ(jsonLines(r.out).size(), 5u);

	/* Text output: one line per report and the summary. */
	r = run(quote(python_) + " " + quote(source_ + "/scripts/candecode") +
			" --heartbeats --log " + quote(dir_ + "/log.log"),
		dir_);
	ASSERT_EQ(r.status, 0) << r.err;
	EXPECT_NE(r.out.find("seq  0 frame "), std::string::npos) << r.out;
	EXPECT_NE(r.out.find(" mm  rpy=("), std::string::npos) << r.out;
	EXPECT_NE(r.out.find("heartbeat  up 0 s"), std::string::npos) << r.out;
	EXPECT_NE(r.out.find("command  enable  mode SEARCH_ONLY  strobe ALTERNATE"),
		  std::string::npos)
		<< r.out;
	EXPECT_NE(r.out.find("reports 40 at 60.0 Hz"), std::string::npos) << r.out;
}

TEST_F(CanToolsTest, CandecodeUsageAndIoErrors)
{
	const std::string tool = quote(python_) + " " + quote(source_ + "/scripts/candecode");
	RunResult r = run(tool + " --log " + quote(dir_ + "/missing.log"), dir_);
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("missing.log: no such log file"), std::string::npos) << r.err;

	{
		std::ofstream(dir_ + "/empty.log") << "";
		std::ofstream(dir_ + "/bad.dbc") << "this is not a DBC\nBO_ 1 X: 8 Y\n";
		std::ofstream(dir_ + "/junk.log") << "hello world\nnot a log\n";
	}
	r = run(tool + " --dbc " + quote(dir_ + "/bad.dbc") + " --log " +
			quote(dir_ + "/empty.log"),
		dir_);
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("bad DBC"), std::string::npos) << r.err;

	r = run(tool + " --dbc " + quote(dir_ + "/nope.dbc") + " --log " +
			quote(dir_ + "/empty.log"),
		dir_);
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("nope.dbc: no such DBC file"), std::string::npos) << r.err;

	r = run(tool + " --log " + quote(dir_ + "/junk.log"), dir_);
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("not a candump log"), std::string::npos) << r.err;

	r = run(tool + " --interface dockposecan9", dir_);
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("dockposecan9: no such CAN interface"), std::string::npos) << r.err;

	r = run(tool + " --log " + quote(dir_ + "/empty.log") + " --base-id 0x7f0", dir_);
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("--base-id"), std::string::npos) << r.err;

	r = run(tool, dir_);
	EXPECT_EQ(r.status, 2);

	r = run(tool + " --log " + quote(dir_ + "/empty.log"), dir_);
	EXPECT_EQ(r.status, 0) << r.err;
	EXPECT_NE(r.out.find("reports 0"), std::string::npos) << r.out;
}

/* SPDX-License-Identifier: MIT */
/*
 * dockpose view's glue between the bus and the page: candump lines parsed,
 * reports encoded by the project's encoder decoded back into the state the
 * page shows (pose, σ, state, fault names, rate), stale after max(3 periods,
 * 300 ms), damaged frames and lines named as problems, a log followed as it
 * grows (a half-written line waits for its end; a truncated file is read
 * again), the 30 s history, the page's command as the DP_Command a sensor
 * decodes, and with --key the command signed so that the sensor's own
 * verifier takes it (and refuses a wrong key's and a replayed one). The page
 * in a browser: view_browser_e2e.py.
 */
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "firmware/protocol/dockpose_can.h"
#include "firmware/protocol/dockpose_can_cmac.h"
#include "tools/dockpose/view/can_input.h"
#include "tools/dockpose/view/candump.h"
#include "tools/dockpose/view/command.h"
#include "tools/dockpose/view/view_state.h"

namespace {

using namespace dockpose;
using dockpose::tool::CandumpLine;
using dockpose::tool::CandumpParse;
using dockpose::tool::parseCandumpLine;
using dockpose::tool::ViewState;
using nlohmann::json;

constexpr std::int64_t kT0Us = 1700000000000000;
constexpr std::int64_t kPeriodUs = 16667; /* 60 reports a second */

can::PoseData poseAt(int k)
{
	can::PoseData p;
	p.frame_counter = static_cast<std::uint32_t>(100 + k);
	p.t_mm[0] = 12.3 + k;
	p.t_mm[1] = -45.6;
	p.t_mm[2] = 1234.5 - k;
	p.q[0] = 1.0;
	p.rpy_deg[0] = 1.25;
	p.rpy_deg[1] = -2.5;
	p.rpy_deg[2] = 0.75;
	p.sigma_t_mm[0] = 0.4;
	p.sigma_t_mm[1] = 0.5;
	p.sigma_t_mm[2] = 2.1;
	p.sigma_rpy_deg[0] = 0.05;
	p.sigma_rpy_deg[1] = 0.06;
	p.sigma_rpy_deg[2] = 0.07;
	p.log10_nfa = -12.3;
	p.sensor_time_us = static_cast<std::uint32_t>(5000000 + k * kPeriodUs);
	return p;
}

can::StatusData statusWith(std::uint8_t faults)
{
	can::StatusData s;
	s.state = can::SensorState::Tracking;
	s.pose_valid = true;
	s.tracked = true;
	s.strobe = can::StrobeMode::Constant;
	s.leds_used = 7;
	s.rms_px = 0.23;
	s.faults = faults;
	s.latency_ms = 1.5;
	return s;
}

/* `count` reports at kPeriodUs into state (or into frames when given); returns the last time. */
std::int64_t feedReports(ViewState *state, can::Encoder *encoder, int count,
			 std::int64_t period_us = kPeriodUs, std::uint8_t faults = 0)
{
	std::int64_t t = kT0Us;
	for (int k = 0; k < count; ++k) {
		t = kT0Us + k * period_us;
		can::PoseData pose = poseAt(k);
		pose.sensor_time_us = static_cast<std::uint32_t>(5000000 + k * period_us);
		can::RawFrame out[can::kMaxReportFrames];
		const int n = encoder->encodeReport(statusWith(faults), &pose, out);
		for (int i = 0; i < n; ++i)
			state->feed(out[i], t);
	}
	return t;
}

bool hasProblem(const json &state, const std::string &name)
{
	for (const json &p : state["problems"])
		if (p["name"] == name)
			return true;
	return false;
}

TEST(Candump, ParsesClassicAndFdLinesWithTheirTime)
{
	CandumpLine line;
	ASSERT_EQ(parseCandumpLine("(1700000000.123456) can0 305#0011223344556677", &line),
		  CandumpParse::Classic);
	EXPECT_EQ(line.time_us, 1700000000123456);
	EXPECT_EQ(line.frame.id, 0x305u);
	EXPECT_EQ(line.frame.len, 8);
	EXPECT_EQ(line.frame.data[0], 0x00);
	EXPECT_EQ(line.frame.data[7], 0x77);

	/* A short fraction is scaled (candump always writes 6 digits; others may not). */
	ASSERT_EQ(parseCandumpLine("(12.5) vcan0 7FF#AB", &line), CandumpParse::Classic);
	EXPECT_EQ(line.time_us, 12500000);
	EXPECT_EQ(line.frame.id, 0x7ffu);
	EXPECT_EQ(line.frame.len, 1);

	const std::string fd = "(1.000001) can0 30A##0" + std::string(128, 'E');
	ASSERT_EQ(parseCandumpLine(fd, &line), CandumpParse::Fd);
	EXPECT_EQ(line.fd.id, 0x30au);
	EXPECT_EQ(line.fd.len, 64);
	EXPECT_EQ(line.fd.data[63], 0xee);
}

TEST(Candump, NamesTruncatedAndMalformedLines)
{
	CandumpLine line;
	/* Cut off: the parser runs out of characters where more was due. */
	EXPECT_EQ(parseCandumpLine("(1700000000.123456) can0 305#00112", &line),
		  CandumpParse::Truncated);
	EXPECT_STRNE(line.error, "");
	EXPECT_EQ(parseCandumpLine("(1700000000.123456) can0 30", &line), CandumpParse::Truncated);
	EXPECT_EQ(parseCandumpLine("(1700000000.12", &line), CandumpParse::Truncated);
	/* A character with no place there. */
	EXPECT_EQ(parseCandumpLine("hello world", &line), CandumpParse::Malformed);
	EXPECT_EQ(parseCandumpLine("(1700000000.123456) can0 305#00ZZ", &line),
		  CandumpParse::Malformed);
	EXPECT_EQ(parseCandumpLine("(1700000000.123456) can0 305#001122334455667788", &line),
		  CandumpParse::Malformed);
	EXPECT_EQ(parseCandumpLine("(1700000000.123456) can0 805#00", &line),
		  CandumpParse::Malformed);
	/* Never ours: extended ids and remote frames; empty lines. */
	EXPECT_EQ(parseCandumpLine("(1.0) can0 00000305#0011223344556677", &line),
		  CandumpParse::Ignored);
	EXPECT_EQ(parseCandumpLine("(1.0) can0 305#R", &line), CandumpParse::Ignored);
	EXPECT_EQ(parseCandumpLine("", &line), CandumpParse::Ignored);
	EXPECT_STREQ(tool::candumpParseName(CandumpParse::Truncated), "truncated log line");
	EXPECT_STREQ(tool::candumpParseName(CandumpParse::Malformed), "malformed log line");
}

TEST(ViewState, DecodesReportsIntoWhatThePageShows)
{
	ViewState state;
	can::Encoder encoder;
	const int count = 10;
	const std::int64_t last =
		feedReports(&state, &encoder, count, kPeriodUs, can::fault::kStrobeError);
	const json s = state.stateJson(last + 1000);

	const can::PoseData want = poseAt(count - 1);
	ASSERT_TRUE(s["t_mm"].is_array()) << s.dump();
	for (int i = 0; i < 3; ++i) {
		EXPECT_NEAR(s["t_mm"][i].get<double>(), want.t_mm[i], 0.05 + 1e-9) << i;
		EXPECT_NEAR(s["rpy_deg"][i].get<double>(), want.rpy_deg[i], 0.005 + 1e-9) << i;
		/* σ is sent rounded up: never below what was sent, within a step. */
		EXPECT_GE(s["sigma_t_mm"][i].get<double>(), want.sigma_t_mm[i] - 1e-9);
		EXPECT_LE(s["sigma_t_mm"][i].get<double>(), want.sigma_t_mm[i] + 0.1 + 1e-9);
	}
	EXPECT_EQ(s["frame"], want.frame_counter);
	EXPECT_EQ(s["state"], "TRACKING");
	EXPECT_EQ(s["faults"], json::array({ "STROBE_ERROR" }));
	EXPECT_EQ(s["fault_bits"], can::fault::kStrobeError);
	EXPECT_EQ(s["leds"], 7);
	EXPECT_NEAR(s["rms_px"].get<double>(), 0.23, 1e-9);
	EXPECT_NEAR(s["log10_nfa"].get<double>(), -12.3, 1e-9);
	EXPECT_TRUE(s["pose_valid"].get<bool>());
	EXPECT_NEAR(s["rate_hz"].get<double>(), 1e6 / kPeriodUs, 0.1);
	EXPECT_NEAR(s["age_ms"].get<double>(), 1.0, 1e-9);
	EXPECT_FALSE(s["stale"].get<bool>());
	EXPECT_EQ(s["counters"]["reports"], count);
	EXPECT_TRUE(s["problems"].empty()) << s["problems"].dump();
	EXPECT_EQ(s["strobe"], "CONSTANT");
}

TEST(ViewState, StaleAfterThreePeriodsOrThreeHundredMilliseconds)
{
	{
		/* 60 reports a second: 3 periods are 50 ms, so 300 ms is the bound. */
		ViewState state;
		can::Encoder encoder;
		const std::int64_t last = feedReports(&state, &encoder, 10);
		EXPECT_DOUBLE_EQ(state.stateJson(last)["stale_after_ms"].get<double>(), 300.0);
		EXPECT_FALSE(state.stateJson(last + 290000)["stale"].get<bool>());
		EXPECT_TRUE(state.stateJson(last + 310000)["stale"].get<bool>());
	}
	{
		/* 5 reports a second: 3 periods, 600 ms. */
		ViewState state;
		can::Encoder encoder;
		const std::int64_t last = feedReports(&state, &encoder, 10, 200000);
		EXPECT_DOUBLE_EQ(state.stateJson(last)["stale_after_ms"].get<double>(), 600.0);
		EXPECT_FALSE(state.stateJson(last + 590000)["stale"].get<bool>());
		EXPECT_TRUE(state.stateJson(last + 610000)["stale"].get<bool>());
	}
	/* Nothing heard yet: stale, with no pose. */
	const ViewState empty;
	const json s = empty.stateJson(kT0Us);
	EXPECT_TRUE(s["stale"].get<bool>());
	EXPECT_TRUE(s["t_mm"].is_null());
	EXPECT_TRUE(s["state"].is_null());
}

TEST(ViewState, NamesBadCrcAndRepeatedCounterAndKeepsTheGoodPose)
{
	ViewState state;
	can::Encoder encoder;
	std::int64_t t = feedReports(&state, &encoder, 8);

	can::PoseData pose = poseAt(50);
	pose.sensor_time_us = static_cast<std::uint32_t>(5000000 + 8 * kPeriodUs);
	can::RawFrame out[can::kMaxReportFrames];
	const int n = encoder.encodeReport(statusWith(0), &pose, out);
	ASSERT_GE(n, 2);
	t += kPeriodUs;
	can::RawFrame bad = out[0];
	bad.data[0] ^= 0x01; /* one bit flipped on the wire: the CRC no longer matches */
	state.feed(bad, t);
	state.feed(out[1], t);
	state.feed(out[1], t); /* the same frame again: its alive counter repeats */
	for (int i = 2; i < n; ++i)
		state.feed(out[i], t);

	const json s = state.stateJson(t);
	EXPECT_TRUE(hasProblem(s, "bad CRC")) << s["problems"].dump();
	EXPECT_TRUE(hasProblem(s, "stale alive counter")) << s["problems"].dump();
	EXPECT_EQ(s["counters"]["crc_errors"], 1);
	/* That report's pose lost a frame: not valid, and the last good pose stays shown. */
	EXPECT_FALSE(s["pose_valid"].get<bool>());
	EXPECT_EQ(s["frame"], poseAt(7).frame_counter);
	EXPECT_TRUE(hasProblem(s, "incomplete pose (a pose frame missing)"))
		<< s["problems"].dump();
}

TEST(ViewState, KeepsThirtySecondsOfPoses)
{
	ViewState state;
	can::Encoder encoder;
	/* 40 s at 5 reports a second. */
	const std::int64_t last = feedReports(&state, &encoder, 200, 200000);
	const json h = state.historyJson(last);
	ASSERT_FALSE(h.empty());
	EXPECT_GE(h.front()[0].get<double>(), -30.0);
	EXPECT_LE(h.front()[0].get<double>(), -29.7);
	EXPECT_DOUBLE_EQ(h.back()[0].get<double>(), 0.0);
	EXPECT_EQ(h.back().size(), 7u);
	EXPECT_NEAR(h.back()[1].get<double>(), poseAt(199).t_mm[0], 0.05 + 1e-6);
}

TEST(ViewState, ProtocolNamesComeFromTheHeader)
{
	const json p = ViewState::protocolJson();
	ASSERT_EQ(p["fault_bits"].size(), 8u);
	for (unsigned int bit = 0; bit < 8; ++bit)
		EXPECT_EQ(p["fault_bits"][bit], can::faultBitName(bit));
	EXPECT_EQ(p["states"][2], "TRACKING");
	EXPECT_EQ(p["strobe_modes"].back(), "UNCHANGED");
	EXPECT_EQ(p["track_modes"], json::array({ "TRACK", "SEARCH_ONLY" }));
}

TEST(Command, ThePagesCommandIsTheDpCommandASensorDecodes)
{
	can::CommandData cmd;
	ASSERT_EQ(tool::commandFromJson(json::parse(R"({"enable": false, "mode": "SEARCH_ONLY",
		"strobe": "ALTERNATE", "exposure_us": 1500, "gain": 2.5})"),
					&cmd),
		  "");
	can::Encoder encoder;
	const can::RawFrame frame = encoder.encodeCommand(cmd);
	EXPECT_EQ(frame.id, can::kDefaultBaseId + can::kCommand);
	can::Decoder sensor;
	ASSERT_EQ(sensor.feed(frame), can::Decoder::Event::Command);
	const can::CommandData &got = sensor.command();
	EXPECT_FALSE(got.enable);
	EXPECT_EQ(got.mode, can::TrackMode::SearchOnly);
	EXPECT_EQ(got.strobe, can::StrobeMode::Alternate);
	EXPECT_EQ(got.exposure_us, 1500);
	EXPECT_NEAR(got.gain, 2.5, 1e-9);

	/* Absent fields: the defaults (enabled, track, nothing else changed). */
	can::CommandData defaults;
	ASSERT_EQ(tool::commandFromJson(json::object(), &defaults), "");
	EXPECT_TRUE(defaults.enable);
	EXPECT_EQ(defaults.strobe, can::StrobeMode::Unchanged);
	EXPECT_EQ(defaults.exposure_us, 0);

	/* Each wrong field says which. */
	const char *wrong[][2] = {
		{ R"({"mode": "FAST"})", "mode" },
		{ R"({"strobe": 2})", "strobe" },
		{ R"({"exposure_us": 70000})", "exposure_us" },
		{ R"({"gain": 30})", "gain" },
		{ R"({"enable": "yes"})", "enable" },
		{ R"([1, 2])", "not a JSON object" },
	};
	for (const auto &[text, field] : wrong) {
		can::CommandData c;
		const std::string error = tool::commandFromJson(json::parse(text), &c);
		EXPECT_NE(error.find(field), std::string::npos) << text << ": " << error;
	}
}

class Follower : public ::testing::Test
{
protected:
	void SetUp() override
	{
		char dir_template[] = "/tmp/view-test.XXXXXX";
		ASSERT_NE(mkdtemp(dir_template), nullptr);
		dir_ = dir_template;
		path_ = dir_ + "/can.log";
	}
	void TearDown() override { (void)std::system(("rm -rf '" + dir_ + "'").c_str()); }

	void append(const std::string &text)
	{
		std::ofstream f(path_, std::ios::app);
		f << text;
	}
	std::string dir_, path_;
};

/* candump -L lines of `count` reports at 60 a second from kT0Us. */
std::string reportLines(can::Encoder *encoder, int first, int count)
{
	std::string text;
	for (int k = first; k < first + count; ++k) {
		can::PoseData pose = poseAt(k);
		can::RawFrame out[can::kMaxReportFrames];
		const int n = encoder->encodeReport(statusWith(0), &pose, out);
		const std::int64_t t = kT0Us + k * kPeriodUs;
		for (int i = 0; i < n; ++i) {
			char stamp[40];
			std::snprintf(stamp, sizeof(stamp), "(%lld.%06lld) can0 ",
				      static_cast<long long>(t / 1000000),
				      static_cast<long long>(t % 1000000));
			text += stamp + tool::candumpFrameText(out[i]) + "\n";
		}
	}
	return text;
}

TEST_F(Follower, FollowsTheLogAsItGrowsAndNamesBadLines)
{
	ViewState state;
	can::Encoder encoder;
	append(reportLines(&encoder, 0, 6));
	tool::CandumpFollower follower(path_, &state);
	EXPECT_EQ(follower.poll(), 6 * 7);
	EXPECT_EQ(state.stateJson(kT0Us)["frame"], poseAt(5).frame_counter);

	/* A report whose last line is half written: nothing of that line is taken yet. */
	const std::string more = reportLines(&encoder, 6, 1);
	const std::size_t cut = more.size() - 10;
	append(more.substr(0, cut));
	EXPECT_EQ(follower.poll(), 6);
	EXPECT_EQ(state.stateJson(kT0Us)["counters"]["reports"], 6);
	append(more.substr(cut));
	EXPECT_EQ(follower.poll(), 1);
	json s = state.stateJson(kT0Us);
	EXPECT_EQ(s["counters"]["reports"], 7);
	EXPECT_EQ(s["frame"], poseAt(6).frame_counter);
	EXPECT_TRUE(s["problems"].empty()) << s["problems"].dump();

	/* A garbage line and a cut one: named, with their line numbers; the follower goes on. */
	append("this is not candump\n(1700000000.5) can0 305#001\n");
	append(reportLines(&encoder, 7, 1));
	follower.poll();
	s = state.stateJson(kT0Us);
	EXPECT_TRUE(hasProblem(s, "malformed log line")) << s["problems"].dump();
	EXPECT_TRUE(hasProblem(s, "truncated log line")) << s["problems"].dump();
	for (const json &p : s["problems"]) {
		if (p["name"] == "malformed log line") {
			EXPECT_NE(p["detail"].get<std::string>().find("line 50"), std::string::npos)
				<< p.dump();
		}
	}
	EXPECT_EQ(s["frame"], poseAt(7).frame_counter);

	/* The log truncated (a new run): read again from its start. */
	{
		std::ofstream f(path_, std::ios::trunc);
	}
	can::Encoder encoder2;
	append(reportLines(&encoder2, 20, 5));
	follower.poll();
	s = state.stateJson(kT0Us);
	EXPECT_TRUE(hasProblem(s, "CAN log")) << s["problems"].dump();
	EXPECT_EQ(s["frame"], poseAt(24).frame_counter);
}

TEST_F(Follower, AMissingLogIsAProblemUntilItAppears)
{
	ViewState state;
	tool::CandumpFollower follower(path_, &state);
	EXPECT_EQ(follower.poll(), 0);
	const json s = state.stateJson(kT0Us);
	ASSERT_TRUE(hasProblem(s, "CAN log")) << s["problems"].dump();
	EXPECT_NE(s["problems"][0]["detail"].get<std::string>().find("No such file"),
		  std::string::npos);
	EXPECT_FALSE(s["problems"][0]["resolved"].get<bool>());

	/* The log appears (the daemon opened its bus): read within a second, the problem resolved. */
	can::Encoder encoder;
	append(reportLines(&encoder, 0, 6));
	usleep(1100000);
	EXPECT_EQ(follower.poll(), 6 * 7);
	const json after = state.stateJson(kT0Us);
	EXPECT_EQ(after["frame"], poseAt(5).frame_counter);
	EXPECT_TRUE(after["problems"][0]["resolved"].get<bool>()) << after["problems"].dump();
}

/* --key: the view's sending path (useCanKey, ViewState, CommandSender, as runView wires them)
 * against the sensor's side as dockposed sets it up (Daemon::startAuthentication): one CMAC for
 * its encoder and its command decoder, a run's freshness values from run << 32, and commands
 * taken within the last 256 of its values. */
class SignedCommand : public ::testing::Test
{
protected:
	static constexpr const char *kKeyHex = "2b7e151628aed2a6abf7158809cf4f3c";
	static constexpr const char *kOtherKeyHex = "000102030405060708090a0b0c0d0e0f";
	static constexpr std::uint64_t kWindow = 256; /* daemon.cpp's kCommandFreshnessWindow */

	void SetUp() override
	{
		char dir_template[] = "/tmp/view-key.XXXXXX";
		ASSERT_NE(mkdtemp(dir_template), nullptr);
		dir_ = dir_template;
		std::array<std::uint8_t, can::kKeyBytes> key{};
		for (std::size_t i = 0; i < key.size(); ++i)
			key[i] = static_cast<std::uint8_t>(
				std::stoi(std::string(kKeyHex + 2 * i, 2), nullptr, 16));
		ASSERT_TRUE(sensor_mac_.setKey(key));
		sensor_.setAuthenticator(&sensor_mac_, std::uint64_t{ 7 } << 32);
		daemon_side_.setAuthenticator(&sensor_mac_);
		daemon_side_.setCommandFreshness(&sensor_, kWindow);
	}
	void TearDown() override { (void)std::system(("rm -rf '" + dir_ + "'").c_str()); }

	std::string keyFile(const std::string &name, const char *hex, mode_t mode)
	{
		const std::string path = dir_ + "/" + name;
		std::ofstream(path) << hex << "\n";
		::chmod(path.c_str(), mode);
		return path;
	}

	/* The sensor's next heartbeat (with DP_Freshness and DP_Auth) or report into *state. */
	void sensorHeartbeat(ViewState *state)
	{
		can::RawFrame out[can::kMaxHeartbeatFrames];
		const int n = sensor_.encodeHeartbeat(can::HeartbeatData{}, out);
		for (int i = 0; i < n; ++i)
			state->feed(out[i], t_us_);
		t_us_ += kPeriodUs;
	}
	void sensorReport(ViewState *state)
	{
		can::PoseData pose = poseAt(0);
		can::RawFrame out[can::kMaxReportFrames];
		const int n = sensor_.encodeReport(statusWith(0), &pose, out);
		for (int i = 0; i < n; ++i)
			state->feed(out[i], t_us_);
		t_us_ += kPeriodUs;
	}

	/* The frames into a sensor's command decoder (by default the one that has seen the
	 * test's every command); its last event. */
	can::Decoder::Event toSensor(const can::RawFrame *frames, int count,
				     can::Decoder *decoder = nullptr)
	{
		can::Decoder &d = decoder ? *decoder : daemon_side_;
		can::Decoder::Event e = can::Decoder::Event::None;
		for (int i = 0; i < count; ++i)
			e = d.feed(frames[i]);
		return e;
	}

	std::string dir_;
	std::int64_t t_us_ = kT0Us;
	can::OpensslCmac sensor_mac_;
	can::Encoder sensor_;
	can::Decoder daemon_side_;
};

TEST_F(SignedCommand, TheSensorTakesTheViewsSignedCommandOnceAndNoneOfAnotherKey)
{
	ViewState view;
	tool::CommandSender sender(can::kDefaultBaseId);
	ASSERT_TRUE(tool::useCanKey(keyFile("can.key", kKeyHex, 0600), &view, &sender).isOk());
	EXPECT_TRUE(sender.signing());
	EXPECT_TRUE(view.stateJson(kT0Us)["verifying"].get<bool>());

	can::CommandData cmd;
	cmd.exposure_us = 1500;
	can::RawFrame first[can::kMaxCommandFrames];
	int count = -1;
	/* No sensor value verified yet: nothing to answer, nothing signed. */
	EXPECT_NE(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), first,
				&count)
			  .find("no authenticated"),
		  std::string::npos);
	EXPECT_EQ(count, 0);

	/* A heartbeat: the view verifies it and answers the sensor's value. */
	sensorHeartbeat(&view);
	ASSERT_EQ(view.sensorFreshness(), sensor_.freshness());
	ASSERT_EQ(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), first,
				&count),
		  "");
	ASSERT_EQ(count, 2);
	EXPECT_EQ(first[0].id, can::kDefaultBaseId + can::kCommand);
	EXPECT_EQ(first[1].id, can::kDefaultBaseId + can::kCommandAuth);
	ASSERT_EQ(toSensor(first, count), can::Decoder::Event::Command)
		<< can::frameErrorName(daemon_side_.lastError());
	EXPECT_EQ(daemon_side_.command().exposure_us, 1500);

	/* The same value again: the sensor would refuse it, so the view does not send it. */
	can::RawFrame again[can::kMaxCommandFrames];
	EXPECT_NE(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), again,
				&count)
			  .find("not moved"),
		  std::string::npos);
	EXPECT_EQ(count, 0);

	/* The next report moves it on: a second command is taken. */
	sensorReport(&view);
	cmd.exposure_us = 1600;
	can::RawFrame second[can::kMaxCommandFrames];
	ASSERT_EQ(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), second,
				&count),
		  "");
	ASSERT_EQ(toSensor(second, count), can::Decoder::Event::Command);
	EXPECT_EQ(daemon_side_.command().exposure_us, 1600);

	/* The first command recorded and replayed: its alive counters pass, its freshness does
	 * not (older than the last command's). */
	EXPECT_EQ(toSensor(first, 2), can::Decoder::Event::Rejected);
	EXPECT_EQ(daemon_side_.lastError(), can::FrameError::Replayed);

	/* A view with another key: the sensor's frames fail their MACs there (named on the page,
	 * nothing shown, no value to answer), and a command it signs, even answering a value the
	 * sensor did send, is refused. (A sensor decoder of its own: another sender's alive
	 * counters start again at 0, which the first decoder would take for repeated frames.) */
	ViewState other_view;
	tool::CommandSender other(can::kDefaultBaseId);
	ASSERT_TRUE(tool::useCanKey(keyFile("other.key", kOtherKeyHex, 0400), &other_view, &other)
			    .isOk());
	sensorHeartbeat(&other_view);
	EXPECT_EQ(other_view.sensorFreshness(), 0u);
	const json shown = other_view.stateJson(t_us_);
	EXPECT_GT(shown["counters"]["auth_failures"].get<std::uint64_t>(), 0u);
	EXPECT_TRUE(hasProblem(shown, can::frameErrorName(can::FrameError::BadMac)))
		<< shown["problems"].dump();
	EXPECT_TRUE(shown["heartbeat"].is_null());
	EXPECT_NE(other.encode(cmd, other_view.sensorFreshness(), other_view.commandAliveOnBus(),
			       again, &count)
			  .find("no authenticated"),
		  std::string::npos);

	sensorReport(&view);
	can::Decoder fresh_sensor_side(can::kDefaultBaseId);
	fresh_sensor_side.setAuthenticator(&sensor_mac_);
	fresh_sensor_side.setCommandFreshness(&sensor_, kWindow);
	can::RawFrame forged[can::kMaxCommandFrames];
	ASSERT_EQ(other.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), forged,
			       &count),
		  "");
	EXPECT_EQ(toSensor(forged, count, &fresh_sensor_side), can::Decoder::Event::Rejected);
	EXPECT_EQ(fresh_sensor_side.lastError(), can::FrameError::BadMac);
	/* The right view's command answering the same value: taken by both. */
	ASSERT_EQ(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), second,
				&count),
		  "");
	EXPECT_EQ(toSensor(second, count), can::Decoder::Event::Command);
	EXPECT_EQ(toSensor(second, count, &fresh_sensor_side), can::Decoder::Event::Command);
}

/* Two command senders on one bus (the arm controller and the view): the sensor keeps one alive
 * counter per identifier and refuses a repeated one, so the view's commands go on from the last
 * DP_Command and DP_CommandAuth it heard on the bus or sent, whoever sent them. */
TEST_F(SignedCommand, TheViewsCommandsContinueTheAliveCountersHeardOnTheBus)
{
	ViewState view;
	tool::CommandSender sender(can::kDefaultBaseId);
	ASSERT_TRUE(tool::useCanKey(keyFile("can.key", kKeyHex, 0600), &view, &sender).isOk());
	sensorHeartbeat(&view);

	/* The controller, with the key (its MAC: the same key's), commands the sensor three
	 * times; the view hears it. */
	can::Encoder controller(can::kDefaultBaseId);
	controller.setAuthenticator(&sensor_mac_);
	can::CommandData cmd;
	can::RawFrame out[can::kMaxCommandFrames];
	for (int i = 0; i < 3; ++i) {
		sensorReport(&view);
		cmd.exposure_us = static_cast<std::uint16_t>(1000 + i);
		ASSERT_EQ(controller.encodeCommand(cmd, view.sensorFreshness(), out), 2);
		ASSERT_EQ(toSensor(out, 2), can::Decoder::Event::Command);
		for (const can::RawFrame &f : out)
			view.feed(f, t_us_);
	}
	EXPECT_EQ(view.commandAliveOnBus().command, 2);
	EXPECT_EQ(view.commandAliveOnBus().command_auth, 2);

	/* The view's command goes on from there: taken, where counters of its own (0) would be
	 * refused as repeated. */
	sensorReport(&view);
	cmd.exposure_us = 1500;
	int count = 0;
	ASSERT_EQ(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), out, &count),
		  "");
	EXPECT_EQ(out[0].data[6] & 0x0f, 3);
	ASSERT_EQ(toSensor(out, count), can::Decoder::Event::Command)
		<< can::frameErrorName(daemon_side_.lastError());
	EXPECT_EQ(daemon_side_.command().exposure_us, 1500);
	for (int i = 0; i < count; ++i)
		view.noteSent(out[i]);
	EXPECT_EQ(view.commandAliveOnBus().command, 3) << "its own frames count too";

	/* A frame with a bad CRC is not what the sensor counts: ignored. */
	can::RawFrame bad = out[0];
	bad.data[6] = static_cast<std::uint8_t>((bad.data[6] & 0xf0) | 9);
	view.feed(bad, t_us_);
	EXPECT_EQ(view.commandAliveOnBus().command, 3);

	/* The controller again, then the view again: both taken. */
	sensorReport(&view);
	controller.continueAliveAfter(can::kCommand, 3);
	controller.continueAliveAfter(can::kCommandAuth, 3);
	ASSERT_EQ(controller.encodeCommand(cmd, view.sensorFreshness(), out), 2);
	ASSERT_EQ(toSensor(out, 2), can::Decoder::Event::Command);
	for (const can::RawFrame &f : out)
		view.feed(f, t_us_);
	sensorReport(&view);
	ASSERT_EQ(sender.encode(cmd, view.sensorFreshness(), view.commandAliveOnBus(), out, &count),
		  "");
	EXPECT_EQ(toSensor(out, count), can::Decoder::Event::Command)
		<< can::frameErrorName(daemon_side_.lastError());
}

TEST_F(SignedCommand, AKeyFileTheSensorWouldRefuseIsRefusedByName)
{
	ViewState view;
	tool::CommandSender sender(can::kDefaultBaseId);
	const std::string open = keyFile("open.key", kKeyHex, 0644);
	const Status s = tool::useCanKey(open, &view, &sender);
	ASSERT_FALSE(s.isOk());
	EXPECT_NE(s.message().find(open), std::string::npos) << s.message();
	EXPECT_NE(s.message().find("lets group or others at it"), std::string::npos) << s.message();
	EXPECT_FALSE(sender.signing());
	EXPECT_FALSE(view.stateJson(kT0Us)["verifying"].get<bool>());
}

} /* namespace */

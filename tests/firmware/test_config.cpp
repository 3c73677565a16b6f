/* SPDX-License-Identifier: MIT */
/*
 * Board configuration files: the committed boards load; a table of bad files
 * each gives exactly the expected errors (JSON path, bad value, what was
 * expected); defaults fill in; relative paths resolve against the file.
 */
#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "algo/correspondence.h"
#include "algo/pipeline.h"
#include "board/board.h"
#include "firmware/config.h"
#include "firmware/config_table.h"
#include "firmware/modes.h"
#include "firmware/protocol/dockpose_can.h"

namespace dockpose::firmware {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using ::testing::HasSubstr;

void writeFile(const fs::path &path, const std::string &text)
{
	std::ofstream out(path, std::ios::binary);
	ASSERT_TRUE(out) << path;
	out << text;
}

std::string readText(const fs::path &path)
{
	std::ifstream in(path, std::ios::binary);
	std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
	return text;
}

std::string joinErrors(const std::vector<std::string> &errors)
{
	std::string out;
	for (const std::string &e : errors)
		out += "\n  " + e;
	return out.empty() ? "\n  (none)" : out;
}

/* A scratch folder with the files a board file refers to. */
class ConfigTest : public ::testing::Test
{
protected:
	void SetUp() override
	{
		char pattern[] = "/tmp/dockpose-config-XXXXXX";
		ASSERT_NE(mkdtemp(pattern), nullptr);
		dir_ = pattern;
		writeFile(
			dir_ / "camera.json",
			R"({ "width": 640, "height": 480, "fx": 560, "fy": 560, "cx": 319.5, "cy": 239.5 })");
		writeFile(dir_ / "target.json",
			  readText(fs::path(DOCKPOSE_TEST_DATA) / "wedge.json"));
		writeFile(dir_ / "square.json",
			  R"({ "points": [[-50, -50, 0], [50, -50, 0], [50, 50, 0],
			[-50, 50, 0]], "faces": [[0, 1, 2, 3]] })");
		fs::create_directory(dir_ / "frames");
		writeFile(dir_ / "frames" / "frame_000000.pgm",
			  std::string("P5\n2 2\n255\n") + "abcd");
		fs::create_directory(dir_ / "empty");
		writeFile(dir_ / "empty" / "notes.txt", "not a frame");
	}
	void TearDown() override
	{
		std::error_code ec;
		fs::remove_all(dir_, ec);
	}

	/* A valid file for the sim board, all values spelled out. */
	static json baseConfig()
	{
		return json::parse(R"({
			"board": "sim",
			"camera": { "backend": "synthetic", "frame_rate_hz": 60, "exposure_us": 2000,
				    "stall_timeout_ms": 500, "intrinsics": "camera.json",
				    "synthetic": { "from": [100, -50, 1500, 3, 10, -2],
						   "to": [30, -10, 250, 0, 2, 0], "duration_s": 5 } },
			"strobe": { "backend": "recording", "mode": "constant" },
			"can": { "backend": "file", "log_file": "can.log", "base_id": "0x300",
				 "bitrate": 500000 },
			"pipeline": { "target": "target.json", "mode": "track" },
			"systemd": { "notify": true }
		})");
	}

	ConfigResult loadText(const std::string &text, const std::string &name = "board.json")
	{
		const fs::path path = dir_ / name;
		writeFile(path, text);
		return loadBoardConfig(path.string());
	}

	fs::path dir_;
};

TEST_F(ConfigTest, BaseConfigIsValid)
{
	const ConfigResult r = loadText(baseConfig().dump(1, '\t'));
	EXPECT_TRUE(r.ok()) << joinErrors(r.errors);
}

TEST(BoardFiles, SimLoads)
{
	const std::string dir = std::string(DOCKPOSE_SOURCE_DIR) + "/board/sim";
	const ConfigResult r = loadBoardConfig(dir + "/board.json");
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	const BoardConfig &c = r.config;
	EXPECT_EQ(c.path, dir + "/board.json");
	EXPECT_EQ(c.board, "sim");
	EXPECT_EQ(c.camera.backend, "synthetic");
	EXPECT_EQ(c.camera.width, 640);
	EXPECT_EQ(c.camera.height, 480);
	EXPECT_DOUBLE_EQ(c.camera.frame_rate_hz, 60.0);
	EXPECT_EQ(fs::path(c.camera.intrinsics), fs::path(dir) / "camera.json");
	EXPECT_EQ(fs::path(c.pipeline.target), fs::path(dir) / "target.json");
	EXPECT_DOUBLE_EQ(c.camera.synthetic.from[2], 1500.0);
	EXPECT_DOUBLE_EQ(c.camera.synthetic.to[2], 250.0);
	EXPECT_GT(c.camera.synthetic.reflections + c.camera.synthetic.glints, 0);
	EXPECT_EQ(c.strobe.backend, "recording");
	EXPECT_EQ(c.strobe.mode, StrobeMode::Constant);
	EXPECT_EQ(c.can.backend, "file");
	EXPECT_EQ(c.can.log_file, "/tmp/dockpose-can.log");
	EXPECT_EQ(c.can.base_id, 0x300u);
	EXPECT_EQ(c.can.bitrate, 500000);
}

TEST(BoardFiles, Rpi5Imx296Loads)
{
	const std::string dir = std::string(DOCKPOSE_SOURCE_DIR) + "/board/rpi5-imx296";
	const ConfigResult r = loadBoardConfig(dir + "/board.json");
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	const BoardConfig &c = r.config;
	EXPECT_EQ(c.board, "rpi5-imx296");
	EXPECT_EQ(c.camera.backend, "libcamera");
	EXPECT_EQ(c.camera.index, 0);
	EXPECT_EQ(c.camera.width, 1456);
	EXPECT_EQ(c.camera.height, 1088);
	EXPECT_EQ(c.camera.exposure_us, 1500);
	EXPECT_EQ(c.strobe.backend, "gpiod");
	EXPECT_EQ(c.strobe.chip, "pinctrl-rp1");
	EXPECT_EQ(c.strobe.line, 17);
	EXPECT_FALSE(c.strobe.active_low);
	EXPECT_EQ(c.strobe.mode, StrobeMode::Alternate);
	EXPECT_EQ(c.can.backend, "socketcan");
	EXPECT_EQ(c.can.interface, "can0");
	EXPECT_EQ(c.can.base_id, 0x300u);
	EXPECT_EQ(c.can.bitrate, 500000);
	EXPECT_EQ(fs::path(c.pipeline.target), fs::path(dir) / "target.json");
}

/*
 * The table: a bad file and the errors it must give, in order, and nothing
 * else. `patch` is a JSON merge patch (RFC 7386: null deletes a key) applied
 * to baseConfig(); `raw` is a whole file instead. Each expected string must be
 * a substring of the corresponding error; "{dir}" stands for the scratch folder
 * the file is written to.
 */
struct BadFile {
	const char *name;
	const char *patch;
	const char *raw;
	std::vector<std::string> expected;
};

const BadFile kBadFiles[] = {
	/* Columns count characters (a tab is one) up to where the parser stopped: the
	 * end of the offending token ("synthetic" ends at column 23). */
	{ "malformed_json",
	  nullptr,
	  "{\n\t\"board\": \"sim\",\n\t\"camera\": {\n\t\t\"backend\" \"synthetic\"\n\t}\n}\n",
	  { "{dir}/board.json: line 4, column 23: syntax error while parsing object separator - "
	    "unexpected string literal; expected ':'" } },
	{ "trailing_comma",
	  nullptr,
	  "{ \"board\": \"sim\", }",
	  { "{dir}/board.json: line 1, column 19: syntax error" } },
	{ "top_level_array",
	  nullptr,
	  "[1, 2]",
	  { "{dir}/board.json: the top level must be an object {...}, got an array" } },
	{ "missing_board", R"({ "board": null })", nullptr, { "board: required key is missing" } },
	{ "empty_board", R"({ "board": "" })", nullptr, { "board: must not be empty" } },
	{ "missing_camera_section",
	  R"({ "camera": null })",
	  nullptr,
	  { "camera: required section is missing" } },
	{ "missing_camera_keys",
	  R"({ "camera": { "backend": null, "intrinsics": null } })",
	  nullptr,
	  { "camera.backend: required key is missing (one of synthetic, replay, libcamera)",
	    "camera.intrinsics: required key is missing" } },
	{ "missing_backends_and_target",
	  R"({ "strobe": { "backend": null }, "can": { "backend": null }, "pipeline": { "target": null } })",
	  nullptr,
	  { "strobe.backend: required key is missing (one of recording, gpiod)",
	    "can.backend: required key is missing (one of file, socketcan)",
	    "pipeline.target: required key is missing" } },
	{ "section_wrong_type",
	  R"({ "strobe": "gpiod" })",
	  nullptr,
	  { "strobe: expected an object, got a string" } },
	{ "rate_is_string",
	  R"({ "camera": { "frame_rate_hz": "60" } })",
	  nullptr,
	  { "camera.frame_rate_hz: expected a number, got a string" } },
	{ "exposure_fraction",
	  R"({ "camera": { "exposure_us": 2.5 } })",
	  nullptr,
	  { "camera.exposure_us: expected an integer, got 2.5" } },
	{ "exposure_zero",
	  R"({ "camera": { "exposure_us": 0 } })",
	  nullptr,
	  { "camera.exposure_us: 0 is out of range [10, 1000000]" } },
	{ "rate_zero",
	  R"({ "camera": { "frame_rate_hz": 0 } })",
	  nullptr,
	  { "camera.frame_rate_hz: 0 is out of range (0, 240]" } },
	{ "rate_too_high",
	  R"({ "camera": { "frame_rate_hz": 240.5 } })",
	  nullptr,
	  { "camera.frame_rate_hz: 240.5 is out of range (0, 240]" } },
	{ "exposure_longer_than_frame",
	  R"({ "camera": { "frame_rate_hz": 100, "exposure_us": 20000 } })",
	  nullptr,
	  { "camera.exposure_us: 20000 us is longer than the frame period of 10000 us at "
	    "camera.frame_rate_hz 100" } },
	{ "stall_within_two_frames",
	  R"({ "camera": { "frame_rate_hz": 10, "stall_timeout_ms": 150 } })",
	  nullptr,
	  { "camera.stall_timeout_ms: 150 ms is not more than 2 frame periods (2 x 100 ms at "
	    "camera.frame_rate_hz 10)" } },
	{ "gain_low",
	  R"({ "camera": { "analogue_gain": 0.5 } })",
	  nullptr,
	  { "camera.analogue_gain: 0.5 is out of range [1, 64]" } },
	{ "buffers_high",
	  R"({ "camera": { "buffer_count": 17 } })",
	  nullptr,
	  { "camera.buffer_count: 17 is out of range [2, 16]" } },
	{ "width_negative",
	  R"({ "camera": { "width": -1 } })",
	  nullptr,
	  { "camera.width: -1 is out of range [0, 16384]" } },
	{ "unknown_top_key",
	  R"({ "camra": { "backend": "synthetic" } })",
	  nullptr,
	  { "unknown key \"camra\" at top level (did you mean \"camera\"?)" } },
	{ "unknown_transposed_key",
	  R"({ "cmaera": {} })",
	  nullptr,
	  { "unknown key \"cmaera\" at top level (did you mean \"camera\"?)" } },
	{ "unknown_nested_key",
	  R"({ "camera": { "exposure": 1000 } })",
	  nullptr,
	  { "unknown key \"exposure\" in camera (did you mean \"exposure_us\"?)" } },
	{ "unknown_key_no_match",
	  R"({ "strobe": { "colour": "red" } })",
	  nullptr,
	  { "unknown key \"colour\" in strobe (known keys: backend, chip, line, active_low, mode, "
	    "pulse_margin_us)" } },
	{ "unknown_synthetic_key",
	  R"({ "camera": { "synthetic": { "seeds": 3 } } })",
	  nullptr,
	  { "unknown key \"seeds\" in camera.synthetic (did you mean \"seed\"?)" } },
	{ "bad_strobe_mode",
	  R"({ "strobe": { "mode": "blink" } })",
	  nullptr,
	  { "strobe.mode: \"blink\" is not one of off, constant, alternate" } },
	{ "bad_camera_backend",
	  R"({ "camera": { "backend": "v4l2" } })",
	  nullptr,
	  { "camera.backend: \"v4l2\" is not one of synthetic, replay, libcamera" } },
	{ "bad_pipeline_mode",
	  R"({ "pipeline": { "mode": "tracking" } })",
	  nullptr,
	  { "pipeline.mode: \"tracking\" is not one of track, search_only" } },
	{ "bad_can_backend",
	  R"({ "can": { "backend": "vcan" } })",
	  nullptr,
	  { "can.backend: \"vcan\" is not one of file, socketcan" } },
	{ "bad_hex_base_id",
	  R"({ "can": { "base_id": "0x3g0" } })",
	  nullptr,
	  { "can.base_id: \"0x3g0\" is not a CAN id (expected a number or a hex string like "
	    "\"0x300\")" } },
	{ "base_id_no_room",
	  R"({ "can": { "base_id": "0x7f8" } })",
	  nullptr,
	  { "can.base_id: 0x7f8 leaves no room for offsets up to 0x11 in 11 bits (max 0x7ee)" } },
	{ "base_id_not_11_bit",
	  R"({ "can": { "base_id": 4096 } })",
	  nullptr,
	  { "can.base_id: 0x1000 is not an 11-bit CAN id (max 0x7ff" } },
	{ "base_id_wrong_type",
	  R"({ "can": { "base_id": true } })",
	  nullptr,
	  { "can.base_id: expected a number or a hex string like \"0x300\", got a boolean" } },
	{ "bitrate_nonstandard",
	  R"({ "can": { "bitrate": 300000 } })",
	  nullptr,
	  { "can.bitrate: 300000 is not a standard CAN bit rate (one of 10000, 20000" } },
	{ "bitrate_too_slow_for_the_reports",
	  R"({ "can": { "bitrate": 50000 } })",
	  nullptr,
	  { "can.bitrate: 50000 bit/s cannot carry a report per camera frame: worst case 116.1 % of "
	    "the bus at camera.frame_rate_hz 60, heartbeat_hz 10 (a faster bus, can.fd, or a lower "
	    "frame rate)" } },
	{ "fd_not_a_boolean",
	  R"({ "can": { "fd": "yes" } })",
	  nullptr,
	  { "can.fd: expected true or false, got a string" } },
	{ "queue_zero",
	  R"({ "can": { "tx_queue_depth": 0 } })",
	  nullptr,
	  { "can.tx_queue_depth: 0 is out of range [1, 4096]" } },
	{ "heartbeat_high",
	  R"({ "can": { "heartbeat_hz": 101 } })",
	  nullptr,
	  { "can.heartbeat_hz: 101 is out of range [1, 100]" } },
	{ "socketcan_without_interface",
	  R"({ "can": { "backend": "socketcan" } })",
	  nullptr,
	  { "can.interface: required when can.backend is \"socketcan\"" } },
	{ "interface_with_slash",
	  R"({ "can": { "backend": "socketcan", "interface": "can/0" } })",
	  nullptr,
	  { "can.interface: \"can/0\" is not an interface name" } },
	{ "interface_too_long",
	  R"({ "can": { "backend": "socketcan", "interface": "can-bus-number-0" } })",
	  nullptr,
	  { "can.interface: \"can-bus-number-0\" is 16 characters long; interface names have at "
	    "most 15 (IFNAMSIZ)" } },
	{ "gpiod_without_chip_and_line",
	  R"({ "strobe": { "backend": "gpiod" } })",
	  nullptr,
	  { "strobe.chip: required when strobe.backend is \"gpiod\"",
	    "strobe.line: required when strobe.backend is \"gpiod\"" } },
	{ "strobe_line_range",
	  R"({ "strobe": { "backend": "gpiod", "chip": "gpiochip0", "line": 1024 } })",
	  nullptr,
	  { "strobe.line: 1024 is out of range [0, 1023]" } },
	{ "pulse_margin_negative",
	  R"({ "strobe": { "pulse_margin_us": -1 } })",
	  nullptr,
	  { "strobe.pulse_margin_us: -1 is out of range [0, 10000]" } },
	{ "active_low_string",
	  R"({ "strobe": { "active_low": "yes" } })",
	  nullptr,
	  { "strobe.active_low: expected true or false, got a string" } },
	{ "missing_target_file",
	  R"({ "pipeline": { "target": "missing.json" } })",
	  nullptr,
	  { "pipeline.target: cannot read target model \"missing.json\": {dir}/missing.json: "
	    "cannot open" } },
	{ "missing_intrinsics_file",
	  R"({ "camera": { "intrinsics": "nope.json" } })",
	  nullptr,
	  { "camera.intrinsics: cannot read camera intrinsics \"nope.json\": {dir}/nope.json: "
	    "cannot open" } },
	{ "intrinsics_not_a_camera",
	  R"({ "camera": { "intrinsics": "target.json" } })",
	  nullptr,
	  { "camera.intrinsics: cannot read camera intrinsics \"target.json\": "
	    "{dir}/target.json: key 'width' is missing" } },
	{ "intrinsics_size_mismatch",
	  R"({ "camera": { "width": 1456, "height": 1088 } })",
	  nullptr,
	  { "camera.intrinsics: \"camera.json\": size 640x480 does not match "
	    "camera.width/height 1456x1088" } },
	{ "replay_without_folder",
	  R"({ "camera": { "backend": "replay" } })",
	  nullptr,
	  { "camera.replay.folder: required when camera.backend is \"replay\"" } },
	{ "replay_missing_folder",
	  R"({ "camera": { "backend": "replay", "replay": { "folder": "no-such-folder" } } })",
	  nullptr,
	  { "camera.replay.folder: \"no-such-folder\" ({dir}/no-such-folder) does not exist" } },
	{ "replay_folder_without_frames",
	  R"({ "camera": { "backend": "replay", "replay": { "folder": "empty" } } })",
	  nullptr,
	  { "camera.replay.folder: \"empty\" ({dir}/empty) holds no frame_*.pgm files" } },
	{ "replay_folder_is_file",
	  R"({ "camera": { "backend": "replay", "replay": { "folder": "camera.json" } } })",
	  nullptr,
	  { "camera.replay.folder: \"camera.json\" ({dir}/camera.json) is not a folder" } },
	{ "min_leds_search_above_target",
	  R"({ "pipeline": { "min_leds_search": 7 } })",
	  nullptr,
	  { "pipeline.min_leds_search: 7 is more than the 6 LEDs of target \"wedge\"" } },
	{ "min_leds_search_below_four",
	  R"({ "pipeline": { "min_leds_search": 3 } })",
	  nullptr,
	  { "pipeline.min_leds_search: 3 is out of range (must be >= 4)" } },
	{ "min_leds_track_below_four",
	  R"({ "pipeline": { "min_leds_track": 3 } })",
	  nullptr,
	  { "pipeline.min_leds_track: 3 is out of range (must be >= 4)" } },
	{ "min_leds_above_small_target",
	  R"({ "pipeline": { "target": "square.json", "min_leds_search": 5 } })",
	  nullptr,
	  { "pipeline.min_leds_search: 5 is more than the 4 LEDs of target "
	    "\"square\"" } },
	{ "min_leds_track_above_search",
	  R"({ "pipeline": { "min_leds_track": 6 } })",
	  nullptr,
	  { "pipeline.min_leds_track: 6 is out of range [4, 4] (at most pipeline.min_leds_search)" } },
	{ "max_rms_zero",
	  R"({ "pipeline": { "max_rms_px": 0 } })",
	  nullptr,
	  { "pipeline.max_rms_px: 0 is out of range (0, 5]" } },
	{ "max_log10_nfa_not_a_bound",
	  R"({ "pipeline": { "max_log10_nfa": 0 } })",
	  nullptr,
	  { "pipeline.max_log10_nfa: 0 is out of range [-40, -2]" } },
	{ "lost_after_zero",
	  R"({ "pipeline": { "lost_after_frames": 0 } })",
	  nullptr,
	  { "pipeline.lost_after_frames: 0 is out of range [1, 1000]" } },
	{ "degraded_hold_high",
	  R"({ "pipeline": { "degraded_hold_frames": 10001 } })",
	  nullptr,
	  { "pipeline.degraded_hold_frames: 10001 is out of range [0, 10000]" } },
	{ "synthetic_behind_camera",
	  R"({ "camera": { "synthetic": { "from": [0, 0, -100, 0, 0, 0] } } })",
	  nullptr,
	  { "camera.synthetic.from[2]: z = -100 mm is not in front of the camera (must be > 0)" } },
	{ "synthetic_short_pose",
	  R"({ "camera": { "synthetic": { "to": [0, 0, 300, 0, 0] } } })",
	  nullptr,
	  { "camera.synthetic.to: expected an array of 6 numbers [x, y, z mm, roll, pan, tilt "
	    "degrees], got an array of 5" } },
	{ "synthetic_pose_element_type",
	  R"({ "camera": { "synthetic": { "to": [0, "0", 300, 0, 0, 0] } } })",
	  nullptr,
	  { "camera.synthetic.to[1]: expected a number, got a string" } },
	{ "synthetic_duration_zero",
	  R"({ "camera": { "synthetic": { "duration_s": 0 } } })",
	  nullptr,
	  { "camera.synthetic.duration_s: 0 is out of range (must be > 0)" } },
	{ "synthetic_clutter_and_noise",
	  R"({ "camera": { "synthetic": { "hot_pixels": 1001, "noise_sigma": 50.5 } } })",
	  nullptr,
	  { "camera.synthetic.hot_pixels: 1001 is out of range [0, 1000]",
	    "camera.synthetic.noise_sigma: 50.5 is out of range [0, 50]" } },
	{ "synthetic_seed_negative",
	  R"({ "camera": { "synthetic": { "seed": -1 } } })",
	  nullptr,
	  { "camera.synthetic.seed: -1 is out of range (must be >= 0)" } },
	{ "systemd_notify_type",
	  R"({ "systemd": { "notify": 1 } })",
	  nullptr,
	  { "systemd.notify: expected true or false, got 1" } },
	{ "duplicate_key",
	  nullptr,
	  R"({ "board": "sim",
	       "camera": { "backend": "synthetic", "intrinsics": "camera.json",
			   "exposure_us": 1000, "exposure_us": 2000 },
	       "strobe": { "backend": "recording" }, "can": { "backend": "file" },
	       "pipeline": { "target": "target.json" } })",
	  { "camera.exposure_us: duplicate key" } },
	{ "many_errors_at_once",
	  R"({ "camera": { "exposure_us": 0 }, "strobe": { "mode": "blink" },
	       "can": { "heartbeat_hz": 0, "base_id": "0x7f8" }, "pipelin": {} })",
	  nullptr,
	  { "camera.exposure_us: 0 is out of range [10, 1000000]",
	    "strobe.mode: \"blink\" is not one of off, constant, alternate",
	    "can.base_id: 0x7f8 leaves no room for offsets up to 0x11 in 11 bits (max 0x7ee)",
	    "can.heartbeat_hz: 0 is out of range [1, 100]",
	    "unknown key \"pipelin\" at top level (did you mean \"pipeline\"?)" } },
};

void PrintTo(const BadFile &row, std::ostream *os)
{
	*os << row.name;
}

class BadFileTest : public ConfigTest, public ::testing::WithParamInterface<BadFile>
{
};

TEST_P(BadFileTest, GivesExactlyTheExpectedErrors)
{
	const BadFile &row = GetParam();
	std::string text;
	if (row.raw) {
		text = row.raw;
	} else {
		json doc = baseConfig();
		doc.merge_patch(json::parse(row.patch));
		text = doc.dump(1, '\t');
	}
	const ConfigResult r = loadText(text);
	EXPECT_FALSE(r.ok());
	for (std::size_t i = 0; i < row.expected.size(); ++i) {
		ASSERT_LT(i, r.errors.size()) << "missing error containing: " << row.expected[i]
					      << "\ngot:" << joinErrors(r.errors);
		std::string want = row.expected[i];
		const std::size_t at = want.find("{dir}");
		if (at != std::string::npos)
			want.replace(at, 5, dir_.string());
		EXPECT_THAT(r.errors[i], HasSubstr(want)) << "got:" << joinErrors(r.errors);
	}
	EXPECT_EQ(r.errors.size(), row.expected.size()) << "got:" << joinErrors(r.errors);
}

INSTANTIATE_TEST_SUITE_P(Table, BadFileTest, ::testing::ValuesIn(kBadFiles),
			 [](const ::testing::TestParamInfo<BadFile> &param) {
				 return std::string(param.param.name);
			 });

TEST_F(ConfigTest, TableHasEnoughRows)
{
	EXPECT_GE(std::size(kBadFiles), 20u);
}

TEST_F(ConfigTest, ParseErrorNamesTheFileAndPosition)
{
	/* The parser stops at "no" (line 3, column 14); the message names the file. */
	const ConfigResult r =
		loadText("{\n  \"board\": \"sim\",\n  \"camera\": nope\n}\n", "x.json");
	ASSERT_EQ(r.errors.size(), 1u) << joinErrors(r.errors);
	EXPECT_THAT(r.errors[0], HasSubstr((dir_ / "x.json").string() + ": line 3, column 14: "));
	EXPECT_THAT(r.errors[0], HasSubstr("invalid literal"));
	EXPECT_EQ(r.errors[0].find("json.exception"), std::string::npos) << r.errors[0];
}

TEST_F(ConfigTest, ANumberBeyondADoubleIsAnErrorNamingItsKey)
{
	/* nlohmann's parser throws out_of_range (not parse_error) for 1e400: it was a crash. */
	const ConfigResult r = loadText(
		"{ \"board\": \"sim\", \"camera\": { \"backend\": \"synthetic\", \"exposure_us\": 1e400 } }",
		"x.json");
	ASSERT_EQ(r.errors.size(), 1u) << joinErrors(r.errors);
	EXPECT_EQ(r.errors[0],
		  (dir_ / "x.json").string() +
			  ": camera.exposure_us: a number beyond the range of a double "
			  "(number overflow parsing '1e400')");
	const ConfigResult top = loadText("{ \"board\": -2e999 }", "y.json");
	ASSERT_EQ(top.errors.size(), 1u) << joinErrors(top.errors);
	EXPECT_THAT(top.errors[0],
		    HasSubstr("y.json: board: a number beyond the range of a double"));
}

TEST_F(ConfigTest, MissingFileIsNamed)
{
	const ConfigResult r = loadBoardConfig((dir_ / "absent.json").string());
	ASSERT_EQ(r.errors.size(), 1u);
	EXPECT_THAT(r.errors[0], HasSubstr((dir_ / "absent.json").string() + ": cannot open"));
	EXPECT_EQ(r.config.path, (dir_ / "absent.json").string());
}

TEST_F(ConfigTest, DefaultsFillIn)
{
	const char *minimal = R"({ "board": "sim",
		"camera": { "backend": "synthetic", "intrinsics": "camera.json" },
		"strobe": { "backend": "recording" }, "can": { "backend": "file" },
		"pipeline": { "target": "target.json" } })";
	const ConfigResult r = loadText(minimal);
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	const BoardConfig d;
	const BoardConfig &c = r.config;
	EXPECT_EQ(c.path, (dir_ / "board.json").string());
	EXPECT_EQ(c.camera.id, d.camera.id);
	EXPECT_EQ(c.camera.index, d.camera.index);
	EXPECT_EQ(c.camera.frame_rate_hz, d.camera.frame_rate_hz);
	EXPECT_EQ(c.camera.exposure_us, d.camera.exposure_us);
	EXPECT_EQ(c.camera.analogue_gain, d.camera.analogue_gain);
	EXPECT_EQ(c.camera.buffer_count, d.camera.buffer_count);
	EXPECT_EQ(c.camera.stall_timeout_ms, d.camera.stall_timeout_ms);
	for (int i = 0; i < 6; ++i) {
		EXPECT_EQ(c.camera.synthetic.from[i], d.camera.synthetic.from[i]);
		EXPECT_EQ(c.camera.synthetic.to[i], d.camera.synthetic.to[i]);
	}
	EXPECT_EQ(c.camera.synthetic.duration_s, d.camera.synthetic.duration_s);
	EXPECT_EQ(c.camera.synthetic.seed, d.camera.synthetic.seed);
	EXPECT_EQ(c.camera.replay.folder, "");
	EXPECT_EQ(c.strobe.line, d.strobe.line);
	EXPECT_EQ(c.strobe.mode, d.strobe.mode);
	EXPECT_EQ(c.strobe.pulse_margin_us, d.strobe.pulse_margin_us);
	EXPECT_EQ(c.can.log_file, "");
	EXPECT_EQ(c.can.base_id, d.can.base_id);
	EXPECT_EQ(c.can.bitrate, d.can.bitrate);
	EXPECT_EQ(c.can.tx_queue_depth, d.can.tx_queue_depth);
	EXPECT_EQ(c.can.heartbeat_hz, d.can.heartbeat_hz);
	EXPECT_EQ(c.pipeline.mode, d.pipeline.mode);
	EXPECT_EQ(c.pipeline.max_rms_px, d.pipeline.max_rms_px);
	EXPECT_EQ(c.pipeline.max_log10_nfa, d.pipeline.max_log10_nfa);
	EXPECT_EQ(c.pipeline.min_leds_search, d.pipeline.min_leds_search);
	EXPECT_EQ(c.pipeline.min_leds_track, d.pipeline.min_leds_track);
	EXPECT_EQ(c.pipeline.full_frame_every, d.pipeline.full_frame_every);
	EXPECT_EQ(c.pipeline.max_rotation_error_deg, d.pipeline.max_rotation_error_deg);
	EXPECT_EQ(c.pipeline.max_translation_error_frac, d.pipeline.max_translation_error_frac);
	EXPECT_EQ(c.pipeline.degraded_hold_frames, d.pipeline.degraded_hold_frames);
	EXPECT_EQ(c.pipeline.lost_after_frames, d.pipeline.lost_after_frames);
	EXPECT_EQ(c.systemd.notify, d.systemd.notify);
	/* width/height 0 take the calibration's size. */
	EXPECT_EQ(c.camera.width, 640);
	EXPECT_EQ(c.camera.height, 480);
}

/* The pipeline section's defaults are the correspondence's own: one default each. */
TEST(PipelineDefaults, EqualTheCorrespondences)
{
	const PipelineSection p;
	const dockpose::CorrespondenceConfig c;
	EXPECT_EQ(p.max_rms_px, c.max_rms_px);
	EXPECT_EQ(p.max_log10_nfa, c.max_log10_nfa);
	EXPECT_EQ(p.min_leds_search, c.min_leds_search);
	EXPECT_EQ(p.min_leds_track, c.min_leds_track);
	EXPECT_EQ(p.full_frame_every, dockpose::PipelineConfig{}.full_frame_every);
	EXPECT_EQ(p.max_rotation_error_deg, dockpose::PipelineConfig{}.max_rotation_error_deg);
	EXPECT_EQ(p.max_translation_error_frac,
		  dockpose::PipelineConfig{}.max_translation_error_frac);
}

TEST_F(ConfigTest, ValuesAreRead)
{
	json doc = baseConfig();
	doc.merge_patch(json::parse(R"({
		"camera": { "id": "/base/imx296@1a", "index": 2, "width": 640, "height": 480,
			    "frame_rate_hz": 30, "exposure_us": 4000, "analogue_gain": 2.5,
			    "buffer_count": 6, "stall_timeout_ms": 800,
			    "synthetic": { "loop": true, "reflections": 4, "glints": 0,
					   "hot_pixels": 7, "noise_sigma": 1.5, "seed": 99 },
			    "replay": { "folder": "frames", "loop": true } },
		"strobe": { "backend": "gpiod", "chip": "gpiochip4", "line": 17, "active_low": true,
			    "mode": "alternate", "pulse_margin_us": 250 },
		"can": { "backend": "socketcan", "interface": "can1", "base_id": 1024,
			 "bitrate": 1000000, "tx_queue_depth": 64, "heartbeat_hz": 5 },
		"pipeline": { "mode": "search_only", "max_rms_px": 1.25, "max_log10_nfa": -6, "min_leds_search": 6,
			      "min_leds_track": 5, "full_frame_every": 7, "degraded_hold_frames": 0,
			      "lost_after_frames": 9 },
		"systemd": { "notify": false } })"));
	const ConfigResult r = loadText(doc.dump());
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	const BoardConfig &c = r.config;
	EXPECT_EQ(c.camera.id, "/base/imx296@1a");
	EXPECT_EQ(c.camera.index, 2);
	EXPECT_EQ(c.camera.frame_rate_hz, 30.0);
	EXPECT_EQ(c.camera.exposure_us, 4000);
	EXPECT_EQ(c.camera.analogue_gain, 2.5);
	EXPECT_EQ(c.camera.buffer_count, 6);
	EXPECT_EQ(c.camera.stall_timeout_ms, 800);
	EXPECT_EQ(c.camera.synthetic.from[0], 100.0);
	EXPECT_EQ(c.camera.synthetic.to[2], 250.0);
	EXPECT_TRUE(c.camera.synthetic.loop);
	EXPECT_EQ(c.camera.synthetic.reflections, 4);
	EXPECT_EQ(c.camera.synthetic.glints, 0);
	EXPECT_EQ(c.camera.synthetic.hot_pixels, 7);
	EXPECT_EQ(c.camera.synthetic.noise_sigma, 1.5);
	EXPECT_EQ(c.camera.synthetic.seed, 99u);
	EXPECT_EQ(c.camera.replay.folder, (dir_ / "frames").string());
	EXPECT_TRUE(c.camera.replay.loop);
	EXPECT_EQ(c.strobe.chip, "gpiochip4");
	EXPECT_EQ(c.strobe.line, 17);
	EXPECT_TRUE(c.strobe.active_low);
	EXPECT_EQ(c.strobe.mode, StrobeMode::Alternate);
	EXPECT_EQ(c.strobe.pulse_margin_us, 250);
	EXPECT_EQ(c.can.interface, "can1");
	EXPECT_EQ(c.can.base_id, 0x400u);
	EXPECT_EQ(c.can.bitrate, 1000000);
	EXPECT_EQ(c.can.tx_queue_depth, 64);
	EXPECT_EQ(c.can.heartbeat_hz, 5);
	EXPECT_EQ(c.pipeline.mode, TrackMode::SearchOnly);
	EXPECT_EQ(c.pipeline.max_rms_px, 1.25);
	EXPECT_EQ(c.pipeline.max_log10_nfa, -6.0);
	EXPECT_EQ(c.pipeline.min_leds_search, 6);
	EXPECT_EQ(c.pipeline.min_leds_track, 5);
	EXPECT_EQ(c.pipeline.full_frame_every, 7);
	EXPECT_EQ(c.pipeline.degraded_hold_frames, 0);
	EXPECT_EQ(c.pipeline.lost_after_frames, 9);
	EXPECT_FALSE(c.systemd.notify);
}

/* The sensor's default bound on a pose's latency is the controller decoder's default age bound. */
TEST(CanSection, PoseLatencyBoundIsTheDecodersDefaultAge)
{
	EXPECT_EQ(board::CanSection{}.max_pose_latency_us, can::Decoder::kDefaultMaxAgeUs);
}

TEST_F(ConfigTest, BaseIdForms)
{
	for (const char *form : { R"("0x2A0")", R"("672")", "672", "672.0" }) {
		json doc = baseConfig();
		doc["can"]["base_id"] = json::parse(form);
		const ConfigResult r = loadText(doc.dump());
		ASSERT_TRUE(r.ok()) << form << joinErrors(r.errors);
		EXPECT_EQ(r.config.can.base_id, 0x2a0u) << form;
	}
	/* The highest base that leaves room for the offsets. */
	json doc = baseConfig();
	doc["can"]["base_id"] = "0x7ee";
	const ConfigResult r = loadText(doc.dump());
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	EXPECT_EQ(r.config.can.base_id, 0x7eeu);
}

TEST_F(ConfigTest, RelativePathsResolveAgainstTheFile)
{
	fs::create_directory(dir_ / "sub");
	json doc = baseConfig();
	doc["camera"]["intrinsics"] = "../camera.json";
	doc["pipeline"]["target"] = "./../target.json";
	doc["can"]["log_file"] = "logs/can.log";
	doc["camera"]["replay"]["folder"] = "../frames";
	const ConfigResult r = loadText(doc.dump(), "sub/board.json");
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	EXPECT_EQ(r.config.camera.intrinsics, (dir_ / "camera.json").string());
	EXPECT_EQ(r.config.pipeline.target, (dir_ / "target.json").string());
	EXPECT_EQ(r.config.can.log_file, (dir_ / "sub" / "logs" / "can.log").string());
	EXPECT_EQ(r.config.camera.replay.folder, (dir_ / "frames").string());
	EXPECT_TRUE(fs::path(r.config.can.log_file).is_absolute());

	/* Absolute paths stay as they are. */
	doc["camera"]["intrinsics"] = (dir_ / "camera.json").string();
	const ConfigResult a = loadText(doc.dump(), "sub/board.json");
	ASSERT_TRUE(a.ok()) << joinErrors(a.errors);
	EXPECT_EQ(a.config.camera.intrinsics, (dir_ / "camera.json").string());
}

TEST_F(ConfigTest, ParseTextUsesBaseDir)
{
	const std::string text = baseConfig().dump();
	const ConfigResult r = parseBoardConfig(text, dir_.string());
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	EXPECT_EQ(r.config.pipeline.target, (dir_ / "target.json").string());
	EXPECT_EQ(r.config.camera.width, 640);

	/* A relative base_dir is taken from the working directory and stored absolute. */
	const fs::path rel = fs::relative(dir_, fs::current_path());
	const ConfigResult rr = parseBoardConfig(text, rel.string());
	ASSERT_TRUE(rr.ok()) << joinErrors(rr.errors);
	EXPECT_EQ(rr.config.pipeline.target, (dir_ / "target.json").string());

	/* The same text against a folder without the files fails on both. */
	fs::create_directory(dir_ / "elsewhere");
	const ConfigResult bad = parseBoardConfig(text, (dir_ / "elsewhere").string());
	ASSERT_EQ(bad.errors.size(), 2u) << joinErrors(bad.errors);
	EXPECT_THAT(bad.errors[0], HasSubstr("camera.intrinsics: cannot read"));
	EXPECT_THAT(bad.errors[1], HasSubstr("pipeline.target: cannot read"));

	const ConfigResult syntax = parseBoardConfig("{", dir_.string());
	ASSERT_EQ(syntax.errors.size(), 1u);
	EXPECT_THAT(syntax.errors[0], HasSubstr("<text>: line 1, column 2: "));
}

TEST_F(ConfigTest, WidthHeightMatchingIntrinsicsIsAccepted)
{
	json doc = baseConfig();
	doc["camera"]["width"] = 640;
	doc["camera"]["height"] = 480;
	const ConfigResult r = loadText(doc.dump());
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	EXPECT_EQ(r.config.camera.width, 640);
	EXPECT_EQ(r.config.camera.height, 480);
}

TEST_F(ConfigTest, CommentsAreAllowed)
{
	const char *text = R"({ "board": "sim", // the host board
		/* calibrated 2024-05 */
		"camera": { "backend": "synthetic", "intrinsics": "camera.json" },
		"strobe": { "backend": "recording", "mode": "off" }, "can": { "backend": "file" },
		"pipeline": { "target": "target.json" } })";
	const ConfigResult r = loadText(text);
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	EXPECT_EQ(r.config.strobe.mode, StrobeMode::Off);
}

TEST_F(ConfigTest, ExposureUpToTheFramePeriodIsAccepted)
{
	json doc = baseConfig();
	doc["camera"]["frame_rate_hz"] = 100;
	doc["camera"]["exposure_us"] = 10000;
	EXPECT_TRUE(loadText(doc.dump()).ok());
	doc["camera"]["exposure_us"] = 10001;
	EXPECT_FALSE(loadText(doc.dump()).ok());
}

/* The bus-load check: 60 reports/s at 50 kbit/s do not fit as classic frames (116 %), but do
 * as one CAN FD frame each (88 %); canBusLoad() is the header's formula. */
TEST_F(ConfigTest, TheBusLoadCheckCountsCanFdReports)
{
	json doc = baseConfig();
	doc["can"]["bitrate"] = 50000;
	EXPECT_FALSE(loadText(doc.dump()).ok());
	doc["can"]["fd"] = true;
	const ConfigResult r = loadText(doc.dump());
	ASSERT_TRUE(r.ok()) << joinErrors(r.errors);
	EXPECT_TRUE(r.config.can.fd);
	EXPECT_NEAR(canBusLoad(r.config), (60 * 712 + 10 * 135) / 50000.0, 1e-12);
	doc["camera"]["frame_rate_hz"] = 70;
	EXPECT_FALSE(loadText(doc.dump()).ok()) << "70 FD reports/s at 50 kbit/s: 102 %";
}

/*
 * docs/configuration.md's key tables are the reader's: each section's table
 * between its markers is exactly what the key tables print
 * (config_table::docTable, `dockposed --print-config-doc SECTION`), so a key,
 * default, range, unit, backend name or line of doc changed on one side only
 * fails here.
 */
std::map<std::string, std::string> generatedBlocks(const std::string &doc)
{
	std::map<std::string, std::string> blocks;
	const std::regex block(
		R"(<!-- generated: dockposed --print-config-doc (\S+) -->\n([^]*?)<!-- end generated -->)");
	for (auto it = std::sregex_iterator(doc.begin(), doc.end(), block);
	     it != std::sregex_iterator(); ++it)
		blocks[(*it)[1].str()] = (*it)[2].str();
	return blocks;
}

TEST(ConfigDoc, TheKeyTablesAreGeneratedFromTheReadersTables)
{
	const auto blocks = generatedBlocks(
		readText(fs::path(DOCKPOSE_SOURCE_DIR) / "docs" / "configuration.md"));
	const std::vector<std::string> sections = config_table::docSections();
	ASSERT_EQ(sections.size(), 9u);
	const char *how = "\ndocs/configuration.md is out of date: build dockposed, run "
			  "scripts/update-config-doc and commit the result";
	for (const std::string &section : sections) {
		SCOPED_TRACE("section \"" + section + "\"");
		const auto it = blocks.find(section);
		ASSERT_NE(it, blocks.end()) << "no <!-- generated: dockposed --print-config-doc "
					    << section << " --> block" << how;
		EXPECT_EQ(it->second, config_table::docTable(section)) << how;
	}
	for (const auto &[section, text] : blocks)
		EXPECT_NE(std::find(sections.begin(), sections.end(), section), sections.end())
			<< "docs/configuration.md has a block for \"" << section
			<< "\", which is no section" << how;
}

/* The reader knows (its "unknown key" message lists them) exactly the keys its table prints. */
TEST_F(ConfigTest, TheReadersKeysAreTheTablesKeys)
{
	for (const std::string &section : config_table::docSections()) {
		SCOPED_TRACE("section \"" + section + "\"");
		std::vector<std::string> table_keys;
		std::istringstream rows(config_table::docTable(section));
		for (std::string row; std::getline(rows, row);)
			if (row.rfind("| `", 0) == 0)
				table_keys.push_back(row.substr(3, row.find('`', 3) - 3));

		json doc = baseConfig();
		json *at = &doc;
		std::istringstream path(section == "top" ? "" : section);
		for (std::string part; std::getline(path, part, '.');)
			at = &(*at)[part];
		(*at)["zzzz_not_a_key"] = 1;
		const ConfigResult r = loadText(doc.dump());
		ASSERT_EQ(r.errors.size(), 1u) << joinErrors(r.errors);
		const std::string &e = r.errors[0];
		const std::size_t from = e.find("known keys: ");
		ASSERT_NE(from, std::string::npos) << e;
		std::vector<std::string> reader_keys;
		std::istringstream list(e.substr(from + 12, e.rfind(')') - from - 12));
		for (std::string k; std::getline(list, k, ',');)
			reader_keys.push_back(k.substr(k.find_first_not_of(' ')));
		EXPECT_EQ(reader_keys, table_keys);
	}
}

/* Every board mode is the protocol's mode of the same meaning (firmware/modes.h). */
TEST(Modes, TheBoardsAreTheProtocols)
{
	const auto upper = [](std::string s) {
		for (char &c : s)
			c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
		return s;
	};
	for (std::size_t i = 0; i < board::kStrobeModeNames.size(); ++i) {
		const auto mode = static_cast<StrobeMode>(i);
		EXPECT_EQ(upper(strobeModeName(mode)), can::strobeModeName(toCan(mode)));
		EXPECT_EQ(fromCan(toCan(mode)), mode);
	}
	EXPECT_EQ(fromCan(can::StrobeMode::Unchanged), std::nullopt);
	for (std::size_t i = 0; i < board::kTrackModeNames.size(); ++i) {
		const auto mode = static_cast<TrackMode>(i);
		EXPECT_EQ(upper(board::kTrackModeNames[i]), can::trackModeName(toCan(mode)));
		EXPECT_EQ(fromCan(toCan(mode)), mode);
	}
}

TEST(StrobeModeName, Names)
{
	EXPECT_STREQ(strobeModeName(StrobeMode::Off), "off");
	EXPECT_STREQ(strobeModeName(StrobeMode::Constant), "constant");
	EXPECT_STREQ(strobeModeName(StrobeMode::Alternate), "alternate");
}

} /* namespace */
} /* namespace dockpose::firmware */

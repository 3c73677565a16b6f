/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the board file reader (parseBoardConfig, firmware/config.h) on
 * arbitrary text, relative paths resolved in board/sim/ (so "camera.json" and
 * "target.json" name real files).
 *
 * Oracle:
 *  - it never throws and reads the same text the same way twice (the same
 *    errors in the same order; no state kept between calls);
 *  - every error is a non-empty line;
 *  - a file it accepts holds what dockposed relies on without checking again:
 *    a board name, a CAN base id whose identifiers stay 11-bit, an exposure
 *    inside the frame period, LED minimums the target can meet, and target
 *    and camera models that pass checkTarget and checkCamera
 *    (tests/fuzz/model_check.h).
 */
#include <cstddef>
#include <cstdint>
#include <string>

#include "firmware/config.h"
#include "firmware/protocol/dockpose_can.h"
#include "tests/fuzz/model_check.h"

using namespace dockpose;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	const std::string text(reinterpret_cast<const char *>(data), size);
	const std::string base_dir = DOCKPOSE_SOURCE_DIR "/board/sim";
	const firmware::ConfigResult first = firmware::parseBoardConfig(text, base_dir);
	const firmware::ConfigResult second = firmware::parseBoardConfig(text, base_dir);
	FUZZ_CHECK(first.errors == second.errors, "the same text reads the same way twice");
	for (const std::string &e : first.errors)
		FUZZ_CHECK(!e.empty() && e.find('\n') == std::string::npos,
			   "every error is one non-empty line");
	if (!first.ok())
		return 0;

	const firmware::BoardConfig &c = first.config;
	FUZZ_CHECK(!c.board.empty(), "an accepted file names its board");
	FUZZ_CHECK(can::validBaseId(c.can.base_id), "the CAN identifiers stay 11-bit");
	FUZZ_CHECK(c.camera.frame_rate_hz >= 0 && c.camera.exposure_us > 0 &&
			   (c.camera.frame_rate_hz == 0 ||
			    c.camera.exposure_us <= 1e6 / c.camera.frame_rate_hz),
		   "the exposure fits the frame period (a free rate: 0)");
	FUZZ_CHECK(c.pipeline.min_leds_search >= 4 &&
			   static_cast<std::size_t>(c.pipeline.min_leds_search) <=
				   c.target_model.points_mm.size() &&
			   c.pipeline.min_leds_track >= 4 &&
			   c.pipeline.min_leds_track <= c.pipeline.min_leds_search,
		   "the LED minimums are at least 4 and within the target");
	fuzz::checkTarget(c.target_model);
	fuzz::checkCamera(c.camera_model);
	return 0;
}

/* SPDX-License-Identifier: MIT */
/*
 * One line of a candump log (candump -l / -L, and what hal's FileCanBus
 * writes):
 *
 *   (1700000000.123456) can0 305#0011223344556677     classic frame
 *   (1700000000.123456) can0 30A##0<128 hex digits>   CAN FD frame (flags nibble)
 *
 * parseCandumpLine() splits it into its time (microseconds since the epoch),
 * and a classic or FD frame. A line that ends where more was due (the writer
 * was cut off, or the reader caught a line half written) is Truncated; a
 * character that has no place there is Malformed. Remote frames ("ID#R") and
 * extended (8-digit) identifiers are Ignored: never ours. candumpFrameText()
 * writes a classic frame the way such a line does ("305#0011223344556677").
 *
 * Allocates: parseCandumpLine() never (the error text is a static string);
 * candumpFrameText() its string. Any thread.
 */
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "firmware/protocol/dockpose_can.h"

namespace dockpose::tool {

enum class CandumpParse : std::uint8_t {
	Classic,
	Fd,
	Ignored, /* a remote or extended frame, or an empty line */
	Truncated,
	Malformed,
};

struct CandumpLine {
	std::int64_t time_us = 0; /* the log's timestamp, microseconds */
	can::RawFrame frame; /* Classic */
	can::FdFrame fd; /* Fd */
	const char *error = ""; /* Truncated / Malformed: what was wrong, a static string */
};

CandumpParse parseCandumpLine(std::string_view line, CandumpLine *out);

/* "305#0011223344556677": the frame as a candump line has it (3 hex digits of identifier, '#',
 * two hex digits a data byte, at most 8). */
std::string candumpFrameText(const can::RawFrame &frame);

/* "malformed log line", "truncated log line", ... (the names the page shows). */
const char *candumpParseName(CandumpParse result);

} /* namespace dockpose::tool */

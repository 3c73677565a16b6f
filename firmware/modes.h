/* SPDX-License-Identifier: MIT */
/*
 * The strobe and track modes between the board file and the CAN protocol.
 *
 * Both enumerations exist twice: in the board layer (board/board_config.h,
 * what a board file chooses) and in the protocol header
 * (firmware/protocol/dockpose_can.h, what goes on the wire). They cannot be
 * one type: the protocol header includes no project header (the arm
 * controller builds it alone), and the board layer may not include the
 * firmware above it (scripts/check-style layers). So the board's enumerators
 * carry the protocol's values, this header is the one place that sees both,
 * and it proves them equal at compile time; converting is then a cast, and
 * no switch can fall out of step. The protocol's one extra value
 * (StrobeMode::Unchanged, "keep the current mode" in a command) is the only
 * value without a board counterpart.
 *
 * Allocates: nothing. Threads: any.
 */
#pragma once

#include <optional>
#include <type_traits>

#include "board/board_config.h"
#include "firmware/protocol/dockpose_can.h"

namespace dockpose::firmware {

namespace modes_detail {

template<typename E>
constexpr auto value(E e)
{
	return static_cast<std::underlying_type_t<E>>(e);
}

} /* namespace modes_detail */

static_assert(std::is_same_v<std::underlying_type_t<board::StrobeMode>,
			     std::underlying_type_t<can::StrobeMode>>);
static_assert(modes_detail::value(board::StrobeMode::Off) ==
	      modes_detail::value(can::StrobeMode::Off));
static_assert(modes_detail::value(board::StrobeMode::Constant) ==
	      modes_detail::value(can::StrobeMode::Constant));
static_assert(modes_detail::value(board::StrobeMode::Alternate) ==
	      modes_detail::value(can::StrobeMode::Alternate));
/* Every board value has a name, and the protocol's next value is Unchanged: none is left out. */
static_assert(board::kStrobeModeNames.size() == modes_detail::value(can::StrobeMode::Unchanged));

static_assert(std::is_same_v<std::underlying_type_t<board::TrackMode>,
			     std::underlying_type_t<can::TrackMode>>);
static_assert(modes_detail::value(board::TrackMode::Track) ==
	      modes_detail::value(can::TrackMode::Track));
static_assert(modes_detail::value(board::TrackMode::SearchOnly) ==
	      modes_detail::value(can::TrackMode::SearchOnly));
/* The protocol's TrackMode is one bit wide (DP_Command Mode, DP_Heartbeat Mode). */
static_assert(board::kTrackModeNames.size() == 2);

constexpr can::StrobeMode toCan(board::StrobeMode mode)
{
	return static_cast<can::StrobeMode>(mode);
}

constexpr can::TrackMode toCan(board::TrackMode mode)
{
	return static_cast<can::TrackMode>(mode);
}

/* A commanded strobe mode; nullopt for Unchanged (or a value no board mode has). */
constexpr std::optional<board::StrobeMode> fromCan(can::StrobeMode mode)
{
	if (modes_detail::value(mode) >= board::kStrobeModeNames.size())
		return std::nullopt;
	return static_cast<board::StrobeMode>(mode);
}

/* A decoded TrackMode is one bit; anything but SearchOnly tracks. */
constexpr board::TrackMode fromCan(can::TrackMode mode)
{
	return mode == can::TrackMode::SearchOnly ? board::TrackMode::SearchOnly
						  : board::TrackMode::Track;
}

} /* namespace dockpose::firmware */

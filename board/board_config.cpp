/* SPDX-License-Identifier: MIT */
#include "board/board_config.h"

namespace dockpose::board {

const char *strobeModeName(StrobeMode mode)
{
	const auto index = static_cast<std::size_t>(mode);
	return index < kStrobeModeNames.size() ? kStrobeModeNames[index] : "unknown";
}

} /* namespace dockpose::board */

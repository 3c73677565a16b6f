/* SPDX-License-Identifier: MIT */
#include "board/board_config.h"

namespace dockpose::board {

const char *strobeModeName(StrobeMode mode)
{
	switch (mode) {
	case StrobeMode::Off:
		return "off";
	case StrobeMode::Constant:
		return "constant";
	case StrobeMode::Alternate:
		return "alternate";
	}
	return "unknown";
}

} /* namespace dockpose::board */

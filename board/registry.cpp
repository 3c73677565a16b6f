/* SPDX-License-Identifier: MIT */
/* The boards built into this binary (DOCKPOSE_BOARDS in board/CMakeLists.txt). */
#include <array>
#include <cstring>

#include "board/board.h"

namespace dockpose::board {

/* Each board's wiring.cpp defines its BoardInfo. */
#if DOCKPOSE_BOARD_SIM
extern const BoardInfo kSimBoard;
#endif
#if DOCKPOSE_BOARD_RPI5_IMX296
extern const BoardInfo kRpi5Imx296Board;
#endif
#if DOCKPOSE_BOARD_VM
extern const BoardInfo kVmBoard;
#endif

namespace {

const BoardInfo *const kBoards[] = {
#if DOCKPOSE_BOARD_SIM
	&kSimBoard,
#endif
#if DOCKPOSE_BOARD_RPI5_IMX296
	&kRpi5Imx296Board,
#endif
#if DOCKPOSE_BOARD_VM
	&kVmBoard,
#endif
};

std::array<BoardInfo, std::size(kBoards)> makeTable()
{
	std::array<BoardInfo, std::size(kBoards)> table{};
	for (std::size_t i = 0; i < std::size(kBoards); ++i)
		table[i] = *kBoards[i];
	return table;
}

} /* namespace */

std::span<const BoardInfo> boards()
{
	static const auto table = makeTable();
	return table;
}

const BoardInfo *findBoard(const std::string &name)
{
	for (const BoardInfo &b : boards())
		if (name == b.name)
			return &b;
	return nullptr;
}

std::vector<const char *> backendNames(BackendKind kind)
{
	std::vector<const char *> names;
	for (const BoardInfo &b : boards()) {
		const std::span<const char *const> list = kind == BackendKind::Camera	? b.cameras
							  : kind == BackendKind::Strobe ? b.strobes
											: b.cans;
		for (const char *name : list) {
			bool seen = false;
			for (const char *n : names)
				seen = seen || std::strcmp(n, name) == 0;
			if (!seen)
				names.push_back(name);
		}
	}
	return names;
}

} /* namespace dockpose::board */

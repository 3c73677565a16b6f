/* SPDX-License-Identifier: MIT */
/*
 * Helpers shared by the simulated CAN buses (FileCanBus, LoopbackCanBus).
 *
 * Filters work like the kernel's CAN_RAW filters with CAN_EFF_FLAG in the
 * mask: a frame passes a filter when its id format (standard/extended) is
 * the filter's and (frame.id & mask) == (filter.id & mask); it is received
 * when it passes any filter (no filters: nothing is received).
 *
 * Allocates: never.
 */
#pragma once

#include <span>

#include "hal/can_bus.h"

namespace dockpose::hal {

bool canFilterPasses(std::span<const CanFilter> filters, const CanFrame &frame);

/* Why a frame cannot be sent (nullptr: it can): id out of range, bad length, FD not enabled. */
const char *canFrameProblem(const CanFrame &frame, bool fd_enabled);

} /* namespace dockpose::hal */

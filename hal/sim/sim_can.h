/* SPDX-License-Identifier: MIT */
/*
 * Helpers shared by the simulated CAN buses (FileCanBus, LoopbackCanBus); the
 * frame validator they share with SocketCAN is hal::canFrameProblem (can_bus.h).
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

} /* namespace dockpose::hal */

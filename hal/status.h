/* SPDX-License-Identifier: MIT */
/*
 * hal's fallible calls return the project's one Status (algo/status.h); hal
 * code names it hal::Status as it always has.
 */
#pragma once

#include "algo/status.h"

namespace dockpose::hal {

using dockpose::Status;

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * What the sensor needs to authenticate its CAN traffic (docs/can-protocol.md,
 * "Authentication"): the shared key, read from a file only its owner can
 * read, and a run counter kept in a state file, so that the freshness values
 * of a run never repeat one of an earlier run's (a recorded session cannot be
 * replayed after a restart).
 *
 * Allocates: both functions (messages, file reads); they run at start-up.
 * Threads: the caller's.
 */
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "firmware/protocol/dockpose_can_cmac.h"
#include "hal/status.h"

namespace dockpose::firmware {

/*
 * The 16-byte AES key in `path`: 32 hexadecimal digits (surrounding white
 * space ignored). Refused, with a message naming the file and the problem:
 * not a regular file, larger than 1 KiB, readable or writable by group or
 * others, owned by another user than root or this process's, or not exactly
 * 32 hex digits.
 */
hal::Status loadCanKey(const std::string &path, std::array<std::uint8_t, can::kKeyBytes> *key);

/*
 * The next run number from the state file `path` (a decimal number; a
 * missing file counts as 0), written back before it is returned (a temporary
 * file, fsync, rename): run N's freshness values start at N << 32. Refused:
 * an unreadable or malformed file, one that cannot be written, or the last
 * run number (2^32 - 1) used up.
 */
hal::Status nextRunNumber(const std::string &path, std::uint32_t *run);

} /* namespace dockpose::firmware */

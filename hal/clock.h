/* SPDX-License-Identifier: MIT */
/*
 * One clock for every timestamp in the firmware: CLOCK_MONOTONIC in
 * nanoseconds, the clock of V4L2/libcamera sensor timestamps, so latency from
 * the sensor to the CAN send is a plain difference. Allocates: never.
 */
#pragma once

#include <cstdint>
#include <ctime>

namespace dockpose::hal {

inline std::int64_t monotonicNs()
{
	timespec ts{};
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

} /* namespace dockpose::hal */

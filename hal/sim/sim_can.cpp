/* SPDX-License-Identifier: MIT */
/*
 * Helpers shared by the simulated CAN buses (see sim_can.h).
 */
#include "hal/sim/sim_can.h"

namespace dockpose::hal {

bool canFilterPasses(std::span<const CanFilter> filters, const CanFrame &frame)
{
	for (const CanFilter &f : filters)
		if (f.extended == frame.extended && (frame.id & f.mask) == (f.id & f.mask))
			return true;
	return false;
}

const char *canFrameProblem(const CanFrame &frame, bool fd_enabled)
{
	if (frame.id > (frame.extended ? 0x1fffffffu : 0x7ffu))
		return frame.extended ? "extended CAN id above 0x1FFFFFFF"
				      : "standard CAN id above 0x7FF";
	if (frame.fd) {
		if (!fd_enabled)
			return "CAN FD frame on a bus opened without FD";
		/* CAN FD data lengths: 0..8, 12, 16, 20, 24, 32, 48, 64. */
		const unsigned len = frame.len;
		if (len > 64 || (len > 8 && len != 12 && len != 16 && len != 20 && len != 24 &&
				 len != 32 && len != 48 && len != 64))
			return "invalid CAN FD data length";
	} else if (frame.len > 8) {
		return "classic CAN frame longer than 8 bytes";
	}
	return nullptr;
}

} /* namespace dockpose::hal */

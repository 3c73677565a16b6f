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

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * Printable names of the hal enums (logs, status reports, tests).
 * Allocates: never (static strings).
 */
#include "hal/can_bus.h"
#include "hal/strobe.h"

namespace dockpose::hal {

const char *lightingName(Lighting lighting)
{
	switch (lighting) {
	case Lighting::Unlit:
		return "unlit";
	case Lighting::Lit:
		return "lit";
	case Lighting::Mixed:
		return "mixed";
	}
	return "invalid";
}

const char *canStateName(CanState state)
{
	switch (state) {
	case CanState::Closed:
		return "closed";
	case CanState::ErrorActive:
		return "error-active";
	case CanState::ErrorWarning:
		return "error-warning";
	case CanState::ErrorPassive:
		return "error-passive";
	case CanState::BusOff:
		return "bus-off";
	case CanState::Down:
		return "down";
	}
	return "invalid";
}

} /* namespace dockpose::hal */

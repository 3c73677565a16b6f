/* SPDX-License-Identifier: MIT */
/* The one CAN frame validator (see can_bus.h). */
#include "hal/can_bus.h"

#include <algorithm>

namespace dockpose::hal {

const char *canFrameProblem(const CanFrame &frame, bool fd_enabled)
{
	if (frame.id > (frame.extended ? 0x1fffffffu : 0x7ffu))
		return frame.extended ? "the id is wider than 29 bits"
				      : "the id is wider than 11 bits (not marked extended)";
	if (frame.fd) {
		if (!fd_enabled)
			return "a CAN FD frame, and the bus was opened without fd";
		if (frame.len > 64)
			return "a CAN FD frame longer than 64 bytes";
	} else if (frame.len > 8) {
		return "a classic CAN frame longer than 8 bytes";
	}
	return nullptr;
}

std::uint8_t canFdLength(std::uint8_t len)
{
	static constexpr std::uint8_t kLengths[] = { 12, 16, 20, 24, 32, 48, 64 };
	if (len <= 8)
		return len;
	for (const std::uint8_t l : kLengths)
		if (len <= l)
			return l;
	return 64;
}

CanFrame canWireFrame(const CanFrame &frame)
{
	CanFrame out = frame;
	if (!frame.fd)
		return out;
	out.len = canFdLength(std::min<std::uint8_t>(frame.len, 64));
	std::fill(out.data.begin() + frame.len, out.data.begin() + out.len, 0);
	return out;
}

} /* namespace dockpose::hal */

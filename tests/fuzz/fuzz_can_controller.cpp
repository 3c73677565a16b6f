/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the controller's decoder (can::Decoder of
 * firmware/protocol/dockpose_can.h) fed sequences of frames, hostile ones
 * included. The input layout and the oracle are runController's
 * (tests/fuzz/can_fuzz.h); the keyed (MAC) variant of the protocol will be a
 * harness file like this one with its own Protocol trait.
 */
#include <cstddef>
#include <cstdint>

#include "tests/fuzz/can_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	dockpose::fuzz::FuzzInput in(data, size);
	dockpose::fuzz::runController<dockpose::fuzz::CrcProtocol>(in);
	return 0;
}

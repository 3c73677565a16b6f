/* SPDX-License-Identifier: MIT */
/*
 * What the AlternateStrobe tests share (test_alternate_strobe.cpp and its
 * no-allocation test): the configuration of a small test frame.
 */
#pragma once

#include <cstdint>

#include "firmware/alternate_strobe.h"

namespace dockpose::test {

/* A width x height camera at period_ns; intervals beyond max_interval_ns are stalls. */
inline firmware::AlternateStrobeConfig alternateStrobeConfig(int width, int height,
							     std::int64_t period_ns,
							     std::int64_t max_interval_ns,
							     std::int64_t pulse_margin_ns)
{
	firmware::AlternateStrobeConfig config;
	config.width = width;
	config.height = height;
	config.period_ns = period_ns;
	config.max_interval_ns = max_interval_ns;
	config.pulse_margin_ns = pulse_margin_ns;
	return config;
}

} /* namespace dockpose::test */

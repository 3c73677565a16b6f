/* SPDX-License-Identifier: MIT */
/*
 * FaultHold: a timed fault bit. An event (a dropped frame, a rejected
 * command, a loop overrun) raises it; it stays raised for hold_ns after the
 * last event, so a one-frame event is seen in at least one status frame and
 * one heartbeat (docs/can-protocol.md, Faults). For events that backends
 * only count, raiseOnChange() raises it whenever the count has moved since
 * the last call.
 *
 * Times are CLOCK_MONOTONIC nanoseconds (hal::monotonicNs()).
 * Allocates: never. Threads: one (the frame thread).
 */
#pragma once

#include <cstdint>

namespace dockpose::firmware {

class FaultHold
{
public:
	explicit constexpr FaultHold(std::int64_t hold_ns)
		: hold_ns_(hold_ns)
	{
	}

	/* An event now: raised until now_ns + hold_ns. */
	void raise(std::int64_t now_ns) { until_ns_ = now_ns + hold_ns_; }
	/* An event when `count` differs from the count of the last call (starts at 0). */
	void raiseOnChange(std::uint64_t count, std::int64_t now_ns)
	{
		if (count != seen_) {
			seen_ = count;
			raise(now_ns);
		}
	}
	bool active(std::int64_t now_ns) const { return now_ns < until_ns_; }

private:
	std::int64_t hold_ns_;
	std::int64_t until_ns_ = 0;
	std::uint64_t seen_ = 0;
};

} /* namespace dockpose::firmware */

/* SPDX-License-Identifier: MIT */
/*
 * LatencyHistogram: sensor-timestamp-to-CAN-send latency statistics in fixed
 * 50 us bins up to 200 ms (one overflow bin). Allocates: never.
 */
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>

namespace dockpose::firmware {

class LatencyHistogram
{
public:
	static constexpr std::int64_t kBinNs = 50000;
	static constexpr int kBins = 4000;

	void add(std::int64_t latency_ns)
	{
		if (latency_ns < 0)
			latency_ns = 0;
		const std::int64_t bin = std::min<std::int64_t>(latency_ns / kBinNs, kBins);
		++bins_[static_cast<std::size_t>(bin)];
		++count_;
		sum_ns_ += latency_ns;
		max_ns_ = std::max(max_ns_, latency_ns);
	}

	std::uint64_t count() const { return count_; }
	double meanMs() const
	{
		return count_ ? static_cast<double>(sum_ns_) / static_cast<double>(count_) * 1e-6
			      : 0.0;
	}
	double maxMs() const { return static_cast<double>(max_ns_) * 1e-6; }
	/* The upper edge of the bin holding quantile p (0..1). */
	double quantileMs(double p) const
	{
		if (!count_)
			return 0.0;
		const auto rank = static_cast<std::uint64_t>(p * static_cast<double>(count_ - 1));
		std::uint64_t seen = 0;
		for (std::size_t i = 0; i < bins_.size(); ++i) {
			seen += bins_[i];
			if (seen > rank)
				return static_cast<double>((static_cast<std::int64_t>(i) + 1) *
							   kBinNs) *
				       1e-6;
		}
		return maxMs();
	}

private:
	std::array<std::uint32_t, kBins + 1> bins_{};
	std::uint64_t count_ = 0;
	std::int64_t sum_ns_ = 0;
	std::int64_t max_ns_ = 0;
};

} /* namespace dockpose::firmware */

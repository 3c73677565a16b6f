/* SPDX-License-Identifier: MIT */
#include "firmware/alternate_strobe.h"

#include <cstddef>
#include <cstring>

#include "algo/ambient.h"

namespace dockpose::firmware {

AlternateStrobe::AlternateStrobe(const AlternateStrobeConfig &config)
	: max_interval_ns_(config.max_interval_ns),
	  pulse_margin_ns_(config.pulse_margin_ns),
	  measured_period_ns_(config.period_ns),
	  ambient_(config.width, config.height),
	  difference_(config.width, config.height)
{
}

void AlternateStrobe::measurePeriod(const hal::Frame &frame)
{
	if (frame.timestamp_ns <= 0)
		return;
	if (have_period_sample_ && frame.sequence > period_sequence_ &&
	    frame.timestamp_ns > period_timestamp_ns_) {
		const std::int64_t interval_ns =
			(frame.timestamp_ns - period_timestamp_ns_) /
			static_cast<std::int64_t>(frame.sequence - period_sequence_);
		/* Intervals across a stall say nothing about the frame grid. */
		if (interval_ns < max_interval_ns_) {
			if (!have_period_measured_)
				measured_period_ns_ = interval_ns;
			else
				measured_period_ns_ += (interval_ns - measured_period_ns_) / 8;
			have_period_measured_ = true;
		}
	}
	have_period_sample_ = true;
	period_sequence_ = frame.sequence;
	period_timestamp_ns_ = frame.timestamp_ns;
}

int AlternateStrobe::schedulePulses(const hal::Frame &frame, std::int64_t now_ns,
				    hal::StrobeController &control)
{
	if (frame.timestamp_ns <= 0)
		return 0;
	/* Light every even frame: aim a pulse at the predicted exposure of the next even frames
	 * that are not yet scheduled. The exposure grid comes from the sensor's own timestamps: this
	 * frame's start of exposure and the period measured between frames. */
	const std::int64_t exposure_ns = static_cast<std::int64_t>(frame.exposure_us) * 1000;
	const std::int64_t lead_ns = now_ns + kPulseLeadNs;
	int scheduled = 0;
	int added = 0;
	for (std::uint64_t k = 1; k <= kLookAheadFrames && scheduled < kFramesToSchedule; ++k) {
		const std::uint64_t target = frame.sequence + k;
		if (target % 2 != 0)
			continue;
		const std::int64_t start_ns = frame.timestamp_ns +
					      static_cast<std::int64_t>(k) * measured_period_ns_ -
					      pulse_margin_ns_;
		if (start_ns < lead_ns)
			continue;
		if (last_scheduled_sequence_ && target <= last_scheduled_sequence_) {
			++scheduled;
			continue;
		}
		if (!control.schedulePulse(start_ns, exposure_ns + 2 * pulse_margin_ns_))
			break;
		last_scheduled_sequence_ = target;
		++scheduled;
		++added;
	}
	return added;
}

ImageView AlternateStrobe::difference(const hal::Frame &frame, hal::Lighting lighting)
{
	if (lighting == hal::Lighting::Unlit) {
		for (int y = 0; y < frame.image.height; ++y)
			std::memcpy(
				ambient_.data() + static_cast<std::ptrdiff_t>(y) * ambient_.width(),
				frame.image.row(y), static_cast<std::size_t>(frame.image.width));
		ambient_sequence_ = frame.sequence;
		have_ambient_ = true;
		return ImageView{};
	}
	if (lighting == hal::Lighting::Lit && have_ambient_ &&
	    frame.sequence - ambient_sequence_ <= kMaxAmbientAge) {
		subtractAmbient(frame.image, ambient_.view(), difference_.data(),
				difference_.width());
		return difference_.view();
	}
	return ImageView{};
}

void AlternateStrobe::restart()
{
	have_ambient_ = false;
	last_scheduled_sequence_ = 0;
}

} /* namespace dockpose::firmware */

/* SPDX-License-Identifier: MIT */
/*
 * AlternateStrobe: the strobe mode "alternate" of the frame loop. The LEDs
 * light every even frame and stay dark for the odd ones; a lit frame minus
 * the unlit frame before it leaves the LEDs alone (algo/ambient.h: what does
 * not blink with them cancels).
 *
 *  - The period estimate: the sensor's real frame period, from the
 *    timestamps of consecutive frames (the first interval, then smoothed by
 *    1/8 of each new one). It starts at the configured period, which a
 *    camera that ignores its frame rate does not keep; intervals across a
 *    stall are not samples.
 *  - The pulse scheduling: from each frame's start of exposure and the
 *    estimated period, a pulse (the exposure grown by the margin on both
 *    sides) is aimed at each of the next two even frames whose exposure has
 *    not begun, on the hal::StrobeController that drives the hal::Strobe.
 *  - The ambient frame and the difference: an unlit frame is copied and
 *    kept; a lit frame at most two frames after it gives lit − unlit. Mixed
 *    frames, and lit frames without an ambient frame that recent, give
 *    nothing.
 *
 * The Daemon decides which frames were lit (the controller's history against
 * the exposure window) and what the mode is; this class only does the
 * alternate mode's part.
 *
 * Times are CLOCK_MONOTONIC nanoseconds (hal::monotonicNs()), sizes pixels.
 * Allocates: the constructor (the ambient and the difference frames, of the
 * configured size); every other call never. Threads: one (the frame thread).
 */
#pragma once

#include <cstdint>

#include "algo/image.h"
#include "hal/camera.h"
#include "hal/strobe.h"

namespace dockpose::firmware {

struct AlternateStrobeConfig {
	int width = 0; /* frame size, px */
	int height = 0;
	std::int64_t period_ns = 0; /* configured frame period: the estimate until frames come */
	/* An interval between two frames this long or longer (a stall) is not a period sample. */
	std::int64_t max_interval_ns = 0;
	std::int64_t pulse_margin_ns = 0; /* a pulse starts this early and ends this late */
};

class AlternateStrobe
{
public:
	/* Allocates: the ambient and the difference frames, width x height each. */
	explicit AlternateStrobe(const AlternateStrobeConfig &config);

	/* A frame's timestamp as a sample of the period (frames without a timestamp are left
	 * out). Called for every frame, whatever the mode, so the estimate is ready when the mode
	 * turns alternate. Allocates: never. */
	void measurePeriod(const hal::Frame &frame);
	/* The estimated frame period, ns. */
	std::int64_t periodNs() const { return measured_period_ns_; }

	/*
	 * Aim pulses at the next even frames after `frame` that are not scheduled yet, keeping two
	 * scheduled, on `control`. A pulse must not start before now_ns + 0.2 ms: frames may come
	 * several periods after their exposure, so it looks as far ahead as it takes (up to 64
	 * frames). Stops at the first pulse the controller refuses. Returns the pulses scheduled
	 * by this call. Allocates: never.
	 */
	int schedulePulses(const hal::Frame &frame, std::int64_t now_ns,
			   hal::StrobeController &control);

	/*
	 * A frame of the configured size and how the LEDs were during its exposure. Unlit: the
	 * frame is kept as the ambient frame; an invalid view is returned. Lit, with an ambient
	 * frame at most two frames older: lit − ambient, a view of this object's difference frame,
	 * valid until the next call. Otherwise (mixed, no ambient, a stale one): an invalid view.
	 * Allocates: never.
	 */
	ImageView difference(const hal::Frame &frame, hal::Lighting lighting);

	/* The ambient frame is no longer the scene's (a stall): lit frames wait for a new one. */
	void forgetAmbient() { have_ambient_ = false; }
	/* The lighting changed (mode, enable): no ambient frame, no pulse taken as scheduled. */
	void restart();

private:
	static constexpr int kFramesToSchedule = 2;
	static constexpr std::uint64_t kLookAheadFrames = 64;
	static constexpr std::int64_t kPulseLeadNs = 200000;
	/* A lit frame uses an ambient frame at most this many frames older. */
	static constexpr std::uint64_t kMaxAmbientAge = 2;

	std::int64_t max_interval_ns_;
	std::int64_t pulse_margin_ns_;

	/* Period estimate. */
	std::int64_t measured_period_ns_;
	bool have_period_sample_ = false;
	bool have_period_measured_ = false;
	std::uint64_t period_sequence_ = 0;
	std::int64_t period_timestamp_ns_ = 0;

	/* Pulses: the last frame one is aimed at (0: none). */
	std::uint64_t last_scheduled_sequence_ = 0;

	/* The last unlit frame and the difference image. */
	Image ambient_;
	std::uint64_t ambient_sequence_ = 0;
	bool have_ambient_ = false;
	Image difference_;
};

} /* namespace dockpose::firmware */

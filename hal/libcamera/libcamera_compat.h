/* SPDX-License-Identifier: MIT */
/*
 * The differences between the libcamera releases LibcameraCamera is built
 * against, in one place: Debian 12's 0.0.3 and Raspberry Pi's 0.5 and 0.7
 * (scripts/libcamera-build; the reference board's Raspberry Pi OS ships the
 * latter). Decided by libcamera's own <libcamera/version.h>.
 *
 * What the backend uses is otherwise the same in all three: CameraManager,
 * Camera::generateConfiguration (a std::vector of roles converts to 0.5's
 * Span), validate(), FrameBufferAllocator, Request::reuse(), SharedFD planes,
 * the controls AeEnable, ExposureTime, AnalogueGain, FrameDurationLimits and
 * SensorTimestamp. Only manual exposure differs:
 *
 *   0.0.3      AeEnable false makes exposure time and gain manual.
 *   >= 0.5     ExposureTimeMode and AnalogueGainMode (Manual) do it per
 *              control; AeEnable remains, as a shorthand that a pipeline may
 *              or may not list. Both are set where listed.
 */
#pragma once

#include <libcamera/control_ids.h>
#include <libcamera/controls.h>
#include <libcamera/version.h>

#define DOCKPOSE_LIBCAMERA_AT_LEAST(major, minor)                                                  \
	(LIBCAMERA_VERSION_MAJOR > (major) ||                                                      \
	 (LIBCAMERA_VERSION_MAJOR == (major) && LIBCAMERA_VERSION_MINOR >= (minor)))

namespace dockpose::hal::compat {

/* Which per-control manual modes the camera lists (always none before 0.5). */
struct ManualModes {
	bool exposure_time = false;
	bool analogue_gain = false;
};

inline ManualModes listedManualModes([[maybe_unused]] const libcamera::ControlInfoMap &controls)
{
	ManualModes modes;
#if DOCKPOSE_LIBCAMERA_AT_LEAST(0, 5)
	/* find(), not count(): see LibcameraCamera::Impl::probeControls(). */
	modes.exposure_time = controls.find(libcamera::controls::ExposureTimeMode.id()) !=
			      controls.end();
	modes.analogue_gain = controls.find(libcamera::controls::AnalogueGainMode.id()) !=
			      controls.end();
#endif
	return modes;
}

/* Sets the listed modes to Manual in controls. */
inline void setManualModes([[maybe_unused]] const ManualModes &modes,
			   [[maybe_unused]] libcamera::ControlList *controls)
{
#if DOCKPOSE_LIBCAMERA_AT_LEAST(0, 5)
	if (modes.exposure_time)
		controls->set(libcamera::controls::ExposureTimeMode,
			      libcamera::controls::ExposureTimeModeManual);
	if (modes.analogue_gain)
		controls->set(libcamera::controls::AnalogueGainMode,
			      libcamera::controls::AnalogueGainModeManual);
#endif
}

} /* namespace dockpose::hal::compat */

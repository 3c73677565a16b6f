/* SPDX-License-Identifier: MIT */
/*
 * A board's configuration as the board layer and the daemon use it: the
 * sections of board/<name>/board.json (docs/configuration.md) and the target
 * and camera models the file names, loaded once. Reading and validating a
 * file is the firmware's (firmware/config.h); the board wiring
 * (board/board.h) only reads these structs, so it depends on nothing above
 * the hal.
 *
 * Allocates: nothing by itself (strings and models are filled at start-up).
 */
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "algo/camera_model.h"
#include "algo/target_model.h"
#include "hal/sim/synthetic_scene.h"

namespace dockpose::board {

/*
 * The modes a board file chooses (strobe.mode, pipeline.mode). The CAN
 * protocol (firmware/protocol/dockpose_can.h) has the same enumerations, with
 * the same values, on the wire: the protocol header stands alone (the arm
 * controller builds it with nothing else) and the board layer sits below the
 * firmware, so neither can include the other. The values here are therefore
 * spelled out as the protocol's, firmware/modes.h checks each one at compile
 * time and converts by a cast: no mapping switch.
 */
enum class StrobeMode : std::uint8_t {
	Off = 0,
	Constant = 1,
	Alternate = 2
};
/* The board file's names, indexed by value: the one list of them (config and logs). */
constexpr std::array<const char *, 3> kStrobeModeNames = { "off", "constant", "alternate" };
const char *strobeModeName(StrobeMode mode);

/* Which frames the pose comes from: full search and tracking, or a cold search every frame. */
enum class TrackMode : std::uint8_t {
	Track = 0,
	SearchOnly = 1
};
constexpr std::array<const char *, 2> kTrackModeNames = { "track", "search_only" };

struct ReplayCameraConfig {
	std::string folder; /* frame_*.pgm in name order (absolute after loading) */
	bool loop = false;
};

struct CameraSection {
	std::string backend; /* "libcamera", "synthetic", "replay": must be one the board wires */
	std::string id; /* libcamera camera id; empty: by index */
	int index = 0;
	int width = 0; /* 0: the sensor's default (libcamera); must match intrinsics */
	int height = 0;
	double frame_rate_hz = 60.0;
	int exposure_us = 2000;
	double analogue_gain = 1.0;
	int buffer_count = 4;
	int stall_timeout_ms = 500; /* no frame for this long: fault, LED off */
	std::string intrinsics; /* camera JSON (method.md section 3) */
	hal::SyntheticScene synthetic; /* the synthetic camera's scene, read as it is */
	ReplayCameraConfig replay;
};

struct StrobeSection {
	std::string backend; /* "gpiod", "recording" */
	std::string chip; /* gpiod: chip name ("gpiochip0"), path, or label ("pinctrl-rp1") */
	int line = -1; /* gpiod: line offset on the chip */
	bool active_low = false;
	StrobeMode mode = StrobeMode::Constant;
	/* Alternate mode: light this long around each lit exposure. */
	int pulse_margin_us = 500;
};

struct CanSection {
	std::string backend; /* "socketcan", "file", "loopback" */
	std::string interface; /* socketcan: "can0" */
	std::string log_file; /* file: candump -l log written here (--can-log overrides) */
	std::uint32_t base_id = 0x300; /* 11-bit; base_id .. base_id + 0x10 are used */
	int bitrate = 500000; /* the bus's bit rate, for the bus-load check and docs */
	int tx_queue_depth = 32;
	int heartbeat_hz = 10;
};

struct PipelineSection {
	std::string target; /* target JSON */
	TrackMode mode = TrackMode::Track;
	double max_rms_px = 0.6;
	/* Acceptance bound of the full search: log10 of the number of false alarms
	 * per frame a match may have (docs/vision.md). The defaults here equal
	 * CorrespondenceConfig's (test_config checks). */
	double max_log10_nfa = -4.0;
	int min_leds_search = 4;
	int min_leds_track = 4;
	/* While tracking, every this many frames one is read whole; between, only
	 * windows around the predicted LEDs (PipelineConfig::full_frame_every). */
	int full_frame_every = 30;
	/* Degraded: a pose is still valid but with fewer LEDs than the model has, or
	 * poses were lost within the last `degraded_hold_frames` frames. */
	int degraded_hold_frames = 30;
	/* Searching frames in a row after which the state becomes degraded->searching. */
	int lost_after_frames = 3;
};

struct SystemdSection {
	bool notify = true; /* sd_notify READY/STATUS/WATCHDOG when NOTIFY_SOCKET is set */
};

struct BoardConfig {
	std::string board; /* "sim", "rpi5-imx296", ... : must match a board built into dockposed */
	std::string path; /* the file it was read from */
	CameraSection camera;
	StrobeSection strobe;
	CanSection can;
	PipelineSection pipeline;
	SystemdSection systemd;
	/* Loaded once, when the file is validated: pipeline.target and camera.intrinsics. */
	TargetModel target_model;
	CameraIntrinsics camera_model;
};

} /* namespace dockpose::board */

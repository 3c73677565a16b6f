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
#include "hal/camera.h"
#include "hal/can_bus.h"
#include "hal/sim/synthetic_scene.h"
#include "hal/strobe.h"

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

/*
 * The camera section is the hal's camera configuration itself (id, index,
 * width, height, exposure_us, analogue_gain, frame_rate_hz, buffer_count:
 * hal/camera.h, handed to Camera::configure() as it is) plus what the board
 * adds. width/height 0: the sensor's default (libcamera); they must match the
 * intrinsics.
 */
struct CameraSection : hal::CameraConfig {
	std::string backend; /* "libcamera", "synthetic", "replay": must be one the board wires */
	int stall_timeout_ms = 500; /* no frame for this long: fault, LED off */
	std::string intrinsics; /* camera JSON (method.md section 3) */
	hal::SyntheticScene synthetic; /* the synthetic camera's scene, read as it is */
	ReplayCameraConfig replay;
};

/* The strobe section is the hal's strobe line (chip, line, active_low: hal/strobe.h, the
 * gpiod backend's) plus what the board adds. */
struct StrobeSection : hal::StrobeLine {
	std::string backend; /* "gpiod", "recording" */
	StrobeMode mode = StrobeMode::Constant;
	/* Alternate mode: light this long around each lit exposure. */
	int pulse_margin_us = 500;
};

/* The CAN section is the hal's bus options (tx_queue_depth; fd: reports as one CAN FD
 * frame, DP_ReportFd) plus what the board adds. */
struct CanSection : hal::CanOptions {
	std::string backend; /* one the board wires (board::backendNames): "socketcan", "file" */
	std::string interface; /* socketcan: "can0" */
	std::string log_file; /* file: candump -l log written here (--can-log overrides) */
	std::uint32_t base_id = 0x300; /* 11-bit; base_id .. base_id + 0x11 are used */
	int bitrate = 500000; /* the bus's bit rate, for the bus-load check and docs */
	int heartbeat_hz = 10;
	/* A report still waiting for the bus this long after it was queued is dropped unsent
	 * (CanStats::tx_expired); 0: one camera frame period. */
	int max_report_age_us = 0;
	/* A pose whose exposure began longer ago than this when its report is made goes out as
	 * no pose (the controller's decoder refuses older than 50 ms by default). */
	int max_pose_latency_us = 50000;
	/* Authentication (docs/can-protocol.md): the 128-bit key's file (empty: frames are not
	 * authenticated), and the state file of the run counter the freshness values start from. */
	std::string key_file;
	std::string run_counter_file = "/var/lib/dockpose/can-run-counter";
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
	/* The precision a reported pose must have (PipelineConfig's, whose defaults these equal;
	 * test_config checks): the 99 % bound of its error from its own covariance within
	 * max_rotation_error_deg and max(5 mm, max_translation_error_frac x range); 0: no limit. */
	double max_rotation_error_deg = 2.0;
	double max_translation_error_frac = 0.02;
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

/* The operator preview (firmware/preview.h): off by default. */
struct PreviewSection {
	bool enabled = false;
	std::string name = "dockpose-preview"; /* the shared memory: /dev/shm/<name> */
	double rate_hz = 10.0; /* at most this many frames a second */
	int width = 320; /* pixels, at most; the frame is shrunk by an integer factor */
};

struct BoardConfig {
	std::string board; /* "sim", "rpi5-imx296", ... : must match a board built into dockposed */
	std::string path; /* the file it was read from */
	CameraSection camera;
	StrobeSection strobe;
	CanSection can;
	PipelineSection pipeline;
	SystemdSection systemd;
	PreviewSection preview;
	/* Loaded once, when the file is validated: pipeline.target and camera.intrinsics. */
	TargetModel target_model;
	CameraIntrinsics camera_model;
};

} /* namespace dockpose::board */

/* SPDX-License-Identifier: MIT */
/*
 * Daemon: the sensor. It owns a board's backends (board/board.h), the vision
 * pipeline and the CAN protocol, and runs the frame loop (handleFrame, top to
 * bottom):
 *
 *   camera frame (the backend's completion ─► hal::FrameQueue ─► waitFrame)
 *                ─► lit / unlit / mixed (strobe history vs. exposure window)
 *                ─► [alternate: lit − last unlit, AlternateStrobe] ─► Pipeline
 *                ─► state machine ─► can::Encoder ─► pose frames + status
 *                   frame on CAN (latency measured from the sensor timestamp
 *                   to the send)
 *
 * and between frames: command frames from the arm controller, the heartbeat,
 * the systemd watchdog, the strobe's dead-man switch, and stall detection
 * (no frame for camera.stall_timeout_ms: state fault, LED off, status frames
 * keep coming at the heartbeat rate, and the camera is restarted).
 *
 * A wrong pose is worse than no pose: a pose is only sent as valid when the
 * pipeline found it, the state is not fault, and it fits the protocol's ranges.
 *
 * Allocates: the constructor and start() allocate every buffer (pipeline,
 * AlternateStrobe's ambient and difference frames); the frame loop does not allocate except
 * in log lines on state changes and in systemd status text (once a second).
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>

#include "algo/image.h"
#include "algo/pipeline.h"
#include "board/board.h"
#include "firmware/alternate_strobe.h"
#include "firmware/capture.h"
#include "firmware/config.h"
#include "firmware/fault_hold.h"
#include "firmware/latency_histogram.h"
#include "firmware/preview.h"
#include "firmware/preview_worker.h"
#include "firmware/protocol/dockpose_can.h"
#include "firmware/protocol/dockpose_can_cmac.h"
#include "firmware/state_machine.h"
#include "firmware/systemd_notify.h"

namespace dockpose::firmware {

struct DaemonStats {
	std::uint64_t frames = 0; /* frames from the camera */
	std::uint64_t frames_lit = 0;
	std::uint64_t frames_unlit = 0;
	std::uint64_t frames_mixed = 0; /* exposure straddled a strobe switch: not used */
	std::uint64_t frames_bad = 0; /* wrong size / invalid view: rejected */
	std::uint64_t sequence_gaps = 0; /* frames the sensor numbered but we never saw */
	std::uint64_t processed = 0; /* frames that went through the pipeline */
	std::uint64_t poses_valid = 0; /* reports sent with a valid pose */
	std::uint64_t poses_late =
		0; /* poses found, but sent as none: older than max_pose_latency_us */
	std::uint64_t reports = 0; /* status frames sent for processed frames */
	std::uint64_t stall_reports = 0; /* status frames sent while the camera stalled */
	std::uint64_t stalls = 0; /* stall episodes */
	std::uint64_t camera_restarts = 0;
	std::uint64_t heartbeats = 0;
	std::uint64_t commands = 0; /* command frames applied */
	std::uint64_t commands_rejected = 0; /* command frames with bad CRC/length/values */
	std::uint64_t can_send_drops = 0; /* sends that dropped an older queued frame */
	std::uint64_t preview_frames = 0; /* preview frames published, or handed to the worker */
	std::uint64_t preview_skipped = 0; /* preview frames skipped: the worker was busy */
	LatencyHistogram latency; /* sensor timestamp -> CAN send, per report */
	LatencyHistogram pipeline; /* time in Pipeline::process, per processed frame */
	double run_s = 0.0;
};

class Daemon
{
public:
	/* Takes the (unopened) backends of a validated configuration. Allocates. */
	Daemon(const BoardConfig &config, board::Backends backends, std::FILE *log = stderr);
	~Daemon();
	Daemon(const Daemon &) = delete;
	Daemon &operator=(const Daemon &) = delete;

	/* Open the strobe (LED off), the CAN bus, configure and start the camera. */
	hal::Status start();

	/*
	 * The frame loop, until stop_requested becomes true, the camera ends (replay
	 * without loop), or run_for_s seconds passed (0: no limit); then a clean
	 * shutdown (LED off, a last status frame with state shutdown). Returns the
	 * process exit status: 0 after a clean run, 1 when the camera failed for good.
	 */
	int run(const std::atomic<bool> &stop_requested, double run_for_s = 0.0);

	/* LED off, last status frame, close everything. Idempotent; run() calls it. */
	void shutdown();

	SensorState state() const { return state_machine_.state(); }
	/* The counts as the frame loop last published them (every 50 ms while it runs, and when
	 * run() returns): a copy, safe from any thread. Allocates: never. The publication is a
	 * 32 KB copy (the two histograms) under a mutex the frame loop takes 20 times a second:
	 * 0.69 us per copy measured here (x86_64, -O2), about 14 us of loop time per second. */
	DaemonStats stats() const;
	StrobeMode strobeMode() const { return strobe_mode_; }
	bool enabled() const { return enabled_; }
	hal::Strobe *strobe() const { return backends_.strobe.get(); }
	/* Every accepted frame (camera model's size) also goes to *tap, on the frame thread,
	 * before the pipeline; null: none. Set before run(). --capture's FrameCapture. */
	void setFrameTap(FrameTap *tap) { frame_tap_ = tap; }

	/* One line of totals (frames, poses, rate, latency, drops) for logs. */
	void printSummary(std::FILE *out) const;

private:
	/* The frame path: handleFrame calls the next four in this order. Allocates: never. */
	void handleFrame(const hal::Frame &frame, std::int64_t now_ns);
	bool acceptFrame(const hal::Frame &frame, std::int64_t now_ns);
	hal::Lighting classifyLighting(const hal::Frame &frame);
	std::optional<ImageView> pipelineInput(const hal::Frame &frame, hal::Lighting lighting);
	const PoseResult *runPipeline(const ImageView &view);
	void reportFrame(const hal::Frame &frame, const PoseResult *result);

	void handleStall(std::int64_t now_ns);
	hal::Status startAuthentication();
	void handleCommands();
	/* A refused command frame: counted, COMMAND_REJECTED raised, logged (at most once a second). */
	void commandRejected(std::uint32_t can_id);
	void applyCommand(const can::CommandData &command);
	void applyStrobeMode(StrobeMode mode);
	can::StatusData statusFor(SensorState state, std::uint8_t faults) const;
	/* deadline_ns: CLOCK_MONOTONIC; frames still queued then are dropped unsent (0: none). */
	int sendReport(const can::StatusData &status, const can::PoseData *pose,
		       std::int64_t deadline_ns);
	void sendFrames(const can::RawFrame *frames, int count, std::int64_t deadline_ns);
	void sendStatusOnly(std::int64_t now_ns);
	void sendHeartbeat(std::int64_t now_ns);
	std::uint8_t activeFaults(std::int64_t now_ns);
	void logState(SensorState before, SensorState after, std::uint64_t sequence);
	void updateSystemdStatus(std::int64_t now_ns);
	void publishStats(std::int64_t now_ns);
	/* Open the ring (and start its worker); false: it could not be opened (said in the log). */
	bool startPreview();
	/* Give back the frame the preview worker holds, waiting for it (before the camera stops). */
	void drainPreview();
	/* The CAN link going down (interface missing or down) or up: one log line each way. */
	void logCanLink();

	BoardConfig config_;
	board::Backends backends_;
	std::FILE *log_;
	std::unique_ptr<Pipeline> pipeline_;
	AlternateStrobe alternate_;
	StateMachine state_machine_;
	can::OpensslCmac cmac_; /* the CAN key's MAC, when can.key_file is set */
	can::Encoder encoder_;
	can::Decoder command_decoder_;
	std::int64_t last_reject_log_ns_ = 0;
	std::uint64_t rejects_unlogged_ = 0;
	/* CLOCK_MONOTONIC when the loop first saw a command held for its MAC frame (0: none held). */
	std::int64_t command_pending_since_ns_ = 0;
	SystemdNotifier notifier_;
	/* The operator preview (preview.enabled, or switched on by a command): every
	 * preview_every_-th frame, through preview_worker_ when it runs (else inline). */
	PreviewWriter preview_;
	PreviewWorker preview_worker_;
	bool preview_on_ = false; /* publishing (the ring may stay open while off) */
	bool frame_held_ = false; /* handleFrame handed the frame to preview_worker_ */
	int preview_every_ = 1;
	int preview_count_ = 0;
	DaemonStats stats_; /* frame thread */
	mutable std::mutex stats_mutex_; /* guards published_stats_ */
	DaemonStats published_stats_;
	std::int64_t last_publish_ns_ = 0;

	/* Settings the arm controller can change. */
	bool enabled_ = true;
	StrobeMode strobe_mode_;
	TrackMode track_mode_;
	int exposure_us_;
	double gain_;

	/* Frame bookkeeping. */
	std::int64_t period_ns_; /* configured frame period: the overrun bound */
	std::int64_t report_max_age_ns_; /* a report still queued this long after it is sent dies */
	std::int64_t max_pose_latency_ns_; /* a pose older than this when sent is sent as none */
	std::int64_t heartbeat_interval_ns_;
	bool have_sequence_ = false;
	std::uint64_t last_sequence_ = 0;
	std::int64_t last_frame_ns_ = 0;
	std::int64_t start_ns_ = 0;
	bool stalled_ = false;
	bool camera_failed_ = false;
	int failed_restarts_ = 0; /* restarts in a row whose start() failed */
	std::int64_t last_stall_report_ns_ = 0;
	std::int64_t last_restart_ns_ = 0;
	std::int64_t next_heartbeat_ns_ = 0;
	std::int64_t last_systemd_status_ns_ = 0;
	std::uint64_t rate_frames_ = 0;
	std::int64_t rate_start_ns_ = 0;
	double frame_rate_hz_ = 0.0;
	bool can_down_ = false; /* the CAN bus was Down when last looked at (logCanLink) */

	/* Timed faults: events keep their bit for kFaultHoldNs after they happen. */
	static constexpr std::int64_t kFaultHoldNs = 1000000000;
	FaultHold frames_dropped_{ kFaultHoldNs };
	FaultHold can_overflow_{ kFaultHoldNs };
	FaultHold bus_off_{ kFaultHoldNs }; /* bus-off events, and while the bus is off or down */
	FaultHold strobe_error_{ kFaultHoldNs };
	FaultHold command_rejected_{ kFaultHoldNs };
	FaultHold overrun_{ kFaultHoldNs };
	std::uint8_t last_faults_ = 0;

	bool started_ = false;
	bool shut_down_ = false;
	FrameTap *frame_tap_ = nullptr;
};

} /* namespace dockpose::firmware */

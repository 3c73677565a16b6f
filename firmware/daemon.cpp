/* SPDX-License-Identifier: MIT */
#include "firmware/daemon.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <thread>

#include "firmware/can_auth.h"
#include "firmware/can_frames.h"
#include "firmware/modes.h"
#include "hal/clock.h"

namespace dockpose::firmware {

namespace {

constexpr std::int64_t kNsPerMs = 1000000;
constexpr std::int64_t kNsPerS = 1000000000;
/* Wait slice of the frame loop: commands, heartbeat and watchdog are served at least this often. */
constexpr int kWaitSliceMs = 20;
/* A stalled camera is restarted at most this often. */
constexpr std::int64_t kRestartIntervalNs = 2 * kNsPerS;
/* After this many restarts in a row whose start() failed, run() gives up with status 1 (systemd's
 * Restart=on-failure then starts the whole process afresh). */
constexpr int kMaxFailedRestarts = 5;
/*
 * After a change of exposure, gain or strobe mode the pipeline reads this
 * many frames whole (not through windows): new controls reach the sensor a
 * few frames late, and the background they give must be re-measured.
 */
constexpr int kWholeFramesAfterLightChange = 4;
/* A command must answer one of the sensor's last this many freshness values (DP_Auth frames:
 * about 3.6 s at 60 frames/s, 25 s when only heartbeats go out). */
constexpr std::uint64_t kCommandFreshnessWindow = 256;
/* With a key, a DP_Command whose DP_CommandAuth has not come this long after the loop first saw
 * it held is refused (a sender sends the two back to back: microseconds apart on the bus). */
constexpr std::int64_t kCommandAuthWaitNs = 100'000'000;

PipelineConfig pipelineConfig(const PipelineSection &section)
{
	PipelineConfig config;
	config.tracking = section.mode == TrackMode::Track;
	config.correspondence.max_rms_px = section.max_rms_px;
	config.correspondence.max_log10_nfa = section.max_log10_nfa; /* the early exit follows */
	config.correspondence.min_leds_search = section.min_leds_search;
	config.correspondence.min_leds_track = section.min_leds_track;
	config.full_frame_every = section.full_frame_every;
	config.max_rotation_error_deg = section.max_rotation_error_deg;
	config.max_translation_error_frac = section.max_translation_error_frac;
	return config;
}

/* The configuration requires a fixed rate (frame_rate_hz > 0). */
std::int64_t framePeriodNs(const BoardConfig &config)
{
	return static_cast<std::int64_t>(config.camera.frameDurationUs()) * 1000;
}

/* How long a report may wait for the bus: can.max_report_age_us, 0 meaning one frame period
 * (by then the next frame's report exists). */
std::int64_t reportMaxAgeNs(const BoardConfig &config)
{
	return config.can.max_report_age_us > 0
		       ? static_cast<std::int64_t>(config.can.max_report_age_us) * 1000
		       : framePeriodNs(config);
}

/* Frames of the camera model's size; none when the model was not loaded (start() refuses). */
AlternateStrobeConfig alternateStrobeConfig(const BoardConfig &config)
{
	AlternateStrobeConfig alternate;
	const CameraIntrinsics &intrinsics = config.camera_model;
	if (intrinsics.width > 0 && intrinsics.height > 0) {
		alternate.width = intrinsics.width;
		alternate.height = intrinsics.height;
	}
	alternate.period_ns = framePeriodNs(config);
	alternate.max_interval_ns =
		static_cast<std::int64_t>(config.camera.stall_timeout_ms) * kNsPerMs;
	alternate.pulse_margin_ns = static_cast<std::int64_t>(config.strobe.pulse_margin_us) * 1000;
	return alternate;
}

} /* namespace */

Daemon::Daemon(const BoardConfig &config, board::Backends backends, std::FILE *log)
	: config_(config),
	  backends_(std::move(backends)),
	  log_(log),
	  alternate_(alternateStrobeConfig(config)),
	  state_machine_(config.pipeline.lost_after_frames, config.pipeline.degraded_hold_frames),
	  encoder_(config.can.base_id),
	  command_decoder_(config.can.base_id),
	  notifier_(config.systemd.notify),
	  strobe_mode_(config.strobe.mode),
	  track_mode_(config.pipeline.mode),
	  exposure_us_(config.camera.exposure_us),
	  gain_(config.camera.analogue_gain),
	  period_ns_(framePeriodNs(config)),
	  report_max_age_ns_(reportMaxAgeNs(config)),
	  max_pose_latency_ns_(static_cast<std::int64_t>(config.can.max_pose_latency_us) * 1000),
	  heartbeat_interval_ns_(kNsPerS / std::max(1, config.can.heartbeat_hz))
{
	/* The configuration was validated: both models loaded (an empty one is a bug upstream,
	 * reported by start()). */
	const TargetModel &target = config_.target_model;
	const CameraIntrinsics &intrinsics = config_.camera_model;
	if (!target.points_mm.empty() && intrinsics.width > 0 && intrinsics.height > 0)
		pipeline_ = std::make_unique<Pipeline>(target, intrinsics,
						       pipelineConfig(config_.pipeline));
}

Daemon::~Daemon()
{
	shutdown();
}

hal::Status Daemon::start()
{
	if (!pipeline_)
		return hal::Status::error("the configuration holds no loaded target model (" +
					  config_.pipeline.target + ") or camera model (" +
					  config_.camera.intrinsics + "): it was not validated");
	if (!backends_.strobe || !backends_.strobe_control || !backends_.camera || !backends_.can)
		return hal::Status::error("board " + config_.board + ": wiring left a backend out");

	/* LED off first: whatever happens next, it must not be left on. */
	if (auto s = backends_.strobe->open(); !s)
		return hal::Status::error("strobe: " + s.message());
	if (auto s = backends_.strobe_control->start(); !s)
		return hal::Status::error("strobe: " + s.message());

	if (auto s = startAuthentication(); !s)
		return s;
	const hal::CanFilter commands[] = { { config_.can.base_id + can::kCommand, 0x7ff, false },
					    { config_.can.base_id + can::kCommandAuth, 0x7ff,
					      false } };
	if (auto s = backends_.can->open(commands, config_.can); !s)
		return hal::Status::error("can: " + s.message());
	/* An interface that is missing or down is waited for (the bus says so once, here). */
	logCanLink();

	if (auto s = backends_.camera->configure(config_.camera); !s)
		return hal::Status::error("camera: " + s.message());
	const auto &k = pipeline_->camera().intrinsics();
	if (backends_.camera->width() != k.width || backends_.camera->height() != k.height)
		return hal::Status::error(
			"camera: delivers " + std::to_string(backends_.camera->width()) + "x" +
			std::to_string(backends_.camera->height()) +
			" frames but the intrinsics (" + config_.camera.intrinsics + ") are for " +
			std::to_string(k.width) + "x" + std::to_string(k.height));
	if (auto s = backends_.camera->start(); !s)
		return hal::Status::error("camera: " + s.message());

	if (config_.preview.enabled)
		startPreview();

	start_ns_ = hal::monotonicNs();
	last_frame_ns_ = start_ns_;
	rate_start_ns_ = start_ns_;
	next_heartbeat_ns_ = start_ns_;
	started_ = true;
	applyStrobeMode(strobe_mode_);
	std::fprintf(log_,
		     "dockposed: board %s: camera %s, strobe %s (%s), can %s (base 0x%03x%s, "
		     "worst-case load %.1f %% of %d bit/s)\n",
		     config_.board.c_str(), backends_.camera->name().c_str(),
		     backends_.strobe->name().c_str(), strobeModeName(strobe_mode_),
		     backends_.can->name().c_str(), config_.can.base_id,
		     config_.can.fd ? ", CAN FD reports" : "", 100.0 * canBusLoad(config_),
		     config_.can.bitrate);
	notifier_.ready();
	return hal::Status::ok();
}

int Daemon::run(const std::atomic<bool> &stop_requested, double run_for_s)
{
	if (!started_)
		return 1;
	const std::int64_t end_ns =
		run_for_s > 0 ? start_ns_ + static_cast<std::int64_t>(run_for_s * 1e9) : 0;
	int exit_status = 0;

	while (!stop_requested.load(std::memory_order_relaxed)) {
		std::int64_t now_ns = hal::monotonicNs();
		if (end_ns && now_ns >= end_ns)
			break;

		backends_.strobe_control->kick();
		handleCommands();

		/* The frame the preview worker is done with goes back to the camera. */
		if (hal::Frame done; preview_worker_.reclaim(&done))
			backends_.camera->releaseFrame(done);

		hal::Frame frame;
		const std::int64_t wait_start_ns = now_ns;
		/* Idle from here until a frame comes: the preview worker's time for its pixel work
		 * (firmware/preview_worker.h). Busy again from the frame to the next wait. */
		preview_worker_.setLoopBusy(false);
		const hal::WaitResult result = backends_.camera->waitFrame(&frame, kWaitSliceMs);
		if (result == hal::WaitResult::Frame)
			preview_worker_.setLoopBusy(true);
		now_ns = hal::monotonicNs();
		if (result == hal::WaitResult::Frame) {
			frame_held_ = false;
			handleFrame(frame, now_ns);
			if (!frame_held_)
				backends_.camera->releaseFrame(frame);
		} else if (result == hal::WaitResult::Stopped && !stalled_) {
			/* Not running without a stall under way: a replay ran out of frames. (During a
			 * stall it is a camera whose restart failed: handled as the stall.) */
			std::fprintf(log_, "dockposed: the camera has no more frames\n");
			break;
		} else {
			if (result == hal::WaitResult::Error && !camera_failed_) {
				camera_failed_ = true;
				std::fprintf(log_, "dockposed: camera error: %s\n",
					     backends_.camera->lastError().c_str());
			}
			handleStall(now_ns);
			if (failed_restarts_ >= kMaxFailedRestarts) {
				std::fprintf(
					log_,
					"dockposed: the camera failed to restart %d times in a "
					"row; exiting with status 1\n",
					failed_restarts_);
				exit_status = 1;
				break;
			}
			/* An unplugged or stopped camera answers at once: wait out the slice
			 * rather than spin a core. */
			const std::int64_t rest_ns =
				wait_start_ns + kWaitSliceMs * kNsPerMs - hal::monotonicNs();
			if (rest_ns > 0)
				std::this_thread::sleep_for(std::chrono::nanoseconds(rest_ns));
		}

		/* A frame may have taken a while (the pipeline): heartbeat and watchdog at the time now. */
		now_ns = hal::monotonicNs();
		if (now_ns >= next_heartbeat_ns_)
			sendHeartbeat(now_ns);
		backends_.can->poll();
		logCanLink();
		notifier_.watchdog(now_ns);
		updateSystemdStatus(now_ns);
		if (now_ns - last_publish_ns_ >= 50 * kNsPerMs)
			publishStats(now_ns);
	}

	if (camera_failed_ && stalled_)
		exit_status = 1;
	stats_.run_s = static_cast<double>(hal::monotonicNs() - start_ns_) * 1e-9;
	shutdown();
	publishStats(hal::monotonicNs());
	return exit_status;
}

DaemonStats Daemon::stats() const
{
	std::lock_guard<std::mutex> lock(stats_mutex_);
	return published_stats_;
}

void Daemon::publishStats(std::int64_t now_ns)
{
	last_publish_ns_ = now_ns;
	std::lock_guard<std::mutex> lock(stats_mutex_);
	published_stats_ = stats_;
}

void Daemon::shutdown()
{
	if (shut_down_ || !started_)
		return;
	shut_down_ = true;
	notifier_.stopping();

	/* LED off before anything else can fail. */
	backends_.strobe_control->stop();
	backends_.strobe->forceOff();

	const SensorState before = state_machine_.state();
	state_machine_.shutdown();
	logState(before, state_machine_.state(), last_sequence_);
	can::StatusData status = statusFor(can::SensorState::Shutdown, last_faults_);
	status.strobe = can::StrobeMode::Off;
	sendReport(status, nullptr, 0); /* no deadline: the last word, however late */
	/* Give the last frames a moment to leave a busy queue, without hanging. */
	for (int i = 0; i < 50 && backends_.can->stats().tx_queued > 0; ++i) {
		backends_.can->poll();
		timespec ts{ 0, 2 * kNsPerMs };
		nanosleep(&ts, nullptr);
	}
	backends_.can->poll();

	preview_worker_.stop();
	drainPreview();
	backends_.camera->stop();
	backends_.can->close();
	backends_.strobe->close();
}

/*
 * One frame, top to bottom. The camera backend's completion queued it (hal::FrameQueue) and
 * run() took it with waitFrame(); run() releases it after this returns.
 */
void Daemon::handleFrame(const hal::Frame &frame, std::int64_t now_ns)
{
	/* Counts, sequence gaps, overrun; a frame of the wrong size goes no further. */
	if (!acceptFrame(frame, now_ns))
		return;

	/* The sensor's period, from every frame; in alternate mode, the next pulses aimed with it. */
	alternate_.measurePeriod(frame);
	if (strobe_mode_ == StrobeMode::Alternate && enabled_)
		alternate_.schedulePulses(frame, hal::monotonicNs(), *backends_.strobe_control);

	/* Lit, unlit or mixed: the strobe's history against the exposure window. */
	const hal::Lighting lighting = classifyLighting(frame);
	if (frame_tap_)
		frame_tap_->onFrame(frame, lighting);

	/* What the pipeline reads in this strobe mode (alternate: lit − last unlit); nothing: the
	 * frame gives no report. */
	const std::optional<ImageView> input = pipelineInput(frame, lighting);
	if (!input)
		return;

	/* Pixels → pose; disabled (an invalid view): a report without a pose. */
	const PoseResult *result = input->valid() ? runPipeline(*input) : nullptr;

	/* State machine → encoder → CAN. */
	reportFrame(frame, result);

	/* Every Nth frame to the operator preview (after the report: it never delays one). The
	 * worker downscales it on its own thread, holding the frame, while run() waits for the next
	 * frame; still busy with the last one, this preview frame is skipped. */
	if (preview_on_ && preview_.isOpen() && ++preview_count_ >= preview_every_) {
		preview_count_ = 0;
		const PreviewStatus status{ static_cast<std::uint8_t>(state_machine_.state()),
					    last_faults_ };
		if (!preview_worker_.running()) {
			preview_.publish(frame.image, frame.sequence, frame.timestamp_ns,
					 *pipeline_, result, status);
			++stats_.preview_frames;
		} else if (preview_worker_.submit(frame, *pipeline_, result, status)) {
			frame_held_ = true;
			++stats_.preview_frames;
		} else {
			++stats_.preview_skipped;
		}
	}
}

void Daemon::drainPreview()
{
	if (hal::Frame held; preview_worker_.drain(&held))
		backends_.camera->releaseFrame(held);
}

/* The frame's bookkeeping. False: the frame is not of the camera model's size (counted). */
bool Daemon::acceptFrame(const hal::Frame &frame, std::int64_t now_ns)
{
	++stats_.frames;
	++rate_frames_;
	if (stalled_) {
		std::fprintf(log_, "dockposed: frames again after a stall (frame %llu)\n",
			     static_cast<unsigned long long>(frame.sequence));
		stalled_ = false;
		camera_failed_ = false;
		failed_restarts_ = 0;
		applyStrobeMode(strobe_mode_);
	}
	last_frame_ns_ = now_ns;

	if (have_sequence_ && frame.sequence > last_sequence_ + 1)
		stats_.sequence_gaps += frame.sequence - last_sequence_ - 1;
	have_sequence_ = true;
	last_sequence_ = frame.sequence;

	/* Behind by more than two frame periods: the loop cannot keep up. */
	if (frame.timestamp_ns > 0 &&
	    now_ns - frame.timestamp_ns > 2 * period_ns_ + frame.exposure_us * 1000LL)
		overrun_.raise(now_ns);

	const auto &k = pipeline_->camera().intrinsics();
	if (!frame.image.valid() || frame.image.width != k.width ||
	    frame.image.height != k.height) {
		if (stats_.frames_bad++ == 0)
			std::fprintf(
				log_,
				"dockposed: rejecting a %dx%d frame (expected %dx%d); counting further ones\n",
				frame.image.width, frame.image.height, k.width, k.height);
		return false;
	}
	return true;
}

/* How the LEDs were during the frame's exposure (counted). */
hal::Lighting Daemon::classifyLighting(const hal::Frame &frame)
{
	const std::int64_t exposure_end_ns =
		frame.timestamp_ns + static_cast<std::int64_t>(frame.exposure_us) * 1000;
	const hal::Lighting lighting =
		backends_.strobe_control->lighting(frame.timestamp_ns, exposure_end_ns);
	switch (lighting) {
	case hal::Lighting::Lit:
		++stats_.frames_lit;
		break;
	case hal::Lighting::Unlit:
		++stats_.frames_unlit;
		break;
	case hal::Lighting::Mixed:
		++stats_.frames_mixed;
		break;
	}
	return lighting;
}

/*
 * The view the pipeline reads for this frame: the frame itself (strobe off; constant, when lit),
 * the lit − unlit difference (alternate), an invalid view when disabled (a report without a
 * pose), or nothing (no report: a frame the mode does not use).
 */
std::optional<ImageView> Daemon::pipelineInput(const hal::Frame &frame, hal::Lighting lighting)
{
	if (!enabled_)
		return ImageView{};
	switch (strobe_mode_) {
	case StrobeMode::Off:
		return frame.image;
	case StrobeMode::Constant:
		if (lighting == hal::Lighting::Lit)
			return frame.image;
		return std::nullopt;
	case StrobeMode::Alternate:
		/* An unlit frame is kept as the ambient frame; a lit one gives the difference. */
		if (const ImageView difference = alternate_.difference(frame, lighting);
		    difference.valid())
			return difference;
		return std::nullopt;
	}
	return std::nullopt;
}

/* Pipeline::process on a valid view, timed. The result is the pipeline's, valid until the next
 * call. */
const PoseResult *Daemon::runPipeline(const ImageView &view)
{
	if (track_mode_ == TrackMode::SearchOnly)
		pipeline_->reset();
	const std::int64_t t0_ns = hal::monotonicNs();
	const PoseResult *result = &pipeline_->process(view);
	stats_.pipeline.add(hal::monotonicNs() - t0_ns);
	++stats_.processed;
	return result;
}

/* The state machine's step for a processed frame (result: null when the pipeline did not run),
 * and its report on CAN: the pose frames when the pose is valid, the status frame. */
void Daemon::reportFrame(const hal::Frame &frame, const PoseResult *result)
{
	const std::int64_t now_ns = hal::monotonicNs();
	const std::uint8_t faults = activeFaults(now_ns);
	bool pose_valid = result && result->found && enabled_;

	const SensorState before = state_machine_.state();
	const SensorState state = state_machine_.update({ pose_valid, faults });
	if (state == SensorState::Fault)
		pose_valid = false;
	logState(before, state, frame.sequence);

	can::StatusData status = statusFor(state, faults);
	status.pose_valid = pose_valid;
	status.tracked = pose_valid && result->tracked;
	status.leds_used = result ? result->leds_used : 0;
	status.rms_px = result ? result->rms_px : 0.0;

	can::PoseData pose;
	if (pose_valid) {
		pose.frame_counter = static_cast<std::uint32_t>(frame.sequence);
		for (int i = 0; i < 3; ++i) {
			pose.t_mm[i] = result->t_mm[i];
			pose.rpy_deg[i] = result->rpy_deg[i];
			pose.sigma_t_mm[i] = result->sigma_t_mm[i];
			pose.sigma_rpy_deg[i] = result->sigma_rpy_deg[i];
		}
		pose.q[0] = result->q.w();
		pose.q[1] = result->q.x();
		pose.q[2] = result->q.y();
		pose.q[3] = result->q.z();
		pose.log10_nfa = result->log10_nfa;
	}

	/* Latency up to this send, from the start of the exposure; the report is dated with the
	 * send time and leaves within report_max_age_ns_ of it or not at all. */
	const std::int64_t send_ns = hal::monotonicNs();
	const std::int64_t latency_ns = frame.timestamp_ns > 0 ? send_ns - frame.timestamp_ns : 0;
	status.latency_ms = static_cast<double>(latency_ns) * 1e-6;
	pose.sensor_time_us = static_cast<std::uint32_t>(send_ns / 1000);
	/* A pose the loop finished late (a loaded machine, a long search) is already stale: sent
	 * as no pose (the soak saw 54 ms from exposure to send under a command flood). */
	if (pose_valid && latency_ns > max_pose_latency_ns_) {
		pose_valid = false;
		status.pose_valid = false;
		status.tracked = false;
		++stats_.poses_late;
	}

	const int n =
		sendReport(status, pose_valid ? &pose : nullptr, send_ns + report_max_age_ns_);
	++stats_.reports;
	if (n > 1)
		++stats_.poses_valid;
	stats_.latency.add(latency_ns);
}

void Daemon::handleStall(std::int64_t now_ns)
{
	const std::int64_t stall_ns =
		static_cast<std::int64_t>(config_.camera.stall_timeout_ms) * kNsPerMs;
	if (!camera_failed_ && now_ns - last_frame_ns_ < stall_ns)
		return;
	if (!stalled_) {
		stalled_ = true;
		++stats_.stalls;
		std::fprintf(log_, "dockposed: %s: no frame for %lld ms; LED off\n",
			     camera_failed_ ? "camera failed" : "camera stalls",
			     static_cast<long long>((now_ns - last_frame_ns_) / kNsPerMs));
		backends_.strobe_control->setOn(false);
		alternate_.forgetAmbient();
		last_stall_report_ns_ = 0;
		last_restart_ns_ = now_ns;
	}
	/* Status keeps coming, at the heartbeat rate, so the controller sees the fault. */
	if (now_ns - last_stall_report_ns_ >= heartbeat_interval_ns_) {
		sendStatusOnly(now_ns);
		last_stall_report_ns_ = now_ns;
	}
	/* Try to bring the camera back. */
	if (now_ns - last_restart_ns_ >= kRestartIntervalNs) {
		last_restart_ns_ = now_ns;
		drainPreview();
		backends_.camera->stop();
		if (auto s = backends_.camera->start(); s) {
			++stats_.camera_restarts;
			failed_restarts_ = 0;
			std::fprintf(log_, "dockposed: camera restarted\n");
		} else {
			++failed_restarts_;
			std::fprintf(log_, "dockposed: camera restart failed (%d of %d): %s\n",
				     failed_restarts_, kMaxFailedRestarts, s.message().c_str());
		}
	}
}

void Daemon::sendStatusOnly(std::int64_t now_ns)
{
	const std::uint8_t faults = activeFaults(now_ns);
	const SensorState before = state_machine_.state();
	const SensorState state = state_machine_.update({ false, faults });
	logState(before, state, last_sequence_);
	/* Outdated by the next one, a heartbeat interval later. */
	sendReport(statusFor(state, faults), nullptr, now_ns + heartbeat_interval_ns_);
	++stats_.stall_reports;
}

void Daemon::sendHeartbeat(std::int64_t now_ns)
{
	next_heartbeat_ns_ = now_ns + heartbeat_interval_ns_;
	if (now_ns - rate_start_ns_ >= kNsPerS) {
		frame_rate_hz_ = static_cast<double>(rate_frames_) * 1e9 /
				 static_cast<double>(now_ns - rate_start_ns_);
		rate_frames_ = 0;
		rate_start_ns_ = now_ns;
	}
	can::HeartbeatData hb;
	hb.uptime_s = static_cast<std::uint32_t>((now_ns - start_ns_) / kNsPerS);
	hb.state = state_machine_.state();
	hb.mode = toCan(track_mode_);
	hb.strobe = toCan(strobe_mode_);
	hb.enabled = enabled_;
	hb.faults = activeFaults(now_ns);
	hb.frame_rate_hz = frame_rate_hz_;
	can::RawFrame frames[can::kMaxHeartbeatFrames];
	const int n = encoder_.encodeHeartbeat(hb, frames);
	sendFrames(frames, n, next_heartbeat_ns_);
	++stats_.heartbeats;
}

/* The fields every status frame carries; the caller adds the pose's (valid, tracked, LEDs, rms)
 * and the latency. */
can::StatusData Daemon::statusFor(SensorState state, std::uint8_t faults) const
{
	can::StatusData status;
	status.state = state;
	status.enabled = enabled_;
	status.strobe = toCan(strobe_mode_);
	status.faults = faults;
	return status;
}

/* One report: the pose frames (when `pose` is given) and the status frame. Returns the frames. */
int Daemon::sendReport(const can::StatusData &status, const can::PoseData *pose,
		       std::int64_t deadline_ns)
{
	can::RawFrame frames[can::kMaxReportFrames];
	const int n = encoder_.encodeReport(status, pose, frames);
	can::FdFrame fd;
	if (config_.can.fd && can::packFd(frames, n, config_.can.base_id, &fd)) {
		if (!backends_.can->send(toHalFrame(fd, deadline_ns)))
			++stats_.can_send_drops;
		return n;
	}
	sendFrames(frames, n, deadline_ns);
	return n;
}

void Daemon::sendFrames(const can::RawFrame *frames, int count, std::int64_t deadline_ns)
{
	for (int i = 0; i < count; ++i)
		if (!backends_.can->send(toHalFrame(frames[i], deadline_ns)))
			++stats_.can_send_drops;
}

/* With can.key_file: the key, the next run number, and the encoder and the command decoder
 * switched to authenticated frames. Without: said once. */
hal::Status Daemon::startAuthentication()
{
	if (config_.can.key_file.empty()) {
		std::fprintf(log_, "dockposed: CAN frames are not authenticated (no can.key_file): "
				   "anyone on the bus can command the sensor or forge its poses\n");
		return hal::Status::ok();
	}
	std::array<std::uint8_t, can::kKeyBytes> key{};
	if (auto s = loadCanKey(config_.can.key_file, &key); !s)
		return hal::Status::error("can: " + s.message());
	const bool keyed = cmac_.setKey(key);
	key.fill(0);
	if (!keyed)
		return hal::Status::error("can: OpenSSL has no AES-128 CMAC");
	std::uint32_t run = 0;
	if (auto s = nextRunNumber(config_.can.run_counter_file, &run); !s)
		return hal::Status::error("can: " + s.message());
	encoder_.setAuthenticator(&cmac_, static_cast<std::uint64_t>(run) << 32);
	command_decoder_.setAuthenticator(&cmac_);
	command_decoder_.setCommandFreshness(&encoder_, kCommandFreshnessWindow);
	std::fprintf(log_, "dockposed: CAN frames authenticated (AES-128-CMAC, key %s, run %u)\n",
		     config_.can.key_file.c_str(), run);
	return hal::Status::ok();
}

/* preview.enabled: the shared-memory ring, every Nth frame. Optional: a preview that cannot be
 * set up is said once and left off; the sensor runs without it. */
bool Daemon::startPreview()
{
	const auto &k = pipeline_->camera().intrinsics();
	if (auto s = preview_.open(config_.preview.name, k.width, k.height, config_.preview.width);
	    !s) {
		std::fprintf(log_, "dockposed: %s; running without it\n", s.message().c_str());
		return false;
	}
	preview_on_ = true;
	/* The worker holds one camera buffer while it downscales: only with two more capturing. */
	bool worker = false;
	if (config_.camera.buffer_count >= 3) {
		if (auto s = preview_worker_.start(&preview_, *pipeline_); s)
			worker = true;
		else
			std::fprintf(log_, "dockposed: %s; publishing in the frame loop\n",
				     s.message().c_str());
	}
	preview_every_ = std::max(
		1, static_cast<int>(std::ceil(
			   config_.camera.frame_rate_hz / config_.preview.rate_hz - 1e-9)));
	preview_count_ = preview_every_ - 1; /* the first frame goes out */
	std::fprintf(log_, "dockposed: preview /dev/shm/%s: every %d frames, %dx%d px, %s\n",
		     config_.preview.name.c_str(), preview_every_, preview_.width(),
		     preview_.height(), worker ? "on a worker thread" : "in the frame loop");
	return true;
}

void Daemon::handleCommands()
{
	hal::CanFrame in;
	while (backends_.can->receive(&in)) {
		const can::Decoder::Event event = command_decoder_.feed(toRawFrame(in));
		if (event == can::Decoder::Event::Command)
			applyCommand(command_decoder_.command());
		else if (event == can::Decoder::Event::Rejected)
			commandRejected(in.id);
	}
	/* A command held for its MAC frame that does not come: refused (a bare command to a
	 * keyed sensor is flagged now, not when the next command arrives). */
	if (!command_decoder_.commandPending()) {
		command_pending_since_ns_ = 0;
	} else if (const std::int64_t now_ns = hal::monotonicNs(); command_pending_since_ns_ == 0) {
		command_pending_since_ns_ = now_ns;
	} else if (now_ns - command_pending_since_ns_ >= kCommandAuthWaitNs) {
		command_pending_since_ns_ = 0;
		if (command_decoder_.dropPendingCommand() == can::Decoder::Event::Rejected)
			commandRejected(config_.can.base_id + can::kCommand);
	}
}

void Daemon::commandRejected(std::uint32_t can_id)
{
	++stats_.commands_rejected;
	const std::int64_t now_ns = hal::monotonicNs();
	command_rejected_.raise(now_ns);
	/* A flood of forged frames must not flood the journal: one line a second. */
	++rejects_unlogged_;
	if (now_ns - last_reject_log_ns_ >= kNsPerS) {
		std::fprintf(log_,
			     "dockposed: command frame 0x%03x rejected: %s (%llu "
			     "rejected since the last such line)\n",
			     can_id, can::frameErrorName(command_decoder_.lastError()),
			     static_cast<unsigned long long>(rejects_unlogged_));
		rejects_unlogged_ = 0;
		last_reject_log_ns_ = now_ns;
	}
}

void Daemon::applyCommand(const can::CommandData &command)
{
	/* Check before changing anything: a command is applied whole or not at all. */
	const int exposure_us = command.exposure_us ? command.exposure_us : exposure_us_;
	const double gain = command.gain > 0 ? command.gain : gain_;
	const double period_us = static_cast<double>(period_ns_) / 1000.0;
	if (exposure_us < 10 || exposure_us > period_us || gain < 1.0 || gain > 64.0) {
		++stats_.commands_rejected;
		command_rejected_.raise(hal::monotonicNs());
		std::fprintf(
			log_,
			"dockposed: command rejected: exposure %d us / gain %.1f outside [10, %.0f] us / [1, 64]\n",
			exposure_us, gain, period_us);
		return;
	}
	/* The preview: 3 is reserved; on needs the ring, opened now if it is not yet (allocates:
	 * a command, not a frame). */
	if (command.preview == can::PreviewSwitch::Reserved ||
	    (command.preview == can::PreviewSwitch::On && !preview_.isOpen() && !startPreview())) {
		++stats_.commands_rejected;
		command_rejected_.raise(hal::monotonicNs());
		std::fprintf(log_, "dockposed: command rejected: preview %s\n",
			     command.preview == can::PreviewSwitch::Reserved
				     ? "3 is reserved"
				     : "on, but its ring cannot be opened");
		return;
	}
	++stats_.commands;

	if (command.preview != can::PreviewSwitch::Unchanged) {
		const bool on = command.preview == can::PreviewSwitch::On;
		if (on != preview_on_) {
			preview_on_ = on;
			preview_count_ = preview_every_ - 1; /* on: the next frame goes out */
			std::fprintf(log_, "dockposed: command: preview %s\n", on ? "on" : "off");
		}
	}

	if (exposure_us != exposure_us_ || gain != gain_) {
		if (auto s = backends_.camera->setControls(exposure_us, gain); s) {
			exposure_us_ = exposure_us;
			gain_ = gain;
			pipeline_->readWhole(kWholeFramesAfterLightChange);
		} else {
			std::fprintf(log_, "dockposed: camera controls: %s\n", s.message().c_str());
		}
	}
	const TrackMode mode = fromCan(command.mode);
	const StrobeMode strobe = fromCan(command.strobe).value_or(strobe_mode_);
	const bool changed = command.enable != enabled_ || mode != track_mode_ ||
			     strobe != strobe_mode_;
	enabled_ = command.enable;
	if (mode != track_mode_) {
		track_mode_ = mode;
		pipeline_->reset();
	}
	if (changed) {
		std::fprintf(log_,
			     "dockposed: command: %s, %s, strobe %s, exposure %d us, gain %.1f\n",
			     enabled_ ? "enabled" : "disabled",
			     mode == TrackMode::Track ? "track" : "search only",
			     strobeModeName(strobe), exposure_us_, gain_);
		applyStrobeMode(strobe);
	}
	/* An unchanged command changes nothing: controllers repeat theirs cyclically, and
	 * re-applying the strobe mode would restart alternate mode's schedule every time. */
}

void Daemon::applyStrobeMode(StrobeMode mode)
{
	if (pipeline_ && mode != strobe_mode_)
		pipeline_->readWhole(kWholeFramesAfterLightChange);
	strobe_mode_ = mode;
	alternate_.restart();
	hal::StrobeController &control = *backends_.strobe_control;
	if (!enabled_ || stalled_) {
		control.setOn(false);
		return;
	}
	switch (mode) {
	case StrobeMode::Off:
		control.setOn(false);
		break;
	case StrobeMode::Constant:
		control.setOn(true);
		break;
	case StrobeMode::Alternate:
		control.setOn(false); /* pulses are scheduled frame by frame */
		break;
	}
}

std::uint8_t Daemon::activeFaults(std::int64_t now_ns)
{
	const hal::CameraStats camera = backends_.camera->stats();
	frames_dropped_.raiseOnChange(camera.dropped, now_ns);
	const hal::CanStats can_stats = backends_.can->stats();
	/* Frames that never left: a full queue, or reports that outlived can.max_report_age_us. */
	can_overflow_.raiseOnChange(can_stats.tx_dropped + can_stats.tx_expired, now_ns);
	strobe_error_.raiseOnChange(backends_.strobe_control->errorCount(), now_ns);

	std::uint8_t faults = 0;
	if (stalled_ && !camera_failed_)
		faults |= can::fault::kCameraStall;
	if (camera_failed_)
		faults |= can::fault::kCameraError;
	if (strobe_error_.active(now_ns) || backends_.strobe_control->stalled())
		faults |= can::fault::kStrobeError;
	if (can_overflow_.active(now_ns))
		faults |= can::fault::kCanTxOverflow;
	/* Down: the interface is missing or down, and frames wait in the queue for it. Held for a
	 * second after it (and after every bus-off event): the frames made during it mostly expire
	 * unsent, so it is the statuses and heartbeats after the recovery that say it (the soak,
	 * docs/soak.md, saw 19 of 33 bus-offs go unreported without the hold). */
	bus_off_.raiseOnChange(can_stats.bus_off, now_ns);
	if (can_stats.state == hal::CanState::BusOff || can_stats.state == hal::CanState::Down)
		bus_off_.raise(now_ns);
	if (bus_off_.active(now_ns))
		faults |= can::fault::kCanBusOff;
	if (frames_dropped_.active(now_ns))
		faults |= can::fault::kFramesDropped;
	if (overrun_.active(now_ns))
		faults |= can::fault::kLoopOverrun;
	if (command_rejected_.active(now_ns))
		faults |= can::fault::kCommandRejected;
	last_faults_ = faults;
	return faults;
}

void Daemon::logState(SensorState before, SensorState after, std::uint64_t sequence)
{
	if (before == after)
		return;
	std::fprintf(log_, "dockposed: %s -> %s (frame %llu)\n", can::sensorStateName(before),
		     can::sensorStateName(after), static_cast<unsigned long long>(sequence));
}

void Daemon::logCanLink()
{
	const hal::CanStats can_stats = backends_.can->stats();
	const bool down = can_stats.state == hal::CanState::Down;
	if (down == can_down_)
		return;
	can_down_ = down;
	if (down)
		std::fprintf(log_, "dockposed: %s\n", backends_.can->lastError().c_str());
	else
		std::fprintf(log_, "dockposed: can: %s is up (restarts %llu)\n",
			     backends_.can->name().c_str(),
			     static_cast<unsigned long long>(can_stats.restarts));
}

void Daemon::updateSystemdStatus(std::int64_t now_ns)
{
	if (!notifier_.active() || now_ns - last_systemd_status_ns_ < kNsPerS)
		return;
	last_systemd_status_ns_ = now_ns;
	char text[160];
	std::snprintf(text, sizeof(text), "%s, %.1f frames/s, %llu poses, latency p50 %.2f ms%s",
		      can::sensorStateName(state_machine_.state()), frame_rate_hz_,
		      static_cast<unsigned long long>(stats_.poses_valid),
		      stats_.latency.quantileMs(0.5), can_down_ ? ", CAN down" : "");
	notifier_.status(text);
}

void Daemon::printSummary(std::FILE *out) const
{
	const hal::CameraStats camera = backends_.camera->stats();
	const hal::CanStats can_stats = backends_.can->stats();
	std::fprintf(
		out,
		"dockposed: %.1f s: %llu frames (%.1f/s; lit %llu, unlit %llu, mixed %llu, dropped %llu), "
		"%llu reports, %llu valid poses; latency p50 %.2f ms, p99 %.2f ms, max %.2f ms; "
		"pipeline p50 %.2f ms; CAN %llu frames sent, %llu dropped; %llu frames numbered but "
		"never seen, %llu rejected (wrong size)\n",
		stats_.run_s, static_cast<unsigned long long>(stats_.frames),
		stats_.run_s > 0 ? static_cast<double>(stats_.frames) / stats_.run_s : 0.0,
		static_cast<unsigned long long>(stats_.frames_lit),
		static_cast<unsigned long long>(stats_.frames_unlit),
		static_cast<unsigned long long>(stats_.frames_mixed),
		static_cast<unsigned long long>(camera.dropped),
		static_cast<unsigned long long>(stats_.reports),
		static_cast<unsigned long long>(stats_.poses_valid), stats_.latency.quantileMs(0.5),
		stats_.latency.quantileMs(0.99), stats_.latency.maxMs(),
		stats_.pipeline.quantileMs(0.5),
		static_cast<unsigned long long>(can_stats.tx_frames),
		static_cast<unsigned long long>(can_stats.tx_dropped),
		static_cast<unsigned long long>(stats_.sequence_gaps),
		static_cast<unsigned long long>(stats_.frames_bad));
}

} /* namespace dockpose::firmware */

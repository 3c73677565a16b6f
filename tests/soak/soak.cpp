/* SPDX-License-Identifier: MIT */
/*
 * dockpose_soak: the sim board at 60 frames/s for a long run, with faults injected on a schedule,
 * authenticated CAN, and the arm controller's side decoding with the header-only decoder, its key
 * and the frames' wire times. docs/soak.md says what it injects and asserts, and the figures of
 * the 10-minute run (scripts/soak); ctest runs a short one (label soak).
 *
 *   dockpose_soak [--duration-s S] [--seed N] [--keep-log]
 *
 * One fault cycle (about 17.5 s), in constant strobe / track mode unless said:
 *   camera stall 1 s; stall 3.2 s whose first restart fails; camera unplugged 2.5 s and plugged
 *   back; bus-off 0.5 s; three 200 ms blocked-bus bursts (frames wait, as on ENOBUFS); a genuine
 *   command (alternate strobe, search only); strobe errors for 300 ms (every LED switch fails);
 *   a 2 s command flood (random frames with valid CRCs on the command ids, a few on the
 *   sensor's, commands signed with another key, replays of the last genuine command, bare
 *   commands) with a genuine command in it (constant strobe, track).
 *
 * Checked (any failure: exit status 1, each one named):
 *   1. no stale pose: every pose the controller accepts crossed the bus at most one frame
 *      period after the sensor stamped it (wire time against SensorTimeUs, both
 *      CLOCK_MONOTONIC here), its age by the decoder is within the decoder's bound, the
 *      decoder counts no stale pose, and every accepted pose is the truth of its frame (a
 *      forged one would not be);
 *   2. no command but the genuine ones is taken: every mode the heartbeats show is the start's
 *      or a genuine command's, and the daemon applied no more commands than were sent signed;
 *   3. memory flat: resident set size drift at most 1 % from the end of the first fault cycle
 *      (every path, restarts and floods included, has run once) to the end;
 *   4. every fault injected is reported (its fault bit in an authenticated status or heartbeat
 *      within its bound after the injection) and recovered from (an accepted pose within its
 *      bound after the fault cleared);
 *   5. the daemon runs until it is stopped, then exits with status 0 and the LED off.
 */
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>

#include "algo/pose.h"
#include "board/sim/sim_board.h"
#include "firmware/can_frames.h"
#include "firmware/config.h"
#include "firmware/daemon.h"
#include "firmware/protocol/dockpose_can.h"
#include "firmware/protocol/dockpose_can_cmac.h"
#include "hal/clock.h"
#include "hal/sim/loopback_can_bus.h"
#include "hal/sim/recording_strobe.h"
#include "hal/sim/synthetic_camera.h"

namespace dockpose::soak {
namespace {

constexpr std::int64_t kNsPerMs = 1000000;
constexpr std::int64_t kNsPerS = 1000000000;
constexpr std::int64_t kTickNs = 2 * kNsPerMs;
constexpr std::uint32_t kBase = can::kDefaultBaseId;

/* The bits of the faults the soak injects: a settled sensor shows none of them. */
constexpr std::uint8_t kInjectedBits = can::fault::kCameraStall | can::fault::kCameraError |
				       can::fault::kStrobeError | can::fault::kCanTxOverflow |
				       can::fault::kCanBusOff | can::fault::kCommandRejected;

enum class Kind : std::uint8_t {
	Stall,
	StallFailedRestart,
	Unplug,
	BusOff,
	BlockedBursts,
	StrobeErrors,
	CommandFlood,
};
constexpr int kKinds = 7;

struct KindSpec {
	const char *name;
	std::uint8_t bit; /* the fault bit that reports it */
	std::int64_t report_bound_ns; /* from the injection */
	std::int64_t recovery_bound_ns; /* from the end of the fault */
};

/* Bounds: a stall is declared after stall_timeout_ms (200 ms) and restarted every 2 s; nothing
 * crosses a bus that is off or blocked, so those bounds include the fault's length. */
constexpr std::array<KindSpec, kKinds> kSpecs{ {
	{ "camera stall 1 s", can::fault::kCameraStall, 1000 * kNsPerMs, 3000 * kNsPerMs },
	{ "camera stall 3.2 s, a restart fails", can::fault::kCameraStall, 1000 * kNsPerMs,
	  4000 * kNsPerMs },
	{ "camera unplugged 2.5 s", can::fault::kCameraError, 500 * kNsPerMs, 4500 * kNsPerMs },
	{ "bus-off 0.5 s", can::fault::kCanBusOff, 1000 * kNsPerMs, 2000 * kNsPerMs },
	{ "blocked bus 3 x 200 ms", can::fault::kCanTxOverflow, 1000 * kNsPerMs, 2000 * kNsPerMs },
	{ "strobe errors 300 ms", can::fault::kStrobeError, 1000 * kNsPerMs, 3000 * kNsPerMs },
	{ "command flood 2 s", can::fault::kCommandRejected, 1000 * kNsPerMs, 3000 * kNsPerMs },
} };

struct KindStats {
	int injected = 0;
	int reported = 0;
	int recovered = 0;
	std::int64_t max_report_ns = 0;
	std::int64_t max_recovery_ns = 0;
};

/* The settings the arm controller can change, as the heartbeat shows them. */
struct Mode {
	can::TrackMode track = can::TrackMode::Track;
	can::StrobeMode strobe = can::StrobeMode::Constant;
	bool enabled = true;

	bool operator==(const Mode &) const = default;
};

struct Options {
	double duration_s = 80.0;
	std::uint64_t seed = 1;
	bool keep_log = false;
};

double rssKb()
{
	std::ifstream statm("/proc/self/statm");
	long size = 0, resident = 0;
	statm >> size >> resident;
	return static_cast<double>(resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) /
	       1024.0;
}

double seconds(std::int64_t ns)
{
	return static_cast<double>(ns) * 1e-9;
}

class Soak
{
public:
	explicit Soak(const Options &options);
	~Soak();
	int run();

private:
	/* Setup. */
	bool prepare();

	/* The controller's side: decode what arrived, with its wire time. */
	void pump();
	void onReport(std::int64_t arrival_ns);
	void onHeartbeat(std::int64_t arrival_ns);
	/* Where the schedule is, for messages. */
	const char *phase();
	void failure(const char *what, ...) __attribute__((format(printf, 2, 3)));

	/* The controller for `ns`, a tick() and a pump() every kTickNs. */
	void runFor(std::int64_t ns);
	/* Until pred() or the timeout; whether pred() held. */
	template<typename Pred>
	bool runUntil(Pred pred, std::int64_t timeout_ns);

	/* Faults. */
	void inject(Kind kind);
	void cleared();
	void finishFault();
	void settle();
	void cycle();

	bool sendGenuine(const can::CommandData &command, Mode target);
	/* What runs every kTickNs besides the decoding: the flood, the strobe errors. */
	void tick();
	void floodTick();
	void sendAttacker(const can::RawFrame *frames, int n);

	bool stopDaemon();
	void summary(bool stopped_ok);

	Options options_;
	std::mt19937_64 rng_;
	std::string dir_;
	std::string log_path_;
	std::FILE *log_ = nullptr;
	firmware::BoardConfig config_;
	std::array<std::uint8_t, can::kKeyBytes> key_{};

	std::shared_ptr<hal::LoopbackHub> hub_;
	hal::LoopbackCanBus *sensor_bus_ = nullptr; /* the daemon's end */
	hal::RecordingStrobe *strobe_ = nullptr;
	hal::SyntheticCamera *camera_ = nullptr;
	std::unique_ptr<firmware::Daemon> daemon_;
	std::unique_ptr<hal::LoopbackCanBus> controller_;
	std::unique_ptr<hal::LoopbackCanBus> attacker_;
	std::thread thread_;
	std::atomic<bool> stop_{ false };
	std::atomic<bool> finished_{ false };
	int exit_status_ = -1;

	can::OpensslCmac controller_mac_;
	can::OpensslCmac forger_mac_;
	can::Decoder decoder_{ kBase };
	can::Encoder command_encoder_{ kBase };
	can::Encoder forger_{ kBase };
	can::Encoder bare_{ kBase };

	std::int64_t t0_ns_ = 0;
	std::int64_t max_wait_bound_us_ = 0;
	int failures_ = 0;

	/* Freshness (1). */
	std::int64_t last_quality_wait_us_ = -1;
	std::uint64_t poses_ = 0;
	std::uint64_t stale_accepted_ = 0;
	std::uint64_t wrong_poses_ = 0;
	std::int64_t max_wait_us_ = 0;
	std::int64_t max_age_us_ = 0;
	double max_latency_ms_ = 0.0;
	std::uint64_t stale_refused_ = 0;
	double max_stale_latency_ms_ = 0.0;
	std::int64_t last_pose_ns_ = 0;
	std::uint8_t last_faults_ = 0xff;

	/* Commands (2). */
	bool have_mode_ = false;
	Mode mode_;
	bool pending_ = false;
	Mode pending_mode_;
	std::uint64_t genuine_sent_ = 0;
	std::uint64_t genuine_seen_ = 0; /* mode changes to a genuine command's */
	std::uint64_t foreign_modes_ = 0; /* heartbeats showing a mode nobody genuine asked for */
	std::uint64_t last_echo_ = 0;
	std::array<can::RawFrame, can::kMaxCommandFrames> last_genuine_{};
	bool have_genuine_ = false;
	std::uint64_t random_sent_ = 0;
	std::uint64_t forged_sent_ = 0;
	std::uint64_t replays_sent_ = 0;
	std::uint64_t bare_sent_ = 0;

	/* Memory (3). */
	double rss_warm_kb_ = 0.0;
	double rss_end_kb_ = 0.0;
	double rss_max_kb_ = 0.0;
	std::int64_t warm_ns_ = 0;

	/* Faults (4). */
	bool flooding_ = false;
	std::uint64_t flood_ticks_ = 0;
	bool strobe_failing_ = false;
	bool active_ = false;
	Kind kind_ = Kind::Stall;
	std::int64_t injected_ns_ = 0;
	std::int64_t cleared_ns_ = 0;
	std::int64_t reported_ns_ = 0;
	std::int64_t recovered_ns_ = 0;
	std::uint8_t bits_seen_ =
		0; /* every fault bit in statuses and heartbeats since injection */
	std::array<KindStats, kKinds> kinds_{};
	int cycles_ = 0;
	std::array<char, 96> phase_{};
};

Soak::Soak(const Options &options)
	: options_(options),
	  rng_(options.seed)
{
}

Soak::~Soak()
{
	stop_ = true;
	if (thread_.joinable())
		thread_.join();
	daemon_.reset();
	if (log_)
		std::fclose(log_);
	if (!dir_.empty() && failures_ == 0 && !options_.keep_log)
		std::filesystem::remove_all(dir_);
}

void Soak::failure(const char *what, ...)
{
	++failures_;
	std::va_list args;
	va_start(args, what);
	std::fprintf(stdout, "soak: FAILED at %.1f s: ", seconds(hal::monotonicNs() - t0_ns_));
	std::vfprintf(stdout, what, args);
	std::fputc('\n', stdout);
	std::fflush(stdout);
	va_end(args);
}

bool Soak::prepare()
{
	char dir[] = "/tmp/dockpose-soak.XXXXXX";
	if (!::mkdtemp(dir)) {
		std::perror("soak: mkdtemp");
		return false;
	}
	dir_ = dir;
	const std::string key_path = dir_ + "/can.key";
	for (std::size_t i = 0; i < key_.size(); ++i)
		key_[i] = static_cast<std::uint8_t>(rng_());
	{
		std::ofstream key_file(key_path);
		for (std::uint8_t b : key_) {
			char hex[3];
			std::snprintf(hex, sizeof hex, "%02x", b);
			key_file << hex;
		}
		key_file << '\n';
	}
	::chmod(key_path.c_str(), 0600);

	firmware::ConfigResult loaded = firmware::loadBoardConfig(std::string(DOCKPOSE_SOURCE_DIR) +
								  "/board/sim/board.json");
	if (!loaded.ok()) {
		std::fprintf(stderr, "soak: board/sim/board.json: %s\n",
			     loaded.errors.empty() ? "?" : loaded.errors.front().c_str());
		return false;
	}
	config_ = loaded.config;
	config_.can.backend = "loopback";
	config_.camera.frame_rate_hz = 60.0;
	config_.camera.synthetic.loop = true;
	config_.camera.stall_timeout_ms = 200;
	config_.systemd.notify = false;
	config_.can.key_file = key_path;
	config_.can.run_counter_file = dir_ + "/run";
	max_wait_bound_us_ = config_.camera.frameDurationUs();

	log_path_ = dir_ + "/dockposed.log";
	log_ = std::fopen(log_path_.c_str(), "w");
	if (!log_) {
		std::perror("soak: daemon log");
		return false;
	}
	std::setvbuf(log_, nullptr, _IOLBF, 0);

	hub_ = std::make_shared<hal::LoopbackHub>();
	board::Backends backends;
	auto sensor_bus = std::make_unique<hal::LoopbackCanBus>(hub_, "sensor");
	sensor_bus_ = sensor_bus.get();
	if (auto s = board::wireSimulated(config_, std::move(sensor_bus), &backends); !s) {
		std::fprintf(stderr, "soak: wiring: %s\n", s.message().c_str());
		return false;
	}
	/* The sim wiring's types (board.json's camera.backend is "synthetic"). */
	strobe_ = static_cast<hal::RecordingStrobe *>(backends.strobe.get());
	camera_ = static_cast<hal::SyntheticCamera *>(backends.camera.get());
	daemon_ = std::make_unique<firmware::Daemon>(config_, std::move(backends), log_);

	/* The controller takes the sensor's ids (base .. base + 0xf), as a controller would. */
	const hal::CanFilter sensor_ids{ kBase, 0x7f0, false };
	controller_ = std::make_unique<hal::LoopbackCanBus>(hub_, "controller");
	attacker_ = std::make_unique<hal::LoopbackCanBus>(hub_, "attacker");
	if (!controller_->open(std::span<const hal::CanFilter>(&sensor_ids, 1),
			       hal::CanOptions{}) ||
	    !attacker_->open({}, hal::CanOptions{})) {
		std::fprintf(stderr, "soak: cannot open the controller's or the attacker's bus\n");
		return false;
	}
	std::array<std::uint8_t, can::kKeyBytes> other = key_;
	other[0] ^= 0x01;
	if (!controller_mac_.setKey(key_) || !forger_mac_.setKey(other)) {
		std::fprintf(stderr, "soak: OpenSSL has no AES-128 CMAC\n");
		return false;
	}
	decoder_.setAuthenticator(&controller_mac_);
	command_encoder_.setAuthenticator(&controller_mac_);
	forger_.setAuthenticator(&forger_mac_);
	return true;
}

void Soak::pump()
{
	hal::CanFrame f;
	while (controller_->receive(&f)) {
		const can::RawFrame raw = firmware::toRawFrame(f);
		const std::int64_t arrival_us = f.timestamp_ns / 1000;
		const can::Decoder::Event event = firmware::feedDecoder(decoder_, f, arrival_us);
		/* The wait of the report's DP_Quality as the decoder took it (a frame it refused is
		 * in no report): its wire time against the sensor's stamp. */
		if (raw.id == kBase + can::kQuality && event != can::Decoder::Event::Rejected) {
			const auto sensor_us = static_cast<std::uint32_t>(
				can::detail::get(raw.data, can::layout::kSensorTime));
			last_quality_wait_us_ = static_cast<std::int32_t>(
				static_cast<std::uint32_t>(arrival_us) - sensor_us);
		}
		if (event == can::Decoder::Event::Report)
			onReport(f.timestamp_ns);
		else if (event == can::Decoder::Event::Heartbeat)
			onHeartbeat(f.timestamp_ns);
	}
	if (finished_.load() && !stop_.load())
		failure("the daemon's run ended by itself (exit status %d)", exit_status_);
}

const char *Soak::phase()
{
	if (!active_)
		return "between faults";
	std::snprintf(phase_.data(), phase_.size(), "%s %s", cleared_ns_ ? "after" : "during",
		      kSpecs[static_cast<int>(kind_)].name);
	return phase_.data();
}

void Soak::onReport(std::int64_t arrival_ns)
{
	const can::StatusData &status = decoder_.status();
	last_faults_ = status.faults;
	if (active_ && arrival_ns >= injected_ns_)
		bits_seen_ |= status.faults;
	if (active_ && !reported_ns_ && arrival_ns >= injected_ns_ &&
	    (status.faults & kSpecs[static_cast<int>(kind_)].bit))
		reported_ns_ = arrival_ns;
	if (!decoder_.poseValid()) {
		/* A complete report the decoder refused as too old: what made it old. */
		if (status.pose_valid && decoder_.poseAgeUs() > decoder_.maxAgeUs()) {
			max_stale_latency_ms_ = std::max(max_stale_latency_ms_, status.latency_ms);
			if (++stale_refused_ <= 10)
				std::printf(
					"soak: at %.1f s the decoder refused a stale pose: age %.2f ms, "
					"latency (exposure to send) %.2f ms, wait on the way %.2f ms, "
					"faults 0x%02x, %s\n",
					seconds(arrival_ns - t0_ns_),
					static_cast<double>(decoder_.poseAgeUs()) * 1e-3,
					status.latency_ms,
					static_cast<double>(last_quality_wait_us_) * 1e-3,
					status.faults, phase());
			std::fflush(stdout);
		}
		return;
	}

	++poses_;
	last_pose_ns_ = arrival_ns;
	const std::int64_t wait_us = last_quality_wait_us_;
	const std::int64_t age_us = decoder_.poseAgeUs();
	max_wait_us_ = std::max(max_wait_us_, wait_us);
	max_latency_ms_ = std::max(max_latency_ms_, status.latency_ms);
	max_age_us_ = std::max(max_age_us_, age_us);
	if (wait_us < 0 || wait_us > max_wait_bound_us_ || age_us < 0 ||
	    age_us > decoder_.maxAgeUs()) {
		if (++stale_accepted_ <= 5)
			failure("a stale pose was accepted: frame %u waited %.2f ms on the way "
				"(bound %.2f ms), age by the decoder %.2f ms",
				decoder_.pose().frame_counter, static_cast<double>(wait_us) * 1e-3,
				static_cast<double>(max_wait_bound_us_) * 1e-3,
				static_cast<double>(age_us) * 1e-3);
	}

	/* The truth of its frame, at the vision core's bar (rotation 2 deg, translation
	 * max(5 mm, 2 % of the range)): a forged or mixed-up pose would not be. */
	const can::PoseData &pose = decoder_.pose();
	const Pose truth = camera_->truthAt(pose.frame_counter);
	const Eigen::Vector3d t(pose.t_mm[0], pose.t_mm[1], pose.t_mm[2]);
	const double trans_err_mm = (t - truth.t_mm).norm();
	const Eigen::Quaterniond q(pose.q[0], pose.q[1], pose.q[2], pose.q[3]);
	const double rot_err_deg =
		q.normalized().angularDistance(Eigen::Quaterniond(truth.R)) * 180.0 / M_PI;
	if (trans_err_mm > std::max(5.0, 0.02 * truth.t_mm.norm()) || rot_err_deg > 2.0) {
		if (++wrong_poses_ <= 5)
			failure("a wrong pose was accepted: frame %u off by %.1f mm, %.2f deg",
				pose.frame_counter, trans_err_mm, rot_err_deg);
	}

	if (active_ && cleared_ns_ && !recovered_ns_ && arrival_ns >= cleared_ns_)
		recovered_ns_ = arrival_ns;
}

void Soak::onHeartbeat(std::int64_t arrival_ns)
{
	const can::HeartbeatData &hb = decoder_.heartbeat();
	if (active_ && arrival_ns >= injected_ns_)
		bits_seen_ |= hb.faults;
	if (active_ && !reported_ns_ && arrival_ns >= injected_ns_ &&
	    (hb.faults & kSpecs[static_cast<int>(kind_)].bit))
		reported_ns_ = arrival_ns;

	const Mode seen{ hb.mode, hb.strobe, hb.enabled };
	if (!have_mode_) {
		mode_ = seen;
		have_mode_ = true;
		return;
	}
	if (seen == mode_)
		return;
	if (pending_ && seen == pending_mode_) {
		mode_ = seen;
		pending_ = false;
		++genuine_seen_;
		return;
	}
	if (++foreign_modes_ <= 5)
		failure("the heartbeat shows a mode nobody genuine asked for: %s, strobe %d, %s",
			hb.mode == can::TrackMode::Track ? "track" : "search only",
			static_cast<int>(hb.strobe), hb.enabled ? "enabled" : "disabled");
}

void Soak::tick()
{
	if (flooding_)
		floodTick();
	if (strobe_failing_)
		strobe_->failNextSet("soak: injected strobe error");
}

void Soak::runFor(std::int64_t ns)
{
	const std::int64_t end_ns = hal::monotonicNs() + ns;
	while (hal::monotonicNs() < end_ns) {
		tick();
		pump();
		const timespec ts{ 0, kTickNs };
		::nanosleep(&ts, nullptr);
	}
	pump();
}

template<typename Pred>
bool Soak::runUntil(Pred pred, std::int64_t timeout_ns)
{
	const std::int64_t end_ns = hal::monotonicNs() + timeout_ns;
	for (;;) {
		tick();
		pump();
		if (pred())
			return true;
		if (hal::monotonicNs() >= end_ns)
			return false;
		const timespec ts{ 0, kTickNs };
		::nanosleep(&ts, nullptr);
	}
}

void Soak::inject(Kind kind)
{
	active_ = true;
	kind_ = kind;
	injected_ns_ = hal::monotonicNs();
	cleared_ns_ = 0;
	reported_ns_ = 0;
	recovered_ns_ = 0;
	bits_seen_ = 0;
	++kinds_[static_cast<int>(kind)].injected;
}

void Soak::cleared()
{
	cleared_ns_ = hal::monotonicNs();
}

/* Wait for the report and the recovery within their bounds, then count them. */
void Soak::finishFault()
{
	const KindSpec &spec = kSpecs[static_cast<int>(kind_)];
	KindStats &k = kinds_[static_cast<int>(kind_)];
	const std::int64_t report_by_ns = injected_ns_ + spec.report_bound_ns;
	const std::int64_t recover_by_ns = cleared_ns_ + spec.recovery_bound_ns;
	runUntil([&] { return reported_ns_ && recovered_ns_; },
		 std::max(report_by_ns, recover_by_ns) - hal::monotonicNs());
	if (reported_ns_ && reported_ns_ <= report_by_ns) {
		++k.reported;
		k.max_report_ns = std::max(k.max_report_ns, reported_ns_ - injected_ns_);
	} else {
		failure("%s: not reported within %.1f s of the injection (%s; fault bits seen "
			"since: 0x%02x)",
			spec.name, seconds(spec.report_bound_ns),
			reported_ns_ ? "reported later" : "never reported", bits_seen_);
	}
	if (recovered_ns_ && recovered_ns_ <= recover_by_ns) {
		++k.recovered;
		k.max_recovery_ns = std::max(k.max_recovery_ns, recovered_ns_ - cleared_ns_);
	} else {
		/* Not recovered in time: wait longer, to tell late from never. */
		if (!recovered_ns_)
			runUntil([&] { return recovered_ns_ != 0; }, 10 * kNsPerS);
		failure("%s: no pose within %.1f s after it ended (%s)", spec.name,
			seconds(spec.recovery_bound_ns),
			recovered_ns_ ? "a pose came later" : "none in 10 s more");
	}
	active_ = false;
}

/* Until the last status shows none of the injected faults' bits (event bits hold 1 s) and poses
 * come, so that the next fault's report and recovery are its own. */
void Soak::settle()
{
	if (!runUntil(
		    [&] {
			    return (last_faults_ & kInjectedBits) == 0 &&
				   hal::monotonicNs() - last_pose_ns_ < 100 * kNsPerMs;
		    },
		    5 * kNsPerS))
		failure("the sensor did not settle (faults 0x%02x, last pose %.1f s ago)",
			last_faults_, seconds(hal::monotonicNs() - last_pose_ns_));
}

void Soak::sendAttacker(const can::RawFrame *frames, int n)
{
	for (int i = 0; i < n; ++i)
		(void)attacker_->send(firmware::toHalFrame(frames[i]));
	attacker_->poll();
}

/* A command signed with the controller's key, answering the newest sensor freshness value the
 * controller verified (a newer one than the last command's), until the heartbeat shows it. */
bool Soak::sendGenuine(const can::CommandData &command, Mode target)
{
	for (int attempt = 0; attempt < 5; ++attempt) {
		if (!runUntil([&] { return decoder_.freshness() > last_echo_; }, 3 * kNsPerS))
			continue;
		last_echo_ = decoder_.freshness();
		const int n =
			command_encoder_.encodeCommand(command, last_echo_, last_genuine_.data());
		for (int i = 0; i < n; ++i)
			(void)controller_->send(
				firmware::toHalFrame(last_genuine_[static_cast<std::size_t>(i)]));
		controller_->poll();
		have_genuine_ = true;
		++genuine_sent_;
		pending_ = true;
		pending_mode_ = target;
		if (runUntil([&] { return !pending_; }, 700 * kNsPerMs))
			return true;
	}
	failure("a genuine command was not taken in 5 attempts");
	pending_ = false;
	return false;
}

/* One tick (2 ms) of the flood: random frames with valid CRCs on the command ids (about 1000 a
 * second), now and then one on a sensor id (the controller must refuse those), and a forged, a
 * replayed and a bare command. */
void Soak::floodTick()
{
	static constexpr std::array<std::uint32_t, 10> kSensorOffsets{
		can::kTranslation, can::kQuatA,	    can::kQuatB,   can::kAngles, can::kSigma,
		can::kStatus,	   can::kHeartbeat, can::kQuality, can::kAuth,	 can::kFreshness,
	};
	const std::uint64_t tick = flood_ticks_++;
	for (int i = 0; i < 2; ++i) {
		const std::uint64_t r = rng_();
		can::RawFrame f;
		if (tick % 25 == 0 && i == 0)
			f.id = kBase + kSensorOffsets[r % kSensorOffsets.size()];
		else
			f.id = kBase + ((r & 1) ? can::kCommand : can::kCommandAuth);
		f.len = 8;
		const std::uint64_t bytes = rng_();
		for (std::size_t b = 0; b < 7; ++b)
			f.data[b] = static_cast<std::uint8_t>(bytes >> (8 * b));
		f.data[7] = can::frameCrc(f.id, f.data);
		sendAttacker(&f, 1);
		++random_sent_;
	}
	can::RawFrame out[can::kMaxCommandFrames];
	if (tick % 10 == 0) {
		/* Signed with another key, answering the real freshness: disable the sensor. */
		can::CommandData forged;
		forged.enable = false;
		forged.strobe = can::StrobeMode::Off;
		sendAttacker(out, forger_.encodeCommand(forged, decoder_.freshness(), out));
		++forged_sent_;
	}
	if (tick % 25 == 5 && have_genuine_) {
		sendAttacker(last_genuine_.data(), static_cast<int>(last_genuine_.size()));
		++replays_sent_;
	}
	if (tick % 20 == 15) {
		can::CommandData bare;
		bare.mode = can::TrackMode::SearchOnly;
		bare.enable = false;
		out[0] = bare_.encodeCommand(bare);
		sendAttacker(out, 1);
		++bare_sent_;
	}
}

void Soak::cycle()
{
	/* Camera stall, frames back on their own. */
	inject(Kind::Stall);
	camera_->setStall(true);
	runFor(1000 * kNsPerMs);
	camera_->setStall(false);
	cleared();
	finishFault();
	settle();

	/* A longer stall; the first restart (2 s after the stall is declared) fails, the second
	 * brings the camera back. */
	inject(Kind::StallFailedRestart);
	camera_->failStarts(1);
	camera_->setStall(true);
	runFor(3200 * kNsPerMs);
	camera_->setStall(false);
	cleared();
	finishFault();
	settle();

	/* Unplugged, plugged back: the next restart finds it. */
	inject(Kind::Unplug);
	camera_->setDisconnected(true);
	runFor(2500 * kNsPerMs);
	camera_->setDisconnected(false);
	cleared();
	finishFault();
	settle();

	inject(Kind::BusOff);
	hub_->setBusOff(true);
	runFor(500 * kNsPerMs);
	hub_->setBusOff(false);
	cleared();
	finishFault();
	settle();

	inject(Kind::BlockedBursts);
	for (int i = 0; i < 3; ++i) {
		hub_->setBlocked(true);
		runFor(200 * kNsPerMs);
		hub_->setBlocked(false);
		runFor(i < 2 ? 200 * kNsPerMs : 0);
	}
	cleared();
	finishFault();
	settle();

	/* Alternate strobe (the LED switches at every lit frame), search only. */
	can::CommandData alternate;
	alternate.mode = can::TrackMode::SearchOnly;
	alternate.strobe = can::StrobeMode::Alternate;
	(void)sendGenuine(alternate,
			  Mode{ can::TrackMode::SearchOnly, can::StrobeMode::Alternate, true });
	if (!runUntil([&] { return hal::monotonicNs() - last_pose_ns_ < 100 * kNsPerMs; },
		      5 * kNsPerS))
		failure("no pose in alternate mode");

	/* Every LED switch fails for 300 ms (the controller retries every 10 ms). */
	inject(Kind::StrobeErrors);
	strobe_failing_ = true;
	runFor(300 * kNsPerMs);
	strobe_failing_ = false;
	/* A set() may still be primed to fail: the next switch takes it, a 10 ms retry later. */
	cleared();
	finishFault();
	settle();

	/* The flood, with the way back to constant strobe and tracking as a genuine command
	 * in the middle of it. */
	inject(Kind::CommandFlood);
	flooding_ = true;
	runFor(1000 * kNsPerMs);
	can::CommandData constant;
	constant.mode = can::TrackMode::Track;
	constant.strobe = can::StrobeMode::Constant;
	const std::int64_t genuine_ns = hal::monotonicNs();
	(void)sendGenuine(constant, Mode{ can::TrackMode::Track, can::StrobeMode::Constant, true });
	runFor(std::max<std::int64_t>(0, genuine_ns + 1000 * kNsPerMs - hal::monotonicNs()));
	flooding_ = false;
	cleared();
	finishFault();
	settle();
	++cycles_;
}

bool Soak::stopDaemon()
{
	stop_ = true;
	if (thread_.joinable())
		thread_.join();
	pump();
	bool ok = true;
	if (exit_status_ != 0) {
		failure("the daemon exited with status %d", exit_status_);
		ok = false;
	}
	if (strobe_->isOn()) {
		failure("the LED is on after the daemon stopped");
		ok = false;
	}
	return ok;
}

int Soak::run()
{
	if (!prepare())
		return 2;
	t0_ns_ = hal::monotonicNs();
	if (auto s = daemon_->start(); !s) {
		std::fprintf(stderr, "soak: the daemon did not start: %s\n", s.message().c_str());
		return 2;
	}
	thread_ = std::thread([this] {
		exit_status_ = daemon_->run(stop_);
		finished_ = true;
	});
	std::printf("soak: %.0f s on the sim board at 60 frames/s, authenticated CAN, seed %llu; "
		    "daemon log %s\n",
		    options_.duration_s, static_cast<unsigned long long>(options_.seed),
		    log_path_.c_str());
	std::fflush(stdout);

	if (!runUntil([&] { return poses_ > 0; }, 20 * kNsPerS))
		failure("no pose at the start");
	settle();

	const std::int64_t end_ns = t0_ns_ + static_cast<std::int64_t>(options_.duration_s * 1e9);
	std::int64_t longest_cycle_ns = 0;
	for (;;) {
		const std::int64_t start_ns = hal::monotonicNs();
		if (cycles_ > 0 && start_ns + longest_cycle_ns > end_ns)
			break;
		cycle();
		const std::int64_t now_ns = hal::monotonicNs();
		longest_cycle_ns = std::max(longest_cycle_ns, now_ns - start_ns);
		const double rss = rssKb();
		rss_max_kb_ = std::max(rss_max_kb_, rss);
		if (cycles_ == 1) {
			rss_warm_kb_ = rss;
			warm_ns_ = now_ns;
		}
		std::printf(
			"soak: cycle %d done at %.1f s (%.1f s long): %llu poses, RSS %.0f kB\n",
			cycles_, seconds(now_ns - t0_ns_), seconds(now_ns - start_ns),
			static_cast<unsigned long long>(poses_), rss);
		std::fflush(stdout);
	}
	/* The rest of the time without faults. */
	if (hal::monotonicNs() < end_ns)
		runFor(end_ns - hal::monotonicNs());
	rss_end_kb_ = rssKb();
	rss_max_kb_ = std::max(rss_max_kb_, rss_end_kb_);

	const bool stopped_ok = stopDaemon();
	summary(stopped_ok);
	return failures_ == 0 ? 0 : 1;
}

void Soak::summary(bool stopped_ok)
{
	const firmware::DaemonStats &stats = daemon_->stats();
	const can::Decoder::Counters &c = decoder_.counters();
	const double run_s = seconds(hal::monotonicNs() - t0_ns_);

	/* (1) The decoder's own count of stale poses. */
	if (c.stale_poses != 0)
		failure("the decoder refused %llu stale poses",
			static_cast<unsigned long long>(c.stale_poses));
	/* (2) Commands: the daemon took no more than were sent signed; every genuine one that was
	 * taken changed the mode (the ones sent again after a lost heartbeat may not have). */
	if (stats.commands > genuine_sent_)
		failure("the daemon applied %llu commands, only %llu were sent signed",
			static_cast<unsigned long long>(stats.commands),
			static_cast<unsigned long long>(genuine_sent_));
	if (genuine_seen_ != 2u * static_cast<std::uint64_t>(cycles_))
		failure("%llu genuine mode changes seen for %d cycles (2 each)",
			static_cast<unsigned long long>(genuine_seen_), cycles_);
	/* (3) Memory. */
	const double drift = rss_warm_kb_ > 0 ? (rss_end_kb_ - rss_warm_kb_) / rss_warm_kb_ : 0.0;
	if (cycles_ < 2)
		failure("%d fault cycles: at least 2 are needed (one to warm up)", cycles_);
	else if (drift > 0.01)
		failure("RSS grew %.2f %% from the end of the first cycle to the end", drift * 100);

	std::printf("\n==== soak summary: %.1f s, %d fault cycles, daemon %s\n", run_s, cycles_,
		    stopped_ok ? "ran throughout, exit status 0, LED off" : "FAILED");
	std::printf("poses: sensor sent %llu valid of %llu reports (%llu frames); controller "
		    "accepted %llu (%.1f/s)\n",
		    static_cast<unsigned long long>(stats.poses_valid),
		    static_cast<unsigned long long>(stats.reports),
		    static_cast<unsigned long long>(stats.frames),
		    static_cast<unsigned long long>(poses_), static_cast<double>(poses_) / run_s);
	std::printf("freshness: max wait on the way %.2f ms (bound %.2f ms), max age by the "
		    "decoder %.2f ms (bound %.2f ms); stale accepted %llu, decoder stale %llu, "
		    "wrong poses %llu\n",
		    static_cast<double>(max_wait_us_) * 1e-3,
		    static_cast<double>(max_wait_bound_us_) * 1e-3,
		    static_cast<double>(max_age_us_) * 1e-3,
		    static_cast<double>(decoder_.maxAgeUs()) * 1e-3,
		    static_cast<unsigned long long>(stale_accepted_),
		    static_cast<unsigned long long>(c.stale_poses),
		    static_cast<unsigned long long>(wrong_poses_));
	std::printf("latency (exposure to send) of accepted poses: max %.2f ms; complete reports "
		    "the decoder refused as stale: %llu, their max latency %.2f ms\n",
		    max_latency_ms_, static_cast<unsigned long long>(stale_refused_),
		    max_stale_latency_ms_);
	std::printf(
		"decoder: reports %llu, incomplete %llu, undated %llu, CRC errors %llu, stale "
		"frames %llu, alive gaps %llu, MAC failures %llu, replays %llu, unauthenticated "
		"%llu, unsynced %llu\n",
		static_cast<unsigned long long>(c.reports),
		static_cast<unsigned long long>(c.incomplete_poses),
		static_cast<unsigned long long>(c.undated_poses),
		static_cast<unsigned long long>(c.crc_errors),
		static_cast<unsigned long long>(c.stale_frames),
		static_cast<unsigned long long>(c.alive_gaps),
		static_cast<unsigned long long>(c.auth_failures),
		static_cast<unsigned long long>(c.replays),
		static_cast<unsigned long long>(c.unauthenticated),
		static_cast<unsigned long long>(c.unsynced));
	std::printf("commands: genuine sent %llu, applied by the daemon %llu, mode changes seen "
		    "%llu, foreign modes seen %llu; hostile: random frames %llu, forged %llu, "
		    "replayed %llu, bare %llu; daemon rejected %llu\n",
		    static_cast<unsigned long long>(genuine_sent_),
		    static_cast<unsigned long long>(stats.commands),
		    static_cast<unsigned long long>(genuine_seen_),
		    static_cast<unsigned long long>(foreign_modes_),
		    static_cast<unsigned long long>(random_sent_),
		    static_cast<unsigned long long>(forged_sent_),
		    static_cast<unsigned long long>(replays_sent_),
		    static_cast<unsigned long long>(bare_sent_),
		    static_cast<unsigned long long>(stats.commands_rejected));
	std::printf("faults (injected / reported / recovered, max time to report, max time to a "
		    "pose after):\n");
	int injected = 0, reported = 0, recovered = 0;
	for (int i = 0; i < kKinds; ++i) {
		const KindStats &k = kinds_[static_cast<std::size_t>(i)];
		injected += k.injected;
		reported += k.reported;
		recovered += k.recovered;
		std::printf("  %-36s %3d / %3d / %3d   %6.0f ms   %6.0f ms\n",
			    kSpecs[static_cast<std::size_t>(i)].name, k.injected, k.reported,
			    k.recovered, static_cast<double>(k.max_report_ns) * 1e-6,
			    static_cast<double>(k.max_recovery_ns) * 1e-6);
	}
	std::printf("  %-36s %3d / %3d / %3d\n", "all", injected, reported, recovered);
	std::printf("daemon: stalls %llu, camera restarts %llu, frames dropped (sequence gaps) "
		    "%llu, heartbeats %llu\n",
		    static_cast<unsigned long long>(stats.stalls),
		    static_cast<unsigned long long>(stats.camera_restarts),
		    static_cast<unsigned long long>(stats.sequence_gaps),
		    static_cast<unsigned long long>(stats.heartbeats));
	const hal::CanStats can_stats = sensor_bus_->stats();
	std::printf("sensor's CAN: sent %llu frames, dropped from a full queue %llu, expired "
		    "unsent %llu\n",
		    static_cast<unsigned long long>(can_stats.tx_frames),
		    static_cast<unsigned long long>(can_stats.tx_dropped),
		    static_cast<unsigned long long>(can_stats.tx_expired));
	std::printf(
		"memory: RSS %.0f kB after cycle 1 (%.1f s), %.0f kB at the end, drift %+.2f %% "
		"(bound 1 %%), max %.0f kB\n",
		rss_warm_kb_, seconds(warm_ns_ - t0_ns_), rss_end_kb_, drift * 100, rss_max_kb_);
	std::printf("%s: %d failures\n", failures_ == 0 ? "soak passed" : "soak FAILED", failures_);
	if (failures_ != 0)
		std::printf("the daemon's log is kept: %s\n", log_path_.c_str());
}

int usage()
{
	std::fprintf(stderr, "usage: dockpose_soak [--duration-s S] [--seed N] [--keep-log]\n");
	return 2;
}

} /* namespace */
} /* namespace dockpose::soak */

int main(int argc, char **argv)
{
	dockpose::soak::Options options;
	for (int i = 1; i < argc; ++i) {
		const std::string arg = argv[i];
		if (arg == "--duration-s" && i + 1 < argc) {
			char *end = nullptr;
			options.duration_s = std::strtod(argv[++i], &end);
			if (*end != '\0' || !(options.duration_s > 0) || options.duration_s > 86400)
				return dockpose::soak::usage();
		} else if (arg == "--seed" && i + 1 < argc) {
			options.seed = std::strtoull(argv[++i], nullptr, 10);
		} else if (arg == "--keep-log") {
			options.keep_log = true;
		} else {
			return dockpose::soak::usage();
		}
	}
	dockpose::soak::Soak soak(options);
	return soak.run();
}

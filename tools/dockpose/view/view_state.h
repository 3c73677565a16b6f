/* SPDX-License-Identifier: MIT */
/*
 * What `dockpose view` knows: the sensor's reports decoded from the CAN bus
 * through the project's decoder (firmware/protocol/dockpose_can.h, the DBC's
 * contract), the last 30 s of poses, how often reports come and so when they
 * are overdue (stale), the problems seen on the way (named), and the latest
 * preview frame from the daemon's ring (firmware/preview.h).
 *
 * Time: every call takes the time it is about, in microseconds of one clock
 * (the view uses CLOCK_REALTIME: a candump log's timestamps are that clock).
 * A frame's time is its arrival (a log line's timestamp); "now" is the
 * reader's. Stale: no report for longer than max(3 report periods, 300 ms),
 * the period being the median of the last kPeriodSamples report intervals.
 *
 * With a key (setKey, `dockpose view --key`) the decoder checks the sensor's
 * MACs as a controller does: nothing is shown before its MAC checked, a
 * refused group is a named problem, and the newest freshness value verified
 * is what a signed command answers (sensorFreshness()).
 *
 * Threads: the CAN reader thread calls feed*(), problem() and setPreview*();
 * any thread (httplib's pool) calls the *Json() functions and waitForUpdate().
 * One mutex guards everything; no call holds it for more than a copy.
 *
 * Allocates: feed() appends to the 30 s history (a deque, amortised) and to the
 * problem table (a new name only); the *Json() functions build their documents.
 */
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "algo/status.h"
#include "firmware/protocol/dockpose_can.h"
#include "firmware/protocol/dockpose_can_cmac.h"

namespace dockpose {
class CameraModel;
} /* namespace dockpose */
namespace dockpose::firmware {
struct PreviewFrame;
} /* namespace dockpose::firmware */

namespace dockpose::tool {

/* The alive counters of the last DP_Command and DP_CommandAuth on the bus (-1: none seen). */
struct BusAlive {
	int command = -1;
	int command_auth = -1;
};

class ViewState
{
public:
	/* Report intervals the period is the median of. */
	static constexpr std::size_t kPeriodSamples = 32;
	/* The least bound on a report's absence before the view says stale. */
	static constexpr std::int64_t kMinStaleUs = 300000;
	/* Report periods of absence before stale. */
	static constexpr int kStalePeriods = 3;
	/* The strip chart's span. */
	static constexpr std::int64_t kHistoryUs = 30000000;
	/* CAN poses kept to find the one of a preview frame (by frame counter). */
	static constexpr std::size_t kRecentPoses = 64;
	/* The target's axes drawn on the preview: this long (mm). */
	static constexpr double kAxisLengthMm = 100.0;

	explicit ViewState(std::uint32_t base_id = can::kDefaultBaseId);
	ViewState(const ViewState &) = delete;
	ViewState &operator=(const ViewState &) = delete;
	~ViewState();

	/* The camera file (intrinsics), to project the target's axes (none: no axes); an
	 * error names the file and the problem. (Eigen, which the camera model and
	 * firmware/preview.h bring, stays out of this header: httplib's headers bring glibc's
	 * _res macro, which breaks Eigen's.) */
	Status loadCamera(const std::string &path);
	/* What the view reads, for the page ("can-log /tmp/x.log"). */
	void setSource(const std::string &source);

	/* A classic / FD frame from the bus that arrived at arrival_us. CAN reader thread. */
	void feed(const can::RawFrame &frame, std::int64_t arrival_us);
	void feedFd(const can::FdFrame &frame, std::int64_t arrival_us);
	/* A named problem (the page lists it with its count and last detail). */
	void problem(const std::string &name, const std::string &detail, std::int64_t now_us);
	/* A problem that is a condition (a missing log or ring) is over: listed as resolved
	 * until it comes again. */
	void resolve(const std::string &name);

	/* The preview: the ring could not be read (why), or a new frame (taken: *frame is
	 * swapped with the kept one; the caller gets the previous buffer back to reuse). */
	void setPreviewError(const std::string &message, std::int64_t now_us);
	void setPreviewFrame(std::unique_ptr<firmware::PreviewFrame> *frame,
			     std::uint64_t published, std::int64_t now_us);

	/* GET /api/state: the latest decoded state (see docs/operator-view.md). */
	nlohmann::json stateJson(std::int64_t now_us) const;
	/* GET /api/history: the last 30 s of poses, [[t_s, x, y, z, roll, pan, tilt], ..],
	 * t_s relative to now (negative). */
	nlohmann::json historyJson(std::int64_t now_us) const;
	/* The preview frame's overlays and size, and the CAN pose's axes projected into it;
	 * *pixels gets its image (width x height bytes). Null JSON when there is no frame. */
	nlohmann::json previewJson(std::string *pixels) const;
	/* The protocol's names, from dockpose_can.h: states, fault bits, strobe and track
	 * modes, and the signals' resolutions (for the page; one fact in one place). */
	static nlohmann::json protocolJson();

	/* Whether the sensor says it authenticates (its heartbeat): unsigned commands are refused. */
	bool sensorAuthenticates() const;

	/* Verify the sensor's frames with this key from now on (an own OpenSSL context: the
	 * reader thread's); an error when OpenSSL has no AES-128 CMAC. Before the reader
	 * thread starts. Allocates OpenSSL's context. */
	Status setKey(const std::array<std::uint8_t, can::kKeyBytes> &key);
	/* The newest sensor freshness value whose MAC checked (0: none yet, or no key). Any
	 * thread. */
	std::uint64_t sensorFreshness() const;
	/* The alive counters of the last DP_Command and DP_CommandAuth on the bus with a good
	 * length and CRC (what the sensor's receiver counts), fed or sent by the view. Any
	 * thread. */
	BusAlive commandAliveOnBus() const;
	/* A frame the view sent (its socket does not hear its own frames). Any thread. */
	void noteSent(const can::RawFrame &frame);

	/* A counter that moves on every report and problem; waits (any thread) until it
	 * passes `seen` or `timeout` ends; returns it. wakeAll() ends every wait (shutdown). */
	std::uint64_t waitForUpdate(std::uint64_t seen, std::chrono::milliseconds timeout) const;
	void wakeAll();

private:
	struct Problem {
		std::uint64_t count = 0;
		std::string detail;
		std::int64_t last_us = 0;
		bool resolved = false;
	};
	struct HistorySample {
		std::int64_t t_us;
		float v[6];
	};
	struct RecentPose {
		std::uint32_t frame;
		can::PoseData pose;
	};

	void afterFeed(can::Decoder::Event event, std::int64_t arrival_us);
	/* A DP_Command or DP_CommandAuth with a good length and CRC: its alive counter. */
	void noteCommandAlive(const can::RawFrame &frame);
	void noteProblem(const std::string &name, const std::string &detail, std::int64_t now_us);
	void countProblems(std::int64_t now_us);
	std::int64_t periodUs() const;
	nlohmann::json axesJson(const firmware::PreviewFrame &frame) const;

	mutable std::mutex mutex_;
	mutable std::condition_variable updated_;
	std::uint64_t version_ = 0;
	bool stopping_ = false;

	can::Decoder decoder_;
	std::uint32_t base_id_;
	BusAlive bus_alive_;
	std::unique_ptr<can::OpensslCmac> mac_; /* setKey(): the decoder's MAC */
	can::Decoder::Counters seen_counters_{};
	std::string source_;
	std::unique_ptr<CameraModel> camera_;

	bool have_report_ = false;
	can::StatusData status_;
	std::int64_t last_report_us_ = 0;
	bool last_pose_valid_ = false;
	bool have_pose_ = false;
	can::PoseData pose_;
	std::int64_t pose_us_ = 0;
	std::int64_t pose_age_us_ = -1;
	std::deque<std::int64_t> report_times_us_;
	std::deque<HistorySample> history_;
	std::deque<RecentPose> recent_;
	bool have_heartbeat_ = false;
	can::HeartbeatData heartbeat_;

	std::map<std::string, Problem> problems_;

	std::unique_ptr<firmware::PreviewFrame> preview_;
	std::uint64_t preview_published_ = 0;
	std::int64_t preview_us_ = 0;
	std::string preview_error_;
};

} /* namespace dockpose::tool */

/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/view/view_state.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "algo/camera_model.h"
#include "algo/io/model_json.h"
#include "firmware/preview.h"
#include "tools/dockpose/view/candump.h"

namespace dockpose::tool {

namespace {

using nlohmann::json;

json vec3(const double (&v)[3])
{
	return json::array({ v[0], v[1], v[2] });
}

json faultNames(std::uint8_t bits)
{
	json names = json::array();
	for (unsigned int bit = 0; bit < 8; ++bit)
		if (bits & (1u << bit))
			names.push_back(can::faultBitName(bit));
	return names;
}

double roundTo(double value, double res)
{
	return std::round(value / res) * res;
}

} /* namespace */

ViewState::ViewState(std::uint32_t base_id)
	: decoder_(base_id),
	  base_id_(base_id)
{
}

ViewState::~ViewState() = default;

Status ViewState::loadCamera(const std::string &path)
{
	const Result<CameraIntrinsics> camera = loadCameraIntrinsics(path);
	if (!camera.isOk())
		return camera.status();
	const std::lock_guard<std::mutex> lock(mutex_);
	camera_ = std::make_unique<CameraModel>(camera.value());
	return Status();
}

void ViewState::setSource(const std::string &source)
{
	const std::lock_guard<std::mutex> lock(mutex_);
	source_ = source;
}

void ViewState::feed(const can::RawFrame &frame, std::int64_t arrival_us)
{
	std::unique_lock<std::mutex> lock(mutex_);
	noteCommandAlive(frame);
	const can::Decoder::Event event = decoder_.feed(frame, arrival_us);
	if (event == can::Decoder::Event::Rejected)
		noteProblem(can::frameErrorName(decoder_.lastError()), candumpFrameText(frame),
			    arrival_us);
	afterFeed(event, arrival_us);
	lock.unlock();
	updated_.notify_all();
}

void ViewState::feedFd(const can::FdFrame &frame, std::int64_t arrival_us)
{
	std::unique_lock<std::mutex> lock(mutex_);
	const can::Decoder::Event event = decoder_.feedFd(frame, arrival_us);
	if (event == can::Decoder::Event::Rejected) {
		char id[16];
		std::snprintf(id, sizeof(id), "%03X##", static_cast<unsigned int>(frame.id));
		noteProblem(can::frameErrorName(decoder_.lastError()), id, arrival_us);
	}
	afterFeed(event, arrival_us);
	lock.unlock();
	updated_.notify_all();
}

void ViewState::afterFeed(can::Decoder::Event event, std::int64_t arrival_us)
{
	countProblems(arrival_us);
	if (event == can::Decoder::Event::Heartbeat) {
		have_heartbeat_ = true;
		heartbeat_ = decoder_.heartbeat();
		++version_;
		return;
	}
	if (event != can::Decoder::Event::Report)
		return;

	if (have_report_ && arrival_us > last_report_us_) {
		report_times_us_.push_back(arrival_us - last_report_us_);
		if (report_times_us_.size() > kPeriodSamples)
			report_times_us_.pop_front();
	}
	have_report_ = true;
	last_report_us_ = arrival_us;
	status_ = decoder_.status();
	last_pose_valid_ = decoder_.poseValid();
	pose_age_us_ = decoder_.poseAgeUs();
	if (last_pose_valid_) {
		have_pose_ = true;
		pose_ = decoder_.pose();
		pose_us_ = arrival_us;
		recent_.push_back({ pose_.frame_counter, pose_ });
		if (recent_.size() > kRecentPoses)
			recent_.pop_front();
		HistorySample s{ arrival_us, {} };
		for (int i = 0; i < 3; ++i) {
			s.v[i] = static_cast<float>(pose_.t_mm[i]);
			s.v[3 + i] = static_cast<float>(pose_.rpy_deg[i]);
		}
		history_.push_back(s);
	}
	while (!history_.empty() && history_.front().t_us < arrival_us - kHistoryUs)
		history_.pop_front();
	++version_;
}

/* The decoder's counters that moved since the last frame, as named problems. */
void ViewState::countProblems(std::int64_t now_us)
{
	const can::Decoder::Counters &c = decoder_.counters();
	const std::pair<std::uint64_t can::Decoder::Counters::*, const char *> counted[] = {
		{ &can::Decoder::Counters::alive_gaps, "frames lost (alive counter skipped)" },
		{ &can::Decoder::Counters::incomplete_poses,
		  "incomplete pose (a pose frame missing)" },
		{ &can::Decoder::Counters::stale_poses, "pose too old at arrival" },
		/* With a key: a group whose MAC never came is dropped without a rejected frame
		 * (keyless traffic to a keyed view, or its DP_Auth lost). */
		{ &can::Decoder::Counters::unauthenticated,
		  "not authenticated (a group without its MAC)" },
	};
	for (const auto &[member, name] : counted) {
		if (c.*member > seen_counters_.*member)
			noteProblem(name, "counted " + std::to_string(c.*member), now_us);
	}
	seen_counters_ = c;
}

void ViewState::problem(const std::string &name, const std::string &detail, std::int64_t now_us)
{
	{
		const std::lock_guard<std::mutex> lock(mutex_);
		noteProblem(name, detail, now_us);
	}
	updated_.notify_all();
}

void ViewState::noteProblem(const std::string &name, const std::string &detail, std::int64_t now_us)
{
	Problem &p = problems_[name];
	++p.count;
	p.detail = detail.size() > 200 ? detail.substr(0, 200) + "..." : detail;
	p.last_us = now_us;
	p.resolved = false;
	++version_;
}

void ViewState::resolve(const std::string &name)
{
	{
		const std::lock_guard<std::mutex> lock(mutex_);
		const auto it = problems_.find(name);
		if (it == problems_.end() || it->second.resolved)
			return;
		it->second.resolved = true;
		++version_;
	}
	updated_.notify_all();
}

void ViewState::setPreviewError(const std::string &message, std::int64_t now_us)
{
	{
		const std::lock_guard<std::mutex> lock(mutex_);
		if (message != preview_error_)
			noteProblem("preview ring", message, now_us);
		preview_error_ = message;
		++version_;
	}
	updated_.notify_all();
}

void ViewState::setPreviewFrame(std::unique_ptr<firmware::PreviewFrame> *frame,
				std::uint64_t published, std::int64_t now_us)
{
	{
		const std::lock_guard<std::mutex> lock(mutex_);
		preview_.swap(*frame);
		preview_published_ = published;
		preview_us_ = now_us;
		preview_error_.clear();
		const auto it = problems_.find("preview ring");
		if (it != problems_.end())
			it->second.resolved = true;
		++version_;
	}
	updated_.notify_all();
}

std::int64_t ViewState::periodUs() const
{
	if (report_times_us_.empty())
		return 0;
	std::vector<std::int64_t> sorted(report_times_us_.begin(), report_times_us_.end());
	const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
	std::nth_element(sorted.begin(), mid, sorted.end());
	return *mid;
}

json ViewState::stateJson(std::int64_t now_us) const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	json j;
	j["source"] = source_;
	j["updates"] = version_;
	const std::int64_t period_us = periodUs();
	const std::int64_t stale_after_us = std::max(kStalePeriods * period_us, kMinStaleUs);
	j["period_ms"] = period_us > 0 ? json(period_us / 1000.0) : json(nullptr);
	j["rate_hz"] = period_us > 0 ? json(1e6 / static_cast<double>(period_us)) : json(nullptr);
	j["stale_after_ms"] = stale_after_us / 1000.0;
	j["have_report"] = have_report_;
	const std::int64_t age_us = now_us - last_report_us_;
	j["age_ms"] = have_report_ ? json(static_cast<double>(age_us) / 1000.0) : json(nullptr);
	j["stale"] = !have_report_ || age_us > stale_after_us;

	if (have_report_) {
		j["state"] = can::sensorStateName(status_.state);
		j["state_code"] = static_cast<int>(status_.state);
		j["enabled"] = status_.enabled;
		j["tracked"] = status_.tracked;
		j["strobe"] = can::strobeModeName(status_.strobe);
		j["faults"] = faultNames(status_.faults);
		j["fault_bits"] = status_.faults;
		j["leds"] = status_.leds_used;
		j["rms_px"] = roundTo(status_.rms_px, 0.01);
		j["latency_ms"] = roundTo(status_.latency_ms, 0.01);
		j["pose_valid"] = last_pose_valid_;
	} else {
		j["state"] = nullptr;
		j["faults"] = json::array();
		j["leds"] = nullptr;
		j["rms_px"] = nullptr;
		j["pose_valid"] = false;
	}
	/* The last valid pose (pose_valid says whether the latest report had one). */
	if (have_pose_) {
		j["frame"] = pose_.frame_counter;
		j["t_mm"] = vec3(pose_.t_mm);
		j["rpy_deg"] = vec3(pose_.rpy_deg);
		j["q_wxyz"] = json::array({ pose_.q[0], pose_.q[1], pose_.q[2], pose_.q[3] });
		j["sigma_t_mm"] = vec3(pose_.sigma_t_mm);
		j["sigma_rpy_deg"] = vec3(pose_.sigma_rpy_deg);
		j["log10_nfa"] = roundTo(pose_.log10_nfa, 0.1);
		j["pose_since_ms"] = static_cast<double>(now_us - pose_us_) / 1000.0;
	} else {
		for (const char *key : { "frame", "t_mm", "rpy_deg", "q_wxyz", "sigma_t_mm",
					 "sigma_rpy_deg", "log10_nfa", "pose_since_ms" })
			j[key] = nullptr;
	}
	j["pose_age_ms"] = pose_age_us_ >= 0 ? json(static_cast<double>(pose_age_us_) / 1000.0)
					     : json(nullptr);
	if (have_heartbeat_) {
		j["heartbeat"] = {
			{ "uptime_s", heartbeat_.uptime_s },
			{ "authenticated", heartbeat_.authenticated },
			{ "state", can::sensorStateName(heartbeat_.state) },
			{ "mode", can::trackModeName(heartbeat_.mode) },
			{ "strobe", can::strobeModeName(heartbeat_.strobe) },
			{ "enabled", heartbeat_.enabled },
			{ "faults", faultNames(heartbeat_.faults) },
			{ "frame_rate_hz", heartbeat_.frame_rate_hz },
		};
	} else {
		j["heartbeat"] = nullptr;
	}

	const can::Decoder::Counters &c = decoder_.counters();
	j["counters"] = {
		{ "frames", c.frames },
		{ "reports", c.reports },
		{ "valid_poses", c.valid_poses },
		{ "incomplete_poses", c.incomplete_poses },
		{ "crc_errors", c.crc_errors },
		{ "length_errors", c.length_errors },
		{ "unknown_ids", c.unknown_ids },
		{ "alive_gaps", c.alive_gaps },
		{ "stale_frames", c.stale_frames },
		{ "stale_poses", c.stale_poses },
		{ "undated_poses", c.undated_poses },
		{ "auth_failures", c.auth_failures },
		{ "replays", c.replays },
		{ "unsynced", c.unsynced },
		{ "unauthenticated", c.unauthenticated },
	};
	/* With a key: only what the sensor's MACs vouch for is shown. */
	j["verifying"] = decoder_.authenticating();

	json problems = json::array();
	for (const auto &[name, p] : problems_)
		problems.push_back({ { "name", name },
				     { "count", p.count },
				     { "detail", p.detail },
				     { "resolved", p.resolved },
				     { "ago_s", static_cast<double>(now_us - p.last_us) / 1e6 } });
	j["problems"] = std::move(problems);

	json preview;
	preview["ok"] = preview_ != nullptr && preview_error_.empty();
	preview["error"] = preview_error_;
	preview["published"] = preview_published_;
	preview["frame"] = preview_ ? json(preview_->frame_counter) : json(nullptr);
	preview["ago_s"] = preview_ ? json(static_cast<double>(now_us - preview_us_) / 1e6)
				    : json(nullptr);
	j["preview"] = std::move(preview);
	return j;
}

json ViewState::historyJson(std::int64_t now_us) const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	json rows = json::array();
	for (const HistorySample &s : history_) {
		if (s.t_us < now_us - kHistoryUs)
			continue;
		json row = json::array({ static_cast<double>(s.t_us - now_us) / 1e6 });
		for (float v : s.v)
			row.push_back(v);
		rows.push_back(std::move(row));
	}
	return rows;
}

json ViewState::axesJson(const firmware::PreviewFrame &frame) const
{
	if (!camera_ || recent_.empty())
		return nullptr;
	/* The CAN pose of this very frame when it is among the recent ones, else the latest. */
	const RecentPose *chosen = &recent_.back();
	for (const RecentPose &r : recent_)
		if (r.frame == static_cast<std::uint32_t>(frame.frame_counter))
			chosen = &r;
	const can::PoseData &p = chosen->pose;
	Eigen::Quaterniond q(p.q[0], p.q[1], p.q[2], p.q[3]);
	if (q.norm() < 0.5)
		return nullptr;
	q.normalize();
	const Eigen::Vector3d t(p.t_mm[0], p.t_mm[1], p.t_mm[2]);
	json axes;
	Eigen::Vector2d uv;
	if (!camera_->project(t, &uv))
		return nullptr;
	axes["origin"] = json::array({ uv.x(), uv.y() });
	const char *names[3] = { "x", "y", "z" };
	for (int i = 0; i < 3; ++i) {
		Eigen::Vector3d axis = Eigen::Vector3d::Zero();
		axis[i] = kAxisLengthMm;
		if (camera_->project(q * axis + t, &uv))
			axes[names[i]] = json::array({ uv.x(), uv.y() });
		else
			axes[names[i]] = nullptr;
	}
	axes["frame"] = chosen->frame;
	axes["same_frame"] = chosen->frame == static_cast<std::uint32_t>(frame.frame_counter);
	axes["length_mm"] = kAxisLengthMm;
	return axes;
}

json ViewState::previewJson(std::string *pixels) const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	if (!preview_)
		return nullptr;
	const firmware::PreviewFrame &f = *preview_;
	const std::size_t n = std::min<std::size_t>(static_cast<std::size_t>(f.width) * f.height,
						    firmware::kMaxPreviewPixels);
	pixels->assign(reinterpret_cast<const char *>(f.pixels), n);
	json j;
	j["published"] = preview_published_;
	j["frame"] = f.frame_counter;
	j["width"] = f.width;
	j["height"] = f.height;
	j["full_width"] = f.full_width;
	j["full_height"] = f.full_height;
	j["state"] = can::sensorStateName(static_cast<can::SensorState>(f.state & 7));
	j["found"] = f.found != 0;
	j["tracked"] = f.tracked != 0;
	j["leds_used"] = f.leds_used;
	json blobs = json::array();
	for (std::uint32_t i = 0; i < std::min<std::uint32_t>(f.blob_count, kMaxCandidates); ++i) {
		const firmware::PreviewBlob &b = f.blobs[i];
		blobs.push_back({ b.u_px, b.v_px, b.area_px, b.peak, b.matched });
	}
	j["blobs"] = std::move(blobs);
	json leds = json::array();
	if (f.found) {
		for (std::uint32_t i = 0; i < std::min<std::uint32_t>(f.led_count, kMaxLeds); ++i) {
			const firmware::PreviewLed &l = f.leds[i];
			leds.push_back({ l.u_px, l.v_px, l.index, l.matched, l.visible });
		}
	}
	j["leds"] = std::move(leds);
	json faces = json::array();
	for (std::uint32_t i = 0; i < std::min<std::uint32_t>(f.face_count, kMaxFaces); ++i)
		faces.push_back({ f.faces[i][0], f.faces[i][1], f.faces[i][2], f.faces[i][3] });
	j["faces"] = std::move(faces);
	j["axes"] = axesJson(f);
	return j;
}

json ViewState::protocolJson()
{
	json states = json::array();
	for (int s = 0; s <= static_cast<int>(can::SensorState::Shutdown); ++s)
		states.push_back(can::sensorStateName(static_cast<can::SensorState>(s)));
	json faults = json::array();
	for (unsigned int bit = 0; bit < 8; ++bit)
		faults.push_back(can::faultBitName(bit));
	json strobe = json::array();
	for (int m = 0; m <= static_cast<int>(can::StrobeMode::Unchanged); ++m)
		strobe.push_back(can::strobeModeName(static_cast<can::StrobeMode>(m)));
	json modes = json::array();
	for (int m = 0; m <= static_cast<int>(can::TrackMode::SearchOnly); ++m)
		modes.push_back(can::trackModeName(static_cast<can::TrackMode>(m)));
	return {
		{ "states", states },
		{ "fault_bits", faults },
		{ "strobe_modes", strobe },
		{ "track_modes", modes },
		{ "resolution",
		  { { "t_mm", can::detail::kTranslationRes },
		    { "rpy_deg", can::detail::kAngleRes },
		    { "sigma_t_mm", can::detail::kSigmaTRes },
		    { "sigma_rpy_deg", can::detail::kSigmaRpyRes },
		    { "rms_px", can::detail::kRmsRes },
		    { "latency_ms", can::detail::kLatencyRes },
		    { "gain", can::detail::kGainRes } } },
	};
}

bool ViewState::sensorAuthenticates() const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	return have_heartbeat_ && heartbeat_.authenticated;
}

Status ViewState::setKey(const std::array<std::uint8_t, can::kKeyBytes> &key)
{
	auto mac = std::make_unique<can::OpensslCmac>();
	if (!mac->setKey(key))
		return Status::error("OpenSSL has no AES-128 CMAC: the sensor's frames cannot be "
				     "verified");
	const std::lock_guard<std::mutex> lock(mutex_);
	decoder_.setAuthenticator(mac.get());
	mac_ = std::move(mac);
	return Status::ok();
}

std::uint64_t ViewState::sensorFreshness() const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	return decoder_.authenticating() ? decoder_.freshness() : 0;
}

void ViewState::noteCommandAlive(const can::RawFrame &frame)
{
	if (!can::frameIntact(frame))
		return;
	const int alive = can::frameAlive(frame.data);
	if (frame.id == ((base_id_ + can::kCommand) & 0x7ff))
		bus_alive_.command = alive;
	else if (frame.id == ((base_id_ + can::kCommandAuth) & 0x7ff))
		bus_alive_.command_auth = alive;
}

BusAlive ViewState::commandAliveOnBus() const
{
	const std::lock_guard<std::mutex> lock(mutex_);
	return bus_alive_;
}

void ViewState::noteSent(const can::RawFrame &frame)
{
	const std::lock_guard<std::mutex> lock(mutex_);
	noteCommandAlive(frame);
}

std::uint64_t ViewState::waitForUpdate(std::uint64_t seen, std::chrono::milliseconds timeout) const
{
	std::unique_lock<std::mutex> lock(mutex_);
	updated_.wait_for(lock, timeout, [&] { return version_ != seen || stopping_; });
	return version_;
}

void ViewState::wakeAll()
{
	{
		const std::lock_guard<std::mutex> lock(mutex_);
		stopping_ = true;
	}
	updated_.notify_all();
}

} /* namespace dockpose::tool */

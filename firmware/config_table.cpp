/* SPDX-License-Identifier: MIT */
/*
 * The board file's key tables (firmware/config_table.h) and the markdown
 * docs/configuration.md shows of them.
 */
#include "firmware/config_table.h"

#include <cctype>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <functional>
#include <type_traits>
#include <utility>

#include <nlohmann/json.hpp>

#include "firmware/protocol/dockpose_can.h"

namespace dockpose::firmware::config_table {

using board::BoardConfig;
using board::CameraSection;
using board::CanSection;
using board::PipelineSection;
using board::PreviewSection;
using board::ReplayCameraConfig;
using board::StrobeSection;
using board::SystemdSection;
using hal::SyntheticScene;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
/* CiA 301 / common CAN bit rates. */
constexpr std::int64_t kCanBitrates[] = { 10000,  20000,  50000,  100000, 125000,
					  250000, 500000, 800000, 1000000 };
constexpr std::size_t kIfNameSize = 16; /* IFNAMSIZ, including the terminating NUL */

std::string quote(const std::string &s)
{
	return nlohmann::json(s).dump();
}

/* The kernel's dev_valid_name(). Empty when fine, else why not. */
std::string interfaceNameProblem(const std::string &name)
{
	if (name.empty())
		return "must not be empty (a network interface such as \"can0\")";
	if (name.size() >= kIfNameSize)
		return quote(name) + " is " + std::to_string(name.size()) +
		       " characters long; interface names have at most " +
		       std::to_string(kIfNameSize - 1) + " (IFNAMSIZ)";
	if (name == "." || name == "..")
		return quote(name) + " is not an interface name";
	for (char c : name)
		if (c == '/' || c == ':' || std::isspace(static_cast<unsigned char>(c)))
			return quote(name) +
			       " is not an interface name (no '/', ':' or white space allowed)";
	return {};
}

/* can.interface: a valid name; an empty one is left alone when another backend is chosen. */
std::string checkInterface(const CanSection &can, const std::string &name)
{
	if (name.empty() && !can.backend.empty() && can.backend != "socketcan")
		return {};
	return interfaceNameProblem(name);
}

/* preview.name: a POSIX shared-memory name without its leading "/". */
std::string checkPreviewName(const PreviewSection & /*preview*/, const std::string &name)
{
	if (name.empty() || name.size() > 200)
		return "must be 1 to 200 characters";
	if (name.find('/') != std::string::npos)
		return "must not contain '/' (it names /dev/shm/<name>)";
	return {};
}

const Field<BoardConfig> kTopFields[] = {
	{ .key = "board",
	  .kind = Kind::String,
	  .member = &BoardConfig::board,
	  .doc = "The board this file is for (the boards above). dockposed refuses a file for a "
		 "board it was not built with, and a backend that board does not wire.",
	  .required = true,
	  .hint = "the board's name, e.g. \"sim\"",
	  .non_empty = true,
	  .range_doc = "non-empty" },
	{ .key = "camera",
	  .kind = Kind::Object,
	  .member = &BoardConfig::camera,
	  .doc = "Where frames come from and how they are taken (`camera`, below).",
	  .required = true },
	{ .key = "strobe",
	  .kind = Kind::Object,
	  .member = &BoardConfig::strobe,
	  .doc = "The IR LEDs' switching (`strobe`, below).",
	  .required = true },
	{ .key = "can",
	  .kind = Kind::Object,
	  .member = &BoardConfig::can,
	  .doc = "The CAN bus the pose is sent on (`can`, below).",
	  .required = true },
	{ .key = "pipeline",
	  .kind = Kind::Object,
	  .member = &BoardConfig::pipeline,
	  .doc = "The target and the pose's acceptance (`pipeline`, below).",
	  .required = true },
	{ .key = "systemd",
	  .kind = Kind::Object,
	  .member = &BoardConfig::systemd,
	  .doc = "The service manager's notifications (`systemd`, below)." },
	{ .key = "preview",
	  .kind = Kind::Object,
	  .member = &BoardConfig::preview,
	  .doc = "The operator preview for `dockpose view` (`preview`, below)." },
};

const Field<CameraSection> kCameraFields[] = {
	{ .key = "backend",
	  .kind = Kind::Backend,
	  .member = &CameraSection::backend,
	  .doc = "Where frames come from: frames rendered with known truth, a folder of PGM "
		 "frames, or a real camera.",
	  .required = true,
	  .backend = board::BackendKind::Camera },
	{ .key = "id",
	  .kind = Kind::String,
	  .member = &CameraSection::id,
	  .doc = "libcamera camera id (`cam -l` lists them); empty: choose by `index`." },
	{ .key = "index",
	  .kind = Kind::Integer,
	  .member = &CameraSection::index,
	  .doc = "Index into libcamera's sorted list of cameras when `id` is empty.",
	  .range = { 0, 255 } },
	{ .key = "width",
	  .kind = Kind::Integer,
	  .member = &CameraSection::width,
	  .doc = "Frame width. `0`: the calibration's (from `intrinsics`). Non-zero values must "
		 "equal the calibration's size: the intrinsics only hold at the size they were "
		 "measured at.",
	  .range = { 0, 16384 },
	  .unit = "px" },
	{ .key = "height",
	  .kind = Kind::Integer,
	  .member = &CameraSection::height,
	  .doc = "Frame height; as `width`.",
	  .range = { 0, 16384 },
	  .unit = "px" },
	{ .key = "frame_rate_hz",
	  .kind = Kind::Number,
	  .member = &CameraSection::frame_rate_hz,
	  .doc = "Fixed frame rate (libcamera frame-duration limits min = max).",
	  .range = { 0.0, 240.0, true, false },
	  .unit = "Hz" },
	{ .key = "exposure_us",
	  .kind = Kind::Integer,
	  .member = &CameraSection::exposure_us,
	  .doc = "Manual exposure time (auto exposure is off).",
	  .range = { 10, 1000000 },
	  .unit = "us",
	  .range_note = "and at most one frame period (1e6 / `frame_rate_hz`)" },
	{ .key = "analogue_gain",
	  .kind = Kind::Number,
	  .member = &CameraSection::analogue_gain,
	  .doc = "Manual analogue gain.",
	  .range = { 1.0, 64.0 } },
	{ .key = "buffer_count",
	  .kind = Kind::Integer,
	  .member = &CameraSection::buffer_count,
	  .doc = "Frame buffers allocated at start-up.",
	  .range = { 2, 16 } },
	{ .key = "stall_timeout_ms",
	  .kind = Kind::Integer,
	  .member = &CameraSection::stall_timeout_ms,
	  .doc = "No frame for this long is a fault: the LEDs go off and the state is reported.",
	  .range = { 50, 60000 },
	  .unit = "ms",
	  .range_note = "and more than 2 frame periods" },
	{ .key = "intrinsics",
	  .kind = Kind::Path,
	  .member = &CameraSection::intrinsics,
	  .doc = "The camera calibration (method.md section 3: `width`, `height`, `fx`, `fy`, "
		 "`cx`, `cy`, `k1`, `k2`, `p1`, `p2`).",
	  .required = true,
	  .hint = "the camera calibration JSON file",
	  .range_doc = "a readable camera JSON" },
	{ .key = "synthetic",
	  .kind = Kind::Object,
	  .member = &CameraSection::synthetic,
	  .doc = "The synthetic camera's scene (below); read, and checked, whatever the backend." },
	{ .key = "replay",
	  .kind = Kind::Object,
	  .member = &CameraSection::replay,
	  .doc = "The replay camera's frames (below)." },
};

const Field<SyntheticScene> kSyntheticFields[] = {
	{ .key = "from",
	  .kind = Kind::Pose,
	  .member = &SyntheticScene::from,
	  .doc = "Pose at the start.",
	  .unit = "mm, degrees" },
	{ .key = "to",
	  .kind = Kind::Pose,
	  .member = &SyntheticScene::to,
	  .doc = "Pose at the end.",
	  .unit = "mm, degrees" },
	{ .key = "duration_s",
	  .kind = Kind::Number,
	  .member = &SyntheticScene::duration_s,
	  .doc = "Time from `from` to `to`.",
	  .range = { 0.0, kInf, true, false },
	  .unit = "s" },
	{ .key = "loop",
	  .kind = Kind::Boolean,
	  .member = &SyntheticScene::loop,
	  .doc = "Start again from `from` after `duration_s`." },
	{ .key = "reflections",
	  .kind = Kind::Integer,
	  .member = &SyntheticScene::reflections,
	  .doc = "Clutter: LED-like round spots (reflections, other lights), at the same places in "
		 "every frame.",
	  .range = { 0, 1000 } },
	{ .key = "glints",
	  .kind = Kind::Integer,
	  .member = &SyntheticScene::glints,
	  .doc = "Clutter: long thin bright streaks.",
	  .range = { 0, 1000 } },
	{ .key = "hot_pixels",
	  .kind = Kind::Integer,
	  .member = &SyntheticScene::hot_pixels,
	  .doc = "Clutter: single hot pixels.",
	  .range = { 0, 1000 } },
	{ .key = "noise_sigma",
	  .kind = Kind::Number,
	  .member = &SyntheticScene::noise_sigma,
	  .doc = "Gaussian sensor noise.",
	  .range = { 0.0, 50.0 },
	  .unit = "grey levels" },
	{ .key = "seed",
	  .kind = Kind::Unsigned,
	  .member = &SyntheticScene::seed,
	  .doc = "Random seed: the same seed renders the same frames." },
};

const Field<ReplayCameraConfig> kReplayFields[] = {
	{ .key = "folder",
	  .kind = Kind::Path,
	  .member = &ReplayCameraConfig::folder,
	  .doc = "Frames, 8-bit binary PGM, played in name order.",
	  .range_doc = "an existing folder holding at least one `frame_*.pgm`",
	  .default_note = "**required** when `camera.backend` is `replay`" },
	{ .key = "loop",
	  .kind = Kind::Boolean,
	  .member = &ReplayCameraConfig::loop,
	  .doc = "Start again after the last frame (otherwise the camera stops)." },
};

const Field<StrobeSection> kStrobeFields[] = {
	{ .key = "backend",
	  .kind = Kind::Backend,
	  .member = &StrobeSection::backend,
	  .doc = "A recording of the switching (simulation), or a GPIO line (libgpiod) switching "
		 "the LED driver.",
	  .required = true,
	  .backend = board::BackendKind::Strobe },
	{ .key = "chip",
	  .kind = Kind::String,
	  .member = &StrobeSection::chip,
	  .doc = "GPIO chip: a name (`gpiochip0`), a path (`/dev/gpiochip0`) or a label "
		 "(`pinctrl-rp1`). A label survives kernels that renumber the chips.",
	  .range_doc = "non-empty for `gpiod`",
	  .default_note = "**required** for `gpiod`" },
	{ .key = "line",
	  .kind = Kind::Integer,
	  .member = &StrobeSection::line,
	  .doc = "Line offset on the chip (on the Pi 5's `pinctrl-rp1`, the BCM GPIO number).",
	  .range = { 0, 1023 },
	  .default_note = "**required** for `gpiod`" },
	{ .key = "active_low",
	  .kind = Kind::Boolean,
	  .member = &StrobeSection::active_low,
	  .doc = "`true` when a low level switches the LEDs on (an inverting driver)." },
	{ .key = "mode",
	  .kind = Kind::Choice,
	  .member = &StrobeSection::mode,
	  .doc = "LEDs never on; on during every exposure; on during every other exposure, so "
		 "unlit frames show the ambient light to subtract.",
	  .choices = board::kStrobeModeNames },
	{ .key = "pulse_margin_us",
	  .kind = Kind::Integer,
	  .member = &StrobeSection::pulse_margin_us,
	  .doc = "`alternate` mode: the LEDs come on this long before a lit exposure and go off "
		 "this long after it.",
	  .range = { 0, 10000 },
	  .unit = "us" },
};

const Field<CanSection> kCanFields[] = {
	{ .key = "backend",
	  .kind = Kind::Backend,
	  .member = &CanSection::backend,
	  .doc = "A candump log file (simulation), or a kernel CAN interface.",
	  .required = true,
	  .backend = board::BackendKind::Can },
	{ .key = "interface",
	  .kind = Kind::String,
	  .member = &CanSection::interface,
	  .doc = "The SocketCAN interface, e.g. `can0`. dockposed does not configure it (bit rate, "
		 "up): the system does (`board/rpi5-imx296/README.md`).",
	  .check = checkInterface,
	  .range_doc = "a network interface name: 1 to 15 characters (IFNAMSIZ), no `/`, `:` or "
		       "white space",
	  .default_note = "**required** for `socketcan`" },
	{ .key = "log_file",
	  .kind = Kind::Path,
	  .member = &CanSection::log_file,
	  .doc = "`file` backend: where the candump log (`candump -l` format) is written. "
		 "`dockposed --can-log FILE` overrides it; a `file` board needs one or the other.",
	  .empty_ok = true },
	{ .key = "base_id",
	  .kind = Kind::CanId,
	  .member = &CanSection::base_id,
	  .doc = "First CAN id of the protocol; the frames use base_id .. base_id + 0x11." },
	{ .key = "bitrate",
	  .kind = Kind::OneOf,
	  .member = &CanSection::bitrate,
	  .doc = "The bus's bit rate, for the bus-load check and messages. It must match the "
		 "interface's configuration; dockposed does not set it.",
	  .unit = "bit/s",
	  .hint = "a standard CAN bit rate",
	  .one_of = kCanBitrates },
	{ .key = "fd",
	  .kind = Kind::Boolean,
	  .member = &CanSection::fd,
	  .doc = "CAN FD: each report goes as one 64-byte DP_ReportFd frame instead of up to eight "
		 "classic frames (heartbeats and commands stay classic; docs/can-protocol.md). The "
		 "interface must be an FD one (`ip link set can0 type can bitrate 500000 dbitrate "
		 "2000000 fd on`); dockposed sends without bit-rate switching." },
	{ .key = "tx_queue_depth",
	  .kind = Kind::Integer,
	  .member = &CanSection::tx_queue_depth,
	  .doc = "Frames queued for sending; when full, the oldest is dropped and counted.",
	  .range = { 1, static_cast<double>(hal::kMaxCanTxQueueDepth) },
	  .unit = "frames" },
	{ .key = "heartbeat_hz",
	  .kind = Kind::Integer,
	  .member = &CanSection::heartbeat_hz,
	  .doc = "Rate of the status (heartbeat) frames.",
	  .range = { 1, 100 },
	  .unit = "Hz" },
	{ .key = "max_report_age_us",
	  .kind = Kind::Integer,
	  .member = &CanSection::max_report_age_us,
	  .doc = "How long a pose report may wait for the bus (a stall, bus-off, ENOBUFS): one "
		 "still queued this long after it was sent is dropped unsent, so no stale pose "
		 "goes out as valid. 0: one camera frame period (by then the next report exists). "
		 "Status-only reports and heartbeats expire after one heartbeat interval.",
	  .range = { 0, 1000000 },
	  .unit = "us" },
	{ .key = "max_pose_latency_us",
	  .kind = Kind::Integer,
	  .member = &CanSection::max_pose_latency_us,
	  .doc = "A pose whose exposure began longer ago than this when its report is made "
		 "(LatencyMs) goes out as no pose: the frame loop finished it too late to be "
		 "true still. The default matches the controller-side decoder's default age "
		 "bound (dockpose_can.h, Decoder::kDefaultMaxAgeUs).",
	  .range = { 1000, 1000000 },
	  .unit = "us" },
	{ .key = "key_file",
	  .kind = Kind::Path,
	  .member = &CanSection::key_file,
	  .doc = "The 128-bit AES key that authenticates the CAN frames (AES-128-CMAC, "
		 "docs/can-protocol.md): 32 hexadecimal digits in a regular file of mode 0600 or "
		 "0400 owned by root or the daemon's user. Set, the sensor signs its reports and "
		 "heartbeats and accepts only signed commands; empty, nothing is authenticated "
		 "(the heartbeat's Authenticated bit says which).",
	  .empty_ok = true },
	{ .key = "run_counter_file",
	  .kind = Kind::Path,
	  .member = &CanSection::run_counter_file,
	  .doc = "With `key_file`: the state file of the run counter (a number, +1 at every "
		 "start) the freshness values of a run start from, so that none repeats an "
		 "earlier run's. It must be writable (systemd: StateDirectory=dockpose)." },
};

const Field<PipelineSection> kPipelineFields[] = {
	{ .key = "target",
	  .kind = Kind::Path,
	  .member = &PipelineSection::target,
	  .doc = "The LED target model (method.md section 3).",
	  .required = true,
	  .hint = "the target model JSON file",
	  .range_doc = "a readable target JSON" },
	{ .key = "mode",
	  .kind = Kind::Choice,
	  .member = &PipelineSection::mode,
	  .doc = "Track from the last pose when there is one; or search the whole frame every "
		 "frame.",
	  .choices = board::kTrackModeNames },
	{ .key = "max_rms_px",
	  .kind = Kind::Number,
	  .member = &PipelineSection::max_rms_px,
	  .doc = "A pose whose RMS reprojection error is larger is rejected.",
	  .range = { 0.0, 5.0, true, false },
	  .unit = "px" },
	{ .key = "max_log10_nfa",
	  .kind = Kind::Number,
	  .member = &PipelineSection::max_log10_nfa,
	  .doc = "Acceptance bound of the full search: a match is a pose only if its expected "
		 "number of false alarms per frame is at most 10^value (docs/vision.md). Lower is "
		 "stricter: fewer poses from weak evidence (one face, far, in clutter).",
	  .range = { -40.0, -2.0 },
	  .unit = "log10" },
	{ .key = "max_rotation_error_deg",
	  .kind = Kind::Number,
	  .member = &PipelineSection::max_rotation_error_deg,
	  .doc = "Precision a pose must have to be reported: the 99 % bound of its rotation error, "
		 "from its own covariance, within this; a pose the image determines less well (far, "
		 "few LEDs, blurred) is refused as imprecise. 0: no limit.",
	  .range = { 0.0, 180.0 },
	  .unit = "degrees" },
	{ .key = "max_translation_error_frac",
	  .kind = Kind::Number,
	  .member = &PipelineSection::max_translation_error_frac,
	  .doc = "The same for the translation: the 99 % bound of its error within max(5 mm, this "
		 "x range). 0: no limit.",
	  .range = { 0.0, 1.0 },
	  .unit = "of range" },
	{ .key = "min_leds_search",
	  .kind = Kind::Integer,
	  .member = &PipelineSection::min_leds_search,
	  .doc = "Floor on the LEDs a pose from a full search rests on; acceptance itself is the "
		 "false-alarm bound (docs/vision.md).",
	  .range = { 4, kInf },
	  .unit = "LEDs",
	  .range_note = "at most the target's LED count" },
	{ .key = "min_leds_track",
	  .kind = Kind::Integer,
	  .member = &PipelineSection::min_leds_track,
	  .doc = "LEDs needed for a pose while tracking.",
	  .range = { 4, kInf },
	  .unit = "LEDs",
	  .range_note = "at most `min_leds_search`" },
	{ .key = "full_frame_every",
	  .kind = Kind::Integer,
	  .member = &PipelineSection::full_frame_every,
	  .doc = "While tracking, one frame in this many is read whole (to re-measure the "
		 "background, the noise and the clutter density that acceptance uses); between, "
		 "only windows around the predicted LEDs are read (docs/vision.md, \"Regions of "
		 "interest\"). A frame whose windows fail is read whole at once. `1`: every frame "
		 "whole.",
	  .range = { 1, 10000 },
	  .unit = "frames" },
	{ .key = "degraded_hold_frames",
	  .kind = Kind::Integer,
	  .member = &PipelineSection::degraded_hold_frames,
	  .doc = "The state stays *degraded* this many frames after a pose was lost or LEDs were "
		 "missing.",
	  .range = { 0, 10000 },
	  .unit = "frames" },
	{ .key = "lost_after_frames",
	  .kind = Kind::Integer,
	  .member = &PipelineSection::lost_after_frames,
	  .doc = "Frames in a row without a pose before the state drops to *searching*.",
	  .range = { 1, 1000 },
	  .unit = "frames" },
};

const Field<SystemdSection> kSystemdFields[] = {
	{ .key = "notify",
	  .kind = Kind::Boolean,
	  .member = &SystemdSection::notify,
	  .doc = "Send sd_notify READY/STATUS/WATCHDOG messages when `NOTIFY_SOCKET` is set (under "
		 "systemd)." },
};

const Field<PreviewSection> kPreviewFields[] = {
	{ .key = "enabled",
	  .kind = Kind::Boolean,
	  .member = &PreviewSection::enabled,
	  .doc = "Publish downscaled frames with what the pipeline found in them (blobs, matched "
		 "LEDs, pose, state) into shared memory for `dockpose view`. The frame loop never "
		 "waits for a reader." },
	{ .key = "name",
	  .kind = Kind::String,
	  .member = &PreviewSection::name,
	  .doc = "The shared memory's name: `/dev/shm/<name>` (`dockpose view --preview NAME`).",
	  .check = checkPreviewName,
	  .range_doc = "1 to 200 characters, no `/`" },
	{ .key = "rate_hz",
	  .kind = Kind::Number,
	  .member = &PreviewSection::rate_hz,
	  .doc = "At most this many frames a second are published (every Nth camera frame, N = "
		 "ceil(camera.frame_rate_hz / rate_hz)).",
	  .range = { 0.1, 10.0 },
	  .unit = "Hz" },
	{ .key = "width",
	  .kind = Kind::Integer,
	  .member = &PreviewSection::width,
	  .doc = "The preview's width at most: the frame is shrunk by the smallest integer factor "
		 "that fits (the mean of each block).",
	  .range = { 16, 640 },
	  .unit = "px" },
};

std::string hex(std::uint64_t v)
{
	char buf[24];
	std::snprintf(buf, sizeof(buf), "0x%" PRIx64, v);
	return buf;
}

std::string code(const std::string &s)
{
	return "`" + s + "`";
}

std::string codeList(std::span<const char *const> names)
{
	std::string out;
	for (const char *n : names)
		out += (out.empty() ? "" : ", ") + code(n);
	return out;
}

template<typename S>
std::string typeText(const Field<S> &f)
{
	switch (f.kind) {
	case Kind::Integer:
	case Kind::Unsigned:
	case Kind::OneOf:
		return "integer";
	case Kind::Number:
		return "number";
	case Kind::Boolean:
		return "boolean";
	case Kind::String:
	case Kind::Backend:
	case Kind::Choice:
		return "string";
	case Kind::Path:
		return "path";
	case Kind::Pose:
		return "array of 6 numbers";
	case Kind::CanId:
		return R"(integer, or string `"0x300"` (hex) or `"768"`)";
	case Kind::Object:
		return "object";
	}
	return "";
}

/*
 * Whether a Member<S> alternative M can point at a member of S: std::monostate
 * cannot, nor a pointer to a type wider than S. The visit below instantiates
 * every alternative, and GCC 12 at -O2 flags reading one wider than S with
 * -Warray-bounds (an int of the 1-byte SystemdSection), though never held.
 */
template<typename S, typename M>
constexpr bool kNamesMember = false;
template<typename S, typename T>
constexpr bool kNamesMember<S, T S::*> = sizeof(T) <= sizeof(S);

/* GCC 12 at -O3 (the aarch64 release build) warns that the strings of `defaults` below "may be
 * used uninitialized": a false positive of its inlining of the static's construction (they are
 * value-initialised), which -Werror would turn into a failed build. */
#if defined(__GNUC__) && !defined(__clang__) /* clang has no such warning, and says so */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
template<typename S>
std::string defaultText(const Field<S> &f)
{
	if (f.required)
		return "**required**";
	if (f.kind == Kind::Object)
		return "";
	static const S defaults{};
	std::string out = std::visit(
		[&f](auto member) -> std::string {
			using M = decltype(member);
			if constexpr (!kNamesMember<S, M>) {
				return "";
			} else {
				const auto &v = defaults.*member;
				using V = std::remove_cvref_t<decltype(v)>;
				if constexpr (std::is_same_v<V, bool>) {
					return v ? "`true`" : "`false`";
				} else if constexpr (std::is_same_v<V, std::string>) {
					return code(quote(v));
				} else if constexpr (std::is_same_v<V, double[6]>) {
					std::string list;
					for (double d : v)
						list += (list.empty() ? "" : ", ") +
							formatNumber(d);
					return code("[" + list + "]");
				} else if constexpr (std::is_enum_v<V>) {
					return code(f.choices[static_cast<std::size_t>(v)]);
				} else if constexpr (std::is_arithmetic_v<V>) {
					if (f.kind == Kind::CanId)
						return code(hex(v));
					return code(formatNumber(static_cast<double>(v)));
				} else {
					return "";
				}
			}
		},
		f.member);
	if (*f.default_note)
		out += std::string("; ") + f.default_note;
	return out;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

template<typename S>
std::string rangeText(const Field<S> &f)
{
	std::string out;
	if (*f.range_doc) {
		out = f.range_doc;
	} else {
		switch (f.kind) {
		case Kind::Integer:
		case Kind::Number:
			out = f.range.docText();
			break;
		case Kind::Unsigned:
			out = ">= 0 (64 bit)";
			break;
		case Kind::Backend: {
			const std::vector<const char *> names = board::backendNames(f.backend);
			out = codeList(names);
			break;
		}
		case Kind::Choice:
			out = codeList(f.choices);
			break;
		case Kind::OneOf:
			for (std::int64_t v : f.one_of)
				out += (out.empty() ? "" : ", ") + std::to_string(v);
			break;
		case Kind::Pose:
			out = "z > 0 (in front of the camera); angles [-180, 180]";
			break;
		case Kind::CanId:
			out = "11-bit: base_id + " + hex(0x7ff - can::kMaxBaseId) +
			      " <= 0x7ff, so at most " + code(hex(can::kMaxBaseId));
			break;
		case Kind::Boolean:
		case Kind::String:
		case Kind::Path:
		case Kind::Object:
			break;
		}
	}
	if (*f.range_note)
		out += (out.empty() ? "" : ", ") + std::string(f.range_note);
	return out;
}

template<typename S>
std::string tableOf()
{
	std::string out = "| key | type | default | range | unit | meaning |\n"
			  "|---|---|---|---|---|---|\n";
	for (const Field<S> &f : fieldsOf<S>()) {
		out += "| " + code(f.key) + " | " + typeText(f) + " | " + defaultText(f) + " | " +
		       rangeText(f) + " | " + f.unit + " | " + f.doc + " |\n";
	}
	return out;
}

/*
 * The sections in document order: S's own table, then each subsection row's
 * struct, depth first, named by JSON path ("top" for the top level).
 */
template<typename S>
void walk(const std::string &path,
	  const std::function<void(const std::string &, std::string (*)())> &visit)
{
	visit(path.empty() ? "top" : path, tableOf<S>);
	for (const Field<S> &f : fieldsOf<S>()) {
		if (f.kind != Kind::Object)
			continue;
		std::visit(
			[&](auto member) {
				using M = decltype(member);
				if constexpr (!std::is_same_v<M, std::monostate>) {
					using T = std::remove_cvref_t<decltype(std::declval<S &>().*
									       member)>;
					if constexpr (std::is_class_v<T> &&
						      !std::is_same_v<T, std::string>)
						walk<T>(path.empty() ? f.key : path + "." + f.key,
							visit);
				}
			},
			f.member);
	}
}

} /* namespace */

std::string formatNumber(double v)
{
	char buf[40];
	if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) < 1e15)
		std::snprintf(buf, sizeof(buf), "%.0f", v);
	else
		std::snprintf(buf, sizeof(buf), "%.6g", v);
	return buf;
}

std::string Range::text() const
{
	if (std::isinf(hi))
		return std::string("(must be ") + (lo_open ? "> " : ">= ") + formatNumber(lo) + ")";
	return std::string(lo_open ? "(" : "[") + formatNumber(lo) + ", " + formatNumber(hi) +
	       (hi_open ? ")" : "]");
}

std::string Range::docText() const
{
	if (std::isinf(hi))
		return std::string(lo_open ? "> " : ">= ") + formatNumber(lo);
	return std::string(lo_open ? "(" : "[") + formatNumber(lo) + ", " + formatNumber(hi) +
	       (hi_open ? ")" : "]");
}

template<>
std::span<const Field<BoardConfig>> fieldsOf<BoardConfig>()
{
	return kTopFields;
}
template<>
std::span<const Field<CameraSection>> fieldsOf<CameraSection>()
{
	return kCameraFields;
}
template<>
std::span<const Field<SyntheticScene>> fieldsOf<SyntheticScene>()
{
	return kSyntheticFields;
}
template<>
std::span<const Field<ReplayCameraConfig>> fieldsOf<ReplayCameraConfig>()
{
	return kReplayFields;
}
template<>
std::span<const Field<StrobeSection>> fieldsOf<StrobeSection>()
{
	return kStrobeFields;
}
template<>
std::span<const Field<CanSection>> fieldsOf<CanSection>()
{
	return kCanFields;
}
template<>
std::span<const Field<PipelineSection>> fieldsOf<PipelineSection>()
{
	return kPipelineFields;
}
template<>
std::span<const Field<SystemdSection>> fieldsOf<SystemdSection>()
{
	return kSystemdFields;
}

template<>
std::span<const Field<PreviewSection>> fieldsOf<PreviewSection>()
{
	return kPreviewFields;
}

std::span<const std::int64_t> canBitrates()
{
	return kCanBitrates;
}

std::vector<std::string> docSections()
{
	std::vector<std::string> names;
	walk<BoardConfig>("", [&names](const std::string &name, std::string (*)()) {
		names.push_back(name);
	});
	return names;
}

std::string docTable(const std::string &section)
{
	std::string out;
	walk<BoardConfig>("", [&](const std::string &name, std::string (*table)()) {
		if (name == section)
			out = table();
	});
	return out;
}

} /* namespace dockpose::firmware::config_table */

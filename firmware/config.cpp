/* SPDX-License-Identifier: MIT */
/*
 * Board configuration: JSON -> BoardConfig, with every error collected and
 * named by its JSON path (docs/configuration.md).
 *
 * The reader walks the document section by section, each by its table
 * (firmware/config_table.h): every row is read and range-checked by its kind
 * (readField), a subsection row recursing into its struct's table. Each
 * section records the keys it knows while it reads them; what is left
 * afterwards is an unknown key (a typo), reported with the closest known key.
 * Values are stored only when they are valid, so the checks across keys
 * (checkAcross: exposure against the frame period, LED counts against the
 * target), run after a section's table, see either the user's valid value or
 * the default; such a check is skipped when one of its inputs was already
 * reported.
 */
#include "firmware/config.h"

#include <algorithm>
#include <cctype>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <set>
#include <span>
#include <system_error>
#include <type_traits>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "algo/io/model_json.h"
#include "board/board.h"
#include "firmware/config_table.h"
#include "firmware/protocol/dockpose_can.h"

namespace dockpose::firmware {

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

using config_table::Field;
using config_table::Kind;
using config_table::Range;

/* The protocol's identifiers: base_id + 0 .. base_id + kCanIdSpan, 11 bits (firmware/protocol). */
constexpr std::uint32_t kCanMaxId = 0x7ff;
constexpr std::uint32_t kCanIdSpan = kCanMaxId - can::kMaxBaseId;

std::string num(double v)
{
	return config_table::formatNumber(v);
}

std::string hex(std::uint64_t v)
{
	char buf[24];
	std::snprintf(buf, sizeof(buf), "0x%" PRIx64, v);
	return buf;
}

std::string quote(const std::string &s)
{
	return json(s).dump();
}

std::string joinNames(std::span<const char *const> names)
{
	std::string out;
	for (const char *n : names) {
		if (!out.empty())
			out += ", ";
		out += n;
	}
	return out;
}

/* What a JSON value is, for "expected X, got Y". Numbers show themselves. */
std::string describe(const json &j)
{
	if (j.is_string())
		return "a string";
	if (j.is_boolean())
		return "a boolean";
	if (j.is_null())
		return "null";
	if (j.is_array())
		return "an array";
	if (j.is_object())
		return "an object";
	if (j.is_number())
		return j.dump();
	return "something else";
}

/* Optimal string alignment distance (Levenshtein plus adjacent transpositions). */
std::size_t editDistance(const std::string &a, const std::string &b)
{
	const std::size_t n = a.size(), m = b.size();
	std::vector<std::vector<std::size_t>> d(n + 1, std::vector<std::size_t>(m + 1));
	for (std::size_t i = 0; i <= n; ++i)
		d[i][0] = i;
	for (std::size_t j = 0; j <= m; ++j)
		d[0][j] = j;
	for (std::size_t i = 1; i <= n; ++i) {
		for (std::size_t j = 1; j <= m; ++j) {
			const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
			d[i][j] = std::min(
				{ d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost });
			if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
				d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
		}
	}
	return d[n][m];
}

/* The closest known key when it is close enough to be a typo of it, else empty. */
std::string closestKey(const std::string &key, const std::vector<std::string> &known)
{
	std::string lower = key;
	std::transform(lower.begin(), lower.end(), lower.begin(),
		       [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
	std::string best;
	std::size_t best_d = std::numeric_limits<std::size_t>::max();
	for (const std::string &k : known) {
		std::size_t d = editDistance(lower, k);
		/* A prefix ("exposure" for "exposure_us") counts as close. */
		if (lower.size() >= 3 && (k.rfind(lower, 0) == 0 || lower.rfind(k, 0) == 0))
			d = std::min<std::size_t>(d, 1);
		if (d < best_d) {
			best_d = d;
			best = k;
		}
	}
	const std::size_t limit = std::max<std::size_t>(2, (key.size() + 2) / 3);
	return best_d <= limit ? best : std::string();
}

enum class Got : std::uint8_t {
	Absent,
	Ok,
	Bad
};

class Checker
{
public:
	explicit Checker(fs::path base)
		: base_(std::move(base))
	{
	}

	void fail(const std::string &path, const std::string &what)
	{
		errors_.push_back(path + ": " + what);
		bad_.insert(path);
	}
	void failRaw(const std::string &message) { errors_.push_back(message); }
	bool failed(const std::string &path) const { return bad_.count(path) != 0; }

	std::string resolve(const std::string &p) const
	{
		fs::path fp(p);
		if (fp.is_relative())
			fp = base_ / fp;
		return fp.lexically_normal().string();
	}

	std::vector<std::string> take() { return std::move(errors_); }

private:
	fs::path base_;
	std::vector<std::string> errors_;
	std::set<std::string> bad_;
};

/* One JSON object of the document: a section, or the top level (empty path). */
class Section
{
public:
	Section(Checker *checker, const json *object, std::string path)
		: checker_(checker),
		  object_(object),
		  path_(std::move(path))
	{
	}

	Checker &checker() const { return *checker_; }
	bool present() const { return object_ != nullptr; }
	const std::string &path() const { return path_; }
	std::string at(const std::string &key) const
	{
		return path_.empty() ? key : path_ + "." + key;
	}

	/* The value of a key (nullptr when absent); marks the key as known. */
	const json *get(const char *key)
	{
		known_.emplace_back(key);
		if (!object_)
			return nullptr;
		const auto it = object_->find(key);
		return it == object_->end() ? nullptr : &*it;
	}

	/* Report a missing key unless its whole section was already reported. */
	void missing(const char *key, const std::string &what)
	{
		if (!object_ && checker_->failed(path_))
			return;
		checker_->fail(at(key), what);
	}

	/* Report the keys nobody asked for. */
	void finish()
	{
		if (!object_)
			return;
		for (const auto &item : object_->items()) {
			const std::string &key = item.key();
			if (std::find(known_.begin(), known_.end(), key) != known_.end())
				continue;
			const std::string where = path_.empty() ? std::string("at top level")
								: "in " + path_;
			const std::string close = closestKey(key, known_);
			std::string hint;
			if (!close.empty()) {
				hint = "did you mean " + quote(close) + "?";
			} else {
				hint = "known keys: ";
				for (std::size_t i = 0; i < known_.size(); ++i)
					hint += (i ? ", " : "") + known_[i];
			}
			std::string message = "unknown key " + quote(key);
			message.append(" ").append(where).append(" (").append(hint).append(")");
			checker_->failRaw(message);
		}
	}

private:
	Checker *checker_;
	const json *object_;
	std::string path_;
	std::vector<std::string> known_;
};

Section subsection(Section &parent, const char *key, bool required)
{
	const json *j = parent.get(key);
	if (!j) {
		if (required)
			parent.missing(key, "required section is missing");
		return Section(&parent.checker(), nullptr, parent.at(key));
	}
	if (!j->is_object()) {
		parent.checker().fail(parent.at(key), "expected an object, got " + describe(*j));
		return Section(&parent.checker(), nullptr, parent.at(key));
	}
	return Section(&parent.checker(), j, parent.at(key));
}

Got getString(Section &s, const char *key, std::string *out)
{
	const json *j = s.get(key);
	if (!j)
		return Got::Absent;
	if (!j->is_string()) {
		s.checker().fail(s.at(key), "expected a string, got " + describe(*j));
		return Got::Bad;
	}
	*out = j->get<std::string>();
	return Got::Ok;
}

Got getBool(Section &s, const char *key, bool *out)
{
	const json *j = s.get(key);
	if (!j)
		return Got::Absent;
	if (!j->is_boolean()) {
		s.checker().fail(s.at(key), "expected true or false, got " + describe(*j));
		return Got::Bad;
	}
	*out = j->get<bool>();
	return Got::Ok;
}

/* An integral JSON number (2000 or 2000.0) as int64, saturated. False for anything else. */
bool asInt64(const json &j, std::int64_t *out)
{
	constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
	if (j.is_number_unsigned()) {
		const std::uint64_t u = j.get<std::uint64_t>();
		*out = u > static_cast<std::uint64_t>(kMax) ? kMax : static_cast<std::int64_t>(u);
		return true;
	}
	if (j.is_number_integer()) {
		*out = j.get<std::int64_t>();
		return true;
	}
	if (j.is_number_float()) {
		const double d = j.get<double>();
		if (!std::isfinite(d) || d != std::floor(d))
			return false;
		if (std::fabs(d) >= 9.2e18)
			*out = d > 0 ? kMax : std::numeric_limits<std::int64_t>::min();
		else
			*out = static_cast<std::int64_t>(d);
		return true;
	}
	return false;
}

/*
 * The key's value as an integer (asInt64): Absent when the key is missing,
 * Bad (with "expected an integer" reported) when it is not an integral
 * number; *j is the key's JSON value when not Absent.
 */
Got readInteger(Section &s, const char *key, const json **j, std::int64_t *out)
{
	*j = s.get(key);
	if (!*j)
		return Got::Absent;
	if (!asInt64(**j, out)) {
		s.checker().fail(s.at(key), "expected an integer, got " + describe(**j));
		return Got::Bad;
	}
	return Got::Ok;
}

/* An upper bound for getInt() that is only the int's own limit (not shown in messages). */
constexpr std::int64_t kNoLimit = std::numeric_limits<int>::max();

Got getInt(Section &s, const char *key, const Range &range, int *out)
{
	const std::int64_t lo = std::isinf(range.lo) ? std::numeric_limits<int>::min()
						     : static_cast<std::int64_t>(range.lo);
	const std::int64_t hi = std::isinf(range.hi) ? kNoLimit
						     : static_cast<std::int64_t>(range.hi);
	const json *j = nullptr;
	std::int64_t v = 0;
	if (const Got got = readInteger(s, key, &j, &v); got != Got::Ok)
		return got;
	if (v < lo || v > hi) {
		s.checker().fail(s.at(key),
				 j->dump() + " is out of range " +
					 (hi == kNoLimit ? "(must be >= " + std::to_string(lo) + ")"
							 : "[" + std::to_string(lo) + ", " +
								   std::to_string(hi) + "]"));
		return Got::Bad;
	}
	*out = static_cast<int>(v);
	return Got::Ok;
}

Got getUint64(Section &s, const char *key, std::uint64_t *out)
{
	const json *j = nullptr;
	std::int64_t v = 0;
	if (const Got got = readInteger(s, key, &j, &v); got != Got::Ok)
		return got;
	if (j->is_number_unsigned()) {
		*out = j->get<std::uint64_t>(); /* all of uint64, beyond int64's saturation */
		return Got::Ok;
	}
	if (v < 0) {
		s.checker().fail(s.at(key), j->dump() + " is out of range (must be >= 0)");
		return Got::Bad;
	}
	*out = static_cast<std::uint64_t>(v);
	return Got::Ok;
}

Got getDouble(Section &s, const char *key, const Range &range, double *out)
{
	const json *j = s.get(key);
	if (!j)
		return Got::Absent;
	if (!j->is_number()) {
		s.checker().fail(s.at(key), "expected a number, got " + describe(*j));
		return Got::Bad;
	}
	const double v = j->get<double>();
	if (!range.contains(v)) {
		s.checker().fail(s.at(key), j->dump() + " is out of range " + range.text());
		return Got::Bad;
	}
	*out = v;
	return Got::Ok;
}

/* A string that must be one of `names`; *index gets its position. */
Got getChoice(Section &s, const char *key, std::span<const char *const> names, std::size_t *index,
	      std::string *value = nullptr)
{
	std::string v;
	const Got got = getString(s, key, &v);
	if (got != Got::Ok)
		return got;
	for (std::size_t i = 0; i < names.size(); ++i) {
		if (v == names[i]) {
			*index = i;
			if (value)
				*value = v;
			return Got::Ok;
		}
	}
	s.checker().fail(s.at(key), quote(v) + " is not one of " + joinNames(names));
	return Got::Bad;
}

/* A non-empty file path, resolved against the configuration's directory. */
Got getPath(Section &s, const char *key, std::string *written, std::string *resolved)
{
	const Got got = getString(s, key, written);
	if (got != Got::Ok)
		return got;
	if (written->empty()) {
		s.checker().fail(s.at(key), "must not be empty (a file path)");
		return Got::Bad;
	}
	*resolved = s.checker().resolve(*written);
	return Got::Ok;
}

/* [x, y, z, roll, pan, tilt]: mm, degrees; z > 0 (in front of the camera). */
Got getPose(Section &s, const char *key, double out[6])
{
	const json *j = s.get(key);
	if (!j)
		return Got::Absent;
	const std::string path = s.at(key);
	if (!j->is_array() || j->size() != 6) {
		s.checker().fail(path,
				 "expected an array of 6 numbers [x, y, z mm, roll, pan, tilt "
				 "degrees], got " +
					 (j->is_array() ? "an array of " + std::to_string(j->size())
							: describe(*j)));
		return Got::Bad;
	}
	double v[6];
	bool ok = true;
	for (std::size_t i = 0; i < 6; ++i) {
		const json &e = (*j)[i];
		const std::string epath = path + "[" + std::to_string(i) + "]";
		if (!e.is_number()) {
			s.checker().fail(epath, "expected a number, got " + describe(e));
			ok = false;
			continue;
		}
		v[i] = e.get<double>();
		if (i == 2 && !(v[i] > 0.0)) {
			s.checker().fail(epath,
					 "z = " + e.dump() +
						 " mm is not in front of the camera (must be > 0)");
			ok = false;
		} else if (i >= 3 && !(v[i] >= -180.0 && v[i] <= 180.0)) {
			s.checker().fail(epath, e.dump() + " degrees is out of range [-180, 180]");
			ok = false;
		}
	}
	if (!ok)
		return Got::Bad;
	std::copy(v, v + 6, out);
	return Got::Ok;
}

void checkReplayFolder(Checker &c, const std::string &path, const std::string &written,
		       const std::string &folder)
{
	const std::string shown = quote(written) + (written == folder ? "" : " (" + folder + ")");
	std::error_code ec;
	const fs::file_status st = fs::status(folder, ec);
	if (ec || !fs::exists(st)) {
		c.fail(path, shown + " does not exist");
		return;
	}
	if (!fs::is_directory(st)) {
		c.fail(path, shown + " is not a folder");
		return;
	}
	fs::directory_iterator it(folder, ec);
	if (ec) {
		c.fail(path, shown + " cannot be read (" + ec.message() + ")");
		return;
	}
	for (; it != fs::directory_iterator(); it.increment(ec)) {
		const std::string name = it->path().filename().string();
		if (name.size() > 10 && name.rfind("frame_", 0) == 0 &&
		    name.compare(name.size() - 4, 4, ".pgm") == 0)
			return;
	}
	if (ec) {
		c.fail(path, shown + " cannot be read (" + ec.message() + ")");
		return;
	}
	c.fail(path, shown + " holds no frame_*.pgm files");
}

/* An integer that must be one of `values`; the message names them with `what`. */
Got getOneOf(Section &s, const char *key, std::span<const std::int64_t> values, const char *what,
	     int *out)
{
	const json *j = nullptr;
	std::int64_t v = 0;
	if (const Got got = readInteger(s, key, &j, &v); got != Got::Ok)
		return got;
	if (std::find(values.begin(), values.end(), v) == values.end()) {
		std::string list;
		for (std::int64_t r : values)
			list += (list.empty() ? "" : ", ") + std::to_string(r);
		s.checker().fail(s.at(key),
				 j->dump() + " is not " + what + " (one of " + list + ")");
		return Got::Bad;
	}
	*out = static_cast<int>(v);
	return Got::Ok;
}

Got getCanId(Section &s, const char *key, std::uint32_t *out)
{
	const json *j = s.get(key);
	if (!j)
		return Got::Absent;
	const std::string path = s.at(key);
	std::int64_t v = 0;
	if (j->is_string()) {
		const std::string text = j->get<std::string>();
		const bool is_hex = text.size() > 2 && text[0] == '0' &&
				    (text[1] == 'x' || text[1] == 'X');
		const std::string digits = is_hex ? text.substr(2) : text;
		const char *allowed = is_hex ? "0123456789abcdefABCDEF" : "0123456789";
		if (digits.empty() || digits.size() > 8 ||
		    digits.find_first_not_of(allowed) != std::string::npos) {
			s.checker().fail(path, quote(text) + " is not a CAN id (expected a number "
							     "or a hex string like \"0x300\")");
			return Got::Bad;
		}
		v = static_cast<std::int64_t>(std::stoull(digits, nullptr, is_hex ? 16 : 10));
	} else if (!asInt64(*j, &v)) {
		s.checker().fail(path, "expected a number or a hex string like \"0x300\", got " +
					       describe(*j));
		return Got::Bad;
	}
	if (v < 0) {
		s.checker().fail(path, j->dump() + " is not a CAN id (must be >= 0)");
		return Got::Bad;
	}
	const std::uint64_t id = static_cast<std::uint64_t>(v);
	if (id > kCanMaxId) {
		s.checker().fail(path, hex(id) + " is not an 11-bit CAN id (max " + hex(kCanMaxId) +
					       "; " + hex(kCanMaxId - kCanIdSpan) +
					       " to leave room for offsets up to " +
					       hex(kCanIdSpan) + ")");
		return Got::Bad;
	}
	if (!can::validBaseId(static_cast<std::uint32_t>(id))) {
		s.checker().fail(path, hex(id) + " leaves no room for offsets up to " +
					       hex(kCanIdSpan) + " in 11 bits (max " +
					       hex(kCanMaxId - kCanIdSpan) + ")");
		return Got::Bad;
	}
	*out = static_cast<std::uint32_t>(id);
	return Got::Ok;
}

/*
 * What the table pass found, by JSON path ("camera.exposure_us"), for the
 * checks across keys: whether each key was absent, valid or reported, and
 * each path as the file wrote it (for messages).
 */
class Reads
{
public:
	Got got(const std::string &path) const
	{
		const auto it = got_.find(path);
		return it == got_.end() ? Got::Absent : it->second;
	}
	const std::string &written(const std::string &path) const { return written_[path]; }

	void set(const std::string &path, Got got) { got_[path] = got; }
	void setWritten(const std::string &path, std::string text)
	{
		written_[path] = std::move(text);
	}

private:
	std::map<std::string, Got> got_;
	mutable std::map<std::string, std::string> written_;
};

/* The checks across keys, run once a section's table has been read and its unknown keys reported. */
template<typename S>
void checkAcross(Section & /*section*/, S & /*out*/, const Reads & /*reads*/,
		 BoardConfig & /*config*/)
{
}

void checkAcross(Section &cam, CameraSection &out, const Reads &reads, BoardConfig &config)
{
	Checker &c = cam.checker();
	const Got rate = reads.got(cam.at("frame_rate_hz"));
	const Got exposure = reads.got(cam.at("exposure_us"));
	const Got stall = reads.got(cam.at("stall_timeout_ms"));
	if (rate != Got::Bad && exposure != Got::Bad) {
		const double period_us = 1e6 / out.frame_rate_hz;
		if (out.exposure_us > period_us)
			c.fail(cam.at("exposure_us"),
			       std::to_string(out.exposure_us) +
				       " us is longer than the frame period of " + num(period_us) +
				       " us at camera.frame_rate_hz " + num(out.frame_rate_hz));
	}
	if (rate != Got::Bad && stall != Got::Bad) {
		const double period_ms = 1e3 / out.frame_rate_hz;
		if (out.stall_timeout_ms <= 2.0 * period_ms)
			c.fail(cam.at("stall_timeout_ms"),
			       std::to_string(out.stall_timeout_ms) +
				       " ms is not more than 2 frame periods (2 x " +
				       num(period_ms) + " ms at camera.frame_rate_hz " +
				       num(out.frame_rate_hz) + ")");
	}

	if (reads.got(cam.at("intrinsics")) == Got::Ok) {
		const std::string &written = reads.written(cam.at("intrinsics"));
		const Result<CameraIntrinsics> k = loadCameraIntrinsics(out.intrinsics);
		config.camera_model = k ? k.value()
					: CameraIntrinsics{}; /* empty when it did not load */
		if (!k) {
			c.fail(cam.at("intrinsics"), "cannot read camera intrinsics " +
							     quote(written) + ": " + k.message());
		} else if (reads.got(cam.at("width")) != Got::Bad &&
			   reads.got(cam.at("height")) != Got::Bad) {
			const int w = k->width, h = k->height;
			if ((out.width != 0 && out.width != w) ||
			    (out.height != 0 && out.height != h)) {
				c.fail(cam.at("intrinsics"),
				       quote(written) + ": size " + std::to_string(w) + "x" +
					       std::to_string(h) +
					       " does not match camera.width/height " +
					       std::to_string(out.width) + "x" +
					       std::to_string(out.height) +
					       " (calibrate at the size the camera runs at)");
			} else {
				out.width = w;
				out.height = h;
			}
		}
	}

	if (reads.got(cam.at("backend")) == Got::Ok && out.backend == "replay") {
		const std::string folder_path = cam.at("replay.folder");
		const Got folder = reads.got(folder_path);
		if (folder == Got::Absent)
			c.fail(folder_path,
			       "required when camera.backend is \"replay\" (a folder of frame_*.pgm)");
		else if (folder == Got::Ok)
			checkReplayFolder(c, folder_path, reads.written(folder_path),
					  out.replay.folder);
	}
}

void checkAcross(Section &st, StrobeSection &out, const Reads &reads, BoardConfig & /*config*/)
{
	Checker &c = st.checker();
	if (reads.got(st.at("backend")) != Got::Ok || out.backend != "gpiod")
		return;
	const Got chip = reads.got(st.at("chip"));
	if (chip == Got::Absent)
		c.fail(st.at("chip"), "required when strobe.backend is \"gpiod\" (a chip "
				      "name like \"gpiochip0\", a path, or a label like "
				      "\"pinctrl-rp1\")");
	else if (chip == Got::Ok && out.chip.empty())
		c.fail(st.at("chip"), "must not be empty when strobe.backend is \"gpiod\"");
	if (reads.got(st.at("line")) == Got::Absent)
		c.fail(st.at("line"),
		       "required when strobe.backend is \"gpiod\" (the line offset on the chip)");
}

void checkAcross(Section &can, CanSection &out, const Reads &reads, BoardConfig &config)
{
	if (reads.got(can.at("backend")) == Got::Ok && out.backend == "socketcan" &&
	    reads.got(can.at("interface")) == Got::Absent)
		can.checker().fail(
			can.at("interface"),
			R"(required when can.backend is "socketcan" (an interface such as "can0"))");
	/* The bus-load check: a report per camera frame must fit the bus, worst-case stuffing. */
	if (reads.got(can.at("bitrate")) == Got::Bad ||
	    reads.got(can.at("heartbeat_hz")) == Got::Bad)
		return;
	const double load = canBusLoad(config);
	if (load > 1.0)
		can.checker().fail(can.at("bitrate"),
				   std::to_string(out.bitrate) +
					   " bit/s cannot carry a report per "
					   "camera frame: worst case " +
					   num(std::round(load * 1000.0) / 10.0) +
					   " % of the bus at camera.frame_rate_hz " +
					   num(config.camera.frame_rate_hz) + ", heartbeat_hz " +
					   std::to_string(out.heartbeat_hz) +
					   (out.key_file.empty() ? "" : ", authenticated") +
					   (out.fd ? ", CAN FD" : "") +
					   " (a faster bus, can.fd, or a lower frame rate)");
}

void checkAcross(Section &pl, PipelineSection &out, const Reads &reads, BoardConfig &config)
{
	Checker &c = pl.checker();
	const Got search = reads.got(pl.at("min_leds_search"));
	bool search_ok = search != Got::Bad;
	if (reads.got(pl.at("target")) == Got::Ok) {
		const Result<TargetModel> model = loadTargetModel(out.target);
		config.target_model = model ? model.value()
					    : TargetModel{}; /* empty when it did not load */
		if (!model) {
			c.fail(pl.at("target"), "cannot read target model " +
							quote(reads.written(pl.at("target"))) +
							": " + model.message());
		} else if (search_ok) {
			const std::size_t leds = model->points_mm.size();
			if (static_cast<std::size_t>(out.min_leds_search) > leds) {
				c.fail(pl.at("min_leds_search"),
				       std::to_string(out.min_leds_search) +
					       (search == Got::Absent ? " (the default)" : "") +
					       " is more than the " + std::to_string(leds) +
					       " LEDs of target " + quote(model->name));
				search_ok = false;
			}
		}
	}
	if (search_ok && reads.got(pl.at("min_leds_track")) != Got::Bad &&
	    out.min_leds_track > out.min_leds_search)
		c.fail(pl.at("min_leds_track"), std::to_string(out.min_leds_track) +
							" is out of range [4, " +
							std::to_string(out.min_leds_search) +
							"] (at most pipeline.min_leds_search)");
}

/* The string kinds (String, Path, Backend); *hint gets the backends for a missing key's message. */
template<typename S>
Got readString(Section &s, const Field<S> &f, const S *out, std::string *value, Reads *reads,
	       std::string *hint)
{
	switch (f.kind) {
	case Kind::Backend: {
		const std::vector<const char *> names = board::backendNames(f.backend);
		*hint = "one of " + joinNames(names);
		std::size_t index = 0;
		return getChoice(s, f.key, names, &index, value);
	}
	case Kind::Path: {
		std::string written;
		if (f.empty_ok) {
			/* "" stays "" (no file); anything else is resolved. */
			const Got got = getString(s, f.key, &written);
			if (got == Got::Ok && !written.empty())
				*value = s.checker().resolve(written);
			return got;
		}
		const Got got = getPath(s, f.key, &written, value);
		reads->setWritten(s.at(f.key), written);
		return got;
	}
	default: {
		const Got got = getString(s, f.key, value);
		if (got != Got::Ok)
			return got;
		if (f.non_empty && value->empty()) {
			s.checker().fail(s.at(f.key),
					 "must not be empty (" + std::string(f.hint) + ")");
			return Got::Bad;
		}
		if (f.check) {
			const std::string problem = f.check(*out, *value);
			if (!problem.empty())
				s.checker().fail(s.at(f.key), problem);
		}
		return got;
	}
	}
}

template<typename S>
void readObject(Section &section, S *out, Reads &reads, BoardConfig &config);

/* Read one key as its row says, into its member of *out. */
template<typename S>
Got readField(Section &s, const Field<S> &f, S *out, Reads &reads, BoardConfig &config)
{
	const char *key = f.key;
	std::string hint = f.hint;
	Got got = Got::Absent;
	std::visit(
		[&](auto member) {
			using M = decltype(member);
			if constexpr (!std::is_same_v<M, std::monostate>) {
				auto &v = out->*member;
				using V = std::remove_cvref_t<decltype(v)>;
				if constexpr (std::is_same_v<V, int>) {
					got = f.kind == Kind::OneOf
						      ? getOneOf(s, key, f.one_of, f.hint, &v)
						      : getInt(s, key, f.range, &v);
				} else if constexpr (std::is_same_v<V, double>) {
					got = getDouble(s, key, f.range, &v);
				} else if constexpr (std::is_same_v<V, bool>) {
					got = getBool(s, key, &v);
				} else if constexpr (std::is_same_v<V, std::uint32_t>) {
					got = getCanId(s, key, &v);
				} else if constexpr (std::is_same_v<V, std::uint64_t>) {
					got = getUint64(s, key, &v);
				} else if constexpr (std::is_same_v<V, double[6]>) {
					got = getPose(s, key, v);
				} else if constexpr (std::is_enum_v<V>) {
					std::size_t index = 0;
					got = getChoice(s, key, f.choices, &index);
					if (got == Got::Ok)
						v = static_cast<V>(index);
				} else if constexpr (std::is_same_v<V, std::string>) {
					got = readString(s, f, out, &v, &reads, &hint);
				} else {
					Section sub = subsection(s, key, f.required);
					readObject(sub, &v, reads, config);
					got = sub.present() ? Got::Ok : Got::Absent;
				}
			}
		},
		f.member);
	if (got == Got::Absent && f.required && f.kind != Kind::Object)
		s.missing(key, "required key is missing (" + hint + ")");
	return got;
}

/* Every key of the section's table, its unknown keys, then its checks across keys. */
template<typename S>
void readObject(Section &section, S *out, Reads &reads, BoardConfig &config)
{
	for (const Field<S> &f : config_table::fieldsOf<S>())
		reads.set(section.at(f.key), readField(section, f, out, reads, config));
	section.finish();
	checkAcross(section, *out, reads, config);
}

/* Parse JSON (comments allowed), reporting duplicate keys by path. */
bool parseDocument(const std::string &text, const std::string &source, json *doc,
		   std::vector<std::string> *errors)
{
	struct Level {
		std::string name;
		std::set<std::string> keys;
		std::string last_key;
		bool array;
	};
	std::vector<Level> stack;
	std::vector<std::string> duplicates;
	const json::parser_callback_t callback = [&](int, json::parse_event_t event,
						     json &parsed) -> bool {
		switch (event) {
		case json::parse_event_t::object_start:
		case json::parse_event_t::array_start: {
			std::string name;
			if (!stack.empty())
				name = stack.back().array ? "[]" : stack.back().last_key;
			stack.push_back(
				{ name, {}, {}, event == json::parse_event_t::array_start });
			break;
		}
		case json::parse_event_t::object_end:
		case json::parse_event_t::array_end:
			if (!stack.empty())
				stack.pop_back();
			break;
		case json::parse_event_t::key: {
			if (stack.empty() || !parsed.is_string())
				break;
			const std::string key = parsed.get<std::string>();
			if (!stack.back().keys.insert(key).second) {
				std::string path;
				for (std::size_t i = 1; i < stack.size(); ++i)
					path += (path.empty() || stack[i].name == "[]" ? "" : ".") +
						stack[i].name;
				path += (path.empty() ? "" : ".") + key;
				duplicates.push_back(path + ": duplicate key (the last value would "
							    "silently replace the earlier one)");
			}
			stack.back().last_key = key;
			break;
		}
		case json::parse_event_t::value:
			break;
		}
		return true;
	};

	try {
		*doc = json::parse(text, callback, true, /*ignore_comments=*/true);
	} catch (const json::parse_error &e) {
		/* "[json.exception.parse_error.101] parse error at line 12, column 5: msg" */
		const std::string what = e.what();
		const std::size_t line = what.find("line ");
		const std::size_t colon = line == std::string::npos ? line : what.find(": ", line);
		if (line != std::string::npos && colon != std::string::npos) {
			errors->push_back(source + ": " + what.substr(line, colon - line) + ": " +
					  what.substr(colon + 2));
		} else {
			/* No position in the message: count lines up to the byte offset. */
			const std::size_t end = std::min<std::size_t>(e.byte, text.size());
			std::size_t ln = 1, col = 1;
			for (std::size_t i = 0; i + 1 < end; ++i) {
				if (text[i] == '\n') {
					++ln;
					col = 1;
				} else {
					++col;
				}
			}
			errors->push_back(source + ": line " + std::to_string(ln) + ", column " +
					  std::to_string(col) + ": " + what);
		}
		return false;
	} catch (const json::exception &e) {
		/* out_of_range.406, "number overflow parsing '1e400'": named by the key it was for. */
		std::string path;
		for (std::size_t i = 1; i < stack.size(); ++i)
			path += (path.empty() || stack[i].name == "[]" ? "" : ".") + stack[i].name;
		if (!stack.empty() && !stack.back().array && !stack.back().last_key.empty())
			path += (path.empty() ? "" : ".") + stack.back().last_key;
		const std::string what = e.what();
		const std::size_t tag_end = what.find("] ");
		errors->push_back(source + ": " + (path.empty() ? "" : path + ": ") +
				  (dynamic_cast<const json::out_of_range *>(&e)
					   ? "a number beyond the range of a double ("
					   : "cannot be read as JSON (") +
				  (tag_end == std::string::npos ? what : what.substr(tag_end + 2)) +
				  ")");
		return false;
	}
	if (!doc->is_object()) {
		errors->push_back(source + ": the top level must be an object {...}, got " +
				  describe(*doc));
		return false;
	}
	errors->insert(errors->end(), duplicates.begin(), duplicates.end());
	return true;
}

ConfigResult parseWithSource(const std::string &json_text, const std::string &base_dir,
			     const std::string &source)
{
	ConfigResult result;
	json doc;
	if (!parseDocument(json_text, source, &doc, &result.errors))
		return result;

	std::error_code ec;
	fs::path base = base_dir.empty() ? fs::current_path(ec) : fs::absolute(base_dir, ec);
	if (ec)
		base = fs::path(base_dir);
	Checker checker(base.lexically_normal());

	Section top(&checker, &doc, "");
	Reads reads;
	readObject(top, &result.config, reads, result.config);

	std::vector<std::string> errors = checker.take();
	result.errors.insert(result.errors.end(), errors.begin(), errors.end());
	return result;
}

} /* namespace */

double canBusLoad(const BoardConfig &config)
{
	const CanSection &can = config.can;
	const bool authenticated = !can.key_file.empty();
	return can.fd ? can::worstCaseFdBusLoad(config.camera.frame_rate_hz, can.heartbeat_hz,
						can.bitrate, 0.0, authenticated)
		      : can::worstCaseBusLoad(config.camera.frame_rate_hz, can.heartbeat_hz,
					      can.bitrate, 0.0, authenticated);
}

ConfigResult parseBoardConfig(const std::string &json_text, const std::string &base_dir)
{
	return parseWithSource(json_text, base_dir, "<text>");
}

ConfigResult loadBoardConfig(const std::string &path)
{
	const Result<std::string> text = readFileContents(path);
	if (!text) {
		ConfigResult result;
		result.config.path = path;
		result.errors.push_back(text.message());
		return result;
	}
	std::error_code ec;
	fs::path dir = fs::absolute(fs::path(path), ec).parent_path();
	if (ec)
		dir = fs::path(path).parent_path();
	ConfigResult result = parseWithSource(text.value(), dir.string(), path);
	result.config.path = path;
	return result;
}

} /* namespace dockpose::firmware */

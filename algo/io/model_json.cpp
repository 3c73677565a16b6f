/* SPDX-License-Identifier: MIT */
#include "algo/io/model_json.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string_view>

#include <nlohmann/json.hpp>

namespace dockpose {

namespace {

using nlohmann::json;

const char *typeName(const json &j)
{
	if (j.is_number_integer() || j.is_number_unsigned())
		return "an integer";
	if (j.is_number_float())
		return "a number";
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
	return "something else";
}

/* Parse without letting an exception escape: "<source>: ..." on failure. */
Status parseDocument(const std::string &text, const std::string &source, json *doc)
{
	try {
		*doc = json::parse(text, nullptr, true, /*ignore_comments=*/true);
	} catch (const json::parse_error &e) {
		return Status::error(source + ": not valid JSON (" + e.what() + ")");
	} catch (const json::out_of_range &e) {
		/* nlohmann's "[json.exception.out_of_range.406] number overflow parsing '1e400'" */
		const std::string what = e.what();
		const std::size_t tag_end = what.find("] ");
		return Status::error(
			source + ": a number beyond the range of a double (" +
			(tag_end == std::string::npos ? what : what.substr(tag_end + 2)) + ")");
	} catch (const json::exception &e) {
		return Status::error(source + ": cannot be read as JSON (" + e.what() + ")");
	}
	if (!doc->is_object())
		return Status::error(source + ": the top level must be a JSON object, not " +
				     typeName(*doc));
	return Status::ok();
}

Status readNumber(const json &doc, const char *key, const std::string &source, bool required,
		  double *value)
{
	const auto it = doc.find(key);
	if (it == doc.end()) {
		if (required)
			return Status::error(source + ": key '" + key + "' is missing");
		return Status::ok();
	}
	if (!it->is_number())
		return Status::error(source + ": '" + key + "' must be a number, not " +
				     typeName(*it));
	*value = it->get<double>();
	return Status::ok();
}

Status readInt(const json &doc, const char *key, const std::string &source, int *value)
{
	const auto it = doc.find(key);
	if (it == doc.end())
		return Status::error(source + ": key '" + key + "' is missing");
	if (!it->is_number_integer() && !it->is_number_unsigned())
		return Status::error(source + ": '" + key + "' must be an integer, not " +
				     typeName(*it));
	const std::int64_t v = it->get<std::int64_t>();
	if (v < -1000000 || v > 1000000)
		return Status::error(source + ": '" + key + "' = " + std::to_string(v) +
				     " is out of range");
	*value = static_cast<int>(v);
	return Status::ok();
}

/* "an array of 2" or "a string": what a value that should have been an n-array is. */
std::string shapeOf(const json &j)
{
	return j.is_array() ? "an array of " + std::to_string(j.size()) : std::string(typeName(j));
}

/* Target model, step 1: "name" (default: the file's stem) and "units". */
Status readNameAndUnits(const json &doc, const std::string &source, TargetModel *m)
{
	const auto name = doc.find("name");
	if (name != doc.end()) {
		if (!name->is_string())
			return Status::error(source + ": 'name' must be a string, not " +
					     typeName(*name));
		m->name = name->get<std::string>();
	} else {
		m->name = std::filesystem::path(source).stem().string();
	}

	const auto units = doc.find("units");
	if (units != doc.end() && (!units->is_string() || units->get<std::string>() != "mm"))
		return Status::error(
			source + ": 'units' must be \"mm\" (the only unit dockpose uses), not " +
			units->dump());
	return Status::ok();
}

/* Target model, step 2: "points", the LED centres in mm. */
Status readPoints(const json &doc, const std::string &source, TargetModel *m)
{
	const auto points = doc.find("points");
	if (points == doc.end())
		return Status::error(
			source +
			": key 'points' is missing (the LED centres, [[x, y, z], ...] in mm)");
	if (!points->is_array())
		return Status::error(source + ": 'points' must be an array of [x, y, z], not " +
				     typeName(*points));
	if (points->size() > kMaxLeds)
		return Status::error(source + ": 'points' lists " + std::to_string(points->size()) +
				     " LEDs, more than the firmware's capacity of " +
				     std::to_string(kMaxLeds) + " (kMaxLeds in algo/capacities.h)");
	for (std::size_t i = 0; i < points->size(); ++i) {
		const json &p = (*points)[i];
		if (!p.is_array() || p.size() != 3)
			return Status::error(source + ": point " + std::to_string(i) +
					     " must be [x, y, z] (3 numbers), but it is " +
					     shapeOf(p));
		Eigen::Vector3d v;
		for (int k = 0; k < 3; ++k) {
			if (!p[k].is_number())
				return Status::error(source + ": point " + std::to_string(i) +
						     " coordinate " + std::to_string(k) +
						     " must be a number, not " + typeName(p[k]));
			v[k] = p[k].get<double>();
		}
		m->points_mm.push_back(v);
	}
	return Status::ok();
}

/* Target model, step 3: "faces", quadrilaterals of indices into the points. */
Status readFaces(const json &doc, const std::string &source, TargetModel *m)
{
	const auto faces = doc.find("faces");
	if (faces == doc.end())
		return Status::error(
			source +
			": key 'faces' is missing (quadrilaterals of LED indices, [[i, j, k, l], ...])");
	if (!faces->is_array())
		return Status::error(source + ": 'faces' must be an array of [i, j, k, l], not " +
				     typeName(*faces));
	if (faces->size() > kMaxFaces)
		return Status::error(source + ": 'faces' lists " + std::to_string(faces->size()) +
				     " faces, more than the firmware's capacity of " +
				     std::to_string(kMaxFaces) +
				     " (kMaxFaces in algo/capacities.h)");
	for (std::size_t f = 0; f < faces->size(); ++f) {
		const json &face = (*faces)[f];
		if (!face.is_array() || face.size() != 4)
			return Status::error(
				source + ": face " + std::to_string(f) +
				" must be a quadrilateral [i, j, k, l] of 4 LED indices, but it is " +
				shapeOf(face));
		std::array<int, 4> idx{};
		for (int k = 0; k < 4; ++k) {
			if (!face[k].is_number_integer() && !face[k].is_number_unsigned())
				return Status::error(source + ": face " + std::to_string(f) +
						     " entry " + std::to_string(k) +
						     " must be an integer LED index, not " +
						     typeName(face[k]));
			const std::int64_t v = face[k].get<std::int64_t>();
			if (v < 0 || v >= static_cast<std::int64_t>(m->points_mm.size()))
				return Status::error(
					source + ": face " + std::to_string(f) + " names LED " +
					std::to_string(v) +
					(m->points_mm.empty()
						 ? std::string(", but the model has no LEDs")
						 : ", but the model has LEDs 0.." +
							   std::to_string(m->points_mm.size() - 1)));
			idx[k] = static_cast<int>(v);
		}
		m->faces.push_back(idx);
	}
	return Status::ok();
}

/* Target model, step 4: the optional "led_sigma_mm". */
Status readLedSigma(const json &doc, const std::string &source, TargetModel *m)
{
	if (Status s = readNumber(doc, "led_sigma_mm", source, false, &m->led_sigma_mm); !s)
		return s;
	if (!(std::isfinite(m->led_sigma_mm) && m->led_sigma_mm >= 0.0))
		return Status::error(source + ": 'led_sigma_mm' must be a tolerance >= 0 mm, not " +
				     doc["led_sigma_mm"].dump());
	return Status::ok();
}

/* Target model, step 5: the optional "approach" cone. */
Status readApproach(const json &doc, const std::string &source, TargetModel *m)
{
	const auto approach = doc.find("approach");
	if (approach == doc.end())
		return Status::ok();
	if (!approach->is_object())
		return Status::error(
			source +
			R"(: 'approach' must be an object {"axis": [x, y, z], "max_deg": a}, not )" +
			typeName(*approach));
	const auto axis = approach->find("axis");
	if (axis == approach->end())
		return Status::error(
			source +
			": key 'approach.axis' is missing ([x, y, z] in the target frame)");
	if (!axis->is_array() || axis->size() != 3)
		return Status::error(source +
				     ": 'approach.axis' must be [x, y, z] (3 numbers), but it is " +
				     shapeOf(*axis));
	Eigen::Vector3d a;
	for (int k = 0; k < 3; ++k) {
		if (!(*axis)[k].is_number())
			return Status::error(source + ": 'approach.axis' coordinate " +
					     std::to_string(k) + " must be a number, not " +
					     typeName((*axis)[k]));
		a[k] = (*axis)[k].get<double>();
	}
	const double norm = a.norm();
	if (!(std::isfinite(norm) && norm > 1e-12))
		return Status::error(source + ": 'approach.axis' must be a non-zero direction");
	double max_deg = 0.0;
	if (Status s = readNumber(*approach, "max_deg", source + ": 'approach'", true, &max_deg);
	    !s)
		return s;
	if (!(max_deg > 0.0 && max_deg <= 180.0))
		return Status::error(
			source + ": 'approach.max_deg' must be an angle in (0, 180] degrees, not " +
			(*approach)["max_deg"].dump());
	m->approach.set = true;
	m->approach.axis = a / norm;
	m->approach.max_deg = max_deg;
	return Status::ok();
}

/* n decimal digits at text[*i] with a value in [lo, hi]; *i moves past them. */
bool readDigits(std::string_view text, std::size_t *i, int n, int lo, int hi)
{
	if (text.size() < *i + static_cast<std::size_t>(n))
		return false;
	int value = 0;
	for (int k = 0; k < n; ++k) {
		const char c = text[(*i)++];
		if (c < '0' || c > '9')
			return false;
		value = value * 10 + (c - '0');
	}
	return value >= lo && value <= hi;
}

/*
 * ISO 8601 as calibration tools write it: YYYY-MM-DD, then optionally Thh:mm[:ss[.fff]] and
 * Z or +hh:mm / -hh:mm (or +hhmm). Hand-written, not std::regex: libstdc++'s regex recurses
 * per character and a long string would exhaust the stack.
 */
bool isIsoDate(std::string_view text)
{
	std::size_t i = 0;
	const auto expect = [&](char c) {
		return i < text.size() && text[i++] == c;
	};
	if (!readDigits(text, &i, 4, 0, 9999) || !expect('-') || !readDigits(text, &i, 2, 1, 12) ||
	    !expect('-') || !readDigits(text, &i, 2, 1, 31))
		return false;
	if (i == text.size())
		return true;
	if (!expect('T') || !readDigits(text, &i, 2, 0, 23) || !expect(':') ||
	    !readDigits(text, &i, 2, 0, 59))
		return false;
	if (i < text.size() && text[i] == ':') {
		++i;
		if (!readDigits(text, &i, 2, 0, 59))
			return false;
		if (i < text.size() && text[i] == '.') {
			++i;
			const std::size_t first = i;
			while (i < text.size() && text[i] >= '0' && text[i] <= '9')
				++i;
			if (i == first)
				return false;
		}
	}
	if (i == text.size())
		return true;
	if (text[i] == 'Z')
		return i + 1 == text.size();
	if (text[i] != '+' && text[i] != '-')
		return false;
	++i;
	if (!readDigits(text, &i, 2, 0, 23))
		return false;
	if (i < text.size() && text[i] == ':')
		++i;
	return readDigits(text, &i, 2, 0, 59) && i == text.size();
}

/*
 * Camera, the calibration's record (dockpose calibrate writes it; dockpose reads only
 * "sigma", but the rest must be sane): "rms_px" >= 0, "frames" an integer >= 1, "date" an
 * ISO 8601 date or date and time ("2026-12-03" or "2026-12-03T18:40:00Z", a UTC offset
 * instead of Z, or none).
 */
Status readCalibrationRecord(const json &doc, const std::string &source)
{
	double rms_px = 0.0;
	if (Status s = readNumber(doc, "rms_px", source, false, &rms_px); !s)
		return s;
	if (!(std::isfinite(rms_px) && rms_px >= 0.0))
		return Status::error(source +
				     ": 'rms_px' must be a reprojection rms >= 0 px, not " +
				     doc["rms_px"].dump());
	if (const auto frames = doc.find("frames"); frames != doc.end()) {
		if (!frames->is_number_integer() && !frames->is_number_unsigned())
			return Status::error(source + ": 'frames' must be an integer, not " +
					     typeName(*frames));
		if (frames->get<std::int64_t>() < 1)
			return Status::error(source +
					     ": 'frames' must be the number of frames calibrated "
					     "from, >= 1, not " +
					     frames->dump());
	}
	if (const auto date = doc.find("date"); date != doc.end()) {
		if (!date->is_string() || !isIsoDate(date->get<std::string>()))
			return Status::error(source +
					     ": 'date' must be an ISO 8601 date (\"2026-12-03\" or "
					     "\"2026-12-03T18:40:00Z\"), not " +
					     date->dump());
	}
	return Status::ok();
}

struct Field {
	const char *key;
	double *value;
	bool required;
};

/* Camera, optional "sigma": 1 sigma per parameter, any subset. */
Status readSigma(const json &doc, const std::string &source, CameraIntrinsics *k)
{
	const auto sigma = doc.find("sigma");
	if (sigma == doc.end())
		return Status::ok();
	if (!sigma->is_object())
		return Status::error(
			source +
			": 'sigma' must be an object of 1-sigma uncertainties {\"fx\": .., ...}, not " +
			typeName(*sigma));
	CameraIntrinsics::Sigma &sg = k->sigma;
	const Field sigmas[] = {
		{ "fx", &sg.fx, false }, { "fy", &sg.fy, false }, { "cx", &sg.cx, false },
		{ "cy", &sg.cy, false }, { "k1", &sg.k1, false }, { "k2", &sg.k2, false },
		{ "p1", &sg.p1, false }, { "p2", &sg.p2, false },
	};
	for (auto it = sigma->begin(); it != sigma->end(); ++it) {
		bool known = false;
		for (const Field &f : sigmas)
			known = known || it.key() == f.key;
		if (!known)
			return Status::error(
				source + ": 'sigma." + it.key() +
				"' is not a parameter of the camera (fx, fy, cx, cy, k1, k2, p1, p2)");
	}
	for (const Field &f : sigmas) {
		if (Status s = readNumber(*sigma, f.key, source + ": 'sigma'", false, f.value); !s)
			return s;
		if (!(std::isfinite(*f.value) && *f.value >= 0.0))
			return Status::error(source + ": 'sigma." + f.key +
					     "' must be a 1-sigma value >= 0, not " +
					     (*sigma)[f.key].dump());
	}
	return Status::ok();
}

} /* namespace */

Result<std::string> readFileContents(const std::string &path)
{
	/* O_NONBLOCK: opening a FIFO must not wait for a writer (it is refused below). */
	const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
	if (fd < 0) {
		const int err = errno;
		return Status::error(path + ": cannot open (" +
				     (err ? std::strerror(err) : "unknown error") + ")");
	}
	struct FdCloser {
		int fd;
		~FdCloser() { ::close(fd); }
	} const closer{ fd };
	struct stat st {
	};
	if (::fstat(fd, &st) != 0)
		return Status::error(path + ": read error (" + std::strerror(errno) + ")");
	if (S_ISDIR(st.st_mode))
		return Status::error(path + ": is a directory, not a file");
	if (!S_ISREG(st.st_mode))
		return Status::error(path + ": is not a regular file (a device, FIFO or socket)");
	if (st.st_size > static_cast<off_t>(kMaxTextFileBytes))
		return Status::error(path + ": is " + std::to_string(st.st_size) +
				     " bytes; a target, camera or board file has at most " +
				     std::to_string(kMaxTextFileBytes));
	std::string text(static_cast<std::size_t>(st.st_size), '\0');
	std::size_t have = 0;
	while (have < text.size()) {
		const ssize_t n = ::read(fd, text.data() + have, text.size() - have);
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0)
			return Status::error(path + ": read error (" + std::strerror(errno) + ")");
		if (n == 0)
			break; /* shrank while read */
		have += static_cast<std::size_t>(n);
	}
	text.resize(have);
	return text;
}

Result<TargetModel> parseTargetModel(const std::string &json_text, const std::string &source)
{
	json doc;
	if (Status s = parseDocument(json_text, source, &doc); !s)
		return s;

	TargetModel m;
	for (auto step : { readNameAndUnits, readPoints, readFaces, readLedSigma, readApproach })
		if (Status s = step(doc, source, &m); !s)
			return s;
	if (Status s = m.validate(); !s)
		return Status::error(source + ": " + s.message());
	return m;
}

Result<TargetModel> loadTargetModel(const std::string &path)
{
	Result<std::string> text = readFileContents(path);
	if (!text)
		return text.status();
	return parseTargetModel(text.value(), path);
}

Result<CameraIntrinsics> parseCameraIntrinsics(const std::string &json_text,
					       const std::string &source)
{
	json doc;
	if (Status s = parseDocument(json_text, source, &doc); !s)
		return s;

	CameraIntrinsics k;
	if (Status s = readInt(doc, "width", source, &k.width); !s)
		return s;
	if (Status s = readInt(doc, "height", source, &k.height); !s)
		return s;
	const Field fields[] = {
		{ "fx", &k.fx, true },	{ "fy", &k.fy, true },	{ "cx", &k.cx, true },
		{ "cy", &k.cy, true },	{ "k1", &k.k1, false }, { "k2", &k.k2, false },
		{ "p1", &k.p1, false }, { "p2", &k.p2, false },
	};
	for (const Field &f : fields)
		if (Status s = readNumber(doc, f.key, source, f.required, f.value); !s)
			return s;
	for (const char *key : { "k3", "k4", "k5", "k6" }) {
		double v = 0.0;
		if (Status s = readNumber(doc, key, source, false, &v); !s)
			return s;
		if (v != 0.0)
			return Status::error(
				source + ": '" + key +
				"' is not supported: the lens model is Brown-Conrady k1, k2, p1, p2 only");
	}
	if (Status s = readSigma(doc, source, &k); !s)
		return s;
	if (Status s = readCalibrationRecord(doc, source); !s)
		return s;

	if (Status s = k.validate(); !s)
		return Status::error(source + ": " + s.message());
	return k;
}

Result<CameraIntrinsics> loadCameraIntrinsics(const std::string &path)
{
	Result<std::string> text = readFileContents(path);
	if (!text)
		return text.status();
	return parseCameraIntrinsics(text.value(), path);
}

} /* namespace dockpose */

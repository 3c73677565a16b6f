/* SPDX-License-Identifier: MIT */
#include "algo/io/model_json.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

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

/* Parse without letting an exception escape; *error gets "<source>: ..." on failure. */
bool parseDocument(const std::string &text, const std::string &source, json *doc,
		   std::string *error)
{
	try {
		*doc = json::parse(text, nullptr, true, /*ignore_comments=*/true);
	} catch (const json::parse_error &e) {
		*error = source + ": not valid JSON (" + e.what() + ")";
		return false;
	}
	if (!doc->is_object()) {
		*error = source + ": the top level must be a JSON object, not " + typeName(*doc);
		return false;
	}
	return true;
}

bool readNumber(const json &doc, const char *key, const std::string &source, bool required,
		double *value, std::string *error)
{
	const auto it = doc.find(key);
	if (it == doc.end()) {
		if (required)
			*error = source + ": key '" + key + "' is missing";
		return !required;
	}
	if (!it->is_number()) {
		*error = source + ": '" + key + "' must be a number, not " + typeName(*it);
		return false;
	}
	*value = it->get<double>();
	return true;
}

bool readInt(const json &doc, const char *key, const std::string &source, int *value,
	     std::string *error)
{
	const auto it = doc.find(key);
	if (it == doc.end()) {
		*error = source + ": key '" + key + "' is missing";
		return false;
	}
	if (!it->is_number_integer() && !it->is_number_unsigned()) {
		*error = source + ": '" + key + "' must be an integer, not " + typeName(*it);
		return false;
	}
	const std::int64_t v = it->get<std::int64_t>();
	if (v < -1000000 || v > 1000000) {
		*error = source + ": '" + key + "' = " + std::to_string(v) + " is out of range";
		return false;
	}
	*value = static_cast<int>(v);
	return true;
}

} /* namespace */

std::string readFileContents(const std::string &path, std::string *contents)
{
	std::error_code ec;
	if (std::filesystem::is_directory(path, ec))
		return path + ": is a directory, not a file";
	std::ifstream in(path, std::ios::binary);
	if (!in) {
		const int err = errno;
		return path + ": cannot open (" + (err ? std::strerror(err) : "unknown error") +
		       ")";
	}
	std::ostringstream ss;
	ss << in.rdbuf();
	if (in.bad())
		return path + ": read error";
	*contents = ss.str();
	return {};
}

LoadResult<TargetModel> parseTargetModel(const std::string &json_text, const std::string &source)
{
	LoadResult<TargetModel> r;
	json doc;
	if (!parseDocument(json_text, source, &doc, &r.error))
		return r;

	TargetModel &m = r.value;
	const auto name = doc.find("name");
	if (name != doc.end()) {
		if (!name->is_string()) {
			r.error = source + ": 'name' must be a string, not " + typeName(*name);
			return r;
		}
		m.name = name->get<std::string>();
	} else {
		m.name = std::filesystem::path(source).stem().string();
	}

	const auto units = doc.find("units");
	if (units != doc.end() && (!units->is_string() || units->get<std::string>() != "mm")) {
		r.error = source + ": 'units' must be \"mm\" (the only unit dockpose uses), not " +
			  units->dump();
		return r;
	}

	const auto points = doc.find("points");
	if (points == doc.end()) {
		r.error = source +
			  ": key 'points' is missing (the LED centres, [[x, y, z], ...] in mm)";
		return r;
	}
	if (!points->is_array()) {
		r.error = source + ": 'points' must be an array of [x, y, z], not " +
			  typeName(*points);
		return r;
	}
	if (points->size() > kMaxLeds) {
		r.error = source + ": 'points' lists " + std::to_string(points->size()) +
			  " LEDs, more than the firmware's capacity of " +
			  std::to_string(kMaxLeds) + " (kMaxLeds in algo/capacities.h)";
		return r;
	}
	for (std::size_t i = 0; i < points->size(); ++i) {
		const json &p = (*points)[i];
		if (!p.is_array() || p.size() != 3) {
			r.error = source + ": point " + std::to_string(i) +
				  " must be [x, y, z] (3 numbers), but it is " +
				  (p.is_array() ? "an array of " + std::to_string(p.size())
						: std::string(typeName(p)));
			return r;
		}
		Eigen::Vector3d v;
		for (int k = 0; k < 3; ++k) {
			if (!p[k].is_number()) {
				r.error = source + ": point " + std::to_string(i) + " coordinate " +
					  std::to_string(k) + " must be a number, not " +
					  typeName(p[k]);
				return r;
			}
			v[k] = p[k].get<double>();
		}
		m.points_mm.push_back(v);
	}

	const auto faces = doc.find("faces");
	if (faces == doc.end()) {
		r.error =
			source +
			": key 'faces' is missing (quadrilaterals of LED indices, [[i, j, k, l], ...])";
		return r;
	}
	if (!faces->is_array()) {
		r.error = source + ": 'faces' must be an array of [i, j, k, l], not " +
			  typeName(*faces);
		return r;
	}
	if (faces->size() > kMaxFaces) {
		r.error = source + ": 'faces' lists " + std::to_string(faces->size()) +
			  " faces, more than the firmware's capacity of " +
			  std::to_string(kMaxFaces) + " (kMaxFaces in algo/capacities.h)";
		return r;
	}
	for (std::size_t f = 0; f < faces->size(); ++f) {
		const json &face = (*faces)[f];
		if (!face.is_array() || face.size() != 4) {
			r.error =
				source + ": face " + std::to_string(f) +
				" must be a quadrilateral [i, j, k, l] of 4 LED indices, but it is " +
				(face.is_array() ? "an array of " + std::to_string(face.size())
						 : std::string(typeName(face)));
			return r;
		}
		std::array<int, 4> idx{};
		for (int k = 0; k < 4; ++k) {
			if (!face[k].is_number_integer() && !face[k].is_number_unsigned()) {
				r.error = source + ": face " + std::to_string(f) + " entry " +
					  std::to_string(k) +
					  " must be an integer LED index, not " + typeName(face[k]);
				return r;
			}
			const std::int64_t v = face[k].get<std::int64_t>();
			if (v < 0 || v >= static_cast<std::int64_t>(m.points_mm.size())) {
				r.error =
					source + ": face " + std::to_string(f) + " names LED " +
					std::to_string(v) +
					(m.points_mm.empty()
						 ? std::string(", but the model has no LEDs")
						 : ", but the model has LEDs 0.." +
							   std::to_string(m.points_mm.size() - 1));
				return r;
			}
			idx[k] = static_cast<int>(v);
		}
		m.faces.push_back(idx);
	}

	if (!readNumber(doc, "led_sigma_mm", source, false, &m.led_sigma_mm, &r.error))
		return r;
	if (!(std::isfinite(m.led_sigma_mm) && m.led_sigma_mm >= 0.0)) {
		r.error = source + ": 'led_sigma_mm' must be a tolerance >= 0 mm, not " +
			  doc["led_sigma_mm"].dump();
		return r;
	}

	const auto approach = doc.find("approach");
	if (approach != doc.end()) {
		if (!approach->is_object()) {
			r.error =
				source +
				": 'approach' must be an object {\"axis\": [x, y, z], \"max_deg\": a}, not " +
				typeName(*approach);
			return r;
		}
		const auto axis = approach->find("axis");
		if (axis == approach->end()) {
			r.error =
				source +
				": key 'approach.axis' is missing ([x, y, z] in the target frame)";
			return r;
		}
		if (!axis->is_array() || axis->size() != 3) {
			r.error = source +
				  ": 'approach.axis' must be [x, y, z] (3 numbers), but it is " +
				  (axis->is_array() ? "an array of " + std::to_string(axis->size())
						    : std::string(typeName(*axis)));
			return r;
		}
		Eigen::Vector3d a;
		for (int k = 0; k < 3; ++k) {
			if (!(*axis)[k].is_number()) {
				r.error = source + ": 'approach.axis' coordinate " +
					  std::to_string(k) + " must be a number, not " +
					  typeName((*axis)[k]);
				return r;
			}
			a[k] = (*axis)[k].get<double>();
		}
		const double norm = a.norm();
		if (!(std::isfinite(norm) && norm > 1e-12)) {
			r.error = source + ": 'approach.axis' must be a non-zero direction";
			return r;
		}
		double max_deg = 0.0;
		if (!readNumber(*approach, "max_deg", source + ": 'approach'", true, &max_deg,
				&r.error))
			return r;
		if (!(max_deg > 0.0 && max_deg <= 180.0)) {
			r.error =
				source +
				": 'approach.max_deg' must be an angle in (0, 180] degrees, not " +
				(*approach)["max_deg"].dump();
			return r;
		}
		m.approach.set = true;
		m.approach.axis = a / norm;
		m.approach.max_deg = max_deg;
	}

	const std::string invalid = m.validate();
	if (!invalid.empty()) {
		r.error = source + ": " + invalid;
		return r;
	}
	return r;
}

LoadResult<TargetModel> loadTargetModel(const std::string &path)
{
	std::string text;
	LoadResult<TargetModel> r;
	r.error = readFileContents(path, &text);
	if (!r.ok())
		return r;
	return parseTargetModel(text, path);
}

LoadResult<CameraIntrinsics> parseCameraIntrinsics(const std::string &json_text,
						   const std::string &source)
{
	LoadResult<CameraIntrinsics> r;
	json doc;
	if (!parseDocument(json_text, source, &doc, &r.error))
		return r;

	CameraIntrinsics &k = r.value;
	if (!readInt(doc, "width", source, &k.width, &r.error) ||
	    !readInt(doc, "height", source, &k.height, &r.error))
		return r;
	struct Field {
		const char *key;
		double *value;
		bool required;
	};
	const Field fields[] = {
		{ "fx", &k.fx, true },	{ "fy", &k.fy, true },	{ "cx", &k.cx, true },
		{ "cy", &k.cy, true },	{ "k1", &k.k1, false }, { "k2", &k.k2, false },
		{ "p1", &k.p1, false }, { "p2", &k.p2, false },
	};
	for (const Field &f : fields)
		if (!readNumber(doc, f.key, source, f.required, f.value, &r.error))
			return r;
	for (const char *key : { "k3", "k4", "k5", "k6" }) {
		double v = 0.0;
		if (!readNumber(doc, key, source, false, &v, &r.error))
			return r;
		if (v != 0.0) {
			r.error =
				source + ": '" + key +
				"' is not supported: the lens model is Brown-Conrady k1, k2, p1, p2 only";
			return r;
		}
	}

	/* Optional calibration uncertainty: 1 sigma per parameter, any subset. */
	const auto sigma = doc.find("sigma");
	if (sigma != doc.end()) {
		if (!sigma->is_object()) {
			r.error =
				source +
				": 'sigma' must be an object of 1-sigma uncertainties {\"fx\": .., ...}, not " +
				typeName(*sigma);
			return r;
		}
		CameraIntrinsics::Sigma &sg = k.sigma;
		const Field sigmas[] = {
			{ "fx", &sg.fx, false }, { "fy", &sg.fy, false }, { "cx", &sg.cx, false },
			{ "cy", &sg.cy, false }, { "k1", &sg.k1, false }, { "k2", &sg.k2, false },
			{ "p1", &sg.p1, false }, { "p2", &sg.p2, false },
		};
		for (auto it = sigma->begin(); it != sigma->end(); ++it) {
			bool known = false;
			for (const Field &f : sigmas)
				known = known || it.key() == f.key;
			if (!known) {
				r.error =
					source + ": 'sigma." + it.key() +
					"' is not a parameter of the camera (fx, fy, cx, cy, k1, k2, p1, p2)";
				return r;
			}
		}
		for (const Field &f : sigmas) {
			if (!readNumber(*sigma, f.key, source + ": 'sigma'", false, f.value,
					&r.error))
				return r;
			if (!(std::isfinite(*f.value) && *f.value >= 0.0)) {
				r.error = source + ": 'sigma." + f.key +
					  "' must be a 1-sigma value >= 0, not " +
					  (*sigma)[f.key].dump();
				return r;
			}
		}
	}
	/* Written by calibration tools; dockpose does not use them, but they must be sane. */
	double rms_px = 0.0;
	if (!readNumber(doc, "rms_px", source, false, &rms_px, &r.error))
		return r;

	const std::string invalid = k.validate();
	if (!invalid.empty())
		r.error = source + ": " + invalid;
	return r;
}

LoadResult<CameraIntrinsics> loadCameraIntrinsics(const std::string &path)
{
	std::string text;
	LoadResult<CameraIntrinsics> r;
	r.error = readFileContents(path, &text);
	if (!r.ok())
		return r;
	return parseCameraIntrinsics(text, path);
}

} /* namespace dockpose */

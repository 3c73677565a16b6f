/* SPDX-License-Identifier: MIT */
/*
 * The board file's keys, each declared once: one table per section (key,
 * type, where it is stored, range, unit, one-line doc). The reader
 * (firmware/config.cpp) reads and range-checks every key from its row; the
 * key tables of docs/configuration.md are printed from the same rows
 * (configDocTable(), `dockposed --print-config-doc SECTION`,
 * scripts/update-config-doc), and test_config fails when the doc differs.
 * A key's default is its struct's initialiser (board/board_config.h), shown
 * from a default-constructed struct. Backend names are board::backendNames().
 * Checks that need more than one key are code in config.cpp, after a
 * section's table has been read.
 *
 * Allocates: the tables are built once, on first use; configDocTable()
 * returns a new string. Threads: any (start-up only in practice).
 */
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "board/board.h"
#include "board/board_config.h"

namespace dockpose::firmware::config_table {

/* How a key's JSON value is read and checked. */
enum class Kind : std::uint8_t {
	Integer, /* int: an integral number (2000 or 2000.0) in `range` */
	Unsigned, /* std::uint64_t: an integral number >= 0 */
	Number, /* double: any number in `range` */
	Boolean, /* bool */
	String, /* std::string; non-empty when `non_empty` */
	Path, /* std::string, resolved against the file's folder; non-empty unless `empty_ok` */
	Backend, /* std::string, one of board::backendNames(`backend`) */
	Choice, /* an enumeration, by its name in `choices` (indexed by value) */
	Pose, /* double[6]: x, y, z mm, roll, pan, tilt degrees, z > 0, angles [-180, 180] */
	CanId, /* std::uint32_t: a number or a hex string ("0x300"), a valid base id */
	OneOf, /* int, one of `one_of` */
	Object, /* a subsection, read with its own struct's table */
};

/* A closed or open interval; an infinite bound is no bound. */
struct Range {
	double lo = -std::numeric_limits<double>::infinity();
	double hi = std::numeric_limits<double>::infinity();
	bool lo_open = false;
	bool hi_open = false;

	bool contains(double v) const
	{
		return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
	}
	/* As error messages show it: "[10, 1000000]", "(0, 240]", "(must be > 0)". */
	std::string text() const;
	/* As the doc's range column shows it: "[10, 1000000]", "(0, 240]", "> 0". */
	std::string docText() const;
};

/* A number for a message: integers without a fraction, others with 6 significant digits. */
std::string formatNumber(double v);

/* Where a key is stored in its section's struct S. */
template<typename S>
using Member =
	std::variant<std::monostate, int S::*, double S::*, bool S::*, std::string S::*,
		     std::uint32_t S::*, std::uint64_t S::*, double (S::*)[6],
		     board::StrobeMode S::*, board::TrackMode S::*, board::CameraSection S::*,
		     board::StrobeSection S::*, board::CanSection S::*, board::PipelineSection S::*,
		     board::SystemdSection S::*, board::PreviewSection S::*,
		     hal::SyntheticScene S::*, board::ReplayCameraConfig S::*>;

/* One key of a section whose struct is S. */
template<typename S>
struct Field {
	const char *key;
	Kind kind;
	Member<S> member;
	const char *doc; /* the doc's "meaning" column, one line */
	Range range = {}; /* Integer, Number */
	const char *unit = ""; /* "us", "Hz", ...: the doc's unit column */
	bool required = false; /* missing: "required key is missing (hint)" */
	/* Why the key is needed, for the missing and the empty messages ("the board's name"). */
	const char *hint = "";
	bool non_empty = false; /* String: "" is an error */
	bool empty_ok = false; /* Path: "" is allowed and stays "" */
	board::BackendKind backend = board::BackendKind::Camera; /* Backend */
	std::span<const char *const> choices = {}; /* Choice: names indexed by value */
	std::span<const std::int64_t> one_of = {}; /* OneOf */
	/* String: a check of the value once read (may look at the keys read before it);
	 * returns the problem, or "" when fine. */
	std::string (*check)(const S &section, const std::string &value) = nullptr;
	/* The doc's range column when it is not the range, the choices or the kind's own. */
	const char *range_doc = "";
	/* Appended to the doc's range column (a check across keys, in words). */
	const char *range_note = "";
	/* Appended to the doc's default column ("**required** for `gpiod`"). */
	const char *default_note = "";
};

/* The table of each section's struct, in the order the keys are read and documented. */
template<typename S>
std::span<const Field<S>> fieldsOf();
template<>
std::span<const Field<board::BoardConfig>> fieldsOf<board::BoardConfig>();
template<>
std::span<const Field<board::CameraSection>> fieldsOf<board::CameraSection>();
template<>
std::span<const Field<hal::SyntheticScene>> fieldsOf<hal::SyntheticScene>();
template<>
std::span<const Field<board::ReplayCameraConfig>> fieldsOf<board::ReplayCameraConfig>();
template<>
std::span<const Field<board::StrobeSection>> fieldsOf<board::StrobeSection>();
template<>
std::span<const Field<board::CanSection>> fieldsOf<board::CanSection>();
template<>
std::span<const Field<board::PipelineSection>> fieldsOf<board::PipelineSection>();
template<>
std::span<const Field<board::SystemdSection>> fieldsOf<board::SystemdSection>();
template<>
std::span<const Field<board::PreviewSection>> fieldsOf<board::PreviewSection>();

/* The standard CAN bit rates can.bitrate accepts. */
std::span<const std::int64_t> canBitrates();

/* The sections with a key table, as JSON paths ("top" for the top level, "camera.synthetic"). */
std::vector<std::string> docSections();
/* The markdown key table of one section (docSections()); empty for an unknown section. */
std::string docTable(const std::string &section);

} /* namespace dockpose::firmware::config_table */

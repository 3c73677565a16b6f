/* SPDX-License-Identifier: MIT */
/*
 * The project's one error idiom for fallible calls, in every layer (algo/io,
 * hal, board, firmware, tools):
 *
 *   Status     success, or an error with a message that names the problem
 *              ("can0: no such CAN interface", "wedge.json: \"points\" is
 *              missing"): for calls that produce nothing else.
 *   Result<T>  a T, or the Status saying why there is none: for calls that
 *              produce a value (a loaded model, a decoded frame).
 *
 * Both are [[nodiscard]]: an ignored error is a compile warning (an error in
 * CI). A function returning `Status::error(...)` where a Result<T> is expected
 * converts implicitly, so a loader reads `return Status::error("...")` on each
 * failure and `return value` at the end.
 *
 * Not covered, on purpose: the numeric solvers of the frame path (P3P, Horn,
 * refinement) return bool (a degenerate configuration is an expected outcome,
 * not an error with a message), and the board file validation returns every
 * problem it finds (firmware::ConfigResult), not only the first.
 *
 * Allocates: an error allocates its message; success never allocates, so the
 * frame path may return Status::ok() freely. Threads: values, no shared state.
 */
#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <utility>

namespace dockpose {

class [[nodiscard]] Status
{
public:
	Status() = default;
	static Status ok() { return Status(); }
	/* An error; `message` must not be empty (it is what the user reads). */
	static Status error(std::string message) { return Status(std::move(message)); }

	bool isOk() const { return !failed_; }
	explicit operator bool() const { return !failed_; }
	/* Empty on success. */
	const std::string &message() const { return message_; }

private:
	explicit Status(std::string message)
		: failed_(true),
		  message_(std::move(message))
	{
		assert(!message_.empty());
	}
	bool failed_ = false;
	std::string message_;
};

template<typename T>
class [[nodiscard]] Result
{
public:
	/* Success, holding `value`. */
	Result(T value) /* NOLINT(google-explicit-constructor): `return value;` */
		: value_(std::move(value))
	{
	}
	/* Failure; `status` must be an error. */
	Result(Status status) /* NOLINT(google-explicit-constructor): `return Status::error(..);` */
		: status_(std::move(status))
	{
		assert(!status_.isOk());
	}

	bool isOk() const { return value_.has_value(); }
	explicit operator bool() const { return isOk(); }
	const Status &status() const { return status_; }
	/* Empty on success. */
	const std::string &message() const { return status_.message(); }

	/* The value; only on success. */
	const T &value() const &
	{
		assert(isOk());
		return *value_;
	}
	T &value() &
	{
		assert(isOk());
		return *value_;
	}
	T &&value() &&
	{
		assert(isOk());
		return std::move(*value_);
	}
	const T *operator->() const { return &value(); }
	T *operator->() { return &value(); }

private:
	std::optional<T> value_;
	Status status_;
};

} /* namespace dockpose */

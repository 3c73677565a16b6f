/* SPDX-License-Identifier: MIT */
/*
 * Status: success, or an error with a message that names the problem
 * ("can0: no such CAN interface", "gpiochip7: no such GPIO chip").
 *
 * Allocates: an error allocates its message; success never allocates, so the
 * frame path may return Status::ok() freely.
 */
#pragma once

#include <string>
#include <utility>

namespace dockpose::hal {

class [[nodiscard]] Status
{
public:
	Status() = default;
	static Status ok() { return Status(); }
	static Status error(std::string message) { return Status(std::move(message)); }

	bool isOk() const { return !failed_; }
	explicit operator bool() const { return !failed_; }
	const std::string &message() const { return message_; }

private:
	explicit Status(std::string message)
		: failed_(true),
		  message_(std::move(message))
	{
	}
	bool failed_ = false;
	std::string message_;
};

} /* namespace dockpose::hal */

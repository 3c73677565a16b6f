/* SPDX-License-Identifier: MIT */
/*
 * The CAN key and the run counter (see can_auth.h).
 */
#include "firmware/can_auth.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstring>

namespace dockpose::firmware {

namespace {

constexpr off_t kMaxKeyFileBytes = 1024;
constexpr off_t kMaxRunFileBytes = 64;

std::string errnoText(int err)
{
	return std::strerror(err);
}

/* Up to max_bytes of a regular file, through one descriptor (what is checked is what is read). */
hal::Status readSmallFile(const std::string &path, const char *what, off_t max_bytes,
			  std::string *text, struct stat *st)
{
	const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
	if (fd < 0)
		return hal::Status::error(std::string(what) + " " + path + ": " + errnoText(errno));
	hal::Status result = hal::Status::ok();
	if (::fstat(fd, st) != 0) {
		result = hal::Status::error(std::string(what) + " " + path + ": " +
					    errnoText(errno));
	} else if (!S_ISREG(st->st_mode)) {
		result =
			hal::Status::error(std::string(what) + " " + path + ": not a regular file");
	} else if (st->st_size > max_bytes) {
		result = hal::Status::error(std::string(what) + " " + path + ": " +
					    std::to_string(st->st_size) + " bytes, at most " +
					    std::to_string(max_bytes) + " expected");
	} else {
		char buf[1024];
		const ssize_t n = ::read(fd, buf, sizeof(buf));
		if (n < 0)
			result = hal::Status::error(std::string(what) + " " + path + ": " +
						    errnoText(errno));
		else
			text->assign(buf, static_cast<std::size_t>(n));
	}
	::close(fd);
	return result;
}

std::string trimmed(const std::string &s)
{
	std::size_t a = 0, b = s.size();
	while (a < b && std::isspace(static_cast<unsigned char>(s[a])))
		++a;
	while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1])))
		--b;
	return s.substr(a, b - a);
}

} /* namespace */

hal::Status loadCanKey(const std::string &path, std::array<std::uint8_t, can::kKeyBytes> *key)
{
	std::string text;
	struct stat st {
	};
	if (hal::Status s = readSmallFile(path, "CAN key", kMaxKeyFileBytes, &text, &st); !s)
		return s;
	if (st.st_mode & (S_IRWXG | S_IRWXO)) {
		char mode[8];
		std::snprintf(mode, sizeof(mode), "%04o",
			      static_cast<unsigned>(st.st_mode & 07777));
		return hal::Status::error("CAN key " + path + ": mode " + mode +
					  " lets group or others at it; it must be 0600 or 0400 "
					  "(chmod 600 " +
					  path + ")");
	}
	if (st.st_uid != 0 && st.st_uid != ::geteuid())
		return hal::Status::error("CAN key " + path + ": owned by uid " +
					  std::to_string(st.st_uid) +
					  ", neither root nor this process's user");
	const std::string digits = trimmed(text);
	if (digits.size() != 2 * can::kKeyBytes)
		return hal::Status::error(
			"CAN key " + path + ": " + std::to_string(digits.size()) +
			" characters, 32 hexadecimal digits (a 128-bit key) expected");
	for (std::size_t i = 0; i < can::kKeyBytes; ++i) {
		/* Two digits a byte; from_chars stops at the first that is not hex (an unsigned
		 * value takes no sign, base 16 no "0x"). */
		const char *first = digits.data() + 2 * i;
		const auto [end, ec] = std::from_chars(first, first + 2, (*key)[i], 16);
		if (ec != std::errc() || end != first + 2)
			return hal::Status::error("CAN key " + path +
						  ": not hexadecimal (character " +
						  std::to_string(end - digits.data() + 1) + ")");
	}
	return hal::Status::ok();
}

hal::Status nextRunNumber(const std::string &path, std::uint32_t *run)
{
	std::uint64_t last = 0;
	struct stat st {
	};
	if (::lstat(path.c_str(), &st) == 0) {
		std::string text;
		if (hal::Status s =
			    readSmallFile(path, "CAN run counter", kMaxRunFileBytes, &text, &st);
		    !s)
			return s;
		const std::string digits = trimmed(text);
		const auto [end, ec] =
			std::from_chars(digits.data(), digits.data() + digits.size(), last);
		if (digits.empty() || ec != std::errc() || end != digits.data() + digits.size() ||
		    last > 0xffffffffu)
			return hal::Status::error("CAN run counter " + path + ": \"" + digits +
						  "\" is not a run number (0 .. 4294967295)");
	} else if (errno != ENOENT) {
		return hal::Status::error("CAN run counter " + path + ": " + errnoText(errno));
	}
	if (last == 0xffffffffu)
		return hal::Status::error("CAN run counter " + path +
					  ": every run number of this key is used; install a new "
					  "key and remove the file");

	const std::uint64_t next = last + 1;
	const std::string tmp = path + ".new";
	const int fd =
		::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW, 0600);
	if (fd < 0)
		return hal::Status::error("CAN run counter " + tmp + ": " + errnoText(errno));
	const std::string text = std::to_string(next) + "\n";
	const bool written = ::write(fd, text.data(), text.size()) ==
				     static_cast<ssize_t>(text.size()) &&
			     ::fsync(fd) == 0;
	const int write_err = errno;
	::close(fd);
	if (!written || ::rename(tmp.c_str(), path.c_str()) != 0) {
		const int err = written ? errno : write_err;
		::unlink(tmp.c_str());
		return hal::Status::error("CAN run counter " + path + ": cannot write it (" +
					  errnoText(err) + ")");
	}
	*run = static_cast<std::uint32_t>(next);
	return hal::Status::ok();
}

} /* namespace dockpose::firmware */

/* SPDX-License-Identifier: MIT */
/*
 * What every libFuzzer harness of tests/fuzz shares: a property check that
 * ends the run as a finding, and a reader that takes fields off the input.
 *
 * FUZZ_CHECK(condition, message): when the condition is false, prints the
 * message with the file and line and aborts, which libFuzzer reports as a
 * crash and keeps the input as an artifact (crash-<sha1>). A harness states
 * its oracle with these; a sanitizer report or an uncaught exception ends
 * the run the same way.
 *
 * Allocates: FuzzInput never; the checks only the message they print.
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string_view>

namespace dockpose::fuzz {

[[noreturn]] inline void fail(const char *file, int line, const char *condition,
			      const char *message)
{
	std::fprintf(stderr, "%s:%d: fuzz property violated: %s (%s)\n", file, line, message,
		     condition);
	std::fflush(stderr);
	std::abort();
}

#define FUZZ_CHECK(condition, message)                                                             \
	do {                                                                                       \
		if (!(condition))                                                                  \
			::dockpose::fuzz::fail(__FILE__, __LINE__, #condition, message);           \
	} while (false)

/*
 * The input as a sequence of fields, consumed from the front. Past the end,
 * every field reads as zero (a short input is a valid input with zeros).
 */
class FuzzInput
{
public:
	FuzzInput(const std::uint8_t *data, std::size_t size)
		: data_(data),
		  size_(size)
	{
	}

	std::size_t remaining() const { return size_ - pos_; }
	bool empty() const { return pos_ >= size_; }

	std::uint8_t u8() { return pos_ < size_ ? data_[pos_++] : 0; }

	std::uint16_t u16()
	{
		const std::uint16_t lo = u8();
		return static_cast<std::uint16_t>(lo | (u8() << 8));
	}

	std::uint32_t u32()
	{
		const std::uint32_t lo = u16();
		return lo | (static_cast<std::uint32_t>(u16()) << 16);
	}

	/* Up to n bytes (fewer at the end of the input). */
	std::string_view bytes(std::size_t n)
	{
		const std::size_t k = n < remaining() ? n : remaining();
		std::string_view out(reinterpret_cast<const char *>(data_ + pos_), k);
		pos_ += k;
		return out;
	}

	/* Everything left. */
	std::string_view rest() { return bytes(remaining()); }

private:
	const std::uint8_t *data_;
	std::size_t size_;
	std::size_t pos_ = 0;
};

} /* namespace dockpose::fuzz */

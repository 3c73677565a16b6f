/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/view/candump.h"

#include <charconv>
#include <cstddef>
#include <cstdio>
#include <system_error>

namespace dockpose::tool {

namespace {

/* A cursor over the line: each step either moves on, or says why it cannot. */
class Cursor
{
public:
	explicit Cursor(std::string_view text)
		: text_(text)
	{
	}

	bool atEnd() const { return pos_ >= text_.size(); }
	char peek() const { return text_[pos_]; }
	/* The value of the hex digit here, -1 when there is none. */
	int peekHex() const
	{
		unsigned int value = 0;
		const char *at = text_.data() + pos_;
		if (atEnd() || std::from_chars(at, at + 1, value, 16).ec != std::errc())
			return -1;
		return static_cast<int>(value);
	}
	void next() { ++pos_; }
	std::size_t pos() const { return pos_; }

	/* Digits into *value (at most max_digits); false when there are none. */
	bool digits(std::int64_t *value, int max_digits, int *count)
	{
		*value = 0;
		*count = 0;
		while (!atEnd() && peek() >= '0' && peek() <= '9' && *count < max_digits) {
			*value = *value * 10 + (peek() - '0');
			++*count;
			next();
		}
		return *count > 0;
	}

private:
	std::string_view text_;
	std::size_t pos_ = 0;
};

CandumpParse fail(CandumpLine *out, const Cursor &c, const char *why)
{
	out->error = why;
	return c.atEnd() ? CandumpParse::Truncated : CandumpParse::Malformed;
}

} /* namespace */

CandumpParse parseCandumpLine(std::string_view line, CandumpLine *out)
{
	out->error = "";
	while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t'))
		line.remove_suffix(1);
	if (line.empty())
		return CandumpParse::Ignored;

	Cursor c(line);
	if (c.peek() != '(')
		return fail(out, c, "no '(' timestamp at the start");
	c.next();
	std::int64_t seconds = 0;
	int n = 0;
	if (!c.digits(&seconds, 12, &n))
		return fail(out, c, "no seconds in the timestamp");
	if (c.atEnd() || c.peek() != '.')
		return fail(out, c, "no '.' in the timestamp");
	c.next();
	std::int64_t fraction = 0;
	if (!c.digits(&fraction, 6, &n))
		return fail(out, c, "no fraction in the timestamp");
	for (; n < 6; ++n)
		fraction *= 10;
	if (!c.atEnd() && c.peek() >= '0' && c.peek() <= '9')
		return fail(out, c, "more than 6 digits of fraction");
	if (c.atEnd() || c.peek() != ')')
		return fail(out, c, "no ')' after the timestamp");
	c.next();
	out->time_us = seconds * 1000000 + fraction;

	if (c.atEnd() || c.peek() != ' ')
		return fail(out, c, "no space after the timestamp");
	while (!c.atEnd() && c.peek() == ' ')
		c.next();
	std::size_t iface_len = 0;
	while (!c.atEnd() && c.peek() != ' ') {
		c.next();
		++iface_len;
	}
	if (iface_len == 0 || c.atEnd())
		return fail(out, c, "no interface name");
	while (!c.atEnd() && c.peek() == ' ')
		c.next();

	std::uint32_t id = 0;
	int id_digits = 0;
	while (c.peekHex() >= 0 && id_digits < 8) {
		id = (id << 4) | static_cast<std::uint32_t>(c.peekHex());
		++id_digits;
		c.next();
	}
	if (c.atEnd())
		return fail(out, c, "the line ends in the identifier");
	if (c.peek() != '#' || (id_digits != 3 && id_digits != 8))
		return fail(out, c, "the identifier is not 3 or 8 hex digits and '#'");
	c.next();
	if (id_digits == 3 && id > 0x7ff)
		return fail(out, c, "a standard identifier above 0x7FF");

	bool fd = false;
	if (!c.atEnd() && c.peek() == '#') {
		fd = true;
		c.next();
		if (c.atEnd())
			return fail(out, c, "the line ends before the FD flags");
		if (c.peekHex() < 0)
			return fail(out, c, "the FD flags are not a hex digit");
		c.next();
	} else if (!c.atEnd() && (c.peek() == 'R' || c.peek() == 'r')) {
		return CandumpParse::Ignored; /* a remote frame */
	}

	std::uint8_t bytes[64] = {};
	std::size_t count = 0;
	const std::size_t max_bytes = fd ? 64 : 8;
	while (!c.atEnd()) {
		const int hi = c.peekHex();
		if (hi < 0)
			return fail(out, c, "a data byte is not hex");
		c.next();
		if (c.atEnd())
			return fail(out, c, "an odd number of hex digits: the last byte is cut");
		const int lo = c.peekHex();
		if (lo < 0)
			return fail(out, c, "a data byte is not hex");
		c.next();
		if (count >= max_bytes) {
			out->error = fd ? "more than 64 data bytes" : "more than 8 data bytes";
			return CandumpParse::Malformed;
		}
		bytes[count++] = static_cast<std::uint8_t>((hi << 4) | lo);
	}
	if (id_digits == 8)
		return CandumpParse::Ignored; /* extended: not one of ours */

	if (fd) {
		out->fd = can::FdFrame{};
		out->fd.id = id;
		out->fd.len = static_cast<std::uint8_t>(count);
		for (std::size_t i = 0; i < count; ++i)
			out->fd.data[i] = bytes[i];
		return CandumpParse::Fd;
	}
	out->frame = can::RawFrame{};
	out->frame.id = id;
	out->frame.len = static_cast<std::uint8_t>(count);
	for (std::size_t i = 0; i < count; ++i)
		out->frame.data[i] = bytes[i];
	return CandumpParse::Classic;
}

std::string candumpFrameText(const can::RawFrame &frame)
{
	char text[40];
	int n = std::snprintf(text, sizeof(text), "%03X#", static_cast<unsigned int>(frame.id));
	for (std::size_t i = 0; i < frame.len && i < frame.data.size(); ++i)
		n += std::snprintf(text + n, sizeof(text) - static_cast<std::size_t>(n), "%02X",
				   frame.data[i]);
	return text;
}

const char *candumpParseName(CandumpParse result)
{
	switch (result) {
	case CandumpParse::Classic:
		return "classic frame";
	case CandumpParse::Fd:
		return "FD frame";
	case CandumpParse::Ignored:
		return "ignored line";
	case CandumpParse::Truncated:
		return "truncated log line";
	case CandumpParse::Malformed:
		return "malformed log line";
	}
	return "unknown";
}

} /* namespace dockpose::tool */

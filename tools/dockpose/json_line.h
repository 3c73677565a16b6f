/* SPDX-License-Identifier: MIT */
/*
 * One line of JSON built in a buffer that is reused from line to line: clear()
 * keeps the capacity, so once the buffer has held the longest line nothing
 * allocates. Numbers go through snprintf formats into a local array, strings
 * are escaped as nlohmann::json::dump(-1, ' ', false, replace) escapes them
 * (byte for byte: \" \\ \b \f \n \r \t, other control characters as \u00xx,
 * valid UTF-8 as it is); only a string that is not valid UTF-8 goes through
 * nlohmann itself, which replaces the bad bytes (and allocates).
 *
 * Allocates: the buffer in the constructor, and when a line is longer than
 * any before; strings that are not valid UTF-8. Never otherwise.
 */
#pragma once

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace dockpose::tool {

class JsonLine
{
public:
	explicit JsonLine(std::size_t capacity = 4096) { s_.reserve(capacity); }

	void clear() { s_.clear(); }
	const std::string &str() const { return s_; }

	JsonLine &raw(std::string_view text)
	{
		s_.append(text);
		return *this;
	}

	/* printf `format` of v, or null when v is not finite; never "-0.000". */
	JsonLine &number(double v, const char *format)
	{
		if (!std::isfinite(v))
			return raw("null");
		char buf[64];
		std::snprintf(buf, sizeof(buf), format, v);
		/* A negative number that prints as zero is zero. */
		if (buf[0] == '-' && std::strspn(buf + 1, "0.") == std::strlen(buf + 1))
			return raw(buf + 1);
		return raw(buf);
	}

	/* [v[0], v[1], ...]: n numbers, each as number(). */
	template<typename Vec>
	JsonLine &numbers(const Vec &v, int n, const char *format)
	{
		s_ += '[';
		for (int i = 0; i < n; ++i) {
			if (i)
				s_.append(", ");
			number(v[i], format);
		}
		s_ += ']';
		return *this;
	}

	JsonLine &integer(std::int64_t v)
	{
		char buf[24];
		const auto r = std::to_chars(buf, buf + sizeof(buf), v);
		s_.append(buf, r.ptr);
		return *this;
	}

	JsonLine &boolean(bool v) { return raw(v ? "true" : "false"); }

	/* A quoted, escaped JSON string. */
	JsonLine &string(std::string_view text)
	{
		if (!validUtf8(text)) {
			s_.append(nlohmann::json(std::string(text))
					  .dump(-1, ' ', false,
						nlohmann::json::error_handler_t::replace));
			return *this;
		}
		s_ += '"';
		for (const char c : text) {
			switch (c) {
			case '"':
				s_.append("\\\"");
				break;
			case '\\':
				s_.append("\\\\");
				break;
			case '\b':
				s_.append("\\b");
				break;
			case '\f':
				s_.append("\\f");
				break;
			case '\n':
				s_.append("\\n");
				break;
			case '\r':
				s_.append("\\r");
				break;
			case '\t':
				s_.append("\\t");
				break;
			default:
				if (static_cast<unsigned char>(c) < 0x20) {
					char buf[8];
					std::snprintf(buf, sizeof(buf), "\\u%04x",
						      static_cast<unsigned int>(
							      static_cast<unsigned char>(c)));
					s_.append(buf);
				} else {
					s_ += c;
				}
			}
		}
		s_ += '"';
		return *this;
	}

	/* The line and a newline, written and flushed; false when the write failed. */
	bool writeTo(std::FILE *out)
	{
		s_ += '\n';
		const bool ok = std::fwrite(s_.data(), 1, s_.size(), out) == s_.size();
		s_.pop_back();
		return std::fflush(out) == 0 && ok;
	}

	/* Well-formed UTF-8 (Unicode table 3-7: no overlong forms, no surrogates, <= U+10FFFF). */
	static bool validUtf8(std::string_view text)
	{
		const auto *p = reinterpret_cast<const unsigned char *>(text.data());
		const auto *end = p + text.size();
		while (p < end) {
			const unsigned char c = *p;
			if (c < 0x80) {
				++p;
				continue;
			}
			int n = 0;
			unsigned char lo = 0x80, hi = 0xbf;
			if (c >= 0xc2 && c <= 0xdf) {
				n = 1;
			} else if (c >= 0xe0 && c <= 0xef) {
				n = 2;
				if (c == 0xe0)
					lo = 0xa0;
				else if (c == 0xed)
					hi = 0x9f;
			} else if (c >= 0xf0 && c <= 0xf4) {
				n = 3;
				if (c == 0xf0)
					lo = 0x90;
				else if (c == 0xf4)
					hi = 0x8f;
			} else {
				return false;
			}
			if (end - p <= n)
				return false;
			if (p[1] < lo || p[1] > hi)
				return false;
			for (int i = 2; i <= n; ++i)
				if (p[i] < 0x80 || p[i] > 0xbf)
					return false;
			p += n + 1;
		}
		return true;
	}

private:
	std::string s_;
};

} /* namespace dockpose::tool */

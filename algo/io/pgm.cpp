/* SPDX-License-Identifier: MIT */
#include "algo/io/pgm.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "algo/capacities.h"

namespace dockpose {

namespace {

bool isSpace(char c)
{
	return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

/* Skip whitespace and '#' comments; returns the new position. */
std::size_t skipSpaceAndComments(std::string_view s, std::size_t pos)
{
	while (pos < s.size()) {
		if (isSpace(s[pos])) {
			++pos;
		} else if (s[pos] == '#') {
			while (pos < s.size() && s[pos] != '\n' && s[pos] != '\r')
				++pos;
		} else {
			break;
		}
	}
	return pos;
}

/*
 * Read one unsigned decimal header field. Returns an empty string or the
 * reason it failed. Values are capped while reading so absurd sizes cannot
 * overflow.
 */
std::string readField(std::string_view s, std::size_t *pos, const char *what, long *value)
{
	*pos = skipSpaceAndComments(s, *pos);
	if (*pos >= s.size())
		return std::string("the header ends before its ") + what;
	if (s[*pos] < '0' || s[*pos] > '9')
		return std::string("the header's ") + what + " is not a decimal number";
	long v = 0;
	while (*pos < s.size() && s[*pos] >= '0' && s[*pos] <= '9') {
		if (v < 100000000)
			v = v * 10 + (s[*pos] - '0');
		++*pos;
	}
	if (*pos < s.size() && !isSpace(s[*pos]) && s[*pos] != '#')
		return std::string("the header's ") + what + " is followed by '" + s[*pos] +
		       "' instead of whitespace";
	*value = v;
	return {};
}

} /* namespace */

LoadResult<Image> parsePgm(std::string_view bytes, const std::string &source)
{
	LoadResult<Image> r;
	if (bytes.size() < 2 || bytes[0] != 'P') {
		r.error = source + ": not a PGM file (it does not start with \"P5\")";
		return r;
	}
	if (bytes[1] == '2') {
		r.error = source + ": ASCII PGM (P2) is not supported; convert it to binary P5";
		return r;
	}
	if (bytes[1] != '5') {
		r.error = source + ": Netpbm type P" + bytes[1] +
			  " is not a binary graymap; dockpose reads P5 only";
		return r;
	}
	std::size_t pos = 2;
	if (pos < bytes.size() && !isSpace(bytes[pos]) && bytes[pos] != '#') {
		r.error = source + ": malformed PGM header (no whitespace after \"P5\")";
		return r;
	}

	long width = 0, height = 0, maxval = 0;
	std::string err;
	if (!(err = readField(bytes, &pos, "width", &width)).empty() ||
	    !(err = readField(bytes, &pos, "height", &height)).empty() ||
	    !(err = readField(bytes, &pos, "maxval", &maxval)).empty()) {
		r.error = source + ": malformed PGM header: " + err;
		return r;
	}
	if (width <= 0 || height <= 0 || width > kMaxFrameSide || height > kMaxFrameSide) {
		r.error = source + ": PGM size " + std::to_string(width) + "x" +
			  std::to_string(height) + " is not a frame size (1.." +
			  std::to_string(kMaxFrameSide) + " pixels per side)";
		return r;
	}
	if (maxval > 255) {
		r.error = source + ": 16-bit PGM (maxval " + std::to_string(maxval) +
			  ") is not supported; dockpose needs 8-bit frames";
		return r;
	}
	if (maxval < 1) {
		r.error = source + ": PGM maxval 0 is invalid (1..255 expected)";
		return r;
	}
	/* Exactly one whitespace byte separates the header from the pixels. */
	if (pos >= bytes.size() || !isSpace(bytes[pos])) {
		r.error = source + ": truncated PGM (no pixel data after the header)";
		return r;
	}
	++pos;

	const std::size_t need = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
	const std::size_t have = bytes.size() - pos;
	if (have < need) {
		r.error = source + ": truncated PGM: " + std::to_string(width) + "x" +
			  std::to_string(height) + " needs " + std::to_string(need) +
			  " bytes of pixel data, the file has " + std::to_string(have);
		return r;
	}
	r.value = Image(static_cast<int>(width), static_cast<int>(height));
	std::memcpy(r.value.data(), bytes.data() + pos, need);
	return r;
}

LoadResult<Image> readPgm(const std::string &path)
{
	std::string bytes;
	LoadResult<Image> r;
	r.error = readFileContents(path, &bytes);
	if (!r.ok())
		return r;
	return parsePgm(bytes, path);
}

std::string encodePgm(const ImageView &image)
{
	std::string out = "P5\n" + std::to_string(image.width) + " " +
			  std::to_string(image.height) + "\n255\n";
	const std::size_t header = out.size();
	out.resize(header +
		   static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height));
	for (int y = 0; y < image.height; ++y)
		std::memcpy(&out[header + static_cast<std::size_t>(y) *
						  static_cast<std::size_t>(image.width)],
			    image.row(y), static_cast<std::size_t>(image.width));
	return out;
}

std::string writePgm(const std::string &path, const ImageView &image)
{
	if (!image.valid())
		return path + ": cannot write an empty or invalid image";
	const std::string bytes = encodePgm(image);
	std::ofstream out(path, std::ios::binary | std::ios::trunc);
	if (!out) {
		const int err = errno;
		return path + ": cannot create (" + (err ? std::strerror(err) : "unknown error") +
		       ")";
	}
	out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
	out.close();
	if (!out)
		return path + ": write failed";
	return {};
}

} /* namespace dockpose */

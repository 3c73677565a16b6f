/* SPDX-License-Identifier: MIT */
/*
 * Binary 8-bit PGM (P5) frames, as the tools and tests store them.
 *
 * Reading accepts the Netpbm header in full: "P5", then width, height and
 * maxval separated by any whitespace, with '#' comments (to the end of the
 * line) anywhere between the tokens, then exactly one whitespace byte, then
 * width * height bytes. maxval must be 1..255 (pixel values are taken as
 * they are, not rescaled); trailing bytes after the first image are ignored.
 * Refused, each with its own message: ASCII PGM (P2) and other Netpbm kinds,
 * 16-bit PGM (maxval > 255), a malformed header, a size of zero or above
 * kMaxFrameSide per side, truncated pixel data.
 *
 * Host only. parsePgm(), readPgm(), encodePgm() and writePgm() allocate the
 * image or bytes they return. For many frames in a row, viewPgm() and
 * PgmReader parse in place and read into one reused buffer: after the first
 * frame they allocate nothing but error messages.
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "algo/image.h"
#include "algo/status.h"

namespace dockpose {

/*
 * Check a PGM held in memory and show its pixels where they are: on success
 * *view points into `bytes` (stride = width) and stays valid as long as they
 * do. `source` names the bytes in error messages ("<source>: <reason>").
 * Allocates: only the error message.
 */
Status viewPgm(std::string_view bytes, const std::string &source, ImageView *view);

/* Decode a PGM held in memory; `source` names it in error messages. */
Result<Image> parsePgm(std::string_view bytes, const std::string &source = "<bytes>");

/* Read a PGM file. */
Result<Image> readPgm(const std::string &path);

/* Encode a frame as binary PGM (P5, maxval 255). */
std::string encodePgm(const ImageView &image);

/* Write a frame to a P5 file. Errors say "<path>: <reason>". */
Status writePgm(const std::string &path, const ImageView &image);

/*
 * Reads PGM files one after another into one buffer it owns: open(2),
 * fstat(2), read(2) straight into the buffer, close(2), and the header parsed
 * in place (viewPgm()); the pixels are never copied again. A view from read()
 * is valid until the next read() or the reader's end.
 *
 * Allocates: the buffer, in the constructor (sized for frames of the given
 * size) and again only when a file is larger than any file before; error
 * messages. Never otherwise.
 */
class PgmReader
{
public:
	PgmReader() = default;
	/* Room for a P5 file of width x height pixels with a header of up to 4 kB. */
	PgmReader(int width, int height);

	/*
	 * Read the PGM file at `path` and set *view, or an error "<path>: <reason>":
	 * the messages of readPgm() ("cannot open (...)", "is a
	 * directory, not a file", "read error", and those of viewPgm()).
	 */
	Status read(const std::string &path, ImageView *view);

	/* Bytes the buffer holds without growing. */
	std::size_t capacity() const { return capacity_; }

private:
	void grow(std::size_t bytes);

	std::unique_ptr<std::uint8_t[]> buffer_;
	std::size_t capacity_ = 0;
};

} /* namespace dockpose */

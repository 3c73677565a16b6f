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
 * Host only. Allocates: the returned image and messages.
 */
#pragma once

#include <string>
#include <string_view>

#include "algo/image.h"
#include "algo/io/model_json.h"

namespace dockpose {

/* Decode a PGM held in memory; `source` names it in error messages. */
LoadResult<Image> parsePgm(std::string_view bytes, const std::string &source = "<bytes>");

/* Read a PGM file. */
LoadResult<Image> readPgm(const std::string &path);

/* Encode a frame as binary PGM (P5, maxval 255). */
std::string encodePgm(const ImageView &image);

/* Write a frame to a P5 file. Returns an empty string, or "<path>: <reason>". */
std::string writePgm(const std::string &path, const ImageView &image);

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
#include "algo/io/pgm.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <utility>

#include "algo/capacities.h"

namespace dockpose {

namespace {

/* What PgmReader allows beyond the pixels for the header (comments included) and trailing bytes. */
constexpr std::size_t kHeaderRoom = 4096;

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
 * Read one unsigned decimal header field; an error gives the reason it failed. Values are capped while reading so absurd sizes cannot
 * overflow.
 */
Status readField(std::string_view s, std::size_t *pos, const char *what, long *value)
{
	*pos = skipSpaceAndComments(s, *pos);
	if (*pos >= s.size())
		return Status::error(std::string("the header ends before its ") + what);
	if (s[*pos] < '0' || s[*pos] > '9')
		return Status::error(std::string("the header's ") + what +
				     " is not a decimal number");
	long v = 0;
	while (*pos < s.size() && s[*pos] >= '0' && s[*pos] <= '9') {
		if (v < 100000000)
			v = v * 10 + (s[*pos] - '0');
		++*pos;
	}
	if (*pos < s.size() && !isSpace(s[*pos]) && s[*pos] != '#')
		return Status::error(std::string("the header's ") + what + " is followed by '" +
				     s[*pos] + "' instead of whitespace");
	*value = v;
	return Status::ok();
}

} /* namespace */

Status viewPgm(std::string_view bytes, const std::string &source, ImageView *view)
{
	if (bytes.size() < 2 || bytes[0] != 'P')
		return Status::error(source + ": not a PGM file (it does not start with \"P5\")");
	if (bytes[1] == '2')
		return Status::error(source +
				     ": ASCII PGM (P2) is not supported; convert it to binary P5");
	if (bytes[1] != '5')
		return Status::error(source + ": Netpbm type P" + bytes[1] +
				     " is not a binary graymap; dockpose reads P5 only");
	std::size_t pos = 2;
	if (pos < bytes.size() && !isSpace(bytes[pos]) && bytes[pos] != '#')
		return Status::error(source +
				     ": malformed PGM header (no whitespace after \"P5\")");

	long width = 0, height = 0, maxval = 0;
	for (auto [what, value] : { std::pair{ "width", &width }, std::pair{ "height", &height },
				    std::pair{ "maxval", &maxval } })
		if (Status s = readField(bytes, &pos, what, value); !s)
			return Status::error(source + ": malformed PGM header: " + s.message());
	if (width <= 0 || height <= 0 || width > kMaxFrameSide || height > kMaxFrameSide)
		return Status::error(source + ": PGM size " + std::to_string(width) + "x" +
				     std::to_string(height) + " is not a frame size (1.." +
				     std::to_string(kMaxFrameSide) + " pixels per side)");
	if (maxval > 255)
		return Status::error(source + ": 16-bit PGM (maxval " + std::to_string(maxval) +
				     ") is not supported; dockpose needs 8-bit frames");
	if (maxval < 1)
		return Status::error(source + ": PGM maxval 0 is invalid (1..255 expected)");
	/* Exactly one whitespace byte separates the header from the pixels. */
	if (pos >= bytes.size() || !isSpace(bytes[pos]))
		return Status::error(source + ": truncated PGM (no pixel data after the header)");
	++pos;

	const std::size_t need = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
	const std::size_t have = bytes.size() - pos;
	if (have < need)
		return Status::error(source + ": truncated PGM: " + std::to_string(width) + "x" +
				     std::to_string(height) + " needs " + std::to_string(need) +
				     " bytes of pixel data, the file has " + std::to_string(have));
	view->data = reinterpret_cast<const std::uint8_t *>(bytes.data() + pos);
	view->width = static_cast<int>(width);
	view->height = static_cast<int>(height);
	view->stride_bytes = static_cast<int>(width);
	return Status::ok();
}

namespace {

Image copyOf(const ImageView &view)
{
	Image image(view.width, view.height);
	if (view.data != nullptr) /* always, after a successful viewPgm() or read() */
		std::memcpy(image.data(), view.data,
			    static_cast<std::size_t>(view.width) *
				    static_cast<std::size_t>(view.height));
	return image;
}

} /* namespace */

Result<Image> parsePgm(std::string_view bytes, const std::string &source)
{
	ImageView view;
	if (Status s = viewPgm(bytes, source, &view); !s)
		return s;
	return copyOf(view);
}

Result<Image> readPgm(const std::string &path)
{
	PgmReader reader;
	ImageView view;
	if (Status s = reader.read(path, &view); !s)
		return s;
	return copyOf(view);
}

PgmReader::PgmReader(int width, int height)
{
	if (width > 0 && height > 0)
		grow(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) +
		     kHeaderRoom);
}

void PgmReader::grow(std::size_t bytes)
{
	/* new[] without (): the buffer is not zeroed, read(2) fills what is used. */
	buffer_.reset(new std::uint8_t[bytes]);
	capacity_ = bytes;
}

Status PgmReader::read(const std::string &path, ImageView *view)
{
	const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		const int err = errno;
		return Status::error(path + ": cannot open (" +
				     (err ? std::strerror(err) : "unknown error") + ")");
	}
	struct stat st;
	if (::fstat(fd, &st) != 0) {
		::close(fd);
		return Status::error(path + ": read error");
	}
	if (S_ISDIR(st.st_mode)) {
		::close(fd);
		return Status::error(path + ": is a directory, not a file");
	}

	/*
	 * A regular file: read exactly its size, no read(2) to see the end. A
	 * pipe or device: read to the end, growing the buffer as needed.
	 */
	const bool regular = S_ISREG(st.st_mode);
	std::size_t want = regular ? static_cast<std::size_t>(st.st_size) : capacity_;
	if (want > capacity_ || capacity_ == 0)
		grow(std::max<std::size_t>(want, kHeaderRoom));
	std::size_t have = 0;
	for (;;) {
		if (!regular && have == capacity_) {
			std::unique_ptr<std::uint8_t[]> old = std::move(buffer_);
			grow(2 * capacity_);
			std::memcpy(buffer_.get(), old.get(), have);
			want = capacity_;
		}
		if (have == want)
			break;
		const ssize_t n = ::read(fd, buffer_.get() + have, want - have);
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0) {
			::close(fd);
			return Status::error(path + ": read error");
		}
		if (n == 0)
			break;
		have += static_cast<std::size_t>(n);
	}
	::close(fd);
	return viewPgm(std::string_view(reinterpret_cast<const char *>(buffer_.get()), have), path,
		       view);
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

Status writePgm(const std::string &path, const ImageView &image)
{
	if (!image.valid())
		return Status::error(path + ": cannot write an empty or invalid image");
	const std::string bytes = encodePgm(image);
	std::ofstream out(path, std::ios::binary | std::ios::trunc);
	if (!out) {
		const int err = errno;
		return Status::error(path + ": cannot create (" +
				     (err ? std::strerror(err) : "unknown error") + ")");
	}
	out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
	out.close();
	if (!out)
		return Status::error(path + ": write failed");
	return Status::ok();
}

} /* namespace dockpose */

/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the PGM reader (algo/io/pgm.h) on arbitrary bytes.
 *
 * Oracle, for every input:
 *  - viewPgm() and parsePgm() agree: both accept or both refuse, and a refusal
 *    is a message that names the source ("<fuzz>: ...");
 *  - an accepted frame is 1..kMaxFrameSide pixels per side, its view lies
 *    inside the input bytes (stride = width), and parsePgm()'s pixels are the
 *    view's;
 *  - encodePgm() of it parses back to the same size and pixels (a round trip
 *    through the writer).
 * Sanitizers (ASan, UBSan) and libFuzzer's own checks (timeouts, memory) add
 * the rest: no read past the input, no overflow in the size arithmetic.
 */
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "algo/capacities.h"
#include "algo/io/pgm.h"
#include "tests/fuzz/fuzz_check.h"

using namespace dockpose;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	const std::string_view bytes(reinterpret_cast<const char *>(data), size);
	const std::string source = "<fuzz>";

	ImageView view;
	const Status viewed = viewPgm(bytes, source, &view);
	const Result<Image> parsed = parsePgm(bytes, source);
	FUZZ_CHECK(viewed.isOk() == parsed.isOk(), "viewPgm and parsePgm disagree");
	if (!viewed) {
		FUZZ_CHECK(viewed.message().rfind(source + ": ", 0) == 0,
			   "a refusal names its source");
		FUZZ_CHECK(viewed.message() == parsed.message(),
			   "viewPgm and parsePgm refuse with different messages");
		return 0;
	}

	FUZZ_CHECK(view.valid(), "an accepted frame has a valid view");
	FUZZ_CHECK(view.width <= kMaxFrameSide && view.height <= kMaxFrameSide,
		   "an accepted frame is at most kMaxFrameSide per side");
	FUZZ_CHECK(view.stride_bytes == view.width, "the view's stride is its width");
	const std::size_t n_pixels =
		static_cast<std::size_t>(view.width) * static_cast<std::size_t>(view.height);
	FUZZ_CHECK(view.data >= data && view.data + n_pixels <= data + size,
		   "the view lies inside the input");

	const Image &image = parsed.value();
	FUZZ_CHECK(image.width() == view.width && image.height() == view.height,
		   "parsePgm's size is viewPgm's");
	FUZZ_CHECK(std::memcmp(image.data(), view.data, n_pixels) == 0,
		   "parsePgm's pixels are viewPgm's");

	const std::string encoded = encodePgm(view);
	const Result<Image> again = parsePgm(encoded, "<encoded>");
	FUZZ_CHECK(again.isOk(), "encodePgm's output parses");
	FUZZ_CHECK(again->width() == view.width && again->height() == view.height,
		   "the round trip keeps the size");
	FUZZ_CHECK(std::memcmp(again->data(), view.data, n_pixels) == 0,
		   "the round trip keeps the pixels");
	return 0;
}

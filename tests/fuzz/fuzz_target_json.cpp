/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the target model reader (parseTargetModel, algo/io/model_json.h)
 * on arbitrary text.
 *
 * Oracle: it never throws (the reader promises a Result for every input) and
 * an accepted model passes checkTarget (tests/fuzz/model_check.h: valid,
 * finite, plausible, unit front normals, the same after a JSON round trip)
 * and checkPipeline with the sim board's camera (a Pipeline built on it finds
 * no pose in a dark frame or in a frame of one spot). A refusal names the
 * source.
 */
#include <cstddef>
#include <cstdint>
#include <string>

#include "algo/io/model_json.h"
#include "tests/fuzz/model_check.h"

using namespace dockpose;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	static const CameraIntrinsics camera = [] {
		Result<CameraIntrinsics> k =
			loadCameraIntrinsics(DOCKPOSE_SOURCE_DIR "/tests/data/cam512.json");
		FUZZ_CHECK(k.isOk(), "tests/data/cam512.json loads");
		return k.value();
	}();

	const std::string text(reinterpret_cast<const char *>(data), size);
	const Result<TargetModel> model = parseTargetModel(text, "<fuzz>");
	if (!model) {
		FUZZ_CHECK(model.message().rfind("<fuzz>", 0) == 0, "a refusal names its source");
		return 0;
	}
	fuzz::checkTarget(model.value());
	fuzz::checkPipeline(model.value(), camera);
	return 0;
}

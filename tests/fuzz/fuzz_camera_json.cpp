/* SPDX-License-Identifier: MIT */
/*
 * Fuzz harness: the camera model reader (parseCameraIntrinsics,
 * algo/io/model_json.h) on arbitrary text.
 *
 * Oracle: it never throws, and an accepted camera passes checkCamera
 * (tests/fuzz/model_check.h: valid, finite, the same after a JSON round trip,
 * pixels mapped to rays and back where undistortion converges) and, up to
 * 512 x 512 pixels, checkPipeline with the wedge target (no pose in a dark
 * frame or a frame of one spot). A refusal names the source.
 */
#include <cstddef>
#include <cstdint>
#include <string>

#include "algo/io/model_json.h"
#include "tests/fuzz/model_check.h"

using namespace dockpose;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size)
{
	static const TargetModel target = [] {
		Result<TargetModel> m =
			loadTargetModel(DOCKPOSE_SOURCE_DIR "/tests/data/wedge.json");
		FUZZ_CHECK(m.isOk(), "tests/data/wedge.json loads");
		return m.value();
	}();

	const std::string text(reinterpret_cast<const char *>(data), size);
	const Result<CameraIntrinsics> camera = parseCameraIntrinsics(text, "<fuzz>");
	if (!camera) {
		FUZZ_CHECK(camera.message().rfind("<fuzz>", 0) == 0, "a refusal names its source");
		return 0;
	}
	fuzz::checkCamera(camera.value());
	fuzz::checkPipeline(target, camera.value());
	return 0;
}

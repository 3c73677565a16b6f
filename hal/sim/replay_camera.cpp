/* SPDX-License-Identifier: MIT */
/*
 * The replay camera (see replay_camera.h).
 */
#include "hal/sim/replay_camera.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <utility>

#include "algo/io/pgm.h"

namespace dockpose::hal {

namespace fs = std::filesystem;

ReplayCamera::ReplayCamera(std::string folder, bool loop)
	: SimCameraBase(LatePolicy::CatchUp),
	  folder_(std::move(folder)),
	  loop_(loop)
{
}

ReplayCamera::~ReplayCamera()
{
	stop();
}

std::string ReplayCamera::name() const
{
	return "replay camera (" + folder_ + ")";
}

Status ReplayCamera::configure(const CameraConfig &config)
{
	if (folder_.empty())
		return fail("replay camera: no folder given");
	std::error_code ec;
	if (!fs::is_directory(folder_, ec))
		return fail(
			name() + ": " +
			(fs::exists(folder_, ec) ? "not a folder" : "the folder does not exist"));

	std::vector<std::string> paths;
	fs::directory_iterator it(folder_, ec);
	if (ec)
		return fail(name() + ": cannot list the folder (" + ec.message() + ")");
	for (const fs::directory_entry &entry : it) {
		const std::string file = entry.path().filename().string();
		if (file.size() > 10 && file.rfind("frame_", 0) == 0 &&
		    file.compare(file.size() - 4, 4, ".pgm") == 0 && entry.is_regular_file(ec))
			paths.push_back(entry.path().string());
	}
	if (paths.empty())
		return fail(name() + ": the folder has no frame_*.pgm files");
	std::sort(paths.begin(), paths.end());

	std::vector<Image> frames;
	frames.reserve(paths.size());
	for (const std::string &path : paths) {
		Result<Image> pgm = readPgm(path);
		if (!pgm)
			return fail(name() + ": " + pgm.message());
		if (!frames.empty() &&
		    (pgm->width() != frames[0].width() || pgm->height() != frames[0].height()))
			return fail(name() + ": " + path + ": size " +
				    std::to_string(pgm->width()) + "x" +
				    std::to_string(pgm->height()) + " differs from " + paths[0] +
				    "'s " + std::to_string(frames[0].width()) + "x" +
				    std::to_string(frames[0].height()));
		frames.push_back(std::move(pgm).value());
	}
	const int width = frames[0].width(), height = frames[0].height();
	if ((config.width != 0 && config.width != width) ||
	    (config.height != 0 && config.height != height))
		return fail(name() + ": requested size " + std::to_string(config.width) + "x" +
			    std::to_string(config.height) + " does not match the frames' " +
			    std::to_string(width) + "x" + std::to_string(height) +
			    " (use 0x0 or the frames' size)");
	if (Status status = setup(config, width, height); !status)
		return status;
	frames_ = std::move(frames);
	return Status::ok();
}

bool ReplayCamera::produceFrame(const Exposure &exposure, Image *image)
{
	const std::size_t count = frames_.size();
	if (count == 0 || (!loop_ && exposure.sequence >= count))
		return false;
	const Image &src = frames_[static_cast<std::size_t>(exposure.sequence % count)];
	std::memcpy(image->data(), src.data(),
		    static_cast<std::size_t>(src.width()) * static_cast<std::size_t>(src.height()));
	return true;
}

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
#include "firmware/capture.h"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <utility>

#include "algo/io/pgm.h"

namespace dockpose::firmware {

Status prepareCaptureDir(const std::string &dir)
{
	if (dir.empty())
		return Status::error("--capture: the directory name is empty");
	std::error_code ec;
	std::filesystem::create_directories(dir, ec);
	if (ec)
		return Status::error("cannot create the capture directory " + dir + ": " +
				     ec.message());
	if (!std::filesystem::is_directory(dir, ec))
		return Status::error("the capture path " + dir + " is not a directory");
	/* access(2) is not enough (root passes it on a read-only mount): create a file. */
	const std::string probe = dir + "/.dockposed-capture-probe";
	std::FILE *f = std::fopen(probe.c_str(), "wb");
	if (!f)
		return Status::error("cannot write in the capture directory " + dir + ": " +
				     std::strerror(errno));
	std::fclose(f);
	std::remove(probe.c_str());
	return Status::ok();
}

FrameCapture::FrameCapture(std::string dir, int frames, int every, bool only_lit,
			   std::atomic<bool> *stop)
	: dir_(std::move(dir)),
	  frames_(frames),
	  every_(every),
	  only_lit_(only_lit),
	  stop_(stop)
{
}

std::string FrameCapture::fileName(int index)
{
	char name[32];
	std::snprintf(name, sizeof(name), "frame-%06d.pgm", index);
	return name;
}

void FrameCapture::onFrame(const hal::Frame &frame, hal::Lighting lighting)
{
	if (done() || !error_.empty())
		return;
	if (only_lit_ && lighting != hal::Lighting::Lit)
		return;
	const std::uint64_t usable = usable_++;
	if (usable % static_cast<std::uint64_t>(every_) != 0)
		return;
	const int index = written_.load();
	if (auto s = writePgm(dir_ + "/" + fileName(index), frame.image); !s) {
		error_ = s.message();
		stop_->store(true);
		return;
	}
	written_.store(index + 1);
	if (done())
		stop_->store(true);
}

} /* namespace dockpose::firmware */

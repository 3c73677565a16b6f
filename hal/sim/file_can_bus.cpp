/* SPDX-License-Identifier: MIT */
/*
 * The candump-log CAN bus (see file_can_bus.h).
 */
#include "hal/sim/file_can_bus.h"

#include <cerrno>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <system_error>
#include <utility>

#include "hal/clock.h"
#include "hal/sim/sim_can.h"

namespace dockpose::hal {

namespace {

constexpr std::size_t kFileBufferBytes = std::size_t{ 64 } * 1024;
constexpr std::size_t kMaxInterfaceName = 32;
constexpr char kHex[] = "0123456789ABCDEF";

} /* namespace */

FileCanBus::FileCanBus(std::string path, std::string interface_name)
	: CanBusBase("file CAN bus " + interface_name + " (" + path + ")"),
	  path_(std::move(path)),
	  interface_(std::move(interface_name))
{
}

FileCanBus::~FileCanBus()
{
	close();
}

void FileCanBus::writeFailed(int err)
{
	++stats_.tx_errors;
	setError("%s: cannot write the CAN log: %s", path_.c_str(), std::strerror(err));
}

Status FileCanBus::fail(const std::string &message)
{
	setError("%s", message.c_str());
	publish();
	return Status::error(message);
}

Status FileCanBus::open(std::span<const CanFilter> filters, const CanOptions &options)
{
	close();
	if (Status s = openQueues(options, kRxCapacity); !s.isOk())
		return s;
	if (interface_.empty() || interface_.size() > kMaxInterfaceName ||
	    interface_.find_first_of(" \t\r\n#()") != std::string::npos)
		return fail("file CAN bus: invalid interface name \"" + interface_ +
			    "\" (1 to 32 characters, no spaces, '#' or parentheses)");
	if (path_.empty())
		return fail("file CAN bus: no log file path given");

	std::error_code ec;
	const std::filesystem::path parent = std::filesystem::path(path_).parent_path();
	if (!parent.empty() && !std::filesystem::is_directory(parent, ec))
		return fail(path_ + ": cannot create the CAN log: the folder " + parent.string() +
			    " does not exist");
	std::FILE *file = std::fopen(path_.c_str(), "w");
	if (!file) {
		const int err = errno;
		return fail(path_ + ": cannot create the CAN log: " + std::strerror(err));
	}
	file_buffer_.assign(kFileBufferBytes, '\0');
	std::setvbuf(file, file_buffer_.data(), _IOFBF, file_buffer_.size());
	file_ = file;
	budget_ = frames_per_poll_;
	{
		std::lock_guard<std::mutex> lock(filter_mutex_);
		filters_.assign(filters.begin(), filters.end());
	}
	markOpen();
	return Status::ok();
}

void FileCanBus::close()
{
	if (file_) {
		if (std::fflush(file_) != 0)
			writeFailed(errno);
		std::fclose(file_);
		file_ = nullptr;
	}
	closeQueues();
}

bool FileCanBus::writeFrame(const CanFrame &frame)
{
	timespec now{};
	clock_gettime(CLOCK_REALTIME, &now);
	/* "(sssssssssss.uuuuuu) " + name + " " + id + "##f" + 128 hex digits + "\n" */
	char line[32 + kMaxInterfaceName + 16 + 4 + 128 + 2];
	int n = std::snprintf(line, sizeof(line), "(%lld.%06ld) %s %0*X#",
			      static_cast<long long>(now.tv_sec),
			      static_cast<long>(now.tv_nsec / 1000), interface_.c_str(),
			      frame.extended ? 8 : 3, static_cast<unsigned>(frame.id));
	if (n < 0)
		return false;
	std::size_t len = static_cast<std::size_t>(n);
	if (frame.fd) {
		line[len++] = '#';
		line[len++] = '0'; /* flags: no bit rate switch, no error state indicator */
	}
	for (std::uint8_t i = 0; i < frame.len; ++i) {
		line[len++] = kHex[frame.data[i] >> 4];
		line[len++] = kHex[frame.data[i] & 0xf];
	}
	line[len++] = '\n';
	return std::fwrite(line, 1, len, file_) == len;
}

void FileCanBus::transmit()
{
	const std::int64_t now_ns = monotonicNs();
	if (budget_ == 0)
		expire(now_ns);
	while (budget_ != 0) {
		const CanFrame *next = nextToSend(now_ns);
		if (!next)
			break;
		if (writeFrame(*next))
			++stats_.tx_frames;
		else
			writeFailed(errno);
		tx_.pop();
		if (budget_ > 0)
			--budget_;
	}
}

void FileCanBus::poll()
{
	if (!file_)
		return;
	budget_ = frames_per_poll_;
	transmit();
	if (std::fflush(file_) != 0)
		writeFailed(errno);
	publish();
}

void FileCanBus::setBandwidth(int frames_per_poll)
{
	frames_per_poll_ = frames_per_poll < 0 ? -1 : frames_per_poll;
	budget_ = frames_per_poll_;
}

void FileCanBus::inject(const CanFrame &frame)
{
	{
		std::lock_guard<std::mutex> lock(filter_mutex_);
		if (!canFilterPasses(filters_, frame))
			return;
	}
	received(frame);
}

} /* namespace dockpose::hal */

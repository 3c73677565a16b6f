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
	: path_(std::move(path)),
	  interface_(std::move(interface_name))
{
}

FileCanBus::~FileCanBus()
{
	close();
}

std::string FileCanBus::name() const
{
	return "file CAN bus " + interface_ + " (" + path_ + ")";
}

void FileCanBus::setError(const char *what, int err)
{
	std::snprintf(error_, sizeof(error_), "%s: %s%s%s", path_.c_str(), what, err ? ": " : "",
		      err ? std::strerror(err) : "");
}

Status FileCanBus::open(std::span<const CanFilter> filters, const CanOptions &options)
{
	close();
	auto failed = [&](const std::string &message) {
		std::snprintf(error_, sizeof(error_), "%s", message.c_str());
		return Status::error(message);
	};
	if (interface_.empty() || interface_.size() > kMaxInterfaceName ||
	    interface_.find_first_of(" \t\r\n#()") != std::string::npos)
		return failed("file CAN bus: invalid interface name \"" + interface_ +
			      "\" (1 to 32 characters, no spaces, '#' or parentheses)");
	if (options.tx_queue_depth < 1)
		return failed(name() + ": tx_queue_depth " +
			      std::to_string(options.tx_queue_depth) + " must be at least 1");
	if (path_.empty())
		return failed("file CAN bus: no log file path given");

	std::error_code ec;
	const std::filesystem::path parent = std::filesystem::path(path_).parent_path();
	if (!parent.empty() && !std::filesystem::is_directory(parent, ec))
		return failed(path_ + ": cannot create the CAN log: the folder " + parent.string() +
			      " does not exist");
	std::FILE *file = std::fopen(path_.c_str(), "w");
	if (!file) {
		const int err = errno;
		return failed(path_ + ": cannot create the CAN log: " + std::strerror(err));
	}
	file_buffer_.assign(kFileBufferBytes, '\0');
	std::setvbuf(file, file_buffer_.data(), _IOFBF, file_buffer_.size());
	file_ = file;
	options_ = options;
	tx_.reset(options.tx_queue_depth);
	budget_ = frames_per_poll_;
	{
		std::lock_guard<std::mutex> lock(rx_mutex_);
		filters_.assign(filters.begin(), filters.end());
		rx_ring_.assign(kRxCapacity, CanFrame{});
		rx_head_ = 0;
		rx_count_ = 0;
		rx_open_ = true;
	}
	error_[0] = '\0';
	publishQueue();
	state_.store(CanState::ErrorActive);
	return Status::ok();
}

void FileCanBus::close()
{
	{
		std::lock_guard<std::mutex> lock(rx_mutex_);
		rx_open_ = false;
		rx_count_ = 0;
	}
	if (file_) {
		if (std::fflush(file_) != 0) {
			setError("cannot write the CAN log", errno);
			tx_errors_.fetch_add(1, std::memory_order_relaxed);
		}
		std::fclose(file_);
		file_ = nullptr;
	}
	tx_.clear();
	publishQueue();
	state_.store(CanState::Closed);
}

void FileCanBus::publishQueue()
{
	tx_queued_.store(static_cast<std::uint32_t>(tx_.size()), std::memory_order_relaxed);
	tx_dropped_.store(tx_.dropped(), std::memory_order_relaxed);
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

void FileCanBus::pump()
{
	while (!tx_.empty() && budget_ != 0) {
		if (writeFrame(tx_.front())) {
			tx_frames_.fetch_add(1, std::memory_order_relaxed);
		} else {
			tx_errors_.fetch_add(1, std::memory_order_relaxed);
			setError("cannot write the CAN log", errno);
		}
		tx_.pop();
		if (budget_ > 0)
			--budget_;
	}
	publishQueue();
}

bool FileCanBus::send(const CanFrame &frame)
{
	if (!file_) {
		tx_errors_.fetch_add(1, std::memory_order_relaxed);
		setError("send() on a closed bus", 0);
		return false;
	}
	if (const char *problem = canFrameProblem(frame, options_.fd)) {
		tx_errors_.fetch_add(1, std::memory_order_relaxed);
		setError(problem, 0);
		return false;
	}
	CanFrame queued = canWireFrame(frame);
	queued.timestamp_ns = monotonicNs();
	const bool kept = tx_.push(queued);
	pump();
	return kept;
}

void FileCanBus::poll()
{
	if (!file_)
		return;
	budget_ = frames_per_poll_;
	pump();
	if (std::fflush(file_) != 0) {
		tx_errors_.fetch_add(1, std::memory_order_relaxed);
		setError("cannot write the CAN log", errno);
	}
}

void FileCanBus::setBandwidth(int frames_per_poll)
{
	frames_per_poll_ = frames_per_poll < 0 ? -1 : frames_per_poll;
	budget_ = frames_per_poll_;
}

void FileCanBus::inject(const CanFrame &frame)
{
	std::lock_guard<std::mutex> lock(rx_mutex_);
	if (!rx_open_ || !canFilterPasses(filters_, frame))
		return;
	if (rx_count_ == rx_ring_.size()) {
		rx_head_ = (rx_head_ + 1) % rx_ring_.size();
		--rx_count_;
		rx_dropped_.fetch_add(1, std::memory_order_relaxed);
	}
	CanFrame &slot = rx_ring_[(rx_head_ + rx_count_) % rx_ring_.size()];
	slot = frame;
	if (slot.timestamp_ns == 0)
		slot.timestamp_ns = monotonicNs();
	++rx_count_;
}

bool FileCanBus::receive(CanFrame *frame)
{
	std::lock_guard<std::mutex> lock(rx_mutex_);
	if (rx_count_ == 0 || !frame)
		return false;
	*frame = rx_ring_[rx_head_];
	rx_head_ = (rx_head_ + 1) % rx_ring_.size();
	--rx_count_;
	rx_frames_.fetch_add(1, std::memory_order_relaxed);
	return true;
}

CanStats FileCanBus::stats() const
{
	CanStats s;
	s.tx_frames = tx_frames_.load(std::memory_order_relaxed);
	s.tx_dropped = tx_dropped_.load(std::memory_order_relaxed);
	s.tx_errors = tx_errors_.load(std::memory_order_relaxed);
	s.rx_frames = rx_frames_.load(std::memory_order_relaxed);
	s.tx_queued = tx_queued_.load(std::memory_order_relaxed);
	s.state = state_.load(std::memory_order_relaxed);
	return s;
}

std::string FileCanBus::lastError() const
{
	return error_;
}

} /* namespace dockpose::hal */

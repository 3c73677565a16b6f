/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/view/can_input.h"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <exception>
#include <utility>

#include "firmware/preview.h"
#include "tools/dockpose/view/candump.h"

namespace dockpose::tool {

namespace {
constexpr std::int64_t kRetryUs = 1000000;
/* The preview ring is read this often, and reopened when it has not moved for this long. */
constexpr std::chrono::milliseconds kPreviewPoll{ 50 };
constexpr std::int64_t kPreviewStillUs = 2000000;

/* A frame read from the socket as the protocol's classic or FD frame (its data cut to what the
 * frame holds). */
template<typename Frame>
Frame fromSocket(const canfd_frame &raw)
{
	Frame f;
	f.id = raw.can_id & CAN_SFF_MASK;
	f.len = static_cast<std::uint8_t>(std::min<std::size_t>(raw.len, f.data.size()));
	std::memcpy(f.data.data(), raw.data, f.len);
	return f;
}
} /* namespace */

std::int64_t realtimeUs()
{
	timespec ts{};
	clock_gettime(CLOCK_REALTIME, &ts);
	return static_cast<std::int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

/* ---- CandumpFollower ---- */

CandumpFollower::CandumpFollower(std::string path, ViewState *state)
	: path_(std::move(path)),
	  state_(state)
{
	reopen();
}

CandumpFollower::~CandumpFollower()
{
	if (fd_ >= 0)
		::close(fd_);
}

void CandumpFollower::reopen()
{
	if (fd_ >= 0)
		::close(fd_);
	fd_ = -1;
	offset_ = 0;
	pending_.clear();
	dropping_ = false;
	line_number_ = 0;
	last_open_try_us_ = realtimeUs();
	fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
	if (fd_ < 0) {
		if (!missing_reported_)
			state_->problem("CAN log", path_ + ": " + std::strerror(errno),
					last_open_try_us_);
		missing_reported_ = true;
		return;
	}
	if (missing_reported_)
		state_->resolve("CAN log");
	missing_reported_ = false;
	struct stat st {
	};
	inode_ = ::fstat(fd_, &st) == 0 ? static_cast<std::uint64_t>(st.st_ino) : 0;
}

int CandumpFollower::poll()
{
	if (fd_ < 0) {
		if (realtimeUs() - last_open_try_us_ >= kRetryUs)
			reopen();
		if (fd_ < 0)
			return 0;
	}
	/* Replaced (another inode at the path) or truncated: start again. */
	struct stat by_path {
	};
	struct stat by_fd {
	};
	if (::stat(path_.c_str(), &by_path) == 0 && ::fstat(fd_, &by_fd) == 0) {
		if (static_cast<std::uint64_t>(by_path.st_ino) != inode_) {
			state_->problem("CAN log", path_ + ": replaced, read again from its start",
					realtimeUs());
			reopen();
			if (fd_ < 0)
				return 0;
		} else if (by_fd.st_size < offset_) {
			state_->problem("CAN log", path_ + ": truncated, read again from its start",
					realtimeUs());
			reopen();
			if (fd_ < 0)
				return 0;
		}
	}

	int taken = 0;
	char buffer[16384];
	for (int chunk = 0; chunk < 64; ++chunk) {
		const ssize_t n = ::pread(fd_, buffer, sizeof(buffer), offset_);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			state_->problem("CAN log", path_ + ": " + std::strerror(errno),
					realtimeUs());
			break;
		}
		if (n == 0)
			break;
		offset_ += n;
		for (ssize_t i = 0; i < n; ++i) {
			const char c = buffer[i];
			if (c == '\n') {
				++line_number_;
				if (dropping_) {
					state_->problem("malformed log line",
							"line " + std::to_string(line_number_) +
								": longer than " +
								std::to_string(kMaxLineBytes) +
								" bytes",
							realtimeUs());
					dropping_ = false;
				} else {
					takeLine(pending_);
					++taken;
				}
				pending_.clear();
			} else if (!dropping_) {
				if (pending_.size() >= kMaxLineBytes) {
					dropping_ = true;
					pending_.clear();
				} else {
					pending_.push_back(c);
				}
			}
		}
	}
	return taken;
}

void CandumpFollower::takeLine(const std::string &line)
{
	CandumpLine parsed;
	const CandumpParse result = parseCandumpLine(line, &parsed);
	switch (result) {
	case CandumpParse::Classic:
		state_->feed(parsed.frame, parsed.time_us);
		return;
	case CandumpParse::Fd:
		state_->feedFd(parsed.fd, parsed.time_us);
		return;
	case CandumpParse::Ignored:
		return;
	case CandumpParse::Truncated:
	case CandumpParse::Malformed:
		break;
	}
	std::string shown;
	for (char c : line.substr(0, 60))
		shown.push_back(c >= 0x20 && c < 0x7f ? c : '?');
	state_->problem(candumpParseName(result),
			"line " + std::to_string(line_number_) + ": " + parsed.error + ": \"" +
				shown + (line.size() > 60 ? "...\"" : "\""),
			realtimeUs());
}

/* ---- SocketCanInput ---- */

SocketCanInput::SocketCanInput(std::string interface_name, ViewState *state)
	: interface_(std::move(interface_name)),
	  state_(state)
{
	reopen();
}

SocketCanInput::~SocketCanInput()
{
	const std::lock_guard<std::mutex> lock(mutex_);
	if (fd_ >= 0)
		::close(fd_);
}

void SocketCanInput::reopen()
{
	const std::lock_guard<std::mutex> lock(mutex_);
	if (fd_ >= 0)
		::close(fd_);
	fd_ = -1;
	last_open_try_us_ = realtimeUs();
	const unsigned int index = if_nametoindex(interface_.c_str());
	if (index == 0) {
		state_->problem("CAN socket", interface_ + ": no such interface",
				last_open_try_us_);
		return;
	}
	const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC | SOCK_NONBLOCK, CAN_RAW);
	if (fd < 0) {
		state_->problem("CAN socket", interface_ + ": socket: " + std::strerror(errno),
				last_open_try_us_);
		return;
	}
	const int on = 1;
	/* FD frames when the kernel has them (a classic-only kernel refuses: fine). */
	(void)::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof(on));
	sockaddr_can addr{};
	addr.can_family = AF_CAN;
	addr.can_ifindex = static_cast<int>(index);
	if (::bind(fd, reinterpret_cast<sockaddr *>(&addr), sizeof(addr)) != 0) {
		state_->problem("CAN socket", interface_ + ": bind: " + std::strerror(errno),
				last_open_try_us_);
		::close(fd);
		return;
	}
	fd_ = fd;
}

int SocketCanInput::poll(int timeout_ms)
{
	int fd = -1;
	{
		const std::lock_guard<std::mutex> lock(mutex_);
		fd = fd_;
	}
	if (fd < 0) {
		if (realtimeUs() - last_open_try_us_ >= kRetryUs)
			reopen();
		::usleep(static_cast<useconds_t>(timeout_ms) * 1000);
		return 0;
	}
	pollfd p{ fd, POLLIN, 0 };
	if (::poll(&p, 1, timeout_ms) <= 0)
		return 0;
	int fed = 0;
	for (int i = 0; i < 256; ++i) {
		canfd_frame raw{};
		const ssize_t n = ::read(fd, &raw, sizeof(raw));
		if (n < 0) {
			if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)
				break;
			state_->problem("CAN socket",
					interface_ + ": read: " + std::strerror(errno),
					realtimeUs());
			reopen();
			break;
		}
		const std::int64_t now_us = realtimeUs();
		if ((raw.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) != 0)
			continue; /* extended, remote or error frames: never ours */
		if (n == static_cast<ssize_t>(CAN_MTU))
			state_->feed(fromSocket<can::RawFrame>(raw), now_us);
		else if (n == static_cast<ssize_t>(CANFD_MTU))
			state_->feedFd(fromSocket<can::FdFrame>(raw), now_us);
		else
			continue;
		++fed;
	}
	return fed;
}

bool SocketCanInput::send(const can::RawFrame &frame, std::string *error)
{
	const std::lock_guard<std::mutex> lock(mutex_);
	if (fd_ < 0) {
		*error = interface_ + ": not open";
		return false;
	}
	can_frame raw{};
	raw.can_id = frame.id & CAN_SFF_MASK;
	raw.len = frame.len > 8 ? 8 : frame.len;
	std::memcpy(raw.data, frame.data.data(), raw.len);
	const ssize_t n = ::write(fd_, &raw, sizeof(raw));
	if (n != static_cast<ssize_t>(sizeof(raw))) {
		*error = interface_ + ": write: " + (n < 0 ? std::strerror(errno) : "short write");
		return false;
	}
	return true;
}

/* ---- ViewInput ---- */

ViewInput::ViewInput(const std::string &can_log, const std::string &can_interface,
		     std::string preview, ViewState *state)
	: preview_name_(std::move(preview)),
	  state_(state),
	  reader_(std::make_unique<firmware::PreviewReader>()),
	  scratch_(std::make_unique<firmware::PreviewFrame>())
{
	if (!can_log.empty())
		log_ = std::make_unique<CandumpFollower>(can_log, state);
	else if (!can_interface.empty())
		socket_ = std::make_unique<SocketCanInput>(can_interface, state);
}

ViewInput::~ViewInput()
{
	stop();
}

void ViewInput::start()
{
	thread_ = std::thread([this] { run(); });
}

void ViewInput::stop()
{
	stop_ = true;
	if (thread_.joinable())
		thread_.join();
}

void ViewInput::run()
{
	auto next_preview = std::chrono::steady_clock::now();
	while (!stop_) {
		try {
			if (socket_) {
				socket_->poll(10);
			} else {
				if (log_)
					log_->poll();
				std::this_thread::sleep_for(std::chrono::milliseconds(10));
			}
			if (std::chrono::steady_clock::now() >= next_preview) {
				next_preview = std::chrono::steady_clock::now() + kPreviewPoll;
				pollPreview();
			}
		} catch (const std::exception &e) {
			/* Out of memory, or a bug: said, and the reader goes on. */
			state_->problem("internal error", e.what(), realtimeUs());
			std::this_thread::sleep_for(std::chrono::milliseconds(100));
		}
	}
}

void ViewInput::pollPreview()
{
	const std::int64_t now_us = realtimeUs();
	if (!reader_->isOpen()) {
		if (now_us - last_open_us_ < kRetryUs)
			return;
		last_open_us_ = now_us;
		const Status s = reader_->open(preview_name_);
		if (!s.isOk()) {
			state_->setPreviewError(s.message(), now_us);
			return;
		}
		seen_ = 0;
		moved_us_ = now_us;
	}
	const std::uint64_t count = reader_->latest(scratch_.get(), seen_);
	if (count > 0) {
		seen_ = count;
		moved_us_ = now_us;
		state_->setPreviewFrame(&scratch_, count, now_us);
		if (!scratch_)
			scratch_ = std::make_unique<firmware::PreviewFrame>();
	} else if (now_us - moved_us_ > kPreviewStillUs) {
		/* The daemon stopped (its segment is unlinked; this mapping is the old one) or
		 * restarted with a new segment: look again. */
		reader_->close();
		last_open_us_ = 0;
		state_->setPreviewError("/dev/shm/" + preview_name_ +
						": no new frame for 2 s (dockposed stopped?)",
					now_us);
	}
}

} /* namespace dockpose::tool */

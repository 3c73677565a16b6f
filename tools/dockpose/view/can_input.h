/* SPDX-License-Identifier: MIT */
/*
 * Where `dockpose view` reads the bus: a candump log followed as it grows
 * (like tail -f), or a SocketCAN interface. Both hand every frame and every
 * problem to a ViewState.
 *
 * CandumpFollower: reads what was appended since the last poll() and parses
 * every complete line (a line still without its newline waits for the next
 * poll(); one that never gets it is never read). A file that shrank or was
 * replaced (another inode) is read again from its start; one that is missing
 * is a problem ("CAN log") and is looked for again at each poll().
 *
 * SocketCanInput: a CAN_RAW socket (FD frames on when the kernel has them)
 * bound to one interface, read without blocking longer than poll()'s
 * timeout; send() writes one classic frame (the command). An interface that
 * is missing or down is a problem ("CAN socket") and is tried again each
 * second.
 *
 * ViewInput: the view's CAN reader thread, which runs one of the two and
 * polls the daemon's preview ring (firmware/preview.h, PreviewReader) every
 * 50 ms, reopening it when it is missing or has not moved for 2 s (the daemon
 * stopped: its segment is unlinked; or restarted with a new one).
 *
 * Threads: poll() belongs to the view's CAN reader thread; SocketCanInput's
 * send() may be called from any thread (it writes the socket under a mutex).
 * Allocates: the follower's line buffer (grows to the longest line, at most
 * kMaxLineBytes: a longer "line" is a problem and dropped).
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "firmware/protocol/dockpose_can.h"
#include "tools/dockpose/view/view_state.h"

namespace dockpose::firmware {
class PreviewReader;
} /* namespace dockpose::firmware */

namespace dockpose::tool {

/* CLOCK_REALTIME in microseconds: a candump log's clock. */
std::int64_t realtimeUs();

class CandumpFollower
{
public:
	static constexpr std::size_t kMaxLineBytes = 1024;

	CandumpFollower(std::string path, ViewState *state);
	CandumpFollower(const CandumpFollower &) = delete;
	CandumpFollower &operator=(const CandumpFollower &) = delete;
	~CandumpFollower();

	/* Read and feed what is new; returns the number of lines taken. */
	int poll();
	std::uint64_t lines() const { return line_number_; }

private:
	void reopen();
	void takeLine(const std::string &line);

	std::string path_;
	ViewState *state_;
	int fd_ = -1;
	std::uint64_t inode_ = 0;
	std::int64_t offset_ = 0;
	std::string pending_;
	bool dropping_ = false; /* inside a line longer than kMaxLineBytes */
	std::uint64_t line_number_ = 0;
	std::int64_t last_open_try_us_ = 0;
	bool missing_reported_ = false;
};

class SocketCanInput
{
public:
	SocketCanInput(std::string interface_name, ViewState *state);
	SocketCanInput(const SocketCanInput &) = delete;
	SocketCanInput &operator=(const SocketCanInput &) = delete;
	~SocketCanInput();

	/* Wait up to timeout_ms for frames, feed them; returns the number fed. */
	int poll(int timeout_ms);
	/* Send one classic frame; false with *error when it cannot. Any thread. */
	bool send(const can::RawFrame &frame, std::string *error);

private:
	void reopen();

	std::string interface_;
	ViewState *state_;
	std::mutex mutex_; /* fd_ for send() */
	int fd_ = -1;
	std::int64_t last_open_try_us_ = 0;
};

/* The CAN reader thread (see above). start() starts it, stop() (or the destructor) joins it. */
class ViewInput
{
public:
	/* can_log or can_interface (neither: only the preview); preview: the ring's name. */
	ViewInput(const std::string &can_log, const std::string &can_interface, std::string preview,
		  ViewState *state);
	ViewInput(const ViewInput &) = delete;
	ViewInput &operator=(const ViewInput &) = delete;
	~ViewInput();

	void start();
	void stop();
	/* The socket, to send commands (nullptr with a log). */
	SocketCanInput *socket() { return socket_.get(); }

private:
	void run();
	void pollPreview();

	std::string preview_name_;
	ViewState *state_;
	std::unique_ptr<CandumpFollower> log_;
	std::unique_ptr<SocketCanInput> socket_;
	std::unique_ptr<firmware::PreviewReader> reader_;
	std::unique_ptr<firmware::PreviewFrame> scratch_;
	std::uint64_t seen_ = 0;
	std::int64_t moved_us_ = 0;
	std::int64_t last_open_us_ = -2000000;
	std::atomic<bool> stop_{ false };
	std::thread thread_;
};

} /* namespace dockpose::tool */

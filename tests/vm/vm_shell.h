/* SPDX-License-Identifier: MIT */
/*
 * Shell helpers shared by the VM backend tests (tests/vm/test_vm_*.cpp): run the
 * ecosystem's tools (candump, gpioinfo, cam, ip, tc) as witnesses, and wait for a
 * condition with a timeout. Test code only; allocates freely.
 */
#pragma once

#include <sys/wait.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "hal/clock.h"

namespace dockpose::vmtest {

struct CommandResult {
	int status = -1;	/* exit status; -1 when it did not exit normally */
	std::string output;	/* stdout and stderr */
};

/* Run a shell command, capturing its output. */
inline CommandResult run(const std::string &command)
{
	CommandResult r;
	FILE *p = popen((command + " 2>&1").c_str(), "r");
	if (!p) {
		r.output = "popen failed: " + std::string(std::strerror(errno));
		return r;
	}
	std::array<char, 4096> buf;
	std::size_t n;
	while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0)
		r.output.append(buf.data(), n);
	const int status = pclose(p);
	r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
	return r;
}

/* Run a command that must succeed (a test's own setup). */
inline void mustRun(const std::string &command)
{
	const CommandResult r = run(command);
	ASSERT_EQ(r.status, 0) << command << ":\n" << r.output;
}

/* Poll done() every 5 ms until it holds or timeout_ms passes; its last answer. */
inline bool waitUntil(const std::function<bool()> &done, int timeout_ms)
{
	const std::int64_t end_ns = hal::monotonicNs() + static_cast<std::int64_t>(timeout_ms) * 1000000;
	while (!done()) {
		if (hal::monotonicNs() > end_ns)
			return done();
		std::this_thread::sleep_for(std::chrono::milliseconds(5));
	}
	return true;
}

} /* namespace dockpose::vmtest */

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
	int status = -1; /* exit status; -1 when it did not exit normally */
	std::string output; /* stdout and stderr */
};

/* A shell word: COMMAND in single quotes. */
inline std::string shellQuote(const std::string &text)
{
	std::string quoted = "'";
	for (char c : text)
		quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
	return quoted + "'";
}

/*
 * Run a shell command, capturing its output (stdout and stderr). A command still running after
 * timeout_s is killed (status 124), and the output then ends with what hung: its threads'
 * state, wchan and syscall from /proc and the kernel log's tail (a hung `cam` in the arm64
 * guest once cost a whole VM timeout and said nothing).
 */
inline CommandResult run(const std::string &command, int timeout_s = 120)
{
	const std::string watched =
		"( " + command + " ) & p=$!; n=0; t=" + std::to_string(timeout_s) +
		"\nwhile kill -0 $p 2>/dev/null; do\n"
		"  if [ $n -ge $((t * 10)) ]; then\n"
		"    echo \"vm_shell: still running after $t s, killed; its threads:\"\n"
		"    for d in /proc/$p/task/*; do\n"
		"      echo \"  ${d##*/} $(cat $d/comm) state $(cut -d' ' -f3 $d/stat) wchan $(cat $d/wchan)"
		" syscall $(cat $d/syscall)\"\n"
		"    done\n"
		"    dmesg | tail -n 20\n"
		"    kill -KILL $p; wait $p; exit 124\n"
		"  fi\n"
		"  sleep 0.1; n=$((n + 1))\n"
		"done\n"
		"wait $p\n";
	CommandResult r;
	FILE *p = popen(("sh -c " + shellQuote(watched) + " 2>&1").c_str(), "r");
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
	const std::int64_t end_ns =
		hal::monotonicNs() + static_cast<std::int64_t>(timeout_ms) * 1000000;
	while (!done()) {
		if (hal::monotonicNs() > end_ns)
			return done();
		std::this_thread::sleep_for(std::chrono::milliseconds(5));
	}
	return true;
}

} /* namespace dockpose::vmtest */

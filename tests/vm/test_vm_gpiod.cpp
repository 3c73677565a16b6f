/* SPDX-License-Identifier: MIT */
/*
 * GpiodStrobe against the kernel's gpio-sim driver, inside a test VM
 * (scripts/vm; run by ctest as vm_<arch>_gpiosim_gpiod). guest-init.sh makes a
 * chip labelled "dockpose-sim" with 8 lines, line 3 named "led-strobe";
 * $DOCKPOSE_GPIO_SIM_DIR/sim_gpio3/value is the level on the line and
 * sim_gpio3/pull the level it returns to when nobody holds it.
 *
 * Witnesses: the sysfs level (read by this process or another), gpioinfo
 * (consumer, direction, active-low), gpioset (a second requester is refused).
 * A level read is only evidence of a driven level when it differs from the
 * pull, so every check first sets the pull to the opposite of what it expects.
 *
 * What can and cannot be observed on gpio-sim: a released line returns to its
 * pull at once (gpio_sim_free), so the level a process left behind is gone by
 * the time anyone looks. What is observed instead is the level at the moment
 * of release, while the line is still held: gpiod_line_release() is
 * interposed (in this program, and in dockposed through a preloaded probe
 * built from this file, DOCKPOSE_VM_RELEASE_PROBE), reads the sysfs level and
 * then releases. For shutdown on SIGTERM and for a fatal signal, a child
 * process (this program with --hold-line) holds the line lit the way
 * dockposed does; on SIGTERM it switches off with forceOff() as
 * Daemon::shutdown() does, lets the parent look at the still-held line, then
 * closes. A fatal signal runs dockposed's handler (forceOff, then the default
 * action); the child's handler also reads the level before dying. And the real
 * dockposed (board vm, strobe constant) is started, seen lighting the line,
 * stopped with SIGTERM, and its release level read by the probe.
 *
 * Outside a test VM the program exits 77 (skipped).
 */
#include <dlfcn.h>
#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

struct gpiod_line;

/* -------------------------------------------------------------------------- */
/* The release probe: in this program, and alone in vm_gpiod_release_probe.so. */

namespace {

/* Where to read the line's level (sim_gpioN/value) and what was read at release. */
char g_probe_value_path[512];
int g_probe_out_fd = -1; /* the probe .so: append "release <offset> <level>" here */
std::atomic<int> g_level_at_release{ -1 }; /* the last level read while releasing a held line */
std::atomic<int> g_releases{ 0 };
static_assert(std::atomic<int>::is_always_lock_free);

/* The first byte of a sysfs value file as 0/1, -1 on error. Async-signal-safe. */
int readLevel(const char *path)
{
	const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0)
		return -1;
	char c = 0;
	const ssize_t n = ::read(fd, &c, 1);
	::close(fd);
	return n == 1 && (c == '0' || c == '1') ? c - '0' : -1;
}

template<typename Fn>
Fn nextSymbol(const char *name)
{
	void *p = dlsym(RTLD_NEXT, name);
	Fn fn = nullptr;
	static_assert(sizeof(fn) == sizeof(p));
	std::memcpy(&fn, &p, sizeof(fn));
	return fn;
}

} /* namespace */

#if !defined(DOCKPOSE_GPIOD_MAJOR) || DOCKPOSE_GPIOD_MAJOR < 2
#define DOCKPOSE_VM_HAVE_RELEASE_PROBE 1
/*
 * libgpiod v1: every line release goes through gpiod_line_release(); this one
 * is found first (it is in the program, or preloaded), reads the level while
 * the line is still held, and calls libgpiod's.
 */
extern "C" void gpiod_line_release(gpiod_line *line)
{
	using ReleaseFn = void (*)(gpiod_line *);
	using IsRequestedFn = bool (*)(gpiod_line *);
	using OffsetFn = unsigned int (*)(gpiod_line *);
	static const ReleaseFn release = nextSymbol<ReleaseFn>("gpiod_line_release");
	static const IsRequestedFn is_requested =
		nextSymbol<IsRequestedFn>("gpiod_line_is_requested");
	static const OffsetFn offset = nextSymbol<OffsetFn>("gpiod_line_offset");

#ifdef DOCKPOSE_VM_RELEASE_PROBE
	if (g_probe_value_path[0] == '\0') {
		const char *path = std::getenv("DOCKPOSE_VM_PROBE_VALUE");
		const char *out = std::getenv("DOCKPOSE_VM_PROBE_OUT");
		if (path && out) {
			std::snprintf(g_probe_value_path, sizeof(g_probe_value_path), "%s", path);
			g_probe_out_fd =
				::open(out, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
		}
	}
#endif
	/* gpiod_chip_close() releases every line object again: only held lines count. */
	if (line && g_probe_value_path[0] != '\0' && is_requested && is_requested(line)) {
		const int level = readLevel(g_probe_value_path);
		g_level_at_release.store(level);
		g_releases.fetch_add(1);
		if (g_probe_out_fd >= 0) {
			char text[64];
			const int n = std::snprintf(text, sizeof(text), "release %u %d\n",
						    offset ? offset(line) : 0u, level);
			if (n > 0 &&
			    ::write(g_probe_out_fd, text, static_cast<std::size_t>(n)) < 0) {
			}
		}
	}
	if (release)
		release(line);
}
#endif

#ifndef DOCKPOSE_VM_RELEASE_PROBE

#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <array>
#include <chrono>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "hal/clock.h"
#include "hal/gpiod/gpiod_strobe.h"
#include "vm_shell.h"

extern char **environ;

namespace {

using dockpose::hal::GpiodStrobe;
using dockpose::hal::monotonicNs;

constexpr int kLine = 3; /* "led-strobe" */
constexpr const char *kLabel = "dockpose-sim";

std::string simChip()
{
	const char *c = std::getenv("DOCKPOSE_GPIO_SIM_CHIP");
	return c ? c : "";
}

std::string simDir()
{
	const char *d = std::getenv("DOCKPOSE_GPIO_SIM_DIR");
	return d ? d : "";
}

std::string valuePath(int line = kLine)
{
	return simDir() + "/sim_gpio" + std::to_string(line) + "/value";
}

/* The level on the line now (sysfs): 0, 1, or -1 when it cannot be read. */
int level(int line = kLine)
{
	return readLevel(valuePath(line).c_str());
}

/* What the line returns to when released: "pull-up" or "pull-down". */
void setPull(const char *pull, int line = kLine)
{
	const std::string path = simDir() + "/sim_gpio" + std::to_string(line) + "/pull";
	std::ofstream out(path);
	out << pull;
	out.close();
	ASSERT_TRUE(out) << "cannot write " << pull << " to " << path;
}

using dockpose::vmtest::CommandResult;
using dockpose::vmtest::run;
using dockpose::vmtest::waitUntil;

/* gpioinfo's line for `line` of the chip, found by its label like the backend does. */
std::string gpioinfoLine(int line = kLine)
{
	const CommandResult r = run(std::string("gpioinfo ") + kLabel);
	std::istringstream in(r.output);
	std::string text;
	const std::string key =
		"line " + std::string(line < 10 ? "  " : " ") + std::to_string(line) + ":";
	while (std::getline(in, text))
		if (text.find(key) != std::string::npos)
			return text;
	return "(no line " + std::to_string(line) + " in gpioinfo " + kLabel + ": " + r.output +
	       ")";
}

bool contains(const std::string &text, const std::string &part)
{
	return text.find(part) != std::string::npos;
}

/* Arm the in-process release probe for the sim line. */
void armReleaseProbe()
{
	std::snprintf(g_probe_value_path, sizeof(g_probe_value_path), "%s", valuePath().c_str());
	g_level_at_release = -1;
	g_releases = 0;
}

/* A child process with its stdin and stdout on pipes (stderr inherited). */
class Child
{
public:
	Child(const std::vector<std::string> &args, const std::vector<std::string> &extra_env = {})
	{
		int to_child[2], from_child[2];
		if (::pipe2(to_child, O_CLOEXEC) != 0 || ::pipe2(from_child, O_CLOEXEC) != 0)
			return;
		posix_spawn_file_actions_t actions;
		posix_spawn_file_actions_init(&actions);
		posix_spawn_file_actions_adddup2(&actions, to_child[0], STDIN_FILENO);
		posix_spawn_file_actions_adddup2(&actions, from_child[1], STDOUT_FILENO);
		std::vector<std::string> arg_copy = args;
		std::vector<char *> argv;
		for (std::string &a : arg_copy)
			argv.push_back(a.data());
		argv.push_back(nullptr);
		std::vector<std::string> env_copy;
		for (char **e = environ; *e; ++e)
			env_copy.emplace_back(*e);
		env_copy.insert(env_copy.end(), extra_env.begin(), extra_env.end());
		std::vector<char *> envp;
		for (std::string &e : env_copy)
			envp.push_back(e.data());
		envp.push_back(nullptr);
		if (posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), envp.data()) != 0)
			pid_ = -1;
		posix_spawn_file_actions_destroy(&actions);
		::close(to_child[0]);
		::close(from_child[1]);
		in_ = to_child[1];
		out_ = from_child[0];
	}
	~Child()
	{
		if (pid_ > 0) {
			::kill(pid_, SIGKILL);
			::waitpid(pid_, nullptr, 0);
		}
		if (in_ >= 0)
			::close(in_);
		if (out_ >= 0)
			::close(out_);
	}
	Child(const Child &) = delete;
	Child &operator=(const Child &) = delete;

	bool started() const { return pid_ > 0; }
	void signal(int sig) const
	{
		if (pid_ > 0) /* never kill(-1): not after wait() reaped it */
			::kill(pid_, sig);
	}

	/* The next line the child printed ("" on timeout or end of output). */
	std::string readLine(int timeout_ms)
	{
		const std::int64_t end_ns =
			monotonicNs() + static_cast<std::int64_t>(timeout_ms) * 1000000;
		for (;;) {
			const std::size_t eol = buffer_.find('\n');
			if (eol != std::string::npos) {
				std::string line = buffer_.substr(0, eol);
				buffer_.erase(0, eol + 1);
				return line;
			}
			const std::int64_t left_ms = (end_ns - monotonicNs()) / 1000000;
			if (left_ms <= 0 || out_ < 0)
				return "";
			pollfd p{ out_, POLLIN, 0 };
			if (::poll(&p, 1, static_cast<int>(left_ms)) <= 0)
				continue;
			char chunk[256];
			const ssize_t n = ::read(out_, chunk, sizeof(chunk));
			if (n <= 0) {
				::close(out_);
				out_ = -1;
				continue;
			}
			buffer_.append(chunk, static_cast<std::size_t>(n));
		}
	}
	/* The line starting with prefix, skipping others. */
	std::string readLineStartingWith(const std::string &prefix, int timeout_ms)
	{
		const std::int64_t end_ns =
			monotonicNs() + static_cast<std::int64_t>(timeout_ms) * 1000000;
		for (;;) {
			const std::int64_t left_ms = (end_ns - monotonicNs()) / 1000000;
			if (left_ms <= 0)
				return "";
			std::string line = readLine(static_cast<int>(left_ms));
			if (line.rfind(prefix, 0) == 0)
				return line;
			if (line.empty() && out_ < 0)
				return "";
		}
	}
	void writeLine(const std::string &line)
	{
		const std::string text = line + "\n";
		if (in_ >= 0 && ::write(in_, text.data(), text.size()) < 0) {
		}
	}
	/* The wait status, or -1 when it has not ended within timeout_ms. */
	int wait(int timeout_ms)
	{
		int status = 0;
		const bool ended = waitUntil(
			[&] { return ::waitpid(pid_, &status, WNOHANG) == pid_; }, timeout_ms);
		if (!ended)
			return -1;
		pid_ = -1;
		return status;
	}

private:
	pid_t pid_ = -1;
	int in_ = -1;
	int out_ = -1;
	std::string buffer_;
};

std::string g_self; /* this program, for --hold-line children */

/* ------------------------------------------------------------------------- */
/* --hold-line CHIP LINE [active-low]: hold the strobe lit like dockposed.     */

std::atomic<bool> g_stop{ false };
dockpose::hal::Strobe *g_held = nullptr;

void onStopSignal(int)
{
	g_stop.store(true);
}

/* dockposed's fatal-signal handler (firmware/dockposed.cpp), plus a look at the line. */
void onFatalSignal(int sig)
{
	if (g_held)
		g_held->forceOff();
	char text[32];
	const int n = std::snprintf(text, sizeof(text), "handler-level %d\n",
				    readLevel(g_probe_value_path));
	if (n > 0 && ::write(STDOUT_FILENO, text, static_cast<std::size_t>(n)) < 0) {
	}
	raise(sig);
}

int holdLine(const char *chip, int line, bool active_low)
{
	std::setvbuf(stdout, nullptr, _IONBF, 0);
	struct sigaction stop {
	};
	stop.sa_handler = onStopSignal;
	sigemptyset(&stop.sa_mask);
	for (int sig : { SIGTERM, SIGINT, SIGHUP })
		sigaction(sig, &stop, nullptr);
	struct sigaction fatal {
	};
	fatal.sa_handler = onFatalSignal;
	sigemptyset(&fatal.sa_mask);
	fatal.sa_flags = static_cast<int>(SA_RESETHAND);
	for (int sig : { SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT })
		sigaction(sig, &fatal, nullptr);

	std::snprintf(g_probe_value_path, sizeof(g_probe_value_path), "%s/sim_gpio%d/value",
		      simDir().c_str(), line);
	GpiodStrobe strobe(chip, line, active_low);
	if (auto s = strobe.open(); !s) {
		std::printf("error %s\n", s.message().c_str());
		return 1;
	}
	if (auto s = strobe.set(true); !s) {
		std::printf("error %s\n", s.message().c_str());
		return 1;
	}
	g_held = &strobe;
	std::printf("on\n");
	while (!g_stop.load())
		::usleep(2000);

	/* Daemon::shutdown(): the LED off first, then the rest, then the line is let go. */
	strobe.forceOff();
	g_held = nullptr;
	std::printf("off\n");
	/* Let the parent look at the line while it is still held: until it says "go" (or its end
	 * closes the pipe); a minute only guards a hang, the parent's gpioinfo under TCG may take
	 * seconds. */
	pollfd p{ STDIN_FILENO, POLLIN, 0 };
	(void)::poll(&p, 1, 60000);
	strobe.close();
	std::printf("released-at %d\n", g_level_at_release.load());
	return 0;
}

/* ------------------------------------------------------------------------- */

class GpioSimStrobe : public ::testing::Test
{
protected:
	void TearDown() override
	{
		g_probe_value_path[0] = '\0';
		setPull("pull-down");
	}
};

TEST_F(GpioSimStrobe, OpenByLabelHoldsTheLineAsDockposeOutputDrivenOff)
{
	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	ASSERT_EQ(level(), 1) << "the free line should follow its pull-up";
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();

	GpiodStrobe strobe(kLabel, kLine, false);
	EXPECT_EQ(strobe.name(), "gpio \"dockpose-sim\" line 3");
	const auto status = strobe.open();
	ASSERT_TRUE(status.isOk()) << status.message();
	EXPECT_EQ(strobe.name(), simChip() + " [dockpose-sim] line 3");
	EXPECT_EQ(level(), 0) << "off after open(), against the pull-up: driven";
	EXPECT_FALSE(strobe.isOn());
	const std::string info = gpioinfoLine();
	EXPECT_TRUE(contains(info, "\"led-strobe\"")) << info;
	EXPECT_TRUE(contains(info, "\"dockpose\"")) << info;
	EXPECT_TRUE(contains(info, "output")) << info;
	EXPECT_TRUE(contains(info, "active-high")) << info;
	EXPECT_TRUE(contains(info, "[used]")) << info;
	EXPECT_TRUE(strobe.open().isOk()) << "open() is idempotent";

	strobe.close();
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();
	EXPECT_EQ(level(), 1) << "released: back to its pull";
	strobe.close(); /* idempotent */
}

TEST_F(GpioSimStrobe, ChipByNameNumberPathOrLabel)
{
	const std::string chip = simChip();
	ASSERT_EQ(chip.rfind("gpiochip", 0), 0u) << chip;
	for (const std::string &arg :
	     { chip, chip.substr(8), "/dev/" + chip, std::string(kLabel) }) {
		GpiodStrobe strobe(arg, kLine, false, "dockpose-test");
		const auto status = strobe.open();
		ASSERT_TRUE(status.isOk()) << arg << ": " << status.message();
		EXPECT_EQ(strobe.name(), chip + " [dockpose-sim] line 3") << arg;
		EXPECT_TRUE(contains(gpioinfoLine(), "\"dockpose-test\""))
			<< arg << ": " << gpioinfoLine();
	}
}

TEST_F(GpioSimStrobe, OnAndOffAreTheLineLevel)
{
	GpiodStrobe strobe(kLabel, kLine, false);
	ASSERT_TRUE(strobe.open().isOk()) << strobe.name();
	for (int i = 0; i < 5; ++i) {
		ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
		ASSERT_TRUE(strobe.set(true).isOk());
		EXPECT_TRUE(strobe.isOn());
		EXPECT_EQ(level(), 1) << "on, against the pull-down";
		ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
		EXPECT_EQ(level(), 1) << "the pull does not move a driven line";
		ASSERT_TRUE(strobe.set(false).isOk());
		EXPECT_FALSE(strobe.isOn());
		EXPECT_EQ(level(), 0) << "off, against the pull-up";
	}
	/* Setting the level it already has keeps it. */
	ASSERT_TRUE(strobe.set(false).isOk());
	EXPECT_EQ(level(), 0);
}

TEST_F(GpioSimStrobe, ActiveLowInvertsThePhysicalLevel)
{
	ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
	GpiodStrobe strobe(kLabel, kLine, true);
	ASSERT_TRUE(strobe.open().isOk()) << strobe.name();
	EXPECT_EQ(strobe.name(), simChip() + " [dockpose-sim] line 3 (active-low)");
	EXPECT_EQ(level(), 1) << "off is physical high, against the pull-down";
	EXPECT_TRUE(contains(gpioinfoLine(), "active-low")) << gpioinfoLine();

	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	ASSERT_TRUE(strobe.set(true).isOk());
	EXPECT_TRUE(strobe.isOn());
	EXPECT_EQ(level(), 0) << "on is physical low, against the pull-up";
	ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
	ASSERT_TRUE(strobe.set(false).isOk());
	EXPECT_EQ(level(), 1) << "off again: physical high";

	ASSERT_TRUE(strobe.set(true).isOk());
	strobe.forceOff();
	EXPECT_EQ(level(), 1) << "forceOff: physical high";
}

#ifdef DOCKPOSE_VM_HAVE_RELEASE_PROBE
TEST_F(GpioSimStrobe, CloseDrivesOffBeforeReleasing)
{
	/* Active-high: on is 1; off must be 0 when released, the pull-up would say 1 after. */
	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	GpiodStrobe high(kLabel, kLine, false);
	ASSERT_TRUE(high.open().isOk());
	ASSERT_TRUE(high.set(true).isOk());
	ASSERT_EQ(level(), 1);
	armReleaseProbe();
	high.close();
	EXPECT_EQ(g_releases.load(), 1);
	EXPECT_EQ(g_level_at_release.load(), 0) << "the level while close() released the line";
	EXPECT_EQ(level(), 1) << "released: the pull-up";
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();

	/* Active-low: on is 0; off is 1 at release, the pull-down says 0 after. */
	ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
	GpiodStrobe low(kLabel, kLine, true);
	ASSERT_TRUE(low.open().isOk());
	ASSERT_TRUE(low.set(true).isOk());
	ASSERT_EQ(level(), 0);
	armReleaseProbe();
	low.close();
	EXPECT_EQ(g_releases.load(), 1);
	EXPECT_EQ(g_level_at_release.load(), 1) << "active-low off is physical high at release";
	EXPECT_EQ(level(), 0) << "released: the pull-down";

	/* The destructor closes the same way. */
	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	{
		GpiodStrobe scoped(kLabel, kLine, false);
		ASSERT_TRUE(scoped.open().isOk());
		ASSERT_TRUE(scoped.set(true).isOk());
		armReleaseProbe();
	}
	EXPECT_EQ(g_level_at_release.load(), 0);
}
#endif

TEST_F(GpioSimStrobe, ForceOffLatchesUntilReopened)
{
	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	GpiodStrobe strobe(kLabel, kLine, false);
	strobe.forceOff(); /* not open: nothing to do, no crash */
	ASSERT_TRUE(strobe.open().isOk());
	ASSERT_TRUE(strobe.set(true).isOk());
	ASSERT_EQ(level(), 1);

	strobe.forceOff();
	EXPECT_EQ(level(), 0) << "forced off while held, against the pull-up";
	EXPECT_FALSE(strobe.isOn());
	EXPECT_TRUE(contains(gpioinfoLine(), "\"dockpose\"")) << "still held: " << gpioinfoLine();
	const auto refused = strobe.set(true);
	EXPECT_FALSE(refused.isOk());
	EXPECT_TRUE(contains(refused.message(), "was forced off")) << refused.message();
	EXPECT_EQ(level(), 0);

	strobe.close();
	ASSERT_TRUE(strobe.open().isOk());
	EXPECT_TRUE(strobe.set(true).isOk()) << "a new open() clears the latch";
	EXPECT_EQ(level(), 1);
}

TEST_F(GpioSimStrobe, HeldLineIsBusyForEveryoneElse)
{
	GpiodStrobe strobe(kLabel, kLine, false);
	ASSERT_TRUE(strobe.open().isOk());

	GpiodStrobe second(kLabel, kLine, false);
	const auto busy = second.open();
	ASSERT_FALSE(busy.isOk());
	EXPECT_EQ(busy.message(),
		  "gpio: line 3 on " + simChip() + " is busy (used by \"dockpose\")");
	const CommandResult gpioset = run(std::string("gpioset ") + kLabel + " 3=1");
	EXPECT_NE(gpioset.status, 0) << "gpioset took a held line: " << gpioset.output;

	/* Other lines of the chip are free. */
	GpiodStrobe other(kLabel, 5, false);
	EXPECT_TRUE(other.open().isOk()) << other.name();
}

TEST_F(GpioSimStrobe, WrongChipOrLineIsNamed)
{
	const std::string found = " (found: " + simChip() + " [dockpose-sim])";
	struct Case {
		std::string chip;
		int line;
		std::string message;
	};
	const Case cases[] = {
		{ "no-such-chip", kLine,
		  "gpio: no GPIO chip named or labelled \"no-such-chip\"" + found },
		{ "gpiochip9", kLine,
		  "gpio: no GPIO chip named or labelled \"gpiochip9\"" + found },
		{ "9", kLine, "gpio: no GPIO chip named or labelled \"9\"" + found },
		{ "/dev/gpiochip9", kLine, "gpio: no GPIO chip at /dev/gpiochip9" + found },
		{ "/dev/null", kLine, "gpio: /dev/null is not a GPIO character device" + found },
		{ kLabel, 8,
		  "gpio: " + simChip() + " [dockpose-sim] has 8 lines; line 8 does not exist" },
		{ kLabel, -1, "gpio: line -1 is not a valid line offset (0 or more)" },
		{ "", kLine, "gpio: no GPIO chip given" },
	};
	for (const Case &c : cases) {
		GpiodStrobe strobe(c.chip, c.line, false);
		const auto status = strobe.open();
		EXPECT_FALSE(status.isOk()) << c.chip << " line " << c.line;
		EXPECT_EQ(status.message(), c.message);
		const auto set = strobe.set(true);
		EXPECT_FALSE(set.isOk());
		EXPECT_TRUE(contains(set.message(), "is not open")) << set.message();
	}
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();
}

/* Waits on a --hold-line child: it answers as soon as it has done the thing (holding the line,
 * switching off, dying); the guard only stops a hang, on a guest as slow as it may be. */
constexpr int kChildGuardMs = 60000;

/* The child holding the line lit, seen from here; pull-down first, so 1 is driven. */
void startHolder(Child &child)
{
	ASSERT_TRUE(child.started()) << g_self << " --hold-line";
	const std::string first = child.readLine(kChildGuardMs);
	ASSERT_EQ(first, "on") << "the child did not light the line";
	EXPECT_EQ(level(), 1) << "lit by the child, against the pull-down";
	const std::string info = gpioinfoLine();
	EXPECT_TRUE(contains(info, "\"dockpose\"") && contains(info, "output")) << info;
}

#ifdef DOCKPOSE_VM_HAVE_RELEASE_PROBE
TEST_F(GpioSimStrobe, SigtermChildSwitchesOffWhileHoldingThenReleases)
{
	ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
	Child child({ g_self, "--hold-line", kLabel, std::to_string(kLine) });
	ASSERT_NO_FATAL_FAILURE(startHolder(child));

	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	child.signal(SIGTERM);
	ASSERT_EQ(child.readLine(kChildGuardMs), "off");
	/* Still held by the child (so the pull-up is not what we read): driven low. */
	EXPECT_EQ(level(), 0) << "the child's line after SIGTERM, before release";
	EXPECT_TRUE(contains(gpioinfoLine(), "\"dockpose\"")) << gpioinfoLine();
	child.writeLine("go");
	EXPECT_EQ(child.readLine(kChildGuardMs), "released-at 0")
		<< "the level while close() released it";
	const int status = child.wait(kChildGuardMs);
	ASSERT_NE(status, -1) << "the child did not exit";
	EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "wait status " << status;
	EXPECT_EQ(level(), 1) << "released: the pull-up";
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();
}
#endif

TEST_F(GpioSimStrobe, FatalSignalHandlerForcesOffBeforeTheProcessDies)
{
	for (const int sig : { SIGSEGV, SIGABRT }) {
		SCOPED_TRACE(strsignal(sig));
		ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
		Child child({ g_self, "--hold-line", kLabel, std::to_string(kLine) });
		ASSERT_NO_FATAL_FAILURE(startHolder(child));
		ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
		child.signal(sig);
		/* Read in the handler after forceOff, before the default action killed it. */
		EXPECT_EQ(child.readLine(kChildGuardMs), "handler-level 0");
		const int status = child.wait(kChildGuardMs);
		ASSERT_NE(status, -1);
		EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig)
			<< "wait status " << status;
		EXPECT_EQ(level(), 1) << "the kernel released it: the pull-up";
		EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();
	}
}

TEST_F(GpioSimStrobe, SigkilledHolderLeavesTheLineToItsPull)
{
	/* No handler runs: the kernel releases the line to its pull, whatever was driven. */
	ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
	Child child({ g_self, "--hold-line", kLabel, std::to_string(kLine) });
	ASSERT_NO_FATAL_FAILURE(startHolder(child));
	child.signal(SIGKILL);
	const int status = child.wait(kChildGuardMs);
	ASSERT_NE(status, -1);
	EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
	EXPECT_EQ(level(), 0)
		<< "lit until killed, then the pull-down: wire the LED off at the pull";
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();
}

#if defined(DOCKPOSED) && defined(DOCKPOSE_VM_HAVE_RELEASE_PROBE)
/* A board file for dockposed: the vm board, strobe constant, a small vimc frame. */
std::string writeDockposedBoard(const std::string &dir)
{
	const std::string source = DOCKPOSE_SOURCE_DIR;
	std::ofstream(dir + "/camera.json")
		<< R"({ "width": 636, "height": 480, "fx": 600.0, "fy": 600.0,
  "cx": 317.5, "cy": 239.5, "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0 })";
	std::ofstream board(dir + "/board.json");
	board << R"({
	"board": "vm",
	"camera": { "backend": "libcamera", "id": "", "index": 0, "width": 636, "height": 480,
		"frame_rate_hz": 30, "exposure_us": 2000, "analogue_gain": 1.0, "buffer_count": 4,
		"stall_timeout_ms": 5000, "intrinsics": "camera.json" },
	"strobe": { "backend": "gpiod", "chip": "dockpose-sim", "line": 3, "active_low": false,
		"mode": "constant", "pulse_margin_us": 500 },
	"can": { "backend": "socketcan", "interface": "vcan0", "base_id": "0x300", "bitrate": 500000,
		"tx_queue_depth": 32, "heartbeat_hz": 10 },
	"pipeline": { "target": ")"
	      << source << R"(/board/vm/target.json", "mode": "track",
		"max_rms_px": 0.6, "min_leds_search": 5, "min_leds_track": 4, "degraded_hold_frames": 30,
		"lost_after_frames": 3 },
	"systemd": { "notify": false }
})";
	return dir + "/board.json";
}

/* Waits on dockposed end as soon as it has done what is waited for; this only stops a hang
 * (well inside the VM's own --timeout, so the other tests' results still arrive). */
constexpr int kDaemonGuardMs = 120000;

TEST_F(GpioSimStrobe, DockposedLightsTheLineAndSwitchesItOffOnSigterm)
{
	char dir[] = "/tmp/dockposed-XXXXXX";
	ASSERT_NE(mkdtemp(dir), nullptr);
	const std::string board = writeDockposedBoard(dir);
	const std::string probe_out = std::string(dir) + "/probe.txt";

	ASSERT_NO_FATAL_FAILURE(setPull("pull-down"));
	/*
	 * The strobe in constant mode: lit once dockposed runs (camera started and all). Starting
	 * takes what the guest gives it (seconds under TCG, more on a loaded host): wait while it
	 * runs; the guard only ends a hang. A start-up that blocks (libcamera's start has
	 * deadlocked now and then in the arm64 guest, and once took over the default 20 s) ends
	 * with status 75 after --startup-timeout; systemd restarts it (Restart=on-failure), and
	 * so does this test, once, as tests/vm/firmware_guest.sh does.
	 */
	const int startup_timeout_s = 45;
	std::unique_ptr<Child> daemon;
	int early_status = -1;
	bool lit = false;
	for (int attempt = 0; attempt < 2 && !lit; ++attempt) {
		if (attempt > 0 && early_status != -1 &&
		    !(WIFEXITED(early_status) && WEXITSTATUS(early_status) == 75))
			break;
		early_status = -1;
		daemon = std::make_unique<Child>(
			std::vector<std::string>{ DOCKPOSED, "--board", board, "--startup-timeout",
						  std::to_string(startup_timeout_s) },
			std::vector<std::string>{ std::string("LD_PRELOAD=") +
							  DOCKPOSE_VM_RELEASE_PROBE_LIB,
						  "DOCKPOSE_VM_PROBE_VALUE=" + valuePath(),
						  "DOCKPOSE_VM_PROBE_OUT=" + probe_out });
		ASSERT_TRUE(daemon->started()) << DOCKPOSED;
		lit = waitUntil(
			      [&] {
				      return level() == 1 || (early_status = daemon->wait(0)) != -1;
			      },
			      kDaemonGuardMs) &&
		      level() == 1;
	}
	ASSERT_TRUE(lit)
		<< "dockposed never lit the line"
		<< (early_status != -1
			    ? " and exited (wait status " + std::to_string(early_status) + ")"
			    : "")
		<< "; gpioinfo: " << gpioinfoLine();
	EXPECT_TRUE(contains(gpioinfoLine(), "\"dockpose\"")) << gpioinfoLine();

	ASSERT_NO_FATAL_FAILURE(setPull("pull-up"));
	daemon->signal(SIGTERM);
	/* It stops at the end of the loop iteration under way (a slow one: seconds); the guard only
	 * ends a hang. */
	const int status = daemon->wait(kDaemonGuardMs);
	ASSERT_NE(status, -1)
		<< "dockposed did not stop within " << kDaemonGuardMs / 1000 << " s of SIGTERM";
	EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "wait status " << status;

	std::ifstream in(probe_out);
	std::string word, line_offset, at_release;
	in >> word >> line_offset >> at_release;
	EXPECT_EQ(word + " " + line_offset + " " + at_release, "release 3 0")
		<< "dockposed's line when it released it (probe " << DOCKPOSE_VM_RELEASE_PROBE_LIB
		<< ")";
	EXPECT_EQ(level(), 1) << "released: the pull-up";
	EXPECT_TRUE(contains(gpioinfoLine(), "unused")) << gpioinfoLine();
	(void)run(std::string("rm -rf ") + dir);
}
#endif

} /* namespace */

int main(int argc, char **argv)
{
	char self[4096];
	const ssize_t n = ::readlink("/proc/self/exe", self, sizeof(self) - 1);
	g_self = n > 0 ? std::string(self, static_cast<std::size_t>(n)) : std::string(argv[0]);
	if (argc >= 4 && std::strcmp(argv[1], "--hold-line") == 0)
		return holdLine(argv[2], std::atoi(argv[3]),
				argc >= 5 && std::strcmp(argv[4], "active-low") == 0);

	::testing::InitGoogleTest(&argc, argv);
	if (!std::getenv("DOCKPOSE_VM_ARCH")) {
		std::fprintf(stderr,
			     "test_vm_gpiod: not inside a dockpose test VM; run it there: "
			     "scripts/vm run -- %s (or ctest -L vm)\n",
			     argv[0]);
		return 77;
	}
	if (simChip().empty() || simDir().empty() || level() < 0) {
		std::fprintf(stderr, "test_vm_gpiod: no gpio-sim chip ($DOCKPOSE_GPIO_SIM_CHIP, "
				     "$DOCKPOSE_GPIO_SIM_DIR; tests/vm/guest-init.sh makes it)\n");
		return 1;
	}
	return RUN_ALL_TESTS();
}

#endif /* !DOCKPOSE_VM_RELEASE_PROBE */

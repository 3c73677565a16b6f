/* SPDX-License-Identifier: MIT */
/*
 * dockposed: the docking-sensor daemon.
 *
 *   dockposed --board board/sim/board.json [--for SECONDS] [--can-log FILE] [--startup-timeout S]
 *   dockposed --board B --capture DIR --frames N [--every K]
 *
 * --capture runs the sensor as usual and writes N frames (every Kth) to DIR as PGM
 * (firmware/capture.h), then shuts down as on SIGTERM (LED off) and exits 0; a directory
 * that cannot be made or written is a bad command line (2), a write that fails later or a
 * camera that ends before N frames exits 1.
 *
 * Exit status: 0 after a clean run (SIGTERM/SIGINT, --for elapsed, replay
 * finished), 1 when the hardware failed (a backend could not start, the camera
 * failed for good), 2 for a bad command line or board file, 75 (EX_TEMPFAIL)
 * when start-up did not finish within --startup-timeout seconds (a backend
 * blocked: a device that never answers, a FIFO with no reader as the CAN log,
 * a library that deadlocked); stderr names the step; 70 (EX_SOFTWARE) when an
 * exception escaped (a bug, or out of memory), with its message. systemd restarts it
 * (Restart=on-failure) before its own TimeoutStartSec would kill it.
 */
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>
#include <utility>

#include <CLI/CLI.hpp>

#include "board/board.h"
#include "firmware/capture.h"
#include "firmware/config.h"
#include "firmware/config_table.h"
#include "firmware/daemon.h"

namespace {

std::atomic<bool> g_stop{ false };
/* For fatal signals: the LED goes off before the process dies. */
dockpose::hal::Strobe *g_strobe = nullptr;

/*
 * Start-up's watchdog: the step under way (a string literal), and the
 * message's two fixed parts, formatted when the watchdog is armed (the
 * signal handler may not format).
 */
constexpr int kExitStartupHung = 75;
std::atomic<const char *> g_startup_step{ "start-up" };
constexpr int kDefaultStartupTimeoutS = 20;
constexpr int kExitInternal = 70; /* EX_SOFTWARE: an exception escaped */
char g_startup_head[96] = "";
char g_startup_tail[48] = "";

void writeAll(const char *text)
{
	std::size_t left = std::strlen(text);
	while (left > 0) {
		const ssize_t n = ::write(STDERR_FILENO, text, left);
		if (n <= 0)
			return;
		text += n;
		left -= static_cast<std::size_t>(n);
	}
}

/* SIGALRM while starting: async-signal-safe only (write, _exit; the strobe's forceOff is a plain write). */
void onStartupTimeout(int)
{
	if (g_strobe)
		g_strobe->forceOff();
	writeAll(g_startup_head);
	writeAll(g_startup_step.load());
	writeAll(g_startup_tail);
	::_exit(kExitStartupHung);
}

void armStartupWatchdog(int timeout_s)
{
	std::snprintf(g_startup_head, sizeof(g_startup_head),
		      "dockposed: start-up did not finish within %d s (--startup-timeout), stuck ",
		      timeout_s);
	std::snprintf(g_startup_tail, sizeof(g_startup_tail), "; exiting with status %d\n",
		      kExitStartupHung);
	struct sigaction alarm_action {
	};
	alarm_action.sa_handler = onStartupTimeout;
	sigemptyset(&alarm_action.sa_mask);
	sigaction(SIGALRM, &alarm_action, nullptr);
	::alarm(static_cast<unsigned>(timeout_s));
}

void onStopSignal(int)
{
	g_stop.store(true);
}

/* "dockposed: signal 11 (fatal): LED off\n", built without snprintf (not async-signal-safe). */
void writeFatalSignalLine(int sig)
{
	char digits[12];
	int n = 0;
	unsigned v = static_cast<unsigned>(sig);
	do {
		digits[n++] = static_cast<char>('0' + v % 10);
		v /= 10;
	} while (v > 0 && n < static_cast<int>(sizeof(digits)) - 1);
	char number[12];
	for (int i = 0; i < n; ++i)
		number[i] = digits[n - 1 - i];
	number[n] = '\0';
	writeAll("dockposed: signal ");
	writeAll(number);
	writeAll(g_strobe ? " (fatal): LED off\n" : " (fatal)\n");
}

void onFatalSignal(int sig)
{
	if (g_strobe)
		g_strobe->forceOff();
	writeFatalSignalLine(sig);
	/* SA_RESETHAND restored the default action: die of the same signal. */
	raise(sig);
}

/*
 * Every signal whose default action ends the process is one of these (signal(7)), so
 * none can end it with the LED left on:
 *  - a request to stop (SIGPWR: the power is failing): a clean shutdown, LED off, the
 *    SHUTDOWN status frame, exit 0;
 *  - a fault, or a limit the kernel enforces (its default dumps core): LED off at once,
 *    a line on stderr, then death by the same signal (systemd sees it and restarts);
 *  - signals a stray kill or a library may send that ask nothing of a sensor: ignored, the
 *    sensor keeps running. SIGALRM is start-up's watchdog until start-up ends
 *    (ignoreStrayAlarms()), SIGKILL and SIGSTOP cannot be caught (the board README: the
 *    hardware keeps the LED off without the process).
 */
constexpr int kStopSignals[] = { SIGTERM, SIGINT, SIGHUP, SIGPWR };
constexpr int kFatalSignals[] = { SIGSEGV, SIGBUS,  SIGFPE, SIGILL,  SIGABRT,
				  SIGQUIT, SIGTRAP, SIGSYS, SIGXCPU, SIGXFSZ };
constexpr int kIgnoredSignals[] = {
	SIGPIPE, SIGUSR1, SIGUSR2, SIGIO, SIGVTALRM, SIGPROF, SIGSTKFLT
};

void installSignalHandlers()
{
	struct sigaction stop {
	};
	stop.sa_handler = onStopSignal;
	sigemptyset(&stop.sa_mask);
	for (int sig : kStopSignals)
		sigaction(sig, &stop, nullptr);

	struct sigaction fatal {
	};
	fatal.sa_handler = onFatalSignal;
	sigemptyset(&fatal.sa_mask);
	fatal.sa_flags = static_cast<int>(SA_RESETHAND);
	for (int sig : kFatalSignals)
		sigaction(sig, &fatal, nullptr);

	for (int sig : kIgnoredSignals)
		std::signal(sig, SIG_IGN);
	/* The real-time signals glibc leaves to applications (it keeps those below SIGRTMIN). */
	for (int sig = SIGRTMIN; sig <= SIGRTMAX; ++sig)
		std::signal(sig, SIG_IGN);
}

/* Start-up is over: a SIGALRM from now on is a stray one, not the watchdog's. */
void ignoreStrayAlarms()
{
	::alarm(0);
	std::signal(SIGALRM, SIG_IGN);
}

bool contains(std::span<const char *const> names, const std::string &name)
{
	for (const char *n : names)
		if (name == n)
			return true;
	return false;
}

std::string join(std::span<const char *const> names)
{
	std::string out;
	for (const char *n : names)
		out += (out.empty() ? "" : ", ") + std::string(n);
	return out;
}

/* The command line. */
struct Options {
	std::string board_path;
	double run_for_s = 0.0;
	std::string can_log;
	int startup_timeout_s = kDefaultStartupTimeoutS;
	std::string capture_dir; /* empty: no capture */
	int capture_frames = 0;
	int capture_every = 1;
};

/* Parse the command line into *options: -1 to go on, else the exit status (--help: 0, bad: 2). */
int parseOptions(int argc, char **argv, Options *options)
{
	using namespace dockpose;

	CLI::App app{ "dockposed: LED-target docking sensor (pose on CAN)" };
	app.add_option("--board", options->board_path,
		       "the board's configuration file (board/<name>/board.json)")
		->required();
	app.add_option("--for", options->run_for_s,
		       "run this many seconds, then shut down cleanly (0: until SIGTERM)")
		->check(CLI::NonNegativeNumber);
	app.add_option("--can-log", options->can_log,
		       "write CAN frames to this candump log (boards whose CAN backend is 'file')");
	app.add_option(
		   "--startup-timeout", options->startup_timeout_s,
		   "seconds the backends may take to open and start before dockposed gives up (exit 75)")
		->check(CLI::Range(1, 600))
		->capture_default_str();
	CLI::Option *capture = app.add_option(
		"--capture", options->capture_dir,
		"write camera frames to this directory as PGM (made if missing), then exit");
	app.add_option("--frames", options->capture_frames, "--capture: how many frames to write")
		->check(CLI::Range(1, 1000000))
		->needs(capture);
	capture->needs(app.get_option("--frames"));
	app.add_option("--every", options->capture_every,
		       "--capture: write every Kth frame (lit frames in strobe mode alternate)")
		->check(CLI::Range(1, 100000))
		->needs(capture)
		->capture_default_str();
	/* Prints a key table of docs/configuration.md (scripts/update-config-doc), then exits. */
	std::string doc_sections;
	for (const std::string &name : firmware::config_table::docSections())
		doc_sections += (doc_sections.empty() ? "" : ", ") + name;
	app.add_option_function<std::string>(
		   "--print-config-doc",
		   [](const std::string &section) {
			   std::fputs(firmware::config_table::docTable(section).c_str(), stdout);
			   throw CLI::Success();
		   },
		   "print the markdown key table of one board file section (" + doc_sections +
			   ") and exit")
		->check([](const std::string &section) {
			return firmware::config_table::docTable(section).empty()
				       ? "not a section of the board file"
				       : std::string();
		});
	try {
		app.parse(argc, argv);
	} catch (const CLI::ParseError &e) {
		return app.exit(e) == 0 ? 0 : 2;
	}
	return -1;
}

/*
 * Read and validate the board file, find its board among those built in and
 * check the backends it names are ones that board wires; --can-log goes into
 * the configuration. Null (the problems on stderr) when any of it fails.
 */
const dockpose::board::BoardInfo *loadBoard(const Options &options,
					    dockpose::firmware::BoardConfig *config)
{
	using namespace dockpose;

	firmware::ConfigResult loaded = firmware::loadBoardConfig(options.board_path);
	if (!loaded.ok()) {
		std::fprintf(stderr, "dockposed: %s: %zu error(s) in the board file:\n",
			     options.board_path.c_str(), loaded.errors.size());
		for (const std::string &e : loaded.errors)
			std::fprintf(stderr, "  %s\n", e.c_str());
		return nullptr;
	}
	*config = std::move(loaded.config);

	const board::BoardInfo *info = board::findBoard(config->board);
	if (!info) {
		std::string built;
		for (const board::BoardInfo &b : board::boards())
			built += (built.empty() ? "" : ", ") + std::string(b.name);
		std::fprintf(
			stderr,
			"dockposed: %s: board \"%s\" is not built into this dockposed (built: %s)\n",
			options.board_path.c_str(), config->board.c_str(), built.c_str());
		return nullptr;
	}
	struct {
		const char *section;
		const std::string &value;
		std::span<const char *const> allowed;
	} const backends[] = {
		{ "camera.backend", config->camera.backend, info->cameras },
		{ "strobe.backend", config->strobe.backend, info->strobes },
		{ "can.backend", config->can.backend, info->cans },
	};
	bool wiring_ok = true;
	for (const auto &b : backends) {
		if (!contains(b.allowed, b.value)) {
			std::fprintf(
				stderr,
				"dockposed: %s: %s: board %s has no \"%s\" backend (it has: %s)\n",
				options.board_path.c_str(), b.section, info->name, b.value.c_str(),
				join(b.allowed).c_str());
			wiring_ok = false;
		}
	}
	if (!wiring_ok)
		return nullptr;
	if (!options.can_log.empty()) {
		if (config->can.backend != "file") {
			std::fprintf(
				stderr,
				"dockposed: --can-log only applies to boards whose CAN backend is \"file\" "
				"(%s uses \"%s\")\n",
				info->name, config->can.backend.c_str());
			return nullptr;
		}
		config->can.log_file = options.can_log;
	}
	return info;
}

/* --capture: the daemon's frame loop with a FrameCapture as its frame tap; the exit status. */
int runCapture(const Options &options, const dockpose::firmware::BoardConfig &config,
	       dockpose::firmware::Daemon *daemon)
{
	using namespace dockpose;

	firmware::FrameCapture capture(options.capture_dir, options.capture_frames,
				       options.capture_every,
				       config.strobe.mode == board::StrobeMode::Alternate, &g_stop);
	daemon->setFrameTap(&capture);
	int status = daemon->run(g_stop, options.run_for_s);
	daemon->setFrameTap(nullptr);
	daemon->printSummary(stderr);
	if (!capture.error().empty()) {
		std::fprintf(stderr, "dockposed: --capture: %s\n", capture.error().c_str());
		return 1;
	}
	if (!capture.done()) {
		std::fprintf(stderr,
			     "dockposed: --capture: only %d of %d frames written to %s (the run "
			     "ended first)\n",
			     capture.written(), options.capture_frames,
			     options.capture_dir.c_str());
		return status != 0 ? status : 1;
	}
	std::fprintf(stderr, "dockposed: --capture: %d frames written to %s, LED off\n",
		     capture.written(), options.capture_dir.c_str());
	return status;
}

/* Wire the board, start the daemon under the start-up watchdog, run it: the exit status. */
int runBoard(const Options &options, const dockpose::board::BoardInfo &info,
	     const dockpose::firmware::BoardConfig &config)
{
	using namespace dockpose;

	armStartupWatchdog(options.startup_timeout_s);
	g_startup_step.store("opening the backends (camera, strobe, CAN)");
	board::Backends wired;
	if (auto s = info.wire(config, &wired); !s) {
		std::fprintf(stderr, "dockposed: board %s: %s\n", info.name, s.message().c_str());
		return 1;
	}

	installSignalHandlers();
	firmware::Daemon daemon(config, std::move(wired));
	/* The signal handlers' strobe while the daemon lives; cleared before it is destroyed,
	 * however this is left. */
	const struct StrobeForSignals {
		explicit StrobeForSignals(hal::Strobe *strobe) { g_strobe = strobe; }
		~StrobeForSignals() { g_strobe = nullptr; }
		StrobeForSignals(const StrobeForSignals &) = delete;
		StrobeForSignals &operator=(const StrobeForSignals &) = delete;
	} strobe_for_signals(daemon.strobe());
	g_startup_step.store("starting the camera, strobe and CAN");
	if (auto s = daemon.start(); !s) {
		ignoreStrayAlarms();
		std::fprintf(stderr, "dockposed: cannot start: %s\n", s.message().c_str());
		daemon.shutdown();
		return 1;
	}
	ignoreStrayAlarms();
	if (options.capture_dir.empty()) {
		const int status = daemon.run(g_stop, options.run_for_s);
		daemon.printSummary(stderr);
		return status;
	}
	return runCapture(options, config, &daemon);
}

/* The daemon itself; main() turns an exception that escapes it into exit 70. */
int run(int argc, char **argv)
{
	Options options;
	if (const int status = parseOptions(argc, argv, &options); status >= 0)
		return status;
	dockpose::firmware::BoardConfig config;
	const dockpose::board::BoardInfo *info = loadBoard(options, &config);
	if (!info)
		return 2;
	if (!options.capture_dir.empty()) {
		if (auto s = dockpose::firmware::prepareCaptureDir(options.capture_dir); !s) {
			std::fprintf(stderr, "dockposed: --capture: %s\n", s.message().c_str());
			return 2;
		}
	}
	return runBoard(options, *info, config);
}

} /* namespace */

int main(int argc, char **argv)
{
	try {
		return run(argc, argv);
	} catch (const std::exception &e) {
		/* The Daemon was destroyed on the way here (its strobe off, its threads joined). */
		std::fprintf(stderr, "dockposed: internal error: %s\n", e.what());
		return kExitInternal;
	}
}

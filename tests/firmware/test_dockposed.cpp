/* SPDX-License-Identifier: MIT */
/*
 * dockposed as outside tools run it: `dockposed --board PATH [--for S] [--can-log FILE]`.
 * The CAN log it writes is decoded by scripts/candecode (python-can + canmatrix
 * through the DBC), an independent reader.
 */
#include <sys/stat.h>
#include <sys/wait.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace {

#ifdef DOCKPOSE_TOOL_EMULATOR
const std::string kEmulator = std::string(DOCKPOSE_TOOL_EMULATOR) + " ";
#else
const std::string kEmulator;
#endif
const std::string kSource = DOCKPOSE_SOURCE_DIR;
const std::string kSimBoard = kSource + "/board/sim/board.json";

struct RunResult {
	int status = -1;
	std::string err;
};

class Dockposed : public ::testing::Test
{
protected:
	void SetUp() override
	{
		char dir_template[] = "/tmp/dockposed-test.XXXXXX";
		ASSERT_NE(mkdtemp(dir_template), nullptr);
		dir_ = dir_template;
	}
	void TearDown() override { std::system(("rm -rf '" + dir_ + "'").c_str()); }

	/* Runs a shell command line with dockposed's stderr captured; returns its exit status. */
	RunResult run(const std::string &args, const std::string &prefix = "")
	{
		const std::string err = dir_ + "/stderr.txt";
		const std::string cmd = prefix + kEmulator + DOCKPOSED + std::string(" ") + args +
					" 2>'" + err + "'";
		RunResult r;
		const int raw = std::system(cmd.c_str());
		r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : 128 + WTERMSIG(raw);
		r.err = slurp(err);
		return r;
	}

	std::string writeFile(const std::string &name, const std::string &text)
	{
		const std::string path = dir_ + "/" + name;
		std::ofstream(path) << text;
		return path;
	}

	static std::string slurp(const std::string &path)
	{
		std::ifstream in(path);
		std::stringstream ss;
		ss << in.rdbuf();
		return ss.str();
	}

	/* scripts/candecode --json over a candump log: one JSON object per report. */
	std::vector<nlohmann::json> decode(const std::string &log)
	{
		const std::string out = dir_ + "/decoded.jsonl";
		const std::string cmd = std::string(DOCKPOSE_PYTHON) + " " + kSource +
					"/scripts/candecode --json --log '" + log + "' >'" + out +
					"' 2>'" + dir_ + "/candecode.err'";
		EXPECT_EQ(std::system(cmd.c_str()), 0) << slurp(dir_ + "/candecode.err");
		std::vector<nlohmann::json> reports;
		std::ifstream in(out);
		for (std::string line; std::getline(in, line);)
			if (!line.empty())
				reports.push_back(nlohmann::json::parse(line));
		return reports;
	}

	std::string dir_;
};

TEST_F(Dockposed, RunsTheSimBoardAndItsCanLogDecodesWithTheDbc)
{
	const std::string log = dir_ + "/can.log";
	const RunResult r = run("--board " + kSimBoard + " --for 3 --can-log '" + log + "'");
	ASSERT_EQ(r.status, 0) << r.err;
	EXPECT_NE(r.err.find("-> TRACKING"), std::string::npos) << r.err;
	EXPECT_NE(r.err.find("valid poses"), std::string::npos) << r.err;

	const auto reports = decode(log);
	ASSERT_GT(reports.size(), 60u) << "3 s at 60 frames/s";
	int valid = 0;
	for (const auto &rep : reports)
		valid += rep.at("valid").get<bool>();
	EXPECT_GE(valid, static_cast<int>(0.9 * static_cast<double>(reports.size())));
	EXPECT_EQ(reports.back().at("state").get<std::string>(), "SHUTDOWN");
	/* The approach comes closer: the first valid pose is farther than the last. */
	double first_z = 0, last_z = 0;
	for (const auto &rep : reports)
		if (rep.at("valid").get<bool>()) {
			if (first_z == 0)
				first_z = rep.at("t_mm")[2].get<double>();
			last_z = rep.at("t_mm")[2].get<double>();
		}
	EXPECT_GT(first_z, last_z + 100.0);
}

TEST_F(Dockposed, SigtermShutsDownCleanlyWithALastStatusFrame)
{
	const std::string log = dir_ + "/can.log";
	const RunResult r = run("--board " + kSimBoard + " --can-log '" + log + "'",
				"timeout --preserve-status -s TERM 2 ");
	ASSERT_EQ(r.status, 0) << r.err;
	const auto reports = decode(log);
	ASSERT_FALSE(reports.empty());
	EXPECT_EQ(reports.back().at("state").get<std::string>(), "SHUTDOWN");
}

/* What a run sent signals did: its status (128 + N when signal N ended it), its stderr, and
 * whether it was still running a second after the last signal. */
struct SignalRun {
	RunResult result;
	bool alive = false;
};

TEST_F(Dockposed, EverySignalThatEndsAProcessIsHandledOrIgnored)
{
	/* dockposed on the sim board, sent each of `signals` once it runs (its CAN log has
	 * frames), then 1 s to react; still running then, it gets SIGTERM. */
	auto runAndSignal = [&](const std::vector<int> &signals) {
		const std::string log = dir_ + "/can.log";
		const std::string alive = dir_ + "/alive";
		std::remove(log.c_str());
		std::remove(alive.c_str());
		std::string kills;
		for (int sig : signals)
			kills += "kill -" + std::to_string(sig) + " $pid; ";
		/* ulimit -c 0: the fatal signals' default dumps core. */
		const std::string script =
			"ulimit -c 0; " + std::string(DOCKPOSED) + " --board " + kSimBoard +
			" --for 30 --can-log '" + log + "' 2>'" + dir_ +
			"/stderr.txt' & pid=$!; i=0; " + "while [ ! -s '" + log +
			"' ] && [ $i -lt 300 ]; do sleep 0.1; i=$((i+1)); done; " + "sleep 0.3; " +
			kills + "sleep 1; kill -0 $pid 2>/dev/null && { : > '" + alive +
			"'; kill -TERM $pid; }; wait $pid";
		const std::string sh = dir_ + "/signal.sh";
		std::ofstream(sh) << script << "\n";
		SignalRun r;
		const int raw = std::system(("sh '" + sh + "'").c_str());
		r.result.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : 128 + WTERMSIG(raw);
		r.result.err = slurp(dir_ + "/stderr.txt");
		r.alive = std::ifstream(alive).good();
		return r;
	};
	auto lastState = [&]() {
		const auto reports = decode(dir_ + "/can.log");
		return reports.empty() ? std::string("(no report)")
				       : reports.back().at("state").get<std::string>();
	};

	/* Ignored: it keeps running through all of them (then SIGTERM ends it cleanly). */
	std::vector<int> ignored = { SIGPIPE,	SIGUSR1, SIGUSR2,   SIGIO,
				     SIGVTALRM, SIGPROF, SIGSTKFLT, SIGALRM };
	for (int sig = SIGRTMIN; sig <= SIGRTMAX; ++sig)
		ignored.push_back(sig);
	const SignalRun quiet = runAndSignal(ignored);
	EXPECT_TRUE(quiet.alive) << quiet.result.err;
	EXPECT_EQ(quiet.result.status, 0) << quiet.result.err;
	EXPECT_EQ(quiet.result.err.find("signal"), std::string::npos) << quiet.result.err;
	EXPECT_EQ(lastState(), "SHUTDOWN");

	/* A stop request: a clean shutdown. */
	const SignalRun power = runAndSignal({ SIGPWR });
	EXPECT_FALSE(power.alive);
	EXPECT_EQ(power.result.status, 0) << power.result.err;
	EXPECT_EQ(lastState(), "SHUTDOWN");

	/* Fatal: LED off, said on stderr, then death by the same signal. */
	for (int sig : { SIGQUIT, SIGTRAP, SIGSYS, SIGXCPU, SIGXFSZ, SIGSEGV }) {
		const SignalRun fatal = runAndSignal({ sig });
		EXPECT_FALSE(fatal.alive) << sig;
		EXPECT_EQ(fatal.result.status, 128 + sig) << sig << ": " << fatal.result.err;
		EXPECT_NE(fatal.result.err.find("dockposed: signal " + std::to_string(sig) +
						" (fatal): LED off\n"),
			  std::string::npos)
			<< sig << ": " << fatal.result.err;
	}
}

TEST_F(Dockposed, BadBoardFilesAreRefusedWithTheirErrors)
{
	const std::string bad =
		writeFile("bad.json", "{ \"board\": \"sim\", \"camera\": { \"exposure_us\": 0 } }");
	RunResult r = run("--board '" + bad + "' --for 1");
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("camera.exposure_us"), std::string::npos) << r.err;

	r = run("--board '" + dir_ + "/missing.json' --for 1");
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("missing.json"), std::string::npos) << r.err;

	r = run("--for 1");
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("--board"), std::string::npos) << r.err;
}

TEST_F(Dockposed, BoardsAndBackendsMustBeBuiltIn)
{
	std::string sim = slurp(kSimBoard);
	const auto with = [&](const std::string &from, const std::string &to) {
		std::string text = sim;
		const auto at = text.find(from);
		EXPECT_NE(at, std::string::npos) << from;
		if (at != std::string::npos)
			text.replace(at, from.size(), to);
		return text;
	};
	/* Copy the sim board's neighbours so relative paths still resolve. */
	std::system(("cp " + kSource + "/board/sim/*.json '" + dir_ + "/'").c_str());

	RunResult r =
		run("--board '" +
		    writeFile("other.json", with("\"board\": \"sim\"", "\"board\": \"toaster\"")) +
		    "'");
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("board \"toaster\" is not built into this dockposed (built: sim"),
		  std::string::npos)
		<< r.err;

	r = run("--board '" + writeFile("cam.json5", with("\"synthetic\"", "\"libcamera\"")) + "'");
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("board sim has no \"libcamera\" backend"), std::string::npos) << r.err;
}

TEST_F(Dockposed, TheReferenceBoardFailsCleanlyWithoutItsHardware)
{
	/* This machine has no GPIO, camera or CAN: dockposed must say which device is missing
	 * and exit, not hang or crash. */
	const std::string board = kSource + "/board/rpi5-imx296/board.json";
	RunResult r = run("--board " + board + " --for 1 --can-log x.log");
	EXPECT_EQ(r.status, 2);
	EXPECT_NE(r.err.find("--can-log only applies"), std::string::npos) << r.err;

	r = run("--board " + board + " --for 1");
	EXPECT_EQ(r.status, 1) << r.err;
	EXPECT_NE(r.err.find("cannot start: strobe: gpio"), std::string::npos) << r.err;
}

TEST_F(Dockposed, AStartUpThatBlocksEndsWithStatus75NamingTheStep)
{
	/* A FIFO nobody reads as the CAN log: opening it blocks for ever (as a device that never
	 * answers or a deadlocked library would). dockposed must give up after --startup-timeout,
	 * LED off, say where it was stuck, and exit 75 for systemd to restart it. */
	const std::string fifo = dir_ + "/can.fifo";
	ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
	const auto start = std::chrono::steady_clock::now();
	const RunResult r = run("--board " + kSimBoard +
				" --for 30 --startup-timeout 2 --can-log '" + fifo + "'");
	const double took_s =
		std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
	EXPECT_EQ(r.status, 75) << r.err;
	EXPECT_NE(r.err.find("start-up did not finish within 2 s"), std::string::npos) << r.err;
	EXPECT_NE(r.err.find("stuck starting the camera, strobe and CAN"), std::string::npos)
		<< r.err;
	EXPECT_GE(took_s, 1.9);
	EXPECT_LT(took_s, 25.0); /* (a hang guard, not a timing check: --for is 30 s) */

	/* Under systemd, dockposed's own limit comes first: its default is below the unit's
	 * TimeoutStartSec, so the journal says what was stuck before systemd kills it. */
	const std::string help = dir_ + "/help.txt";
	ASSERT_EQ(std::system(
			  (kEmulator + DOCKPOSED + std::string(" --help >'") + help + "'").c_str()),
		  0);
	const std::string help_text = slurp(help);
	const std::size_t at = help_text.find("--startup-timeout");
	ASSERT_NE(at, std::string::npos) << help_text;
	/* "--startup-timeout INT:INT in [1 - 600]=20" */
	const std::size_t value = help_text.find("]=", at);
	ASSERT_NE(value, std::string::npos) << help_text;
	const int default_s = std::atoi(help_text.c_str() + value + 2);
	const std::string unit = slurp(kSource + "/firmware/packaging/dockposed.service");
	const std::size_t key = unit.find("\nTimeoutStartSec=");
	ASSERT_NE(key, std::string::npos);
	const int systemd_s = std::atoi(unit.c_str() + key + 17);
	EXPECT_GE(default_s, 10) << help_text;
	EXPECT_LT(default_s, systemd_s)
		<< "dockposed --startup-timeout default vs the unit's TimeoutStartSec";

	/* The limit is checked: 0 and non-numbers are refused. */
	EXPECT_EQ(run("--board " + kSimBoard + " --startup-timeout 0").status, 2);
	EXPECT_EQ(run("--board " + kSimBoard + " --startup-timeout soon").status, 2);
}

} /* namespace */

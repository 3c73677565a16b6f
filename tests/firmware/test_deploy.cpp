/* SPDX-License-Identifier: MIT */
/*
 * scripts/deploy: the commands it prints and runs, in order, with the host, port and identity
 * applied, and its refusals (no --host, unknown board, missing or wrong-architecture package,
 * wrong board architecture or OS, a service that does not come up).
 *
 * No cross build and no board: the packages are tiny fakes made with dpkg-deb --build, and ssh,
 * scp and cmake are fake programs first on PATH that log their arguments and answer like a board
 * (uname -m, /etc/os-release, systemctl is-active) as the FAKE_* variables say.
 */

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

struct ShellResult {
	int status = -1; /* exit status, or -1 when the command did not exit normally */
	std::string output; /* stdout and stderr, interleaved */
};

std::string shellQuote(const std::string &s)
{
	std::string out = "'";
	for (char c : s) {
		if (c == '\'')
			out += "'\\''";
		else
			out += c;
	}
	return out + "'";
}

ShellResult runShell(const std::string &command)
{
	ShellResult run;
	FILE *pipe = popen((command + " 2>&1").c_str(), "r");
	if (!pipe) {
		run.output = "popen failed";
		return run;
	}
	char buffer[4096];
	size_t n;
	while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0)
		run.output.append(buffer, n);
	int status = pclose(pipe);
	run.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
	return run;
}

std::vector<std::string> lines(const std::string &text)
{
	std::vector<std::string> out;
	std::istringstream in(text);
	std::string line;
	while (std::getline(in, line))
		out.push_back(line);
	return out;
}

/* The "+ " lines of the output: the commands deploy prints. */
std::vector<std::string> commandLines(const std::string &output)
{
	std::vector<std::string> out;
	for (const std::string &line : lines(output)) {
		if (line.rfind("+ ", 0) == 0)
			out.push_back(line);
	}
	return out;
}

/* Index of the first line at or after `from` that contains every one of `parts`, or -1. */
int findLine(const std::vector<std::string> &text, std::initializer_list<std::string> parts,
	     int from = 0)
{
	for (size_t i = static_cast<size_t>(from); i < text.size(); i++) {
		bool all = true;
		for (const std::string &part : parts)
			all = all && text[i].find(part) != std::string::npos;
		if (all)
			return static_cast<int>(i);
	}
	return -1;
}

void writeFile(const fs::path &path, const std::string &text, bool executable = false)
{
	fs::create_directories(path.parent_path());
	std::ofstream(path) << text;
	if (executable)
		fs::permissions(path, fs::perms::owner_all | fs::perms::group_read |
					      fs::perms::group_exec | fs::perms::others_read |
					      fs::perms::others_exec);
}

class Deploy : public ::testing::Test
{
protected:
	void SetUp() override
	{
		std::string pattern =
			(fs::temp_directory_path() / "dockpose-deploy-XXXXXX").string();
		ASSERT_NE(mkdtemp(pattern.data()), nullptr);
		tmp_ = pattern;
		log_ = tmp_ / "remote.log";
		key_ = tmp_ / "id_test";
		writeFile(key_, "not a real key\n");

		/* ssh answers the probe like a board and runs the wait loop; everything is logged. */
		writeFile(tmp_ / "bin/ssh", R"(#!/bin/bash
printf 'ssh %s\n' "$*" >> "$FAKE_LOG"
last="${*: -1}"
case "$last" in
*"uname -m"*)
	printf '%s\n%s\n%s\n%s\n' "${FAKE_ARCH:-aarch64}" "${FAKE_OS_ID:-debian}" "${FAKE_OS_VERSION:-12}" \
		"${FAKE_PRETTY:-Debian GNU/Linux 12 (bookworm)}" ;;
*"is-active"*)
	# The wait loop runs here, with a systemctl that reports FAKE_STATES one per call.
	PATH="$FAKE_REMOTE_BIN:$PATH" bash -c "$last" ;;
esac
)",
			  true);
		/* "Board" programs for the wait loop: systemctl is-active answers the next word of
		 * FAKE_STATES (the last one from then on); sleep returns at once. */
		writeFile(tmp_ / "remote/systemctl", R"(#!/bin/bash
n=$(cat "$FAKE_LOG.calls" 2>/dev/null || echo 0)
echo $((n + 1)) > "$FAKE_LOG.calls"
read -r -a states <<< "${FAKE_STATES:-active}"
i=$(( n < ${#states[@]} ? n : ${#states[@]} - 1 ))
echo "${states[$i]}"
[ "${states[$i]}" = active ]
)",
			  true);
		writeFile(tmp_ / "remote/sleep", "#!/bin/bash\nexit 0\n", true);
		writeFile(tmp_ / "bin/scp",
			  "#!/bin/bash\nprintf 'scp %s\\n' \"$*\" >> \"$FAKE_LOG\"\n", true);
		writeFile(tmp_ / "bin/cmake",
			  "#!/bin/bash\nprintf 'cmake %s\\n' \"$*\" >> \"$FAKE_LOG\"\nexit 1\n",
			  true);
	}

	void TearDown() override
	{
		std::error_code ec;
		fs::remove_all(tmp_, ec);
	}

	/* A minimal dockpose package for `arch` holding board.json of each of `boards`. */
	fs::path makeDeb(const std::string &arch, const std::vector<std::string> &boards)
	{
		fs::path root = tmp_ / ("root-" + arch);
		writeFile(
			root / "DEBIAN/control",
			"Package: dockpose\nVersion: 0.1.0\nArchitecture: " + arch +
				"\nMaintainer: test <test@example.org>\nDescription: fake dockpose package\n");
		for (const std::string &board : boards)
			writeFile(root / "etc/dockpose/boards" / board / "board.json", "{}\n");
		fs::path deb = tmp_ / ("dockpose_0.1.0_" + arch + ".deb");
		ShellResult built =
			runShell("dpkg-deb --build --root-owner-group " +
				 shellQuote(root.string()) + " " + shellQuote(deb.string()));
		EXPECT_EQ(built.status, 0) << built.output;
		return deb;
	}

	/* Runs scripts/deploy with the fake programs first on PATH and `env` (VAR=value words). */
	ShellResult deploy(const std::string &args, const std::string &env = "")
	{
		const char *path = std::getenv("PATH");
		std::string command =
			"env " +
			shellQuote("PATH=" + (tmp_ / "bin").string() + ":" +
				   (path ? path : "/usr/bin:/bin")) +
			" " + shellQuote("FAKE_LOG=" + log_.string()) + " " +
			shellQuote("FAKE_REMOTE_BIN=" + (tmp_ / "remote").string()) + " " + env +
			" bash " +
			shellQuote(std::string(DOCKPOSE_SOURCE_DIR) + "/scripts/deploy") + " " +
			args + " </dev/null";
		return runShell(command);
	}

	/* What the fake programs were asked to do, one line per call. */
	std::vector<std::string> remoteLog() const
	{
		std::ifstream in(log_);
		std::stringstream text;
		text << in.rdbuf();
		return lines(text.str());
	}

	fs::path tmp_;
	fs::path log_;
	fs::path key_;
};

TEST_F(Deploy, DryRunPrintsEveryStepInOrderWithHostPortAndIdentity)
{
	fs::path deb = makeDeb("arm64", { "sim", "rpi5-imx296" });
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()) +
				 " --board sim --port 2222 --identity " +
				 shellQuote(key_.string()) + " --dry-run");
	ASSERT_EQ(run.status, 0) << run.output;

	std::vector<std::string> cmds = commandLines(run.output);
	const std::string key = key_.string();
	const std::string ssh = "ssh -o ConnectTimeout=10 -p 2222 -i " + key + " pi@cam7";
	const std::string remote_deb = "/tmp/dockpose_0.1.0_arm64.deb";

	int probe = findLine(cmds, { ssh, "uname -m", "/etc/os-release" });
	int copy = findLine(cmds, { "scp -o ConnectTimeout=10 -P 2222 -i " + key + " " +
				    deb.string() + " pi@cam7:" + remote_deb });
	int update = findLine(cmds, { ssh, "sudo apt-get update" });
	int install = findLine(cmds, { ssh, "apt-get install -y", "--force-confold", remote_deb });
	int board = findLine(cmds, { ssh, "DOCKPOSE_BOARD=/etc/dockpose/boards/sim/board.json",
				     "/etc/default/dockposed" });
	int start = findLine(cmds, { ssh, "systemctl enable dockposed.service",
				     "systemctl restart dockposed.service" });
	int active = findLine(cmds, { ssh, "systemctl is-active dockposed.service" });
	int journal = findLine(cmds, { ssh, "journalctl -u dockposed.service" });
	EXPECT_EQ(probe, 0) << run.output;
	EXPECT_GT(copy, probe) << run.output;
	EXPECT_GT(update, copy) << run.output;
	EXPECT_GT(install, update) << run.output;
	EXPECT_GT(board, install) << run.output;
	EXPECT_GT(start, board) << run.output;
	EXPECT_GT(active, start) << run.output;
	EXPECT_GT(journal, active) << run.output;

	/* Every remote command goes to this host with this port and key; nothing is built. */
	for (const std::string &cmd : cmds) {
		if (cmd.rfind("+ ssh ", 0) == 0) {
			EXPECT_THAT(cmd, HasSubstr(ssh));
		}
		EXPECT_THAT(cmd, Not(HasSubstr("cmake")));
	}
	EXPECT_THAT(run.output, HasSubstr("dockpose-candecode --interface can0"));
	EXPECT_TRUE(remoteLog().empty())
		<< "a dry run ran: " << ::testing::PrintToString(remoteLog());
}

TEST_F(Deploy, DryRunWithoutPackageShowsTheCrossBuildAndBuildsNothing)
{
	ShellResult run = deploy("--host pi@cam7 --board rpi5-imx296 --dry-run");
	ASSERT_EQ(run.status, 0) << run.output;
	std::vector<std::string> cmds = commandLines(run.output);
	int configure = findLine(cmds, { "+ cmake --preset aarch64" });
	int build = findLine(cmds, { "+ cmake --build --preset aarch64 --target package" });
	int copy = findLine(cmds, { "+ scp " });
	ASSERT_GE(configure, 0) << run.output;
	EXPECT_GT(build, configure) << run.output;
	ASSERT_GT(copy, build) << run.output;
	EXPECT_TRUE(std::regex_search(
		cmds[static_cast<size_t>(copy)],
		std::regex(
			" /\\S*/build/aarch64/dockpose_[0-9]+\\.[0-9]+\\.[0-9]+_arm64\\.deb pi@cam7:/tmp/")))
		<< cmds[static_cast<size_t>(copy)];
	/* No port or identity given: ssh and scp get only the host. */
	for (const std::string &cmd : cmds) {
		if (cmd.rfind("+ ssh ", 0) == 0) {
			EXPECT_EQ(cmd.rfind("+ ssh -o ConnectTimeout=10 pi@cam7 ", 0), 0u) << cmd;
		}
	}
	EXPECT_EQ(cmds[static_cast<size_t>(copy)].rfind("+ scp -o ConnectTimeout=10 /", 0), 0u);
	EXPECT_TRUE(remoteLog().empty()) << ::testing::PrintToString(remoteLog());
}

TEST_F(Deploy, RunsTheStepsAgainstABoard)
{
	fs::path deb = makeDeb("arm64", { "sim", "rpi5-imx296" });
	ShellResult run = deploy("--host root@10.0.0.5 --deb " + shellQuote(deb.string()) +
					 " --board rpi5-imx296 --timeout 5",
				 shellQuote("FAKE_STATES=activating activating active"));
	ASSERT_EQ(run.status, 0) << run.output;
	EXPECT_THAT(run.output,
		    HasSubstr("dockposed is running on root@10.0.0.5 with board rpi5-imx296"));

	std::vector<std::string> log = remoteLog();
	int probe = findLine(log, { "ssh ", "root@10.0.0.5", "uname -m" });
	int copy = findLine(log, { "scp ", deb.string(),
				   "root@10.0.0.5:/tmp/dockpose_0.1.0_arm64.deb" });
	int install =
		findLine(log, { "ssh ", "apt-get install -y", "/tmp/dockpose_0.1.0_arm64.deb" });
	int board = findLine(log, { "ssh ",
				    "DOCKPOSE_BOARD=/etc/dockpose/boards/rpi5-imx296/board.json" });
	int start = findLine(log, { "ssh ", "systemctl restart dockposed.service" });
	int active = findLine(log, { "ssh ", "systemctl is-active dockposed.service", "-lt 5" });
	int journal = findLine(log, { "ssh ", "journalctl -u dockposed.service" });
	EXPECT_EQ(probe, 0) << ::testing::PrintToString(log);
	EXPECT_GT(copy, probe);
	EXPECT_GT(install, copy);
	EXPECT_GT(board, install);
	EXPECT_GT(start, board);
	EXPECT_GT(active, start);
	EXPECT_GT(journal, active);
	EXPECT_EQ(findLine(log, { "cmake" }), -1);
}

TEST_F(Deploy, ReportsAServiceThatDoesNotComeUpWithItsJournal)
{
	fs::path deb = makeDeb("arm64", { "rpi5-imx296" });
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()),
				 shellQuote("FAKE_STATES=activating failed"));
	EXPECT_NE(run.status, 0) << run.output;
	EXPECT_THAT(run.output,
		    HasSubstr("dockposed.service on pi@cam7 is not active (state: failed)"));
	EXPECT_THAT(run.output, Not(HasSubstr("dockposed is running")));
	EXPECT_GE(findLine(remoteLog(), { "journalctl -u dockposed.service" }), 0);
}

TEST_F(Deploy, ADaemonThatStopsRightAfterStartingIsNotActive)
{
	/* Up for two seconds, then killed (the watchdog) and restarting: not good enough. */
	fs::path deb = makeDeb("arm64", { "rpi5-imx296" });
	ShellResult run =
		deploy("--host pi@cam7 --deb " + shellQuote(deb.string()) + " --timeout 6",
		       shellQuote("FAKE_STATES=active active activating"));
	EXPECT_NE(run.status, 0) << run.output;
	EXPECT_THAT(run.output, HasSubstr("is not active (state: activating)"));

	/* Active for three checks in a row is. */
	fs::remove(log_.string() + ".calls");
	ShellResult ok = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()) + " --timeout 6",
				shellQuote("FAKE_STATES=active activating active active active"));
	EXPECT_EQ(ok.status, 0) << ok.output;
}

TEST_F(Deploy, RefusesABoardThatIsNotAarch64)
{
	fs::path deb = makeDeb("arm64", { "sim", "rpi5-imx296" });
	ShellResult run =
		deploy("--host pi@cam7 --deb " + shellQuote(deb.string()), "FAKE_ARCH=x86_64");
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr("wrong architecture: pi@cam7 is 'x86_64'"));
	std::vector<std::string> log = remoteLog();
	EXPECT_EQ(log.size(), 1u) << "only the probe may run: " << ::testing::PrintToString(log);
}

TEST_F(Deploy, RefusesABoardThatIsNotDebian12)
{
	fs::path deb = makeDeb("arm64", { "sim", "rpi5-imx296" });
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()),
				 "FAKE_OS_ID=debian FAKE_OS_VERSION=11 " +
					 shellQuote("FAKE_PRETTY=Debian GNU/Linux 11 (bullseye)"));
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr("runs 'Debian GNU/Linux 11 (bullseye)'"));
	EXPECT_EQ(findLine(remoteLog(), { "scp " }), -1);

	/* Raspberry Pi OS 12 (32-bit: ID=raspbian) is accepted. */
	ShellResult pi_os =
		deploy("--host pi@cam7 --deb " + shellQuote(deb.string()) + " --timeout 3",
		       "FAKE_OS_ID=raspbian FAKE_OS_VERSION=12");
	EXPECT_EQ(pi_os.status, 0) << pi_os.output;
}

TEST_F(Deploy, RequiresHost)
{
	fs::path deb = makeDeb("arm64", { "sim" });
	ShellResult run = deploy("--deb " + shellQuote(deb.string()) + " --board sim --dry-run");
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr("--host USER@BOARD is required"));
	EXPECT_TRUE(commandLines(run.output).empty()) << run.output;
}

TEST_F(Deploy, RefusesAnUnknownBoardAndListsTheBoards)
{
	fs::path deb = makeDeb("arm64", { "sim" });
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()) +
				 " --board rpi9-nothing --dry-run");
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr("unknown board 'rpi9-nothing'"));
	/* The list comes from board/: both boards of the tree, as words. */
	EXPECT_TRUE(std::regex_search(run.output, std::regex("the boards are: .*\\bsim\\b")))
		<< run.output;
	EXPECT_TRUE(
		std::regex_search(run.output, std::regex("the boards are: .*\\brpi5-imx296\\b")))
		<< run.output;
	EXPECT_TRUE(commandLines(run.output).empty()) << run.output;
}

TEST_F(Deploy, RefusesAMissingPackage)
{
	std::string missing = (tmp_ / "dockpose_9.9.9_arm64.deb").string();
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(missing) + " --dry-run");
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr(".deb not found: " + missing));
	EXPECT_TRUE(commandLines(run.output).empty()) << run.output;
}

TEST_F(Deploy, RefusesAnAmd64Package)
{
	fs::path deb = makeDeb("amd64", { "sim", "rpi5-imx296" });
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()));
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr("wrong architecture"));
	EXPECT_THAT(run.output, HasSubstr("'amd64'"));
	EXPECT_THAT(run.output, HasSubstr("needs arm64"));
	EXPECT_TRUE(remoteLog().empty()) << ::testing::PrintToString(remoteLog());
}

TEST_F(Deploy, RefusesAPackageWithoutTheBoard)
{
	fs::path deb = makeDeb("arm64", { "sim" });
	ShellResult run = deploy("--host pi@cam7 --deb " + shellQuote(deb.string()) +
				 " --board rpi5-imx296 --dry-run");
	EXPECT_NE(run.status, 0);
	EXPECT_THAT(run.output, HasSubstr("has no board 'rpi5-imx296'"));
	EXPECT_TRUE(commandLines(run.output).empty()) << run.output;
}

} /* namespace */

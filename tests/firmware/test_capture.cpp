/* SPDX-License-Identifier: MIT */
/*
 * `dockposed --board B --capture DIR --frames N [--every K]` as outside tools run it: the
 * frames are PGMs of the camera's size, as many as asked, and the run ends as a clean
 * shutdown does (the last CAN status frame says SHUTDOWN with the strobe off).
 */
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "algo/io/model_json.h"
#include "algo/io/pgm.h"

namespace {

#ifdef DOCKPOSE_TOOL_EMULATOR
const std::string kEmulator = std::string(DOCKPOSE_TOOL_EMULATOR) + " ";
#else
const std::string kEmulator;
#endif
const std::string kSource = DOCKPOSE_SOURCE_DIR;
const std::string kSimBoard = kSource + "/board/sim/board.json";

std::string slurp(const std::string &path)
{
	std::ifstream in(path);
	std::stringstream ss;
	ss << in.rdbuf();
	return ss.str();
}

class Capture : public ::testing::Test
{
protected:
	void SetUp() override
	{
		char dir_template[] = "/tmp/dockposed-capture.XXXXXX";
		ASSERT_NE(mkdtemp(dir_template), nullptr);
		dir_ = dir_template;
	}
	void TearDown() override { std::filesystem::remove_all(dir_); }

	int run(const std::string &args, std::string *err)
	{
		const std::string err_path = dir_ + "/stderr.txt";
		const std::string cmd =
			kEmulator + DOCKPOSED + std::string(" ") + args + " 2>'" + err_path + "'";
		const int raw = std::system(cmd.c_str());
		*err = slurp(err_path);
		return WIFEXITED(raw) ? WEXITSTATUS(raw) : 128 + WTERMSIG(raw);
	}

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

TEST_F(Capture, WritesTheFramesAskedForAsPgmsOfTheCamerasSizeThenShutsDownLedOff)
{
	const std::string frames = dir_ + "/frames/nested"; /* made with its parent */
	const std::string log = dir_ + "/can.log";
	std::string err;
	const int status = run("--board " + kSimBoard + " --capture '" + frames +
				       "' --frames 7 --every 2 --can-log '" + log + "'",
			       &err);
	ASSERT_EQ(status, 0) << err;
	EXPECT_NE(err.find("--capture: 7 frames written"), std::string::npos) << err;

	/* The camera's size, from the board's camera file. */
	auto camera = dockpose::loadCameraIntrinsics(kSource + "/board/sim/camera.json");
	ASSERT_TRUE(camera.isOk()) << camera.status().message();

	int files = 0;
	for (const auto &entry : std::filesystem::directory_iterator(frames)) {
		++files;
		EXPECT_EQ(entry.path().extension(), ".pgm") << entry.path();
	}
	EXPECT_EQ(files, 7);
	for (int i = 0; i < 7; ++i) {
		char name[32];
		std::snprintf(name, sizeof(name), "/frame-%06d.pgm", i);
		auto image = dockpose::readPgm(frames + name);
		ASSERT_TRUE(image.isOk()) << image.status().message();
		EXPECT_EQ(image->width(), camera->width);
		EXPECT_EQ(image->height(), camera->height);
		/* The sim's lit wedge: LEDs saturate well above its dark background. */
		int max_value = 0;
		const dockpose::ImageView view = image->view();
		for (int y = 0; y < view.height; ++y)
			for (int x = 0; x < view.width; ++x)
				max_value = std::max<int>(max_value, view.at(x, y));
		EXPECT_GT(max_value, 128) << name << ": no lit LED in the frame";
	}

	/* The run ended as a clean shutdown: last status frame SHUTDOWN, strobe off. */
	const auto reports = decode(log);
	ASSERT_FALSE(reports.empty());
	EXPECT_EQ(reports.back().at("state").get<std::string>(), "SHUTDOWN");
	EXPECT_EQ(reports.back().at("strobe").get<std::string>(), "OFF");
}

TEST_F(Capture, ADirectoryThatCannotBeMadeIsABadCommandLine)
{
	/* A regular file where a parent directory should be. */
	std::ofstream(dir_ + "/file") << "x";
	std::string err;
	EXPECT_EQ(run("--board " + kSimBoard + " --capture '" + dir_ + "/file/frames' --frames 3",
		      &err),
		  2);
	EXPECT_NE(err.find("cannot create the capture directory " + dir_ + "/file/frames"),
		  std::string::npos)
		<< err;

	/* A directory without write permission (root writes anyway: then it is not a test). */
	if (geteuid() != 0) {
		const std::string locked = dir_ + "/locked";
		ASSERT_EQ(mkdir(locked.c_str(), 0500), 0);
		EXPECT_EQ(run("--board " + kSimBoard + " --capture '" + locked + "' --frames 3",
			      &err),
			  2);
		EXPECT_NE(err.find("cannot write in the capture directory " + locked),
			  std::string::npos)
			<< err;
	}
}

TEST_F(Capture, FramesWithoutCaptureAndCaptureWithoutFramesAreRefused)
{
	std::string err;
	EXPECT_EQ(run("--board " + kSimBoard + " --capture '" + dir_ + "/f'", &err), 2);
	EXPECT_NE(err.find("--capture requires --frames"), std::string::npos) << err;
	EXPECT_EQ(run("--board " + kSimBoard + " --frames 3", &err), 2);
	EXPECT_NE(err.find("--frames requires --capture"), std::string::npos) << err;
}

TEST_F(Capture, ARunThatEndsBeforeTheFramesAreWrittenFails)
{
	/* The sim's synthetic approach lasts 5 s at 60 frames/s and does not loop. */
	std::string err;
	EXPECT_EQ(run("--board " + kSimBoard + " --capture '" + dir_ + "/f' --frames 100 --for 0.5",
		      &err),
		  1);
	EXPECT_NE(err.find("of 100 frames written"), std::string::npos) << err;
}

} /* namespace */

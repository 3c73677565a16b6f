/* SPDX-License-Identifier: MIT */
/*
 * GpiodStrobe error paths. The build machine has no GPIO at all, so the
 * messages must say so; where GPIO chips exist (a VM with gpio-sim), the same
 * tests check that the message lists them instead. The real switching is
 * exercised on gpio-sim elsewhere.
 */
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hal/gpiod/gpiod_strobe.h"

using namespace dockpose::hal;
using ::testing::HasSubstr;
using ::testing::Not;

namespace {

bool haveGpioChips()
{
	std::error_code ec;
	for (std::filesystem::directory_iterator it("/dev", ec), end; !ec && it != end;
	     it.increment(ec))
		if (it->path().filename().string().rfind("gpiochip", 0) == 0)
			return true;
	return false;
}

/* The tail every "chip not found" message carries: the list, or why there is none. */
void expectFoundList(const std::string &message)
{
	if (haveGpioChips()) {
		EXPECT_THAT(message, HasSubstr("(found: gpiochip"));
	} else {
		EXPECT_THAT(message, HasSubstr("none found"));
		EXPECT_THAT(message, HasSubstr("CONFIG_GPIO_CDEV"));
	}
}

std::string tempPath(const char *tag)
{
	return (std::filesystem::temp_directory_path() /
		("dockpose_gpiod_" + std::string(tag) + "_" + std::to_string(getpid())))
		.string();
}

} /* namespace */

TEST(GpiodStrobe, UnknownChipNameNamesItAndWhatExists)
{
	GpiodStrobe strobe("gpiochip97", 17, false);
	Status status = strobe.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(),
		    HasSubstr("gpio: no GPIO chip named or labelled \"gpiochip97\""));
	expectFoundList(status.message());
	EXPECT_FALSE(strobe.isOn());
}

TEST(GpiodStrobe, UnknownChipNumber)
{
	GpiodStrobe strobe("97", 3, false);
	Status status = strobe.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("\"97\""));
	expectFoundList(status.message());
}

TEST(GpiodStrobe, UnknownChipPath)
{
	GpiodStrobe strobe("/dev/gpiochip97", 17, false);
	Status status = strobe.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("gpio: no GPIO chip at /dev/gpiochip97"));
	expectFoundList(status.message());

	GpiodStrobe bogus("/nonexistent/dir/gpiochip0", 0, false);
	status = bogus.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("/nonexistent/dir/gpiochip0"));
	expectFoundList(status.message());
}

TEST(GpiodStrobe, UnknownChipLabel)
{
	GpiodStrobe strobe("pinctrl-nonexistent", 17, true);
	Status status = strobe.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("\"pinctrl-nonexistent\""));
	expectFoundList(status.message());
}

TEST(GpiodStrobe, PathThatIsNotAGpioChip)
{
	for (const char *path : { "/dev/null", "/tmp" }) {
		GpiodStrobe strobe(path, 0, false);
		Status status = strobe.open();
		ASSERT_FALSE(status) << path;
		EXPECT_THAT(status.message(), HasSubstr(std::string("gpio: ") + path +
							" is not a GPIO character device"));
	}

	std::string file = tempPath("file");
	std::ofstream(file) << "not a chip\n";
	GpiodStrobe strobe(file, 0, false);
	Status status = strobe.open();
	std::filesystem::remove(file);
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr(file + " is not a GPIO character device"));
}

TEST(GpiodStrobe, PermissionDeniedNamesThePath)
{
	std::string file = tempPath("noaccess");
	std::ofstream(file) << "x\n";
	ASSERT_EQ(chmod(file.c_str(), 0), 0);

	/* Root opens anything: open as "nobody" in a child process then. */
	int fds[2];
	ASSERT_EQ(pipe(fds), 0);
	pid_t pid = fork();
	ASSERT_GE(pid, 0);
	if (pid == 0) {
		::close(fds[0]);
		if (geteuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0))
			_exit(2);
		GpiodStrobe strobe(file, 0, false);
		Status status = strobe.open();
		std::string message = status ? "opened" : status.message();
		ssize_t n = write(fds[1], message.data(), message.size());
		_exit(n == static_cast<ssize_t>(message.size()) ? 0 : 3);
	}
	::close(fds[1]);
	std::string message;
	char buffer[512];
	ssize_t n;
	while ((n = read(fds[0], buffer, sizeof(buffer))) > 0)
		message.append(buffer, static_cast<std::size_t>(n));
	::close(fds[0]);
	int wstatus = 0;
	waitpid(pid, &wstatus, 0);
	std::filesystem::remove(file);
	ASSERT_TRUE(WIFEXITED(wstatus));
	ASSERT_EQ(WEXITSTATUS(wstatus), 0);
	EXPECT_THAT(message, HasSubstr("gpio: permission denied opening " + file));
}

TEST(GpiodStrobe, RejectsNegativeLineAndEmptyChip)
{
	/* The line is checked first, so the message is about the line whatever the chips. */
	GpiodStrobe strobe("gpiochip0", -1, false);
	Status status = strobe.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("gpio: line -1 is not a valid line offset"));
	EXPECT_THAT(status.message(), Not(HasSubstr("chip")));

	GpiodStrobe empty("", 4, false);
	status = empty.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("no GPIO chip given"));

	GpiodStrobe no_consumer("gpiochip0", 4, false, "");
	status = no_consumer.open();
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("consumer"));
}

TEST(GpiodStrobe, UnopenedStrobeIsSafe)
{
	GpiodStrobe strobe("gpiochip97", 17, true);
	EXPECT_EQ(strobe.name(), "gpio \"gpiochip97\" line 17 (active-low)");

	Status status = strobe.set(true);
	ASSERT_FALSE(status);
	EXPECT_THAT(status.message(), HasSubstr("gpio \"gpiochip97\" line 17"));
	EXPECT_THAT(status.message(), HasSubstr("not open"));
	EXPECT_FALSE(strobe.isOn());

	/* forceOff keeps errno (it runs in signal handlers) and does nothing here. */
	errno = EINTR;
	strobe.forceOff();
	EXPECT_EQ(errno, EINTR);
	EXPECT_FALSE(strobe.isOn());

	strobe.close();
	strobe.close();
	EXPECT_FALSE(strobe.isOn());

	/* A failed open leaves it closed and reusable. */
	EXPECT_FALSE(strobe.open());
	strobe.forceOff();
	strobe.close();
	EXPECT_EQ(strobe.name(), "gpio \"gpiochip97\" line 17 (active-low)");

	GpiodStrobe plain("/dev/gpiochip0", 3, false);
	EXPECT_EQ(plain.name(), "gpio \"/dev/gpiochip0\" line 3");
}

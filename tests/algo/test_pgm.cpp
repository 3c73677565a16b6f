/* SPDX-License-Identifier: MIT */
/*
 * PGM frames read in place (algo/io/pgm.h): viewPgm().message() shows the pixels where
 * they are and refuses every bad file with parsePgm()'s own message;
 * PgmReader reads file after file into one buffer, with readPgm()'s messages,
 * from regular files and pipes, and allocates nothing once its buffer is big
 * enough.
 */
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "algo/io/pgm.h"

/* The counting hooks interpose malloc, which the sanitizers' allocator does not allow. */
#include "../common/sanitizer.h"
#if !DOCKPOSE_SANITIZED
#define DOCKPOSE_COUNT_ALLOCATIONS 1
#include "../common/counting_allocator.h"
#endif

using namespace dockpose;

namespace {

class PgmFiles : public ::testing::Test
{
protected:
	void SetUp() override
	{
		const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
		dir_ = std::filesystem::temp_directory_path() /
		       ("dockpose_test_pgm_" + std::to_string(static_cast<long>(::getpid())) + "_" +
			info->name());
		std::filesystem::remove_all(dir_);
		std::filesystem::create_directories(dir_);
	}
	void TearDown() override { std::filesystem::remove_all(dir_); }

	std::string write(const std::string &name, const std::string &bytes) const
	{
		const std::string path = (dir_ / name).string();
		std::ofstream out(path, std::ios::binary | std::ios::trunc);
		out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
		return path;
	}

	std::filesystem::path dir_;
};

Image pattern(int width, int height, int seed)
{
	Image img(width, height);
	for (int y = 0; y < height; ++y)
		for (int x = 0; x < width; ++x)
			img.at(x, y) = static_cast<std::uint8_t>(
				(x * 7 + y * 13 + seed * 31 + x * y) & 0xff);
	return img;
}

void expectSame(const ImageView &got, const Image &want)
{
	ASSERT_EQ(got.width, want.width());
	ASSERT_EQ(got.height, want.height());
	ASSERT_EQ(got.stride_bytes, want.width());
	for (int y = 0; y < want.height(); ++y)
		for (int x = 0; x < want.width(); ++x)
			ASSERT_EQ(got.at(x, y), want.at(x, y)) << x << "," << y;
}

/* The bad inputs of every kind the header parser refuses. */
const std::vector<std::string> &badFiles()
{
	static const std::vector<std::string> files = {
		"",
		"\x89PNG\r\n",
		"P2\n2 2\n255\n1 2 3 4\n",
		"P6\n2 2\n255\n" + std::string(12, 'x'),
		"P5\n2 2\n65535\n" + std::string(8, 'x'),
		"P5\n2 2\n0\n" + std::string(4, 'x'),
		"P5\n4 4\n255\n" + std::string(10, 'x'),
		"P5\n4 4\n255",
		"P5\n4",
		"P5\n4 x\n255\n",
		"P5\n4x 4\n255\n",
		"P54 4 255\n" + std::string(16, 'x'),
		"P5\n0 4\n255\n",
		"P5\n100000 100000\n255\n",
		"P5\n99999999999999999999 2\n255\n",
		"P5 # comment runs to the end\n",
	};
	return files;
}

} /* namespace */

TEST(PgmView, PixelsStayWhereTheyAre)
{
	std::string bytes = "P5 # magic\r\n3\t# width\n#whole line\n 2\n200";
	bytes += '\n';
	const std::size_t offset = bytes.size();
	const unsigned char pixels[6] = { 0, 10, 200, 7, 13, 255 };
	bytes.append(reinterpret_cast<const char *>(pixels), 6);
	bytes += "trailing bytes";

	ImageView view;
	ASSERT_EQ(viewPgm(bytes, "x.pgm", &view).message(), "");
	EXPECT_EQ(view.data, reinterpret_cast<const std::uint8_t *>(bytes.data()) + offset);
	EXPECT_EQ(view.width, 3);
	EXPECT_EQ(view.height, 2);
	EXPECT_EQ(view.stride_bytes, 3);
	EXPECT_EQ(view.at(2, 0), 200);
	EXPECT_EQ(view.at(2, 1), 255);
}

TEST(PgmView, RefusesWhatParsePgmRefusesWithTheSameMessage)
{
	for (const std::string &bytes : badFiles()) {
		SCOPED_TRACE(bytes.substr(0, 24));
		ImageView view;
		const std::string err = viewPgm(bytes, "f.pgm", &view).message();
		EXPECT_EQ(err.rfind("f.pgm: ", 0), 0u) << err;
		EXPECT_EQ(err, parsePgm(bytes, "f.pgm").message());
		EXPECT_EQ(view.data, nullptr) << "a refused file leaves the view alone";
	}
}

TEST_F(PgmFiles, ReaderReadsFileAfterFileIntoOneBuffer)
{
	PgmReader reader(64, 48);
	EXPECT_GE(reader.capacity(), 64u * 48u);
	std::vector<Image> images;
	std::vector<std::string> paths;
	for (int i = 0; i < 5; ++i) {
		images.push_back(pattern(i == 3 ? 30 : 64, i == 3 ? 20 : 48, i));
		paths.push_back((dir_ / ("f" + std::to_string(i) + ".pgm")).string());
		ASSERT_EQ(writePgm(paths.back(), images.back().view()).message(), "");
	}
	const std::uint8_t *first = nullptr;
	for (std::size_t i = 0; i < paths.size(); ++i) {
		SCOPED_TRACE(paths[i]);
		ImageView view;
		ASSERT_EQ(reader.read(paths[i], &view).message(), "");
		expectSame(view, images[i]);
		/* Every frame lands at the same place: one buffer, never copied again. */
		if (!first)
			first = view.data;
		EXPECT_EQ(view.data, first);
		/* The same pixels as readPgm() gives. */
		const auto copy = readPgm(paths[i]);
		ASSERT_TRUE(copy.isOk()) << copy.message();
		expectSame(view, copy.value());
	}
}

TEST_F(PgmFiles, ReaderGrowsForALargerFile)
{
	PgmReader reader(8, 8);
	const std::size_t before = reader.capacity();
	const Image big = pattern(200, 150, 3);
	const std::string path = (dir_ / "big.pgm").string();
	ASSERT_EQ(writePgm(path, big.view()).message(), "");
	ImageView view;
	ASSERT_EQ(reader.read(path, &view).message(), "");
	expectSame(view, big);
	EXPECT_GT(reader.capacity(), before);

	/* A default reader starts empty and still reads. */
	PgmReader empty;
	EXPECT_EQ(empty.capacity(), 0u);
	ASSERT_EQ(empty.read(path, &view).message(), "");
	expectSame(view, big);
}

TEST_F(PgmFiles, ReaderErrorsAreReadPgmsErrors)
{
	PgmReader reader(4, 4);
	ImageView view;
	const std::string missing = (dir_ / "missing.pgm").string();
	EXPECT_EQ(reader.read(missing, &view).message(),
		  missing + ": cannot open (No such file or directory)");
	EXPECT_EQ(readPgm(missing).message(), reader.read(missing, &view).message());

	const std::string dir = dir_.string();
	EXPECT_EQ(reader.read(dir, &view).message(), dir + ": is a directory, not a file");
	EXPECT_EQ(readPgm(dir).message(), reader.read(dir, &view).message());

	const std::string unreadable = write("unreadable.pgm", "P5\n1 1\n255\n\x01");
	::chmod(unreadable.c_str(), 0);
	if (::access(unreadable.c_str(), R_OK) != 0) { /* root reads anything */
		EXPECT_EQ(reader.read(unreadable, &view).message(),
			  unreadable + ": cannot open (Permission denied)");
	}

	int i = 0;
	for (const std::string &bytes : badFiles()) {
		const std::string path = write("bad" + std::to_string(i++) + ".pgm", bytes);
		SCOPED_TRACE(path);
		const std::string err = reader.read(path, &view).message();
		EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
		EXPECT_EQ(err, parsePgm(bytes, path).message());
		EXPECT_EQ(err, readPgm(path).message());
	}

	/* A bad file in between does not spoil the next good one. */
	const Image img = pattern(4, 4, 9);
	const std::string good = (dir_ / "good.pgm").string();
	ASSERT_EQ(writePgm(good, img.view()).message(), "");
	ASSERT_EQ(reader.read(good, &view).message(), "");
	expectSame(view, img);
}

TEST_F(PgmFiles, ReaderReadsAPipeToItsEnd)
{
	/* Not a regular file: no size to read up to, the buffer grows to the end. */
	int fds[2];
	ASSERT_EQ(::pipe(fds), 0);
	const Image img = pattern(300, 200, 5);
	const std::string bytes = encodePgm(img.view()) + "trailer";
	std::thread writer([&] {
		std::size_t done = 0;
		while (done < bytes.size()) {
			const ssize_t n = ::write(fds[1], bytes.data() + done, bytes.size() - done);
			if (n <= 0)
				break;
			done += static_cast<std::size_t>(n);
		}
		::close(fds[1]);
	});
	PgmReader reader(10, 10);
	ImageView view;
	const std::string err = reader.read("/dev/fd/" + std::to_string(fds[0]), &view).message();
	writer.join();
	::close(fds[0]);
	ASSERT_EQ(err, "");
	expectSame(view, img);
	EXPECT_GE(reader.capacity(), bytes.size());
}

#ifdef DOCKPOSE_COUNT_ALLOCATIONS
TEST_F(PgmFiles, ReaderAllocatesNothingOnceItsBufferIsBigEnough)
{
	std::vector<std::string> paths;
	for (int i = 0; i < 4; ++i) {
		paths.push_back((dir_ / ("n" + std::to_string(i) + ".pgm")).string());
		ASSERT_EQ(writePgm(paths.back(), pattern(320, 240, i).view()).message(), "");
	}
	PgmReader reader(320, 240);
	ImageView view;
	std::uint64_t sum = 0;
	dockpose::test::armAllocationCounter();
	for (const std::string &path : paths) {
		const std::string err = reader.read(path, &view).message();
		sum += err.empty() ? view.at(10, 10) : 1000;
	}
	const long allocations = dockpose::test::disarmAllocationCounter();
	EXPECT_EQ(allocations, 0);
	EXPECT_LT(sum, 1000u);

	/* The hooks do count: readPgm() allocates its image. */
	dockpose::test::armAllocationCounter();
	const bool read = readPgm(paths[0]).isOk();
	EXPECT_GT(dockpose::test::disarmAllocationCounter(), 0);
	EXPECT_TRUE(read);
}
#endif

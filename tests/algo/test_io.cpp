/* SPDX-License-Identifier: MIT */
/*
 * Files: target and camera JSON (method.md section 3) and PGM frames.
 * The good files of tests/data load with the exact values written in them;
 * each malformed input gives its own, specific error naming the source.
 */
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "algo/io/model_json.h"
#include "algo/io/pgm.h"

using namespace dockpose;

namespace {

const std::string kData = DOCKPOSE_TEST_DATA;

std::string tempPath(const std::string &name)
{
	const auto dir = std::filesystem::temp_directory_path() /
			 ("dockpose_test_io_" + std::to_string(static_cast<long>(::getpid())));
	std::filesystem::create_directories(dir);
	return (dir / name).string();
}

void writeFile(const std::string &path, const std::string &bytes)
{
	std::ofstream out(path, std::ios::binary | std::ios::trunc);
	out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

} /* namespace */

TEST(ModelJson, WedgeIsTheMethodExample)
{
	const auto r = loadTargetModel(kData + "/wedge.json");
	ASSERT_TRUE(r.isOk()) << r.message();
	const TargetModel &m = r.value();
	EXPECT_EQ(m.name, "wedge");
	const double expected[6][3] = { { -89, -38, 0 }, { -89, 38, 0 }, { 0, 38, -40 },
					{ 0, -38, -40 }, { 89, -38, 0 }, { 89, 38, 0 } };
	ASSERT_EQ(m.points_mm.size(), 6u);
	for (int i = 0; i < 6; ++i)
		for (int k = 0; k < 3; ++k)
			EXPECT_EQ(m.points_mm[i][k], expected[i][k]) << "LED " << i;
	ASSERT_EQ(m.faces.size(), 2u);
	EXPECT_EQ(m.faces[0], (std::array<int, 4>{ 0, 1, 2, 3 }));
	EXPECT_EQ(m.faces[1], (std::array<int, 4>{ 3, 2, 5, 4 }));
}

TEST(ModelJson, CornerIsThreeQuadsAroundABoxCornerFacingTheCamera)
{
	const auto r = loadTargetModel(kData + "/corner.json");
	ASSERT_TRUE(r.isOk()) << r.message();
	const TargetModel &m = r.value();
	ASSERT_EQ(m.points_mm.size(), 7u);
	ASSERT_EQ(m.faces.size(), 3u);
	EXPECT_TRUE(m.validate().message().empty());
	EXPECT_GT(m.diameterMm(), 130.0);
	EXPECT_LT(m.diameterMm(), 170.0);

	Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
	for (const auto &p : m.points_mm)
		centroid += p;
	centroid /= static_cast<double>(m.points_mm.size());
	for (std::size_t f = 0; f < 3; ++f) {
		/* Each pair of faces shares exactly one edge (two LEDs), all share LED 0. */
		for (std::size_t g = f + 1; g < 3; ++g) {
			int shared = 0;
			for (int a : m.faces[f])
				for (int b : m.faces[g])
					shared += a == b;
			EXPECT_EQ(shared, 2) << "faces " << f << ", " << g;
		}
		/* Outward normals point towards a camera at the identity pose (-z). */
		const auto &face = m.faces[f];
		Eigen::Vector3d n = (m.points_mm[face[2]] - m.points_mm[face[0]])
					    .cross(m.points_mm[face[3]] - m.points_mm[face[1]])
					    .normalized();
		const Eigen::Vector3d centre = (m.points_mm[face[0]] + m.points_mm[face[1]] +
						m.points_mm[face[2]] + m.points_mm[face[3]]) /
					       4.0;
		if (n.dot(centre - centroid) < 0)
			n = -n;
		EXPECT_LT(n.z(), -0.3) << "face " << f;
		/* Box faces are mutually perpendicular rectangles: check the corner angle. */
		const Eigen::Vector3d a = m.points_mm[face[1]] - m.points_mm[face[0]];
		const Eigen::Vector3d b = m.points_mm[face[3]] - m.points_mm[face[0]];
		EXPECT_NEAR(a.dot(b) / (a.norm() * b.norm()), 0.0, 1e-4);
	}
	/* The corner (LED 0) is the point nearest the camera. */
	for (std::size_t i = 1; i < 7; ++i)
		EXPECT_GT(m.points_mm[i].z(), m.points_mm[0].z() + 30.0);
}

TEST(ModelJson, Cameras)
{
	const auto a = loadCameraIntrinsics(kData + "/cam1456.json");
	ASSERT_TRUE(a.isOk()) << a.message();
	EXPECT_EQ(a.value().width, 1456);
	EXPECT_EQ(a.value().height, 1088);
	EXPECT_EQ(a.value().fx, 1739.0);
	EXPECT_EQ(a.value().fy, 1739.0);
	EXPECT_EQ(a.value().cx, 727.5);
	EXPECT_EQ(a.value().cy, 543.5);
	EXPECT_EQ(a.value().k1, -0.12);
	EXPECT_EQ(a.value().k2, 0.03);
	EXPECT_EQ(a.value().p1, 0.0005);
	EXPECT_EQ(a.value().p2, -0.0003);

	const auto b = loadCameraIntrinsics(kData + "/cam512.json");
	ASSERT_TRUE(b.isOk()) << b.message();
	EXPECT_EQ(b.value().width, 512);
	EXPECT_EQ(b.value().height, 512);
	EXPECT_EQ(b.value().fx, 400.0);
	EXPECT_EQ(b.value().cx, 255.5);
	EXPECT_EQ(b.value().cy, 255.5);
	EXPECT_EQ(b.value().k1, 0.0);
	EXPECT_EQ(b.value().p2, 0.0);
}

TEST(ModelJson, DefaultsNameAndDistortion)
{
	const auto t = parseTargetModel(
		R"({"points": [[0,0,0],[10,0,0],[10,10,0],[0,10,0]], "faces": [[0,1,2,3]]})",
		"/some/dir/board.json");
	ASSERT_TRUE(t.isOk()) << t.message();
	EXPECT_EQ(t.value().name, "board");
	const auto c = parseCameraIntrinsics(
		R"({"width": 640, "height": 480, "fx": 500, "fy": 501, "cx": 319.5,
		"cy": 239.5, "k3": 0.0})");
	ASSERT_TRUE(c.isOk()) << c.message();
	EXPECT_EQ(c.value().fy, 501.0);
	EXPECT_EQ(c.value().k1, 0.0);
	EXPECT_EQ(c.value().k2, 0.0);
	EXPECT_EQ(c.value().p1, 0.0);
	EXPECT_EQ(c.value().p2, 0.0);
}

namespace {

struct BadCase {
	const char *what;
	std::string text;
	const char *expected; /* substring of the error */
};

std::string manyPoints(int n)
{
	std::string s = "[";
	for (int i = 0; i < n; ++i)
		s += (i ? ",[" : "[") + std::to_string(10 * i) + "," + std::to_string((i * i) % 7) +
		     ",0]";
	return s + "]";
}

} /* namespace */

TEST(ModelJson, BadTargetsGiveTheirOwnError)
{
	const std::string square = R"("points": [[0,0,0],[100,0,0],[100,100,0],[0,100,0]])";
	std::string nine_faces = "[";
	for (int i = 0; i < 9; ++i)
		nine_faces += std::string(i ? "," : "") + "[0,1,2,3]";
	nine_faces += "]";
	const std::vector<BadCase> cases = {
		{ "not JSON", "{\"points\": [", "not valid JSON" },
		{ "overflowing number", R"({"points": [[0,0,1e400]], "faces": []})",
		  "a number beyond the range of a double (number overflow parsing '1e400')" },
		{ "top level array", "[1, 2]",
		  "the top level must be a JSON object, not an array" },
		{ "no points", R"({"faces": [[0,1,2,3]]})", "key 'points' is missing" },
		{ "points not array", R"({"points": 5, "faces": []})",
		  "'points' must be an array of [x, y, z], not an integer" },
		{ "short point", R"({"points": [[0,0,0],[1,2]], "faces": []})",
		  "point 1 must be [x, y, z] (3 numbers), but it is an array of 2" },
		{ "long point", R"({"points": [[0,0,0,0]], "faces": []})",
		  "point 0 must be [x, y, z] (3 numbers), but it is an array of 4" },
		{ "point not array", R"({"points": [{"x": 1}], "faces": []})",
		  "point 0 must be [x, y, z] (3 numbers), but it is an object" },
		{ "string coordinate", R"({"points": [[0,0,"1"]], "faces": []})",
		  "point 0 coordinate 2 must be a number, not a string" },
		{ "null coordinate", R"({"points": [[0,null,1]], "faces": []})",
		  "point 0 coordinate 1 must be a number, not null" },
		{ "no faces", "{" + square + "}", "key 'faces' is missing" },
		{ "faces not array", "{" + square + R"(, "faces": {"a": 1}})",
		  "'faces' must be an array of [i, j, k, l], not an object" },
		{ "triangle", "{" + square + R"(, "faces": [[0,1,2]]})",
		  "face 0 must be a quadrilateral [i, j, k, l] of 4 LED indices, but it is an array of 3" },
		{ "float index", "{" + square + R"(, "faces": [[0,1,2.0,3]]})",
		  "face 0 entry 2 must be an integer LED index, not a number" },
		{ "index out of range", "{" + square + R"(, "faces": [[0,1,2,9]]})",
		  "face 0 names LED 9, but the model has LEDs 0..3" },
		{ "negative index", "{" + square + R"(, "faces": [[0,1,2,-1]]})",
		  "face 0 names LED -1" },
		{ "too many LEDs", "{\"points\": " + manyPoints(17) + ", \"faces\": [[0,1,2,3]]}",
		  "'points' lists 17 LEDs, more than the firmware's capacity of 16" },
		{ "too many faces", "{" + square + ", \"faces\": " + nine_faces + "}",
		  "'faces' lists 9 faces, more than the firmware's capacity of 8" },
		{ "no faces listed", "{" + square + R"(, "faces": []})", "has no faces" },
		{ "too few LEDs", R"({"points": [[0,0,0],[1,0,0],[0,1,0]], "faces": []})",
		  "has 3 LEDs; at least 4" },
		{ "repeated LED in face", "{" + square + R"(, "faces": [[0,1,1,3]]})",
		  "face 0 lists LED 1 twice" },
		{ "not planar",
		  R"({"points": [[0,0,0],[100,0,0],[100,100,30],[0,100,0]], "faces": [[0,1,2,3]]})",
		  "face 0 is not planar" },
		{ "dart (concave)",
		  R"({"points": [[0,0,0],[100,0,0],[30,30,0],[0,100,0]], "faces": [[0,1,2,3]]})",
		  "not a convex quadrilateral" },
		{ "bow tie", "{" + square + R"(, "faces": [[0,2,1,3]]})", "face 0 is degenerate" },
		{ "all LEDs at one point",
		  R"({"points": [[1,2,3],[1,2,3],[1,2,3],[1,2,3]], "faces": [[0,1,2,3]]})",
		  "is 0 mm across; a docking target's LEDs span 1 mm to 100000 mm" },
		{ "a target of 1e-198 mm",
		  R"({"points": [[0,0,0],[1e-198,0,0],[1e-198,1e-198,0],[0,1e-198,0]], "faces": [[0,1,2,3]]})",
		  "mm across; a docking target's LEDs span 1 mm to 100000 mm" },
		{ "a target of 1e300 mm",
		  R"({"points": [[0,0,0],[1e300,0,0],[1e300,1e300,0],[0,1e300,0]], "faces": [[0,1,2,3]]})",
		  "mm across; a docking target's LEDs span 1 mm to 100000 mm" },
		{ "coincident LEDs",
		  R"({"points": [[0,0,0],[100,0,0],[100,100,0],[0,100,0],[0,0,0]], "faces": [[0,1,2,3]]})",
		  "LEDs 0 and 4 coincide" },
		{ "inches", "{\"units\": \"in\", " + square + R"(, "faces": [[0,1,2,3]]})",
		  "'units' must be \"mm\"" },
		{ "numeric name", "{\"name\": 7, " + square + R"(, "faces": [[0,1,2,3]]})",
		  "'name' must be a string, not an integer" },
	};
	for (const BadCase &c : cases) {
		const auto r = parseTargetModel(c.text, "bad.json");
		EXPECT_FALSE(r.isOk()) << c.what;
		EXPECT_EQ(r.message().rfind("bad.json: ", 0), 0u) << c.what << ": " << r.message();
		EXPECT_NE(r.message().find(c.expected), std::string::npos)
			<< c.what << ": expected \"" << c.expected << "\" in \"" << r.message()
			<< "\"";
	}
}

TEST(ModelJson, BadCamerasGiveTheirOwnError)
{
	const std::vector<BadCase> cases = {
		{ "not JSON", "{\"width\": 10,,}", "not valid JSON" },
		{ "overflowing number",
		  R"({"width": 640, "height": 480, "fx": 1e309, "fy": 500, "cx": 320, "cy": 240})",
		  "a number beyond the range of a double (number overflow parsing '1e309')" },
		{ "string top level", "\"camera\"",
		  "the top level must be a JSON object, not a string" },
		{ "no width", R"({"height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240})",
		  "key 'width' is missing" },
		{ "no fx", R"({"width": 640, "height": 480, "fy": 500, "cx": 320, "cy": 240})",
		  "key 'fx' is missing" },
		{ "no cy", R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320})",
		  "key 'cy' is missing" },
		{ "float width",
		  R"({"width": 640.5, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240})",
		  "'width' must be an integer, not a number" },
		{ "string fx",
		  R"({"width": 640, "height": 480, "fx": "500", "fy": 500, "cx": 320, "cy": 240})",
		  "'fx' must be a number, not a string" },
		{ "bool k1",
		  R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240, "k1": true})",
		  "'k1' must be a number, not a boolean" },
		{ "zero width",
		  R"({"width": 0, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240})",
		  "is not a sensor size" },
		{ "negative fx",
		  R"({"width": 640, "height": 480, "fx": -500, "fy": 500, "cx": 320, "cy": 240})",
		  "focal lengths" },
		{ "focal length 1e-300",
		  R"({"width": 640, "height": 480, "fx": 1e-300, "fy": 1e-300, "cx": 320, "cy": 240})",
		  "camera field of view 180 x 180 degrees" },
		{ "telescope",
		  R"({"width": 640, "height": 480, "fx": 1e6, "fy": 1e6, "cx": 320, "cy": 240})",
		  "is not a lens's: each must be in [0.5, 175]" },
		{ "fy ten times fx",
		  R"({"width": 640, "height": 480, "fx": 500, "fy": 5000, "cx": 320, "cy": 240})",
		  "camera pixel aspect fy/fx = 10" },
		{ "k1 9.99",
		  R"({"width": 640, "height": 480, "fx": 560, "fy": 560, "cx": 320, "cy": 240, "k1": 9.99})",
		  "scales the image corners by 6.0" },
		/* Corner at r = 1; r (1 - 0.5 r^2) peaks at r = 0.82 (r_d 0.54): corner factor 0.5
		 * passes, but the edge of the image folds back. */
		{ "folding barrel k1 -0.5",
		  R"({"width": 1000, "height": 1000, "fx": 707.1068, "fy": 707.1068, "cx": 500, "cy": 500, "k1": -0.5})",
		  "folds the image: its radial mapping stops growing at radius 0.7" },
		{ "far principal point",
		  R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 3200, "cy": 240})",
		  "principal point" },
		{ "k3",
		  R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240, "k3": 0.01})",
		  "'k3' is not supported" },
		{ "huge k1",
		  R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240, "k1": 50})",
		  "distortion" },
	};
	for (const BadCase &c : cases) {
		const auto r = parseCameraIntrinsics(c.text, "cam.json");
		EXPECT_FALSE(r.isOk()) << c.what;
		EXPECT_EQ(r.message().rfind("cam.json: ", 0), 0u) << c.what << ": " << r.message();
		EXPECT_NE(r.message().find(c.expected), std::string::npos)
			<< c.what << ": expected \"" << c.expected << "\" in \"" << r.message()
			<< "\"";
	}
}

TEST(ModelJson, MissingFileNamesThePath)
{
	const std::string path = kData + "/no_such_target.json";
	const auto t = loadTargetModel(path);
	EXPECT_FALSE(t.isOk());
	EXPECT_EQ(t.message().rfind(path + ": cannot open", 0), 0u) << t.message();
	const auto c = loadCameraIntrinsics(kData);
	EXPECT_FALSE(c.isOk());
	EXPECT_NE(c.message().find("is a directory"), std::string::npos) << c.message();
}

TEST(ModelJson, OnlyRegularFilesOfBoundedSizeAreRead)
{
	/* /dev/zero was read until memory ran out; a FIFO without a writer blocked for ever. */
	const auto zero = loadTargetModel("/dev/zero");
	EXPECT_EQ(zero.message(), "/dev/zero: is not a regular file (a device, FIFO or socket)");

	const std::string dir = ::testing::TempDir();
	const std::string fifo = dir + "/dockpose_io_fifo_" + std::to_string(::getpid());
	std::filesystem::remove(fifo);
	ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
	const auto from_fifo = loadCameraIntrinsics(fifo);
	EXPECT_EQ(from_fifo.message(), fifo + ": is not a regular file (a device, FIFO or socket)");
	std::filesystem::remove(fifo);

	const std::string big = dir + "/dockpose_io_big_" + std::to_string(::getpid()) + ".json";
	{
		std::ofstream out(big, std::ios::binary);
		out << "{\"points\": [" << std::string(kMaxTextFileBytes, ' ') << "]}";
	}
	const auto too_big = loadTargetModel(big);
	EXPECT_NE(too_big.message().find(": is " + std::to_string(kMaxTextFileBytes + 14) +
					 " bytes; a target, camera or board file has at most " +
					 std::to_string(kMaxTextFileBytes)),
		  std::string::npos)
		<< too_big.message();
	std::filesystem::remove(big);
}

TEST(Pgm, HandMadeFileWithCommentsAndOddWhitespace)
{
	/* 3 x 2, maxval 200, comments between every token, tabs and CRLF. */
	std::string bytes =
		"P5 # a comment right after the magic\r\n3\t# width\n#whole line\n 2\n200";
	bytes += '\n';
	const unsigned char pixels[6] = { 0, 10, 200, 7, 13, 255 };
	bytes.append(reinterpret_cast<const char *>(pixels), 6);
	bytes += "trailing bytes of a second image are ignored";
	const auto r = parsePgm(bytes, "x.pgm");
	ASSERT_TRUE(r.isOk()) << r.message();
	ASSERT_EQ(r.value().width(), 3);
	ASSERT_EQ(r.value().height(), 2);
	EXPECT_EQ(r.value().at(0, 0), 0);
	EXPECT_EQ(r.value().at(1, 0), 10);
	EXPECT_EQ(r.value().at(2, 0), 200);
	EXPECT_EQ(r.value().at(0, 1), 7);
	EXPECT_EQ(r.value().at(1, 1), 13);
	EXPECT_EQ(r.value().at(2, 1), 255); /* values are not rescaled or clipped to maxval */
}

TEST(Pgm, WriteReadRoundTrip)
{
	Image img(37, 23);
	for (int y = 0; y < img.height(); ++y)
		for (int x = 0; x < img.width(); ++x)
			img.at(x, y) = static_cast<std::uint8_t>((x * 31 + y * 17 + x * y) & 0xff);
	const std::string path = tempPath("roundtrip.pgm");
	ASSERT_EQ(writePgm(path, img.view()).message(), "");

	/* The header is exactly the canonical one. */
	std::ifstream in(path, std::ios::binary);
	std::string head(12, '\0');
	in.read(head.data(), 12);
	EXPECT_EQ(head, "P5\n37 23\n255");

	const auto r = readPgm(path);
	ASSERT_TRUE(r.isOk()) << r.message();
	ASSERT_EQ(r.value().width(), 37);
	ASSERT_EQ(r.value().height(), 23);
	for (int y = 0; y < img.height(); ++y)
		for (int x = 0; x < img.width(); ++x)
			ASSERT_EQ(r.value().at(x, y), img.at(x, y)) << x << "," << y;
	std::filesystem::remove(path);

	/* A strided view is written row by row. */
	std::vector<std::uint8_t> strided(4 * 3, 99);
	for (int y = 0; y < 3; ++y)
		for (int x = 0; x < 2; ++x)
			strided[y * 4 + x] = static_cast<std::uint8_t>(10 * y + x);
	const ImageView view{ strided.data(), 2, 3, 4 };
	const auto s = parsePgm(encodePgm(view));
	ASSERT_TRUE(s.isOk()) << s.message();
	for (int y = 0; y < 3; ++y)
		for (int x = 0; x < 2; ++x)
			EXPECT_EQ(s.value().at(x, y), 10 * y + x);
}

TEST(Pgm, BadFilesGiveTheirOwnError)
{
	const std::string four(4, '\x40');
	const std::vector<BadCase> cases = {
		{ "empty", "", "not a PGM file" },
		{ "PNG", "\x89PNG\r\n", "not a PGM file" },
		{ "ASCII PGM", "P2\n2 2\n255\n1 2 3 4\n", "ASCII PGM (P2) is not supported" },
		{ "PPM", "P6\n2 2\n255\n" + std::string(12, 'x'),
		  "Netpbm type P6 is not a binary graymap" },
		{ "16-bit", "P5\n2 2\n65535\n" + std::string(8, 'x'),
		  "16-bit PGM (maxval 65535) is not supported" },
		{ "maxval 0", "P5\n2 2\n0\n" + four, "maxval 0 is invalid" },
		{ "truncated data", "P5\n4 4\n255\n" + std::string(10, 'x'),
		  "truncated PGM: 4x4 needs 16 bytes of pixel data, the file has 10" },
		{ "header only", "P5\n4 4\n255", "truncated PGM (no pixel data after the header)" },
		{ "header ends early", "P5\n4", "the header ends before its height" },
		{ "letters for height", "P5\n4 x\n255\n",
		  "the header's height is not a decimal number" },
		{ "junk after width", "P5\n4x 4\n255\n", "the header's width is followed by 'x'" },
		{ "no space after magic", "P54 4 255\n" + std::string(16, 'x'),
		  "no whitespace after \"P5\"" },
		{ "zero width", "P5\n0 4\n255\n", "PGM size 0x4 is not a frame size" },
		{ "absurd size", "P5\n100000 100000\n255\n",
		  "PGM size 100000x100000 is not a frame size" },
		{ "absurd digits", "P5\n99999999999999999999 2\n255\n", "is not a frame size" },
	};
	for (const BadCase &c : cases) {
		const auto r = parsePgm(c.text, "f.pgm");
		EXPECT_FALSE(r.isOk()) << c.what;
		EXPECT_EQ(r.message().rfind("f.pgm: ", 0), 0u) << c.what << ": " << r.message();
		EXPECT_NE(r.message().find(c.expected), std::string::npos)
			<< c.what << ": expected \"" << c.expected << "\" in \"" << r.message()
			<< "\"";
	}
}

TEST(Pgm, FileErrors)
{
	const auto missing = readPgm("/nonexistent/dir/frame.pgm");
	EXPECT_FALSE(missing.isOk());
	EXPECT_EQ(missing.message().rfind("/nonexistent/dir/frame.pgm: cannot open", 0), 0u)
		<< missing.message();

	const std::string path = tempPath("truncated.pgm");
	writeFile(path, "P5\n8 8\n255\n" + std::string(63, '\x01'));
	const auto t = readPgm(path);
	EXPECT_FALSE(t.isOk());
	EXPECT_NE(t.message().find(path + ": truncated PGM"), std::string::npos) << t.message();
	std::filesystem::remove(path);

	EXPECT_NE(writePgm("/nonexistent/dir/out.pgm", Image(2, 2).view())
			  .message()
			  .find("cannot create"),
		  std::string::npos);
	EXPECT_NE(
		writePgm(tempPath("empty.pgm"), Image().view()).message().find("empty or invalid"),
		std::string::npos);
}

TEST(ModelJson, OptionalUncertaintyAndApproach)
{
	const std::string square =
		R"("points": [[0,0,0],[100,0,0],[100,100,0],[0,100,0]], "faces": [[0,1,2,3]])";
	const auto t = parseTargetModel(
		"{" + square +
		R"(, "led_sigma_mm": 0.2, "approach": {"axis": [0, 0, -2], "max_deg": 60}})");
	ASSERT_TRUE(t.isOk()) << t.message();
	EXPECT_EQ(t.value().led_sigma_mm, 0.2);
	EXPECT_TRUE(t.value().approach.set);
	EXPECT_NEAR((t.value().approach.axis - Eigen::Vector3d(0, 0, -1)).norm(), 0.0, 1e-15);
	EXPECT_EQ(t.value().approach.max_deg, 60.0);
	const auto plain = parseTargetModel("{" + square + "}");
	ASSERT_TRUE(plain.isOk()) << plain.message();
	EXPECT_EQ(plain.value().led_sigma_mm, 0.0);
	EXPECT_FALSE(plain.value().approach.set);

	const auto c = parseCameraIntrinsics(
		R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240,
		"sigma": {"fx": 0.8, "cy": 0.3, "k1": 0.001}, "rms_px": 0.21, "frames": 40, "date": "2024-06-01"})");
	ASSERT_TRUE(c.isOk()) << c.message();
	EXPECT_EQ(c.value().sigma.fx, 0.8);
	EXPECT_EQ(c.value().sigma.cy, 0.3);
	EXPECT_EQ(c.value().sigma.k1, 0.001);
	EXPECT_EQ(c.value().sigma.fy, 0.0);
	EXPECT_TRUE(c.value().sigma.any());
	EXPECT_FALSE(loadCameraIntrinsics(kData + "/cam512.json").value().sigma.any());
	/* What dockpose calibrate writes: a UTC date and time; an offset is ISO 8601 too. */
	for (const char *date : { "2026-12-03T18:40:00Z", "2026-12-03T18:40:00+01:00",
				  "2026-12-03T18:40", "2026-12-03T18:40:00.25Z" })
		EXPECT_TRUE(
			parseCameraIntrinsics(
				R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320,
				    "cy": 240, "frames": 1, "date": ")" +
				std::string(date) + "\"}")
				.isOk())
			<< date;
	/* A very long "date" is refused, not a stack overflow (the check is not a std::regex). */
	EXPECT_FALSE(parseCameraIntrinsics(R"({"width": 640, "height": 480, "fx": 500, "fy": 500,
					       "cx": 320, "cy": 240, "date": "2026-12-03T)" +
					   std::string(200000, '1') + "\"}")
			     .isOk());

	const std::vector<BadCase> targets = {
		{ "negative tolerance", "{" + square + R"(, "led_sigma_mm": -1})",
		  "'led_sigma_mm' must be a tolerance >= 0" },
		{ "string tolerance", "{" + square + R"(, "led_sigma_mm": "0.1"})",
		  "'led_sigma_mm' must be a number" },
		{ "approach not object", "{" + square + R"(, "approach": [0, 0, 1]})",
		  "'approach' must be an object" },
		{ "no axis", "{" + square + R"(, "approach": {"max_deg": 30}})",
		  "'approach.axis' is missing" },
		{ "short axis", "{" + square + R"(, "approach": {"axis": [0, 1], "max_deg": 30}})",
		  "'approach.axis' must be [x, y, z]" },
		{ "zero axis",
		  "{" + square + R"(, "approach": {"axis": [0, 0, 0], "max_deg": 30}})",
		  "non-zero direction" },
		{ "no max_deg", "{" + square + R"(, "approach": {"axis": [0, 0, 1]}})",
		  "'max_deg' is missing" },
		{ "zero max_deg",
		  "{" + square + R"(, "approach": {"axis": [0, 0, 1], "max_deg": 0}})",
		  "'approach.max_deg' must be an angle in (0, 180]" },
		{ "big max_deg",
		  "{" + square + R"(, "approach": {"axis": [0, 0, 1], "max_deg": 181}})",
		  "'approach.max_deg' must be an angle" },
	};
	for (const BadCase &b : targets) {
		const auto r = parseTargetModel(b.text, "bad.json");
		EXPECT_FALSE(r.isOk()) << b.what;
		EXPECT_EQ(r.message().rfind("bad.json: ", 0), 0u) << b.what << ": " << r.message();
		EXPECT_NE(r.message().find(b.expected), std::string::npos)
			<< b.what << ": " << r.message();
	}
	const std::string cam =
		R"("width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240)";
	const std::vector<BadCase> cameras = {
		{ "sigma not object", "{" + cam + R"(, "sigma": 0.5})",
		  "'sigma' must be an object" },
		{ "unknown sigma", "{" + cam + R"(, "sigma": {"k3": 0.1}})",
		  "'sigma.k3' is not a parameter" },
		{ "negative sigma", "{" + cam + R"(, "sigma": {"fx": -1}})",
		  "'sigma.fx' must be a 1-sigma value >= 0" },
		{ "string sigma", "{" + cam + R"(, "sigma": {"cx": "1"}})",
		  "'cx' must be a number" },
		{ "string rms", "{" + cam + R"(, "rms_px": "small"})",
		  "'rms_px' must be a number" },
		{ "negative rms", "{" + cam + R"(, "rms_px": -0.1})",
		  "'rms_px' must be a reprojection rms >= 0 px" },
		{ "fractional frames", "{" + cam + R"(, "frames": 2.5})",
		  "'frames' must be an integer" },
		{ "no frames", "{" + cam + R"(, "frames": 0})", "'frames' must be the number" },
		{ "date not a string", "{" + cam + R"(, "date": 20261203})",
		  "'date' must be an ISO 8601 date" },
		{ "date not ISO", "{" + cam + R"(, "date": "03/12/2026"})",
		  "'date' must be an ISO 8601 date" },
		{ "month 13", "{" + cam + R"(, "date": "2026-13-01"})",
		  "'date' must be an ISO 8601 date" },
		{ "hour 24", "{" + cam + R"(, "date": "2026-12-03T24:00:00Z"})",
		  "'date' must be an ISO 8601 date" },
	};
	for (const BadCase &b : cameras) {
		const auto r = parseCameraIntrinsics(b.text, "cam.json");
		EXPECT_FALSE(r.isOk()) << b.what;
		EXPECT_EQ(r.message().rfind("cam.json: ", 0), 0u) << b.what << ": " << r.message();
		EXPECT_NE(r.message().find(b.expected), std::string::npos)
			<< b.what << ": " << r.message();
	}
}

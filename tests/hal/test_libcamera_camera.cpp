/* SPDX-License-Identifier: MIT */
/*
 * LibcameraCamera: the pure helpers (format choice, camera selection, config
 * checks, timestamps) everywhere; against libcamera the error paths on a
 * machine without cameras (this build host), and a short capture with
 * stop/start cycles where a camera exists (vimc in the VM; skipped here).
 */
#include <chrono>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hal/libcamera/libcamera_camera.h"

using namespace dockpose::hal;
using ::testing::HasSubstr;
using ::testing::StartsWith;

namespace {

constexpr std::uint32_t fourcc(char a, char b, char c, char d)
{
	return static_cast<std::uint32_t>(a) | (static_cast<std::uint32_t>(b) << 8) |
	       (static_cast<std::uint32_t>(c) << 16) | (static_cast<std::uint32_t>(d) << 24);
}

/* Whether the kernel exposes any media controller (a camera libcamera could find). */
bool hasMediaDevices()
{
	std::error_code ec;
	for (const auto &entry : std::filesystem::directory_iterator("/dev", ec))
		if (entry.path().filename().string().rfind("media", 0) == 0)
			return true;
	return false;
}

double secondsSince(std::chrono::steady_clock::time_point t0)
{
	return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} /* namespace */

/* ---- pure helpers ---- */

TEST(LibcameraFormats, FourccsMapToLayouts)
{
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('R', '8', ' ', ' ')), PixelLayout::Gray8);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('Y', 'U', '1', '2')), PixelLayout::YUV420);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('Y', 'V', '1', '2')), PixelLayout::YUV420);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('N', 'V', '1', '2')), PixelLayout::NV12);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('N', 'V', '2', '1')), PixelLayout::NV21);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('Y', 'U', 'Y', 'V')), PixelLayout::YUYV);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('U', 'Y', 'V', 'Y')), PixelLayout::UYVY);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('R', 'G', '2', '4')), PixelLayout::RGB888);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('B', 'G', '2', '4')), PixelLayout::BGR888);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('X', 'R', '2', '4')), PixelLayout::XRGB8888);
	EXPECT_EQ(pixelLayoutForFourcc(fourcc('X', 'B', '2', '4')), PixelLayout::XBGR8888);
}

TEST(LibcameraFormats, FormatsWithoutAnIntensityPlaneAreRefused)
{
	EXPECT_FALSE(pixelLayoutForFourcc(fourcc('B', 'A', '1', '0'))); /* SGRBG10 */
	EXPECT_FALSE(pixelLayoutForFourcc(fourcc('R', 'G', 'G', 'B'))); /* SRGGB8 Bayer */
	EXPECT_FALSE(pixelLayoutForFourcc(fourcc('M', 'J', 'P', 'G'))); /* MJPEG */
	EXPECT_FALSE(pixelLayoutForFourcc(fourcc('R', '1', '0', ' '))); /* R10 */
	/* A modifier (CSI-2 packing, vendor tiling) changes the memory layout. */
	const std::uint64_t csi2_packed = (std::uint64_t{ 11 } << 56) | 1;
	EXPECT_FALSE(pixelLayoutForFourcc(fourcc('R', '8', ' ', ' '), csi2_packed));
	EXPECT_FALSE(pixelLayoutForFourcc(fourcc('N', 'V', '1', '2'), csi2_packed));
}

TEST(LibcameraFormats, MonoBeatsYuvBeatsPackedBeatsRgb)
{
	EXPECT_LT(pixelLayoutCost(PixelLayout::Gray8), pixelLayoutCost(PixelLayout::YUV420));
	EXPECT_EQ(pixelLayoutCost(PixelLayout::YUV420), pixelLayoutCost(PixelLayout::NV12));
	EXPECT_EQ(pixelLayoutCost(PixelLayout::NV12), pixelLayoutCost(PixelLayout::NV21));
	EXPECT_LT(pixelLayoutCost(PixelLayout::NV21), pixelLayoutCost(PixelLayout::YUYV));
	EXPECT_EQ(pixelLayoutCost(PixelLayout::YUYV), pixelLayoutCost(PixelLayout::UYVY));
	EXPECT_LT(pixelLayoutCost(PixelLayout::UYVY), pixelLayoutCost(PixelLayout::RGB888));
	EXPECT_EQ(pixelLayoutCost(PixelLayout::RGB888), pixelLayoutCost(PixelLayout::XBGR8888));
}

TEST(LibcameraSelect, NoCamerasNamesTheLikelyCause)
{
	std::size_t chosen = 99;
	const Status s = selectCamera({}, "", 0, &chosen);
	ASSERT_FALSE(s);
	EXPECT_THAT(s.message(), StartsWith("libcamera: no cameras found"));
	EXPECT_THAT(s.message(), HasSubstr("dtoverlay=imx296"));
	EXPECT_EQ(chosen, 99u);
}

TEST(LibcameraSelect, ById)
{
	const std::vector<std::string> ids = { "/base/a/imx296@1a", "platform/vimc.0 Sensor B" };
	std::size_t chosen = 99;
	ASSERT_TRUE(selectCamera(ids, "platform/vimc.0 Sensor B", 0, &chosen));
	EXPECT_EQ(chosen, 1u);
	/* The id wins over the index. */
	ASSERT_TRUE(selectCamera(ids, "/base/a/imx296@1a", 1, &chosen));
	EXPECT_EQ(chosen, 0u);

	const Status s = selectCamera(ids, "imx296", 0, &chosen);
	ASSERT_FALSE(s);
	EXPECT_EQ(s.message(),
		  "libcamera: no camera with id \"imx296\" (cameras: /base/a/imx296@1a, "
		  "platform/vimc.0 Sensor B)");
}

TEST(LibcameraSelect, ByIndex)
{
	const std::vector<std::string> ids = { "a", "b" };
	std::size_t chosen = 99;
	ASSERT_TRUE(selectCamera(ids, "", 1, &chosen));
	EXPECT_EQ(chosen, 1u);

	Status s = selectCamera(ids, "", 2, &chosen);
	ASSERT_FALSE(s);
	EXPECT_EQ(s.message(), "libcamera: camera index 2 out of range (2 cameras: a, b)");
	s = selectCamera(ids, "", -1, &chosen);
	ASSERT_FALSE(s);
	EXPECT_THAT(s.message(), HasSubstr("camera index -1 out of range"));
	s = selectCamera({ "only" }, "", 1, &chosen);
	ASSERT_FALSE(s);
	EXPECT_EQ(s.message(), "libcamera: camera index 1 out of range (1 camera: only)");
	EXPECT_EQ(chosen, 1u);
}

TEST(LibcameraConfig, ChecksBeforeTouchingTheCamera)
{
	EXPECT_TRUE(checkCameraConfig(CameraConfig{}));

	CameraConfig c;
	c.buffer_count = 1;
	EXPECT_THAT(checkCameraConfig(c).message(),
		    HasSubstr("buffer_count 1 out of range (2..16)"));
	c.buffer_count = 17;
	EXPECT_THAT(checkCameraConfig(c).message(), HasSubstr("buffer_count 17"));

	c = CameraConfig{};
	c.width = 640;
	EXPECT_THAT(checkCameraConfig(c).message(), HasSubstr("frame size 640x0 invalid"));
	c.height = -480;
	EXPECT_FALSE(checkCameraConfig(c));
	c.height = 480;
	EXPECT_TRUE(checkCameraConfig(c));

	c = CameraConfig{};
	c.exposure_us = 0;
	EXPECT_THAT(checkCameraConfig(c).message(), HasSubstr("exposure_us 0 must be > 0"));
	c = CameraConfig{};
	c.analogue_gain = 0.5;
	EXPECT_THAT(checkCameraConfig(c).message(), HasSubstr("analogue_gain"));
	c.analogue_gain = std::nan("");
	EXPECT_FALSE(checkCameraConfig(c));
	c = CameraConfig{};
	c.frame_rate_hz = -1;
	EXPECT_THAT(checkCameraConfig(c).message(), HasSubstr("frame_rate_hz -1"));
	c.frame_rate_hz = std::nan("");
	EXPECT_THAT(checkCameraConfig(c).message(), HasSubstr("frame_rate_hz nan"));
	c = CameraConfig{};
	c.exposure_us = 20000;
	c.frame_rate_hz = 60;
	EXPECT_THAT(checkCameraConfig(c).message(),
		    HasSubstr("exposure_us 20000 exceeds the frame duration 16667 us"));
	c.frame_rate_hz = 0; /* free-running: any exposure */
	EXPECT_TRUE(checkCameraConfig(c));
}

TEST(LibcameraTimestamp, ExposureStartIsFrameStartMinusExposure)
{
	EXPECT_EQ(exposureStartNs(5'000'000'000, 2000), 4'998'000'000);
	EXPECT_EQ(exposureStartNs(5'000'000'000, 0), 5'000'000'000);
	/* Large exposures do not overflow 32 bits. */
	EXPECT_EQ(exposureStartNs(10'000'000'000, 3'000'000), 7'000'000'000);
}

/* ---- against libcamera ---- */

TEST(LibcameraCamera, UnconfiguredCameraIsInert)
{
	LibcameraCamera camera;
	EXPECT_EQ(camera.name(), "libcamera");
	EXPECT_EQ(camera.width(), 0);
	EXPECT_EQ(camera.height(), 0);
	EXPECT_EQ(camera.requestCount(), 0u);
	EXPECT_EQ(camera.requestsQueued(), 0u);
	EXPECT_EQ(camera.strideBytes(), 0);
	EXPECT_TRUE(camera.pixelFormatName().empty());
	EXPECT_FALSE(camera.zeroCopy());

	Frame frame;
	const auto t0 = std::chrono::steady_clock::now();
	EXPECT_EQ(camera.waitFrame(&frame, 1000), WaitResult::Stopped);
	EXPECT_LT(secondsSince(t0), 0.5) << "waitFrame before start() must not wait";
	camera.releaseFrame(frame); /* slot -1: ignored */

	const Status s = camera.start();
	ASSERT_FALSE(s);
	EXPECT_THAT(s.message(), HasSubstr("before a successful configure()"));
	EXPECT_EQ(camera.lastError(), s.message());

	camera.stop();
	camera.stop(); /* idempotent */
	EXPECT_EQ(camera.stats().frames, 0u);
	EXPECT_EQ(camera.stats().dropped, 0u);
	EXPECT_EQ(camera.stats().errors, 0u);
}

TEST(LibcameraCamera, SetControlsValidates)
{
	LibcameraCamera camera;
	EXPECT_THAT(camera.setControls(0, 1.0).message(), HasSubstr("exposure_us 0 must be > 0"));
	EXPECT_THAT(camera.setControls(1000, 0.5).message(), HasSubstr("analogue_gain"));
	EXPECT_FALSE(camera.setControls(1000, std::nan("")));
	EXPECT_TRUE(camera.setControls(1000, 2.0));
}

TEST(LibcameraCamera, BadConfigIsRefusedBeforeLibcamera)
{
	LibcameraCamera camera;
	CameraConfig c;
	c.buffer_count = 0;
	const Status s = camera.configure(c);
	ASSERT_FALSE(s);
	EXPECT_THAT(s.message(), HasSubstr("buffer_count 0 out of range"));
	EXPECT_EQ(camera.lastError(), s.message());
}

TEST(LibcameraCamera, NoCamerasFoundFailsFast)
{
	if (hasMediaDevices())
		GTEST_SKIP() << "this machine has media devices: libcamera may find a camera";
	LibcameraCamera camera;
	const auto t0 = std::chrono::steady_clock::now();
	const Status s = camera.configure(CameraConfig{});
	EXPECT_LT(secondsSince(t0), 10.0);
	ASSERT_FALSE(s);
	EXPECT_THAT(s.message(), StartsWith("libcamera: no cameras found"));
	EXPECT_EQ(camera.lastError(), s.message());
	EXPECT_EQ(camera.name(), "libcamera");
	EXPECT_EQ(camera.width(), 0);
	EXPECT_EQ(camera.requestCount(), 0u);

	/* Still inert after the failure; stop and destruction are safe. */
	Frame frame;
	EXPECT_EQ(camera.waitFrame(&frame, 100), WaitResult::Stopped);
	EXPECT_FALSE(camera.start());
	camera.stop();
	camera.stop();
}

TEST(LibcameraCamera, SelectionErrorsNameTheCameras)
{
	LibcameraCamera camera;
	CameraConfig c;
	c.index = 99;
	Status s = camera.configure(c);
	ASSERT_FALSE(s);
	if (hasMediaDevices())
		EXPECT_THAT(s.message(), HasSubstr("camera index 99 out of range"));
	else
		EXPECT_THAT(s.message(), StartsWith("libcamera: no cameras found"));

	c = CameraConfig{};
	c.id = "/base/soc/no-such-camera@0";
	s = camera.configure(c);
	ASSERT_FALSE(s);
	if (hasMediaDevices())
		EXPECT_THAT(s.message(),
			    HasSubstr("no camera with id \"/base/soc/no-such-camera@0\""));
	else
		EXPECT_THAT(s.message(), StartsWith("libcamera: no cameras found"));
}

TEST(LibcameraCamera, ManagerIsSharedAndRestartable)
{
	/* Two users at once share the process's one CameraManager (each keeps its reference
	 * after a failed configure(); a second CameraManager would abort the process), and
	 * after both are gone a new one starts again. */
	for (int round = 0; round < 2; ++round) {
		LibcameraCamera a;
		LibcameraCamera b;
		CameraConfig c;
		c.index = 99;
		const Status sa = a.configure(c);
		const Status sb = b.configure(c);
		ASSERT_FALSE(sa);
		ASSERT_FALSE(sb);
		EXPECT_EQ(sa.message(), sb.message());
	}
}

/* ---- with a camera (vimc in the VM) ---- */

TEST(LibcameraCamera, CapturesAndCyclesWhereACameraExists)
{
	if (!hasMediaDevices())
		GTEST_SKIP() << "no media devices on this machine";
	LibcameraCamera camera;
	const Status s = camera.configure(CameraConfig{});
	if (!s && s.message().rfind("libcamera: no cameras found", 0) == 0)
		GTEST_SKIP() << s.message();
	ASSERT_TRUE(s) << s.message();
	ASSERT_GT(camera.width(), 0);
	ASSERT_GT(camera.height(), 0);
	ASSERT_GE(camera.requestCount(), 2u);
	const std::size_t requests = camera.requestCount();
	EXPECT_FALSE(camera.pixelFormatName().empty());

	for (int cycle = 0; cycle < 3; ++cycle) {
		const std::uint64_t queued_before = camera.requestsQueued();
		ASSERT_TRUE(camera.start()) << camera.lastError();
		std::uint64_t last_sequence = 0;
		for (int i = 0; i < 8; ++i) {
			Frame frame;
			ASSERT_EQ(camera.waitFrame(&frame, 3000), WaitResult::Frame)
				<< camera.lastError();
			ASSERT_TRUE(frame.image.valid());
			EXPECT_EQ(frame.image.width, camera.width());
			EXPECT_EQ(frame.image.height, camera.height());
			EXPECT_EQ(frame.image.stride_bytes,
				  camera.zeroCopy() ? camera.strideBytes() : camera.width());
			if (i > 0) {
				EXPECT_GT(frame.sequence, last_sequence);
			}
			last_sequence = frame.sequence;
			EXPECT_GT(frame.timestamp_ns, 0);
			camera.releaseFrame(frame);
		}
		camera.stop();
		Frame frame;
		EXPECT_EQ(camera.waitFrame(&frame, 100), WaitResult::Stopped);
		/* Requests are reused, never created anew. */
		EXPECT_EQ(camera.requestCount(), requests);
		EXPECT_GE(camera.requestsQueued(), queued_before + 8);
	}
	EXPECT_GE(camera.stats().frames, 24u);
}

/* SPDX-License-Identifier: MIT */
/*
 * The firmware's frame loop allocates nothing in steady state: the daemon on
 * the simulated board (synthetic camera thread, strobe controller thread,
 * loopback CAN) runs for a while, then every operator new / malloc in the
 * whole process is counted over a window of about a second of frames.
 */
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <new>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "../common/counting_allocator.h"
#include "board/sim/sim_board.h"
#include "firmware/config.h"
#include "firmware/daemon.h"
#include "hal/sim/loopback_can_bus.h"

namespace dockpose::firmware {
namespace {

using namespace std::chrono_literals;

TEST(DaemonNoAlloc, CountingHooksSeeEveryThread)
{
	test::armAllocationCounter();
	std::thread t([] {
		auto *p = new int(3);
		void *q = std::malloc(16);
		delete p;
		std::free(q);
	});
	t.join();
	/* Two in the thread (plus whatever starting it took). */
	EXPECT_GE(test::disarmAllocationCounter(), 2);
}

TEST(DaemonNoAlloc, FrameLoopAllocatesNothingInSteadyState)
{
	ConfigResult loaded =
		loadBoardConfig(std::string(DOCKPOSE_SOURCE_DIR) + "/board/sim/board.json");
	ASSERT_TRUE(loaded.ok());
	BoardConfig config = loaded.config;
	config.systemd.notify = false;
	config.camera.synthetic.loop = true;
	/* The operator preview on: handed to its worker thread (counted too: the whole process). */
	config.preview.enabled = true;
	config.preview.name = "dockpose-test-noalloc-" + std::to_string(getpid());

	auto hub = std::make_shared<hal::LoopbackHub>();
	board::Backends b;
	ASSERT_TRUE(board::wireSimulated(config,
					 std::make_unique<hal::LoopbackCanBus>(hub, "sensor"), &b)
			    .isOk());

	std::FILE *log = std::tmpfile();
	Daemon daemon(config, std::move(b), log);
	ASSERT_TRUE(daemon.start().isOk());
	std::atomic<bool> stop{ false };
	std::thread loop([&] { daemon.run(stop); });

	/* Warm up: tracking, heartbeats, the loopback hub's traffic ring filling. */
	std::this_thread::sleep_for(1500ms);
	const std::uint64_t frames_before = daemon.stats().frames;
	const std::uint64_t poses_before = daemon.stats().poses_valid;
	const std::uint64_t previews_before = daemon.stats().preview_frames;
	test::armAllocationCounter();
	std::this_thread::sleep_for(1000ms);
	const long allocations = test::disarmAllocationCounter();
	const std::uint64_t frames = daemon.stats().frames - frames_before;
	const std::uint64_t poses = daemon.stats().poses_valid - poses_before;
	const std::uint64_t previews = daemon.stats().preview_frames - previews_before;

	stop = true;
	loop.join();
	std::fclose(log);

	ASSERT_GT(frames, 20u) << "the loop did not run";
	EXPECT_GT(poses, frames / 2) << "steady state means tracking";
	EXPECT_GT(previews, 0u) << "the preview published in the window";
	EXPECT_EQ(allocations, 0) << allocations << " allocations over " << frames << " frames";
}

} /* namespace */
} /* namespace dockpose::firmware */

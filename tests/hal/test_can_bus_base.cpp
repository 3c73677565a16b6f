/* SPDX-License-Identifier: MIT */
/*
 * CanBusBase (hal/can_bus_base.h): the contract every CAN backend shares,
 * checked on each of them with one typed test: the candump-log FileCanBus,
 * the in-process LoopbackCanBus, and SocketCanBus over a kernel side that
 * takes every frame (its real kernel runs in the VM tests).
 *  - a send on a closed bus, or of a frame canFrameProblem() refuses, is
 *    refused and counted in tx_errors, with a message naming the bus;
 *  - open() checks tx_queue_depth against 1..kMaxCanTxQueueDepth and starts
 *    the statistics afresh;
 *  - a good frame leaves (tx_frames), receive() on a closed bus gives nothing.
 */
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "hal/sim/file_can_bus.h"
#include "hal/sim/loopback_can_bus.h"
#include "hal/socketcan/socketcan_bus.h"

namespace dockpose::hal {
namespace {

/* A kernel side that opens, takes every write and has nothing to read. */
class AcceptingIo : public SocketCanIo
{
public:
	SocketCanOpenResult open(const SocketCanOpenRequest &, bool, std::span<char>) override
	{
		open_ = true;
		return SocketCanOpenResult::Opened;
	}
	void close() override { open_ = false; }
	int write(const void *, std::size_t) override { return 0; }
	int read(SocketCanRead *) override { return EAGAIN; }
	std::int64_t nowNs() const override { return 0; }
	int fd() const override { return open_ ? 99 : -1; }

private:
	bool open_ = false;
};

struct FileBackend {
	FileBackend()
		: path((std::filesystem::temp_directory_path() /
			("dockpose_can_base_" + std::to_string(::getpid()) + ".log"))
			       .string()),
		  bus(std::make_unique<FileCanBus>(path))
	{
	}
	~FileBackend()
	{
		bus.reset();
		std::filesystem::remove(path);
	}
	std::string path;
	std::unique_ptr<FileCanBus> bus;
};

struct LoopbackBackend {
	std::shared_ptr<LoopbackHub> hub = std::make_shared<LoopbackHub>();
	std::unique_ptr<LoopbackCanBus> bus = std::make_unique<LoopbackCanBus>(hub);
};

struct SocketCanBackend {
	std::unique_ptr<SocketCanBus> bus =
		std::make_unique<SocketCanBus>("vcan0", std::make_unique<AcceptingIo>());
};

CanFrame frame(std::uint32_t id, std::uint8_t len = 2)
{
	CanFrame f;
	f.id = id;
	f.len = len;
	f.data[0] = 0x12;
	f.data[1] = 0x34;
	return f;
}

template<typename Backend>
class CanBusBaseContract : public ::testing::Test
{
protected:
	Backend backend_;
	CanBusBase &bus() { return *backend_.bus; }
};

using Backends = ::testing::Types<FileBackend, LoopbackBackend, SocketCanBackend>;
TYPED_TEST_SUITE(CanBusBaseContract, Backends);

TYPED_TEST(CanBusBaseContract, ASendOnAClosedBusIsRefusedAndCounted)
{
	CanBusBase &bus = this->bus();
	EXPECT_FALSE(bus.send(frame(0x301)));
	EXPECT_EQ(bus.stats().state, CanState::Closed);
	EXPECT_EQ(bus.stats().tx_errors, 1u);
	EXPECT_EQ(bus.stats().tx_dropped, 0u);
	EXPECT_EQ(bus.lastError(),
		  bus.name() + ": send() while the bus is closed; frame 0x301 dropped");
	CanFrame f;
	EXPECT_FALSE(bus.receive(&f));
}

TYPED_TEST(CanBusBaseContract, OpenChecksTheQueueDepthAndStartsAfresh)
{
	CanBusBase &bus = this->bus();
	EXPECT_FALSE(bus.send(frame(0x301)));
	CanOptions options;
	for (const int depth : { 0, -3, static_cast<int>(kMaxCanTxQueueDepth) + 1 }) {
		options.tx_queue_depth = depth;
		const Status s = bus.open({}, options);
		ASSERT_FALSE(s.isOk()) << depth;
		EXPECT_EQ(s.message(), bus.name() + ": tx_queue_depth " + std::to_string(depth) +
					       " must be in [1, 4096]");
		EXPECT_EQ(bus.lastError(), s.message());
		EXPECT_EQ(bus.stats().state, CanState::Closed);
	}
	options.tx_queue_depth = static_cast<int>(kMaxCanTxQueueDepth);
	ASSERT_TRUE(bus.open({}, options).isOk()) << bus.lastError();
	const CanStats s = bus.stats();
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_EQ(s.tx_errors, 0u) << "open() starts the counts afresh";
	EXPECT_EQ(bus.lastError(), "");
}

TYPED_TEST(CanBusBaseContract, FramesTheValidatorRefusesAreNotQueued)
{
	CanBusBase &bus = this->bus();
	ASSERT_TRUE(bus.open({}, CanOptions{}).isOk()) << bus.lastError();
	EXPECT_FALSE(bus.send(frame(0x305, 9)));
	EXPECT_EQ(bus.lastError(),
		  bus.name() + ": frame 0x305 not sent: a classic CAN frame longer than 8 bytes");
	EXPECT_FALSE(bus.send(frame(0x800)));
	CanFrame fd = frame(0x123);
	fd.fd = true;
	EXPECT_FALSE(bus.send(fd));
	EXPECT_NE(bus.lastError().find("opened without fd"), std::string::npos) << bus.lastError();
	const CanStats s = bus.stats();
	EXPECT_EQ(s.tx_errors, 3u);
	EXPECT_EQ(s.tx_frames, 0u);
	EXPECT_EQ(s.tx_queued, 0u);

	EXPECT_TRUE(bus.send(frame(0x305)));
	bus.poll();
	EXPECT_EQ(bus.stats().tx_frames, 1u);
	EXPECT_EQ(bus.stats().tx_errors, 3u);
	bus.close();
	EXPECT_EQ(bus.stats().state, CanState::Closed);
	EXPECT_FALSE(bus.send(frame(0x305)));
}

} /* namespace */
} /* namespace dockpose::hal */

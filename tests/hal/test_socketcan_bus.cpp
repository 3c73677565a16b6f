/* SPDX-License-Identifier: MIT */
/*
 * SocketCanBus: its queueing, error-frame and reopening logic over a scripted
 * kernel side (FakeIo), its pure helpers, and the real kernel's answer on this
 * machine (no SocketCAN here: the clear error; in a CAN-capable VM: the
 * missing-interface error). The vcan behaviour itself is tested in the VM.
 */
#include <linux/can/error.h>
#include <net/if_arp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <new>
#include <thread>

#include <gtest/gtest.h>

#include "hal/socketcan/socketcan_bus.h"

/*
 * Allocation counting for the no-allocation test (tests/common/counting_allocator.h),
 * not under a sanitizer, which owns operator new and malloc (tests/common/sanitizer.h).
 */
#include "../common/sanitizer.h"
#if DOCKPOSE_SANITIZED
#define DOCKPOSE_COUNTS_ALLOCATIONS 0
namespace dockpose::test {
inline std::atomic<long> g_allocations{ 0 };
inline std::atomic<bool> g_armed{ false };
} /* namespace dockpose::test */
#else
#define DOCKPOSE_COUNTS_ALLOCATIONS 1
#include "../common/counting_allocator.h"
#endif

namespace dockpose::hal {
namespace {

using socketcan::WriteErrorKind;

/* A scripted kernel side, fixed-size so it never allocates either. */
class FakeIo : public SocketCanIo
{
public:
	static constexpr int kMax = 320;

	SocketCanOpenResult open(const SocketCanOpenRequest &request, bool describe,
				 std::span<char> error) override
	{
		++opens;
		last_describe = describe;
		last_fd = request.fd;
		last_filter_count = request.filters.size();
		if (!request.filters.empty())
			first_filter = request.filters[0];
		std::snprintf(last_interface, sizeof(last_interface), "%s", request.interface);
		if (fail_opens > 0) {
			--fail_opens;
			std::snprintf(error.data(), error.size(), "fake: no interface \"%s\"",
				      request.interface);
			return fail_result;
		}
		is_open = true;
		return SocketCanOpenResult::Opened;
	}
	void close() override { is_open = false; }
	int write(const void *frame, std::size_t size) override
	{
		EXPECT_TRUE(is_open);
		++write_calls;
		if (accept_writes == 0)
			return write_error;
		if (accept_writes > 0)
			--accept_writes;
		if (written_count < kMax) {
			std::memcpy(&written[written_count], frame, size);
			written_size[written_count] = size;
			++written_count;
		}
		return 0;
	}
	int read(SocketCanRead *out) override
	{
		EXPECT_TRUE(is_open);
		if (read_head == read_count)
			return read_error;
		*out = reads[read_head++];
		return 0;
	}
	std::int64_t nowNs() const override { return now_ns; }
	int fd() const override { return is_open ? 42 : -1; }

	/* Queue a classic frame (or error frame) for read(). */
	void addRead(const can_frame &f, std::int64_t ts_ns = 0)
	{
		SocketCanRead r;
		std::memcpy(&r.frame, &f, CAN_MTU);
		r.size = CAN_MTU;
		r.timestamp_ns = ts_ns;
		reads[read_count++] = r;
	}
	void addReadFd(const canfd_frame &f, std::int64_t ts_ns = 0)
	{
		SocketCanRead r;
		r.frame = f;
		r.size = CANFD_MTU;
		r.timestamp_ns = ts_ns;
		reads[read_count++] = r;
	}
	can_frame writtenClassic(int i) const
	{
		can_frame f;
		std::memcpy(&f, &written[i], CAN_MTU);
		return f;
	}

	/* Script. */
	int fail_opens = 0;
	SocketCanOpenResult fail_result = SocketCanOpenResult::Failed; /* what those opens say */
	int accept_writes = -1; /* -1: all; n: n more, then write_error */
	int write_error = ENOBUFS;
	int read_error = EAGAIN;
	std::int64_t now_ns = 1000000000;
	std::array<SocketCanRead, kMax> reads{};
	int read_head = 0;
	int read_count = 0;

	/* Record. */
	bool is_open = false;
	int opens = 0;
	bool last_describe = false;
	bool last_fd = false;
	std::size_t last_filter_count = 0;
	can_filter first_filter{};
	char last_interface[32] = "";
	int write_calls = 0;
	std::array<canfd_frame, kMax> written{};
	std::array<std::size_t, kMax> written_size{};
	int written_count = 0;
};

CanFrame frame(std::uint32_t id, std::uint8_t len = 2, std::uint8_t first = 0)
{
	CanFrame f;
	f.id = id;
	f.len = len;
	for (int i = 0; i < len; ++i)
		f.data[i] = static_cast<std::uint8_t>(first + i);
	return f;
}

can_frame kernelFrame(canid_t id, std::uint8_t dlc, std::uint8_t first = 0)
{
	can_frame f{};
	f.can_id = id;
	f.can_dlc = dlc;
	for (int i = 0; i < dlc && i < 8; ++i)
		f.data[i] = static_cast<std::uint8_t>(first + i);
	return f;
}

can_frame errorFrame(canid_t classes, std::uint8_t data1 = 0)
{
	can_frame f{};
	f.can_id = CAN_ERR_FLAG | classes;
	f.can_dlc = CAN_ERR_DLC;
	f.data[1] = data1;
	return f;
}

struct Harness {
	FakeIo *io;
	std::unique_ptr<SocketCanBus> bus;
};

Harness makeBus(int depth = 4, std::span<const CanFilter> filters = {}, bool fd = false,
		bool expect_open = true)
{
	auto io = std::make_unique<FakeIo>();
	FakeIo *raw = io.get();
	auto bus = std::make_unique<SocketCanBus>("vcan0", std::move(io));
	CanOptions options;
	options.tx_queue_depth = depth;
	options.fd = fd;
	const Status st = bus->open(filters, options);
	EXPECT_EQ(st.isOk(), expect_open) << st.message();
	return { raw, std::move(bus) };
}

/* ---- the bus over the fake kernel side ---------------------------------- */

TEST(SocketCanBus, OpenHandsTheKernelFiltersAndOptions)
{
	const CanFilter filters[] = { { 0x300, 0x7f0, false }, { 0x18ff0000, 0x1fff0000, true } };
	auto h = makeBus(4, filters, true);
	EXPECT_EQ(h.io->opens, 1);
	EXPECT_TRUE(h.io->last_describe);
	EXPECT_TRUE(h.io->last_fd);
	EXPECT_STREQ(h.io->last_interface, "vcan0");
	ASSERT_EQ(h.io->last_filter_count, 2u);
	EXPECT_EQ(h.io->first_filter.can_id, 0x300u);
	EXPECT_EQ(h.io->first_filter.can_mask, 0x7f0u | CAN_EFF_FLAG | CAN_RTR_FLAG);
	EXPECT_EQ(h.bus->stats().state, CanState::ErrorActive);
	EXPECT_EQ(h.bus->name(), "socketcan:vcan0");
	EXPECT_EQ(h.bus->fd(), 42);
}

TEST(SocketCanBus, OpenFailureLeavesItClosedAndSendsDrop)
{
	auto io = std::make_unique<FakeIo>();
	io->fail_opens = 1;
	SocketCanBus bus("can7", std::move(io));
	const Status st = bus.open({}, CanOptions{});
	ASSERT_FALSE(st.isOk());
	EXPECT_EQ(st.message(), "fake: no interface \"can7\"");
	EXPECT_EQ(bus.lastError(), st.message());
	EXPECT_EQ(bus.stats().state, CanState::Closed);
	EXPECT_FALSE(bus.send(frame(0x300)));
	EXPECT_EQ(bus.stats().tx_errors, 1u)
		<< "a send on a closed bus is refused, as on every backend";
	EXPECT_EQ(bus.stats().tx_dropped, 0u);
	bus.poll();
	CanFrame f;
	EXPECT_FALSE(bus.receive(&f));
	EXPECT_EQ(bus.fd(), -1);
}

TEST(SocketCanBus, OpenRejectsBadArguments)
{
	auto io = std::make_unique<FakeIo>();
	FakeIo *raw = io.get();
	SocketCanBus bus("can0", std::move(io));
	CanOptions options;
	options.tx_queue_depth = 0;
	Status st = bus.open({}, options);
	ASSERT_FALSE(st.isOk());
	EXPECT_EQ(st.message(), "socketcan:can0: tx_queue_depth 0 must be in [1, 4096]");
	options.tx_queue_depth = static_cast<int>(hal::kMaxCanTxQueueDepth) + 1;
	st = bus.open({}, options);
	ASSERT_FALSE(st.isOk());
	EXPECT_EQ(st.message(), "socketcan:can0: tx_queue_depth 4097 must be in [1, 4096]");
	options.tx_queue_depth = 1;

	std::vector<CanFilter> many(CAN_RAW_FILTER_MAX + 1);
	st = bus.open(many, CanOptions{});
	ASSERT_FALSE(st.isOk());
	EXPECT_EQ(st.message(), "can: 513 filters, the kernel takes at most 512");
	EXPECT_EQ(raw->opens, 0);

	SocketCanBus bad("can0:1", std::make_unique<FakeIo>());
	st = bad.open({}, CanOptions{});
	ASSERT_FALSE(st.isOk());
	EXPECT_NE(st.message().find("\"can0:1\" is not a valid interface name"), std::string::npos)
		<< st.message();
}

TEST(SocketCanBus, SendWritesClassicFrames)
{
	auto h = makeBus();
	CanFrame f = frame(0x301, 3, 0xa0);
	EXPECT_TRUE(h.bus->send(f));
	ASSERT_EQ(h.io->written_count, 1);
	EXPECT_EQ(h.io->written_size[0], CAN_MTU);
	const can_frame k = h.io->writtenClassic(0);
	EXPECT_EQ(k.can_id, 0x301u);
	EXPECT_EQ(k.can_dlc, 3);
	EXPECT_EQ(k.data[0], 0xa0);
	EXPECT_EQ(k.data[2], 0xa2);
	const CanStats s = h.bus->stats();
	EXPECT_EQ(s.tx_frames, 1u);
	EXPECT_EQ(s.tx_queued, 0u);
	EXPECT_EQ(s.tx_enobufs, 0u);
}

TEST(SocketCanBus, EnobufsKeepsTheFrameQueuedAndPollRetries)
{
	auto h = makeBus();
	h.io->accept_writes = 1;
	h.io->write_error = ENOBUFS;
	EXPECT_TRUE(h.bus->send(frame(0x300)));
	EXPECT_TRUE(h.bus->send(frame(0x301)));
	EXPECT_TRUE(h.bus->send(frame(0x302)));
	CanStats s = h.bus->stats();
	EXPECT_EQ(s.tx_frames, 1u);
	EXPECT_EQ(s.tx_queued, 2u);
	EXPECT_EQ(s.tx_enobufs, 2u); /* one refused write per send, no spinning */
	EXPECT_EQ(h.io->write_calls, 3);
	EXPECT_EQ(s.state, CanState::ErrorActive);

	h.io->accept_writes = -1;
	h.bus->poll();
	s = h.bus->stats();
	EXPECT_EQ(s.tx_frames, 3u);
	EXPECT_EQ(s.tx_queued, 0u);
	ASSERT_EQ(h.io->written_count, 3);
	EXPECT_EQ(h.io->writtenClassic(1).can_id, 0x301u);
	EXPECT_EQ(h.io->writtenClassic(2).can_id, 0x302u);
}

TEST(SocketCanBus, FullQueueDropsTheOldest)
{
	auto h = makeBus(3);
	h.io->accept_writes = 0;
	h.io->write_error = EAGAIN;
	bool results[5];
	for (int i = 0; i < 5; ++i)
		results[i] = h.bus->send(frame(0x300 + i));
	EXPECT_TRUE(results[0] && results[1] && results[2]);
	EXPECT_FALSE(results[3]);
	EXPECT_FALSE(results[4]);
	CanStats s = h.bus->stats();
	EXPECT_EQ(s.tx_dropped, 2u);
	EXPECT_EQ(s.tx_queued, 3u);
	EXPECT_EQ(s.tx_enobufs, 5u);

	h.io->accept_writes = -1;
	h.bus->poll();
	ASSERT_EQ(h.io->written_count, 3);
	EXPECT_EQ(h.io->writtenClassic(0).can_id, 0x302u);
	EXPECT_EQ(h.io->writtenClassic(1).can_id, 0x303u);
	EXPECT_EQ(h.io->writtenClassic(2).can_id, 0x304u);
}

TEST(SocketCanBus, RefusedFrameIsDroppedAndTheNextGoes)
{
	auto h = makeBus();
	h.io->accept_writes = 0;
	h.io->write_error = EINVAL;
	EXPECT_TRUE(h.bus->send(frame(0x300)));
	CanStats s = h.bus->stats();
	EXPECT_EQ(s.tx_errors, 1u);
	EXPECT_EQ(s.tx_queued, 0u);
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_NE(h.bus->lastError().find("refused frame 0x300"), std::string::npos)
		<< h.bus->lastError();

	h.io->accept_writes = -1;
	EXPECT_TRUE(h.bus->send(frame(0x301)));
	ASSERT_EQ(h.io->written_count, 1);
	EXPECT_EQ(h.io->writtenClassic(0).can_id, 0x301u);
}

TEST(SocketCanBus, UnsendableFramesAreRefusedWithoutQueueing)
{
	auto h = makeBus();
	CanFrame fd = frame(0x300, 12);
	fd.fd = true;
	EXPECT_FALSE(h.bus->send(fd));
	EXPECT_NE(h.bus->lastError().find("opened without fd"), std::string::npos)
		<< h.bus->lastError();
	EXPECT_FALSE(h.bus->send(frame(0x800)));
	CanFrame ext = frame(0x20000000);
	ext.extended = true;
	EXPECT_FALSE(h.bus->send(ext));
	/* A classic frame of 12 bytes: refused, as the simulated buses refuse it (before the
	 * shared validator, SocketCAN cut it to 8 bytes and sent it). */
	EXPECT_FALSE(h.bus->send(frame(0x301, 12)));
	EXPECT_NE(h.bus->lastError().find("longer than 8 bytes"), std::string::npos)
		<< h.bus->lastError();
	const CanStats s = h.bus->stats();
	EXPECT_EQ(s.tx_errors, 4u);
	EXPECT_EQ(s.tx_frames, 0u);
	EXPECT_EQ(s.tx_dropped, 0u);
	EXPECT_EQ(h.io->write_calls, 0);
}

TEST(SocketCanBus, FdFramesGoAsCanFdMtu)
{
	auto h = makeBus(4, {}, true);
	CanFrame f = frame(0x12345678, 10, 1);
	f.extended = true;
	f.fd = true;
	EXPECT_TRUE(h.bus->send(f)); /* 10 bytes go as 12, the padding zero */
	ASSERT_EQ(h.io->written_count, 1);
	EXPECT_EQ(h.io->written_size[0], CANFD_MTU);
	const canfd_frame &k = h.io->written[0];
	EXPECT_EQ(k.can_id, 0x12345678u | CAN_EFF_FLAG);
	EXPECT_EQ(k.len, 12);
	EXPECT_EQ(k.data[9], 10);
	EXPECT_EQ(k.data[11], 0);
}

TEST(SocketCanBus, LinkLossQueuesAndReopensEvery500ms)
{
	auto h = makeBus(3);
	h.io->accept_writes = 0;
	h.io->write_error = ENETDOWN;
	EXPECT_TRUE(h.bus->send(frame(0x300)));
	CanStats s = h.bus->stats();
	EXPECT_EQ(s.state, CanState::Down);
	EXPECT_EQ(s.tx_errors, 1u);
	EXPECT_EQ(s.tx_queued, 1u);
	EXPECT_FALSE(h.io->is_open);
	EXPECT_EQ(h.bus->fd(), -1);
	EXPECT_NE(h.bus->lastError().find("lost vcan0 (write: Network is down)"), std::string::npos)
		<< h.bus->lastError();

	/* Down: sends queue (oldest dropped), nothing is written. */
	const int writes = h.io->write_calls;
	for (int i = 1; i <= 3; ++i)
		h.bus->send(frame(0x300 + i));
	EXPECT_EQ(h.io->write_calls, writes);
	EXPECT_EQ(h.bus->stats().tx_dropped, 1u);

	/* First retry at the next poll (fails), then not before 500 ms. */
	h.io->fail_opens = 2;
	h.bus->poll();
	EXPECT_EQ(h.io->opens, 2);
	EXPECT_FALSE(h.io->last_describe);
	EXPECT_EQ(h.bus->lastError(), "fake: no interface \"vcan0\"");
	h.io->now_ns += 499000000;
	h.bus->poll();
	EXPECT_EQ(h.io->opens, 2);
	h.io->now_ns += 1000000;
	h.bus->poll();
	EXPECT_EQ(h.io->opens, 3);
	EXPECT_EQ(h.bus->stats().state, CanState::Down);

	/* Back: reopened, counted, the queue flushes. */
	h.io->accept_writes = -1;
	h.io->now_ns += 500000000;
	h.bus->poll();
	EXPECT_EQ(h.io->opens, 4);
	s = h.bus->stats();
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_EQ(s.restarts, 1u);
	EXPECT_EQ(s.tx_queued, 0u);
	EXPECT_EQ(s.tx_frames, 3u);
	ASSERT_EQ(h.io->written_count, 3);
	EXPECT_EQ(h.io->writtenClassic(0).can_id, 0x301u);
	EXPECT_EQ(h.io->writtenClassic(2).can_id, 0x303u);
	EXPECT_TRUE(h.io->is_open);
}

TEST(SocketCanBus, ReadErrorTakesTheLinkDown)
{
	auto h = makeBus();
	h.io->read_error = ENODEV;
	h.bus->poll();
	EXPECT_EQ(h.bus->stats().state, CanState::Down);
	EXPECT_EQ(h.bus->stats().tx_errors, 0u);
	EXPECT_NE(h.bus->lastError().find("(read: No such device)"), std::string::npos)
		<< h.bus->lastError();
	h.io->read_error = EAGAIN;
	h.bus->poll();
	EXPECT_EQ(h.bus->stats().state, CanState::ErrorActive);
	EXPECT_EQ(h.bus->stats().restarts, 1u);
}

/* At boot the interface may not exist yet, or not be up yet: the bus opens Down and joins it. */
TEST(SocketCanBus, InterfaceMissingAtOpenWaitsDownAndJoinsWhenItAppears)
{
	auto io = std::make_unique<FakeIo>();
	FakeIo *raw = io.get();
	io->fail_opens = 3;
	io->fail_result = SocketCanOpenResult::NotReady;
	SocketCanBus bus("can0", std::move(io));
	CanOptions options;
	options.tx_queue_depth = 3;
	const Status st = bus.open({}, options);
	ASSERT_TRUE(st.isOk()) << st.message();
	EXPECT_EQ(raw->opens, 1);
	EXPECT_TRUE(raw->last_describe) << "the first message lists the interfaces present";
	EXPECT_EQ(bus.stats().state, CanState::Down);
	EXPECT_EQ(bus.fd(), -1);
	EXPECT_EQ(bus.lastError(),
		  "fake: no interface \"can0\"; waiting for it (retried every 500 ms)");

	/* Down: sends queue (the oldest dropped past the depth), nothing is written. */
	for (int i = 0; i < 4; ++i)
		EXPECT_EQ(bus.send(frame(0x300 + i)), i < 3);
	EXPECT_EQ(raw->write_calls, 0);
	EXPECT_EQ(bus.stats().tx_queued, 3u);
	EXPECT_EQ(bus.stats().tx_dropped, 1u);
	EXPECT_EQ(bus.stats().tx_errors, 0u);

	/* open() itself just tried: the next try is an interval later, then every interval. */
	bus.poll();
	EXPECT_EQ(raw->opens, 1);
	raw->now_ns += 499000000;
	bus.poll();
	EXPECT_EQ(raw->opens, 1);
	raw->now_ns += 1000000;
	bus.poll();
	EXPECT_EQ(raw->opens, 2);
	EXPECT_FALSE(raw->last_describe) << "retries never allocate";
	EXPECT_EQ(bus.lastError(), "fake: no interface \"can0\"");
	raw->now_ns += 500000000;
	bus.poll();
	EXPECT_EQ(raw->opens, 3);
	EXPECT_EQ(bus.stats().state, CanState::Down);

	/* It appears: joined, the queue flushes in order, and joining late is no restart. */
	raw->now_ns += 500000000;
	bus.poll();
	EXPECT_EQ(raw->opens, 4);
	CanStats s = bus.stats();
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_EQ(s.restarts, 0u);
	EXPECT_EQ(s.tx_frames, 3u);
	EXPECT_EQ(s.tx_queued, 0u);
	ASSERT_EQ(raw->written_count, 3);
	EXPECT_EQ(raw->writtenClassic(0).can_id, 0x301u);
	EXPECT_EQ(raw->writtenClassic(2).can_id, 0x303u);
	EXPECT_EQ(bus.fd(), 42);
	EXPECT_TRUE(bus.send(frame(0x310)));
	EXPECT_EQ(raw->written_count, 4);

	/* Lost later, it is back as before: that one is a restart. */
	raw->read_error = ENODEV;
	bus.poll();
	EXPECT_EQ(bus.stats().state, CanState::Down);
	raw->read_error = EAGAIN;
	bus.poll();
	EXPECT_EQ(bus.stats().state, CanState::ErrorActive);
	EXPECT_EQ(bus.stats().restarts, 1u);

	/* A second open() that finds it missing waits again, and again joins without a restart. */
	raw->fail_opens = 1;
	ASSERT_TRUE(bus.open({}, options).isOk());
	EXPECT_EQ(bus.stats().state, CanState::Down);
	raw->now_ns += 500000000;
	bus.poll();
	EXPECT_EQ(bus.stats().state, CanState::ErrorActive);
	EXPECT_EQ(bus.stats().restarts, 0u) << "open() starts the counts afresh";
}

/* Problems the interface appearing would not fix stay open() failures, never retried. */
TEST(SocketCanBus, OtherOpenFailuresAreNotRetried)
{
	auto io = std::make_unique<FakeIo>();
	FakeIo *raw = io.get();
	io->fail_opens = 1;
	io->fail_result = SocketCanOpenResult::Failed;
	SocketCanBus bus("can0", std::move(io));
	const Status st = bus.open({}, CanOptions{});
	ASSERT_FALSE(st.isOk());
	EXPECT_EQ(st.message(), "fake: no interface \"can0\"");
	EXPECT_EQ(bus.stats().state, CanState::Closed);
	raw->now_ns += 5LL * SocketCanBus::kReopenInterval_ms * 1000000;
	bus.poll();
	CanFrame f;
	EXPECT_FALSE(bus.receive(&f));
	EXPECT_EQ(raw->opens, 1);
	EXPECT_EQ(bus.stats().state, CanState::Closed);
}

TEST(SocketCanBus, ReceivesFramesAndClassifiesErrorFrames)
{
	auto h = makeBus();
	h.io->addRead(kernelFrame(0x310, 4, 7), 111);
	h.io->addRead(errorFrame(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_WARNING));
	h.io->addRead(kernelFrame(0x1abcdef0 | CAN_EFF_FLAG, 8, 1), 222);
	canfd_frame fd{};
	fd.can_id = 0x320;
	fd.len = 20;
	fd.data[19] = 0x55;
	h.io->addReadFd(fd, 333);

	CanFrame f;
	ASSERT_TRUE(h.bus->receive(&f)); /* receive() polls when the ring is empty */
	EXPECT_EQ(f.id, 0x310u);
	EXPECT_FALSE(f.extended);
	EXPECT_EQ(f.len, 4);
	EXPECT_EQ(f.data[3], 10);
	EXPECT_EQ(f.timestamp_ns, 111);
	ASSERT_TRUE(h.bus->receive(&f));
	EXPECT_EQ(f.id, 0x1abcdef0u);
	EXPECT_TRUE(f.extended);
	EXPECT_EQ(f.timestamp_ns, 222);
	ASSERT_TRUE(h.bus->receive(&f));
	EXPECT_TRUE(f.fd);
	EXPECT_EQ(f.len, 20);
	EXPECT_EQ(f.data[19], 0x55);
	EXPECT_FALSE(h.bus->receive(&f));

	const CanStats s = h.bus->stats();
	EXPECT_EQ(s.rx_frames, 3u);
	EXPECT_EQ(s.error_frames, 1u);
	EXPECT_EQ(s.state, CanState::ErrorWarning);
}

TEST(SocketCanBus, BusOffAndRestartFromErrorFrames)
{
	auto h = makeBus();
	h.io->addRead(errorFrame(CAN_ERR_BUSOFF));
	h.bus->poll();
	CanStats s = h.bus->stats();
	EXPECT_EQ(s.state, CanState::BusOff);
	EXPECT_EQ(s.bus_off, 1u);

	/* Bus-off: the kernel refuses writes with ENOBUFS, the queue waits. */
	h.io->accept_writes = 0;
	h.io->write_error = ENOBUFS;
	EXPECT_TRUE(h.bus->send(frame(0x300)));
	EXPECT_EQ(h.bus->stats().tx_queued, 1u);

	h.io->addRead(errorFrame(CAN_ERR_RESTARTED));
	h.io->accept_writes = -1;
	h.bus->poll();
	s = h.bus->stats();
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_EQ(s.restarts, 1u);
	EXPECT_EQ(s.error_frames, 2u);
	EXPECT_EQ(s.tx_frames, 1u);
}

TEST(SocketCanBus, ReceiveRingDropsTheOldestAndCountsKernelDrops)
{
	auto h = makeBus();
	const int n = SocketCanBus::kRxRingFrames + 6;
	for (int i = 0; i < n; ++i)
		h.io->addRead(kernelFrame(static_cast<canid_t>(i), 1));
	h.io->reads[10].has_drop_count = true;
	h.io->reads[10].drop_count = 3;
	h.io->reads[20].has_drop_count = true;
	h.io->reads[20].drop_count = 5;
	h.bus->poll();
	EXPECT_EQ(h.bus->rxDropped(), 6u + 5u);
	EXPECT_EQ(h.bus->stats().rx_frames, static_cast<std::uint64_t>(n));
	CanFrame f;
	ASSERT_TRUE(h.bus->receive(&f));
	EXPECT_EQ(f.id, 6u);
	int count = 1;
	while (h.bus->receive(&f))
		++count;
	EXPECT_EQ(count, SocketCanBus::kRxRingFrames);
	EXPECT_EQ(f.id, static_cast<std::uint32_t>(n - 1));
}

TEST(SocketCanBus, PollReadsABoundedNumberOfFrames)
{
	auto h = makeBus();
	for (int i = 0; i < FakeIo::kMax; ++i)
		h.io->addRead(kernelFrame(0x100, 1));
	h.bus->poll();
	EXPECT_EQ(h.io->read_head, SocketCanBus::kMaxReadsPerPoll);
}

TEST(SocketCanBus, CloseStopsEverything)
{
	auto h = makeBus();
	h.io->accept_writes = 0;
	h.bus->send(frame(0x300));
	h.bus->close();
	EXPECT_FALSE(h.io->is_open);
	const CanStats s = h.bus->stats();
	EXPECT_EQ(s.state, CanState::Closed);
	EXPECT_EQ(s.tx_queued, 0u);
	EXPECT_FALSE(h.bus->send(frame(0x301)));
	EXPECT_EQ(h.bus->stats().tx_errors, 1u);

	/* Opening again starts afresh. */
	ASSERT_TRUE(h.bus->open({}, CanOptions{}).isOk());
	EXPECT_EQ(h.bus->stats().tx_errors, 0u);
	EXPECT_EQ(h.bus->stats().state, CanState::ErrorActive);
}

TEST(SocketCanBus, StatsAreSafeFromAnotherThread)
{
	auto h = makeBus(8);
	std::atomic<bool> done{ false };
	std::atomic<bool> consistent{ true };
	std::thread reader([&] {
		std::uint64_t last = 0;
		while (!done.load()) {
			const CanStats s = h.bus->stats();
			if (s.tx_frames < last || s.tx_frames > 20000)
				consistent = false;
			last = s.tx_frames;
		}
	});
	for (int i = 0; i < 20000; ++i) {
		if (h.io->written_count == FakeIo::kMax)
			h.io->written_count = 0;
		h.bus->send(frame(0x300));
	}
	done = true;
	reader.join();
	EXPECT_TRUE(consistent.load());
	EXPECT_EQ(h.bus->stats().tx_frames, 20000u);
}

TEST(SocketCanBus, FramePathNeverAllocates)
{
	if (!DOCKPOSE_COUNTS_ALLOCATIONS)
		GTEST_SKIP() << "allocations are not counted under AddressSanitizer";
	auto h = makeBus(4);
	for (int i = 0; i < 8; ++i)
		h.io->addRead(kernelFrame(0x310, 8));
	h.io->addRead(errorFrame(CAN_ERR_BUSOFF));
	h.io->addRead(errorFrame(CAN_ERR_RESTARTED));
	CanFrame f;

	test::g_allocations = 0;
	test::g_armed = true;
	for (int i = 0; i < 10; ++i)
		h.bus->send(frame(0x300 + i));
	h.io->accept_writes = 0;
	h.io->write_error = ENOBUFS;
	for (int i = 0; i < 10; ++i)
		h.bus->send(frame(0x300 + i));
	while (h.bus->receive(&f)) {
	}
	h.io->write_error = EINVAL;
	h.bus->poll();
	CanFrame fd = frame(0x300, 12);
	fd.fd = true;
	h.bus->send(fd);
	h.io->write_error = ENXIO;
	h.bus->send(frame(0x300)); /* the interface vanished: Down */
	h.io->fail_opens = 1;
	h.bus->poll(); /* a failed reopening */
	h.io->accept_writes = -1;
	h.io->now_ns += 600000000;
	h.bus->poll();
	(void)h.bus->stats();
	(void)h.bus->rxDropped();
	test::g_armed = false;

	EXPECT_EQ(test::g_allocations.load(), 0);
	EXPECT_EQ(h.io->opens, 3);

	/* The counter does count: lastError() returns a new string. */
	test::g_armed = true;
	const std::string error = h.bus->lastError();
	test::g_armed = false;
	EXPECT_GT(test::g_allocations.load(), 0) << error;
	EXPECT_EQ(h.bus->stats().restarts, 2u); /* one error frame, one reopening */
	EXPECT_EQ(h.bus->stats().state, CanState::ErrorActive);
}

/* ---- the real kernel on this machine ------------------------------------ */

int socketCanErrno()
{
	const int s = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
	if (s < 0)
		return errno;
	::close(s);
	return 0;
}

TEST(SocketCanKernel, OpenSaysWhatIsMissing)
{
	SocketCanBus bus("dpnx9");
	const Status st = bus.open({}, CanOptions{});
	const int err = socketCanErrno();
	if (err == 0) {
		/* SocketCAN but no such interface: open, Down, waiting for it. */
		ASSERT_TRUE(st.isOk()) << st.message();
		EXPECT_EQ(bus.stats().state, CanState::Down);
		EXPECT_EQ(bus.lastError().rfind("can: no CAN interface \"dpnx9\"", 0), 0u)
			<< bus.lastError();
		EXPECT_NE(bus.lastError().find("; waiting for it (retried every 500 ms)"),
			  std::string::npos)
			<< bus.lastError();
		EXPECT_TRUE(bus.send(frame(0x300))) << "queued until the interface is there";
		return;
	}
	ASSERT_FALSE(st.isOk());
	EXPECT_EQ(bus.lastError(), st.message());
	EXPECT_EQ(bus.stats().state, CanState::Closed);
	if (err == EAFNOSUPPORT)
		EXPECT_EQ(st.message(),
			  "can: this kernel has no SocketCAN support (socket(PF_CAN): "
			  "Address family not supported by protocol)");
	else
		EXPECT_NE(st.message().find("socket(PF_CAN"), std::string::npos) << st.message();
	EXPECT_FALSE(bus.send(frame(0x300)));
}

TEST(SocketCanKernel, SocketErrorMessages)
{
	char buf[200];
	socketcan::socketErrorMessage(EAFNOSUPPORT, buf);
	EXPECT_STREQ(buf,
		     "can: this kernel has no SocketCAN support (socket(PF_CAN): Address family "
		     "not supported by protocol)");
	socketcan::socketErrorMessage(EPROTONOSUPPORT, buf);
	EXPECT_NE(std::strstr(buf, "CONFIG_CAN_RAW"), nullptr) << buf;
	socketcan::socketErrorMessage(EMFILE, buf);
	EXPECT_STREQ(buf, "can: socket(PF_CAN) failed: Too many open files");
	char tiny[8];
	socketcan::socketErrorMessage(EAFNOSUPPORT, tiny);
	EXPECT_STREQ(tiny, "can: th");
}

TEST(SocketCanKernel, QueryInterfaceOnAnySocket)
{
	const int s = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
	ASSERT_GE(s, 0);
	socketcan::InterfaceInfo info;
	ASSERT_EQ(socketcan::queryInterface(s, "lo", &info), 0);
	EXPECT_GT(info.index, 0);
	EXPECT_FALSE(info.is_can);
	EXPECT_GT(info.mtu, 0);
	char buf[200];
	EXPECT_FALSE(socketcan::checkInterface("lo", info, false, 500000, buf));
	EXPECT_STREQ(buf, "can: interface \"lo\" is not a CAN interface");

	EXPECT_EQ(socketcan::queryInterface(s, "dpnx9", &info), ENODEV);
	EXPECT_EQ(socketcan::queryInterface(s, "", &info), ENODEV);
	::close(s);
}

TEST(SocketCanKernel, CheckInterface)
{
	char buf[200];
	socketcan::InterfaceInfo can0;
	can0.index = 3;
	can0.is_can = true;
	can0.up = false;
	can0.mtu = CAN_MTU;
	EXPECT_FALSE(socketcan::checkInterface("can0", can0, false, 500000, buf));
	EXPECT_STREQ(buf, "can: interface \"can0\" is down "
			  "(ip link set can0 up type can bitrate 500000)");
	EXPECT_FALSE(socketcan::checkInterface("can1", can0, false, 250000, buf));
	EXPECT_STREQ(buf, "can: interface \"can1\" is down "
			  "(ip link set can1 up type can bitrate 250000)");
	EXPECT_FALSE(socketcan::checkInterface("vcan0", can0, false, 500000, buf));
	EXPECT_STREQ(buf, "can: interface \"vcan0\" is down (ip link set vcan0 up)");

	can0.up = true;
	EXPECT_TRUE(socketcan::checkInterface("can0", can0, false, 500000, buf));
	EXPECT_FALSE(socketcan::checkInterface("can0", can0, true, 500000, buf));
	EXPECT_STREQ(buf, "can: interface \"can0\" does not support CAN FD (MTU 16, not 72: "
			  "ip link set can0 type can ... fd on)");
	can0.mtu = CANFD_MTU;
	EXPECT_TRUE(socketcan::checkInterface("can0", can0, true, 500000, buf));
}

class SysfsTree : public ::testing::Test
{
protected:
	void SetUp() override
	{
		root_ = std::filesystem::temp_directory_path() /
			("dockpose_sysfs_" + std::to_string(::getpid()) + "_" +
			 ::testing::UnitTest::GetInstance()->current_test_info()->name());
		std::filesystem::remove_all(root_);
		std::filesystem::create_directories(root_);
	}
	void TearDown() override { std::filesystem::remove_all(root_); }
	void add(const std::string &name, int type, int index)
	{
		std::filesystem::create_directories(root_ / name);
		std::ofstream(root_ / name / "type") << type << "\n";
		std::ofstream(root_ / name / "ifindex") << index << "\n";
	}
	std::filesystem::path root_;
};

TEST_F(SysfsTree, MissingInterfaceListsCanInterfaces)
{
	add("eth0", ARPHRD_ETHER, 2);
	add("lo", ARPHRD_LOOPBACK, 1);
	add("vcan0", ARPHRD_CAN, 5);
	add("can0", ARPHRD_CAN, 4);
	std::ofstream(root_ / "bonding_masters") << "\n";
	EXPECT_EQ(socketcan::missingInterfaceMessage("can7", root_.string()),
		  "can: no CAN interface \"can7\" (CAN interfaces present: can0, vcan0)");
	const auto all = socketcan::listInterfaces(root_.string(), false);
	EXPECT_EQ(all, (std::vector<std::string>{ "lo", "eth0", "can0", "vcan0" }));
}

TEST_F(SysfsTree, MissingInterfaceWithoutAnyCan)
{
	add("eth0", ARPHRD_ETHER, 2);
	add("lo", ARPHRD_LOOPBACK, 1);
	EXPECT_EQ(socketcan::missingInterfaceMessage("can7", root_.string()),
		  "can: no CAN interface \"can7\" "
		  "(interfaces present: lo, eth0; none is a CAN interface)");
	EXPECT_EQ(socketcan::missingInterfaceMessage("can7", (root_ / "absent").string()),
		  "can: no CAN interface \"can7\"");
}

TEST(SocketCanKernel, InterfaceNames)
{
	EXPECT_TRUE(socketcan::validInterfaceName("can0"));
	EXPECT_TRUE(socketcan::validInterfaceName("vcan_long_name0")); /* 15 characters */
	EXPECT_FALSE(socketcan::validInterfaceName("vcan_long_name01"));
	EXPECT_FALSE(socketcan::validInterfaceName(""));
	EXPECT_FALSE(socketcan::validInterfaceName("can 0"));
	EXPECT_FALSE(socketcan::validInterfaceName("a/b"));
	EXPECT_FALSE(socketcan::validInterfaceName(".."));
}

/* ---- pure helpers -------------------------------------------------------- */

TEST(SocketCanPure, ErrorFrameClassification)
{
	CanStats s;
	s.state = CanState::ErrorActive;

	socketcan::classifyErrorFrame(kernelFrame(0x123, 8), &s); /* not an error frame */
	EXPECT_EQ(s.error_frames, 0u);

	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_PROT | CAN_ERR_BUSERROR), &s);
	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_ACK), &s);
	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_TX_TIMEOUT), &s);
	EXPECT_EQ(s.error_frames, 3u);
	EXPECT_EQ(s.state, CanState::ErrorActive);

	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_OVERFLOW), &s);
	EXPECT_EQ(s.state, CanState::ErrorActive);
	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_WARNING), &s);
	EXPECT_EQ(s.state, CanState::ErrorWarning);
	socketcan::classifyErrorFrame(
		errorFrame(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_WARNING | CAN_ERR_CRTL_TX_PASSIVE), &s);
	EXPECT_EQ(s.state, CanState::ErrorPassive);
	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_PASSIVE), &s);
	EXPECT_EQ(s.state, CanState::ErrorPassive);
	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE), &s);
	EXPECT_EQ(s.state, CanState::ErrorActive);

	/* Bus-off wins over a controller state in the same frame. */
	socketcan::classifyErrorFrame(
		errorFrame(CAN_ERR_BUSOFF | CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE), &s);
	EXPECT_EQ(s.state, CanState::BusOff);
	EXPECT_EQ(s.bus_off, 1u);
	EXPECT_EQ(s.restarts, 0u);

	socketcan::classifyErrorFrame(errorFrame(CAN_ERR_RESTARTED), &s);
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_EQ(s.restarts, 1u);
	EXPECT_EQ(s.error_frames, 10u);
	EXPECT_EQ(s.bus_off, 1u);
}

TEST(SocketCanPure, ClassicConversion)
{
	CanFrame f = frame(0x7ff, 12, 1); /* len clamps to 8 */
	can_frame k;
	ASSERT_TRUE(socketcan::toCanFrame(f, &k));
	EXPECT_EQ(k.can_id, 0x7ffu);
	EXPECT_EQ(k.can_dlc, 8);
	EXPECT_EQ(k.data[7], 8);

	f = frame(0x1fffffff, 2);
	f.extended = true;
	ASSERT_TRUE(socketcan::toCanFrame(f, &k));
	EXPECT_EQ(k.can_id, 0x1fffffffu | CAN_EFF_FLAG);
	EXPECT_EQ(k.data[2], 0);

	f.id = 0x20000000;
	EXPECT_FALSE(socketcan::toCanFrame(f, &k));
	EXPECT_FALSE(socketcan::toCanFrame(frame(0x800), &k));
	CanFrame ext_small = frame(0x5);
	ext_small.extended = true;
	ASSERT_TRUE(socketcan::toCanFrame(ext_small, &k));
	EXPECT_EQ(k.can_id, 0x5u | CAN_EFF_FLAG);

	CanFrame back;
	ASSERT_TRUE(socketcan::fromCanFrame(kernelFrame(0x123, 5, 9), 77, &back));
	EXPECT_EQ(back.id, 0x123u);
	EXPECT_FALSE(back.extended);
	EXPECT_FALSE(back.fd);
	EXPECT_EQ(back.len, 5);
	EXPECT_EQ(back.data[4], 13);
	EXPECT_EQ(back.data[5], 0);
	EXPECT_EQ(back.timestamp_ns, 77);

	can_frame big = kernelFrame(0x1234 | CAN_EFF_FLAG, 8);
	big.can_dlc = 15; /* a DLC above 8 still carries 8 bytes */
	ASSERT_TRUE(socketcan::fromCanFrame(big, 0, &back));
	EXPECT_TRUE(back.extended);
	EXPECT_EQ(back.id, 0x1234u);
	EXPECT_EQ(back.len, 8);

	EXPECT_FALSE(socketcan::fromCanFrame(kernelFrame(0x123 | CAN_RTR_FLAG, 0), 0, &back));
	EXPECT_FALSE(socketcan::fromCanFrame(errorFrame(CAN_ERR_BUSOFF), 0, &back));
}

TEST(SocketCanPure, FdConversion)
{
	EXPECT_EQ(canFdLength(0), 0);
	EXPECT_EQ(canFdLength(8), 8);
	EXPECT_EQ(canFdLength(9), 12);
	EXPECT_EQ(canFdLength(13), 16);
	EXPECT_EQ(canFdLength(24), 24);
	EXPECT_EQ(canFdLength(25), 32);
	EXPECT_EQ(canFdLength(33), 48);
	EXPECT_EQ(canFdLength(49), 64);
	EXPECT_EQ(canFdLength(200), 64);

	CanFrame f = frame(0x123, 33, 1);
	f.fd = true;
	f.data[40] = 0xee; /* beyond len: must not leak into the padding */
	canfd_frame k;
	ASSERT_TRUE(socketcan::toCanFdFrame(f, &k));
	EXPECT_EQ(k.can_id, 0x123u);
	EXPECT_EQ(k.len, 48);
	EXPECT_EQ(k.flags, 0);
	EXPECT_EQ(k.data[32], 33);
	EXPECT_EQ(k.data[33], 0);
	EXPECT_EQ(k.data[40], 0);

	f.len = 100;
	ASSERT_TRUE(socketcan::toCanFdFrame(f, &k));
	EXPECT_EQ(k.len, 64);
	f.extended = true;
	f.id = 0x12345678;
	ASSERT_TRUE(socketcan::toCanFdFrame(f, &k));
	EXPECT_EQ(k.can_id, 0x12345678u | CAN_EFF_FLAG);
	f.extended = false;
	EXPECT_FALSE(socketcan::toCanFdFrame(f, &k));

	canfd_frame in{};
	in.can_id = 0x1abc | CAN_EFF_FLAG;
	in.len = 70; /* malformed: clamps to 64 */
	in.data[63] = 0x42;
	CanFrame back;
	ASSERT_TRUE(socketcan::fromCanFdFrame(in, 5, &back));
	EXPECT_TRUE(back.fd);
	EXPECT_TRUE(back.extended);
	EXPECT_EQ(back.id, 0x1abcu);
	EXPECT_EQ(back.len, 64);
	EXPECT_EQ(back.data[63], 0x42);
	in.can_id |= CAN_ERR_FLAG;
	EXPECT_FALSE(socketcan::fromCanFdFrame(in, 5, &back));
}

/* The validator every backend's send() shares (hal/can_bus.h). */
TEST(CanFrameProblem, IdsLengthsAndFd)
{
	EXPECT_EQ(canFrameProblem(frame(0x7ff), false), nullptr);
	EXPECT_NE(canFrameProblem(frame(0x800), false), nullptr);
	CanFrame f = frame(0x1fffffff);
	f.extended = true;
	EXPECT_EQ(canFrameProblem(f, false), nullptr);
	f.id = 0x20000000;
	EXPECT_NE(canFrameProblem(f, false), nullptr);
	f.id = 0x1fffffff;
	f.fd = true;
	EXPECT_NE(canFrameProblem(f, false), nullptr);
	EXPECT_EQ(canFrameProblem(f, true), nullptr);
	/* Lengths: classic up to 8; FD only its own lengths. */
	CanFrame classic = frame(0x123);
	classic.len = 8;
	EXPECT_EQ(canFrameProblem(classic, true), nullptr);
	classic.len = 9;
	EXPECT_NE(canFrameProblem(classic, true), nullptr);
	for (const int len : { 0, 8, 10, 12, 63, 64 }) {
		f.len = static_cast<std::uint8_t>(len);
		EXPECT_EQ(canFrameProblem(f, true), nullptr) << len;
	}
	for (const int len : { 65, 255 }) {
		f.len = static_cast<std::uint8_t>(len);
		EXPECT_NE(canFrameProblem(f, true), nullptr) << len;
	}
	/* On the wire: FD rounded up, zero padded; classic as it is. */
	f.len = 10;
	f.data.fill(0xaa);
	const CanFrame wire = canWireFrame(f);
	EXPECT_EQ(wire.len, 12);
	EXPECT_EQ(wire.data[9], 0xaa);
	EXPECT_EQ(wire.data[10], 0);
	EXPECT_EQ(wire.data[11], 0);
	EXPECT_EQ(canWireFrame(classic).len, 9) << "classic frames are not the wire's business";
}

/* The kernel's CAN_RAW match: (can_id & mask) == (filter.can_id & mask). */
bool kernelPasses(const can_filter &k, canid_t can_id)
{
	return (can_id & k.can_mask) == (k.can_id & k.can_mask);
}

TEST(SocketCanPure, KernelFilters)
{
	const can_filter std_filter = socketcan::toKernelFilter({ 0x300, 0x7f0, false });
	EXPECT_TRUE(kernelPasses(std_filter, 0x300));
	EXPECT_TRUE(kernelPasses(std_filter, 0x30f));
	EXPECT_FALSE(kernelPasses(std_filter, 0x310));
	EXPECT_FALSE(kernelPasses(std_filter, 0x300 | CAN_EFF_FLAG)); /* 29-bit id 0x300 */
	EXPECT_FALSE(kernelPasses(std_filter, 0x300 | CAN_RTR_FLAG));

	const can_filter ext_filter = socketcan::toKernelFilter({ 0x18ff0000, 0x1fff0000, true });
	EXPECT_TRUE(kernelPasses(ext_filter, 0x18ff1234 | CAN_EFF_FLAG));
	EXPECT_FALSE(kernelPasses(ext_filter, 0x18fe1234 | CAN_EFF_FLAG));
	EXPECT_FALSE(kernelPasses(ext_filter, 0x0));
	EXPECT_FALSE(kernelPasses(ext_filter, 0x18ff1234 | CAN_EFF_FLAG | CAN_RTR_FLAG));

	const can_filter all_std = socketcan::toKernelFilter({ 0, 0, false });
	EXPECT_TRUE(kernelPasses(all_std, 0x7ff));
	EXPECT_FALSE(kernelPasses(all_std, 0x7ff | CAN_EFF_FLAG));
}

TEST(SocketCanPure, WriteErrors)
{
	EXPECT_EQ(socketcan::classifyWriteError(ENOBUFS), WriteErrorKind::QueueFull);
	EXPECT_EQ(socketcan::classifyWriteError(EAGAIN), WriteErrorKind::QueueFull);
	EXPECT_EQ(socketcan::classifyWriteError(EINTR), WriteErrorKind::Interrupted);
	EXPECT_EQ(socketcan::classifyWriteError(EINVAL), WriteErrorKind::BadFrame);
	EXPECT_EQ(socketcan::classifyWriteError(EMSGSIZE), WriteErrorKind::BadFrame);
	EXPECT_EQ(socketcan::classifyWriteError(ENETDOWN), WriteErrorKind::LinkLost);
	EXPECT_EQ(socketcan::classifyWriteError(ENXIO), WriteErrorKind::LinkLost);
	EXPECT_EQ(socketcan::classifyWriteError(ENODEV), WriteErrorKind::LinkLost);
}

TEST(SocketCanPure, KernelTimestampsOnTheMonotonicClock)
{
	/* Received 3 ms before now on the wall clock: 3 ms before now on the monotonic clock. */
	EXPECT_EQ(socketcan::realtimeToMonotonicNs(1700000000000000000LL, 1700000000003000000LL,
						   5000000000LL),
		  4997000000LL);
	/* No timestamp, or a wall clock stepped back: the read time. */
	EXPECT_EQ(socketcan::realtimeToMonotonicNs(0, 1700000000000000000LL, 5000000000LL),
		  5000000000LL);
	EXPECT_EQ(socketcan::realtimeToMonotonicNs(1700000000003000000LL, 1700000000000000000LL,
						   5000000000LL),
		  5000000000LL);
}

} /* namespace */
} /* namespace dockpose::hal */

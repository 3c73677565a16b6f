/* SPDX-License-Identifier: MIT */
/*
 * SocketCanBus against the kernel's vcan driver, inside a test VM (scripts/vm;
 * run by ctest as vm_<arch>_vcan_socketcan). The ecosystem's tools are the
 * independent witnesses: candump records what went on the bus, cansend puts
 * frames on it, ip and tc change the interfaces under the open bus.
 *
 *  - frames sent reach candump and a second socket unchanged, in order, with
 *    kernel timestamps on CLOCK_MONOTONIC; the sender does not get its own back;
 *    CAN FD frames travel padded to a CAN FD length
 *  - the kernel filters: of frames sent with cansend only the matching kind and
 *    ids are received; an empty filter list receives nothing
 *  - the bounded queue under ENOBUFS: vcan has no queue of its own (it delivers
 *    while the sender is still in send()), so shrinking txqueuelen alone changes
 *    nothing; a slow qdisc is put in front of it over rtnetlink (what tc does):
 *    tbf at 1 kbit/s (one classic frame per 128 ms) whose pfifo holds txqueuelen
 *    frames (set to 4). The kernel then refuses frames with ENOBUFS; send() still
 *    never blocks, the queue keeps the newest frames and counts the oldest it
 *    drops, and poll() gets the rest out as the qdisc drains, except those whose
 *    deadline passed while they waited: they are dropped unsent (tx_expired),
 *    never sent late, so what reaches the bus after the stall is only what the
 *    kernel already held (txqueuelen frames) and frames still in time. Needs
 *    CONFIG_NET_SCHED and CONFIG_NET_SCH_TBF in the test kernel (skipped, saying
 *    so, without); tc qdisc show is the witness of the setup
 *  - a missing interface at open() (the message lists the CAN interfaces
 *    present) and one that is down at open(): open() succeeds, state Down, and
 *    the bus joins the interface when it is added and up (no restart counted);
 *    one that is not a CAN interface: open() fails. One set down while open, and
 *    one deleted while open and added again: state Down, frames queue, the bus
 *    reopens by itself with its filters (restarts counted) and the queued frames
 *    go out.
 *
 * The VM's guest-init.sh creates vcan0 and vcan1 (up); tests that change them
 * put them back. Outside a test VM the program exits 77 (skipped).
 */
#include <fcntl.h>
#include <linux/netlink.h>
#include <linux/pkt_sched.h>
#include <linux/rtnetlink.h>
#include <net/if.h>
#include <signal.h>
#include <spawn.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "hal/clock.h"
#include "hal/socketcan/socketcan_bus.h"
#include "vm_shell.h"

extern char **environ;

namespace {

using dockpose::hal::CanFilter;
using dockpose::hal::CanFrame;
using dockpose::hal::CanOptions;
using dockpose::hal::CanState;
using dockpose::hal::canStateName;
using dockpose::hal::CanStats;
using dockpose::hal::monotonicNs;
using dockpose::hal::SocketCanBus;

using dockpose::vmtest::CommandResult;
using dockpose::vmtest::mustRun;
using dockpose::vmtest::run;
using dockpose::vmtest::waitUntil;

bool interfaceExists(const std::string &name)
{
	struct stat st {
	};
	return stat(("/sys/class/net/" + name).c_str(), &st) == 0;
}

std::string readFile(const std::string &path)
{
	std::ifstream in(path);
	std::stringstream s;
	s << in.rdbuf();
	return s.str();
}

/* vcan1 as guest-init.sh made it: present and up (tests delete it or set it down). */
void restoreVcan1()
{
	if (!interfaceExists("vcan1"))
		(void)run("ip link add dev vcan1 type vcan");
	(void)run("ip link set vcan1 up");
}

CanFrame classicFrame(std::uint32_t id, std::initializer_list<std::uint8_t> bytes,
		      bool extended = false)
{
	CanFrame f;
	f.id = id;
	f.extended = extended;
	f.len = static_cast<std::uint8_t>(bytes.size());
	std::copy(bytes.begin(), bytes.end(), f.data.begin());
	return f;
}

/* A frame numbered seq: id, then seq in the first two data bytes. */
CanFrame numberedFrame(std::uint32_t id, int seq)
{
	return classicFrame(id, { static_cast<std::uint8_t>(seq >> 8),
				  static_cast<std::uint8_t>(seq & 0xff), 0xa5 });
}

int seqOf(const CanFrame &f)
{
	return (f.data[0] << 8) | f.data[1];
}

/* candump -L's text for a frame: "123#DEADBEEF", "18DAF1AB#01", "123##0<data>" (FD). */
std::string candumpText(const CanFrame &f)
{
	char id[16];
	std::snprintf(id, sizeof(id), f.extended ? "%08X" : "%03X", f.id);
	std::string s = id;
	s += f.fd ? "##0" : "#";
	char byte[4];
	for (int i = 0; i < f.len; ++i) {
		std::snprintf(byte, sizeof(byte), "%02X", f.data[static_cast<std::size_t>(i)]);
		s += byte;
	}
	return s;
}

/* Receive until n frames arrived or timeout_ms passed (a hang guard: vcan delivers at once).
 * longest_receive_ns, when given: the longest receive() call that returned a frame. */
std::vector<CanFrame> receiveFrames(SocketCanBus &bus, std::size_t n, int timeout_ms,
				    std::int64_t *longest_receive_ns = nullptr)
{
	std::vector<CanFrame> frames;
	waitUntil(
		[&] {
			CanFrame f;
			while (frames.size() < n) {
				const std::int64_t t0 = monotonicNs();
				if (!bus.receive(&f))
					break;
				if (longest_receive_ns)
					*longest_receive_ns =
						std::max(*longest_receive_ns, monotonicNs() - t0);
				frames.push_back(f);
			}
			return frames.size() >= n;
		},
		timeout_ms);
	return frames;
}

/* Everything received within quiet_ms of nothing more arriving. */
std::vector<CanFrame> receiveAll(SocketCanBus &bus, int quiet_ms)
{
	std::vector<CanFrame> frames;
	std::int64_t last_ns = monotonicNs();
	while (monotonicNs() - last_ns < static_cast<std::int64_t>(quiet_ms) * 1000000) {
		CanFrame f;
		if (bus.receive(&f)) {
			frames.push_back(f);
			last_ns = monotonicNs();
		} else {
			std::this_thread::sleep_for(std::chrono::milliseconds(2));
		}
	}
	return frames;
}

/* The raw sockets listening to every frame on an interface (/proc/net/can/rcvlist_all). */
int allFrameListeners(const std::string &interface)
{
	std::istringstream in(readFile("/proc/net/can/rcvlist_all"));
	std::string line;
	int n = 0;
	while (std::getline(in, line)) {
		std::istringstream words(line);
		std::string first;
		words >> first;
		if (first == interface)
			++n;
	}
	return n;
}

/*
 * candump -L -n COUNT INTERFACE in the background, writing to a file in the guest's /tmp.
 * It exits by itself after COUNT frames (candump reads one frame per wake-up and stops at
 * SIGTERM, leaving what it has not read yet: a SIGTERM would lose frames).
 */
class Candump
{
public:
	Candump(std::string interface, int count)
		: interface_(std::move(interface))
	{
		char path[] = "/tmp/candump-XXXXXX";
		const int fd = mkstemp(path);
		if (fd < 0)
			return;
		path_ = path;
		const int listeners = allFrameListeners(interface_);
		posix_spawn_file_actions_t actions;
		posix_spawn_file_actions_init(&actions);
		posix_spawn_file_actions_adddup2(&actions, fd, STDOUT_FILENO);
		posix_spawn_file_actions_addclose(&actions, fd);
		std::string iface = interface_;
		std::string count_text = std::to_string(count);
		char arg0[] = "candump";
		char arg1[] = "-L";
		char arg2[] = "-n";
		char *argv[] = { arg0, arg1, arg2, count_text.data(), iface.data(), nullptr };
		if (posix_spawnp(&pid_, "candump", &actions, nullptr, argv, environ) != 0)
			pid_ = -1;
		posix_spawn_file_actions_destroy(&actions);
		::close(fd);
		/* Ready once its socket is bound: one more listener for every frame. */
		ready_ =
			pid_ > 0 &&
			waitUntil([&] { return allFrameListeners(interface_) > listeners; }, 10000);
	}
	~Candump()
	{
		stop();
		if (!path_.empty())
			::unlink(path_.c_str());
	}
	Candump(const Candump &) = delete;
	Candump &operator=(const Candump &) = delete;

	bool ready() const { return ready_; }

	/* Wait for it to exit (SIGTERM after timeout_ms); the frames it logged, as "ID#DATA". */
	std::vector<std::string> stop(int timeout_ms = 10000)
	{
		if (pid_ > 0) {
			int status = 0;
			if (!waitUntil([&] { return ::waitpid(pid_, &status, WNOHANG) == pid_; },
				       timeout_ms)) {
				::kill(pid_, SIGTERM);
				::waitpid(pid_, &status, 0);
			}
			pid_ = -1;
		}
		std::vector<std::string> frames;
		std::istringstream in(readFile(path_));
		std::string ts, iface, frame;
		while (in >> ts >> iface >> frame)
			if (iface == interface_)
				frames.push_back(frame);
		return frames;
	}

private:
	std::string interface_;
	std::string path_;
	pid_t pid_ = -1;
	bool ready_ = false;
};

const CanFilter kAcceptAll[] = { { 0, 0, false }, { 0, 0, true } };

/* A listener on an interface receiving every frame (its own SocketCanBus). */
void openWitness(SocketCanBus &bus, bool fd = false)
{
	CanOptions options;
	options.fd = fd;
	const auto status = bus.open(kAcceptAll, options);
	ASSERT_TRUE(status.isOk()) << status.message();
}

/* ------------------------------------------------------------------------- */

TEST(VcanSocketCan, SentFramesReachCandumpAndASecondSocketUnchanged)
{
	SocketCanBus witness("vcan0");
	openWitness(witness);
	SocketCanBus bus("vcan0");
	/* The sender listens to everything too: its own frames must not come back. */
	const auto status = bus.open(kAcceptAll, CanOptions{});
	ASSERT_TRUE(status.isOk()) << status.message();
	EXPECT_EQ(bus.name(), "socketcan:vcan0");
	EXPECT_EQ(bus.stats().state, CanState::ErrorActive);
	EXPECT_GE(bus.fd(), 0);

	std::vector<CanFrame> sent;
	sent.push_back(classicFrame(0x000, {}));
	sent.push_back(classicFrame(0x7ff, { 0xde, 0xad, 0xbe, 0xef, 0x01, 0x02, 0x03, 0x04 }));
	sent.push_back(classicFrame(0x18daf1ab, { 0x11, 0x22 }, true));
	sent.push_back(classicFrame(0x1fffffff, { 0x00 }, true));
	sent.push_back(
		classicFrame(0x00000123, { 0x33 }, true)); /* 29-bit id 0x123, not 11-bit 0x123 */
	for (int i = 0; i < 20; ++i)
		sent.push_back(numberedFrame(0x300 + static_cast<std::uint32_t>(i % 16), i));

	Candump candump("vcan0", static_cast<int>(sent.size()));
	ASSERT_TRUE(candump.ready()) << "candump -L vcan0 did not start listening";

	const std::int64_t before_ns = monotonicNs();
	for (const CanFrame &f : sent)
		EXPECT_TRUE(bus.send(f)) << bus.lastError();

	std::int64_t longest_receive_ns = 0;
	const std::vector<CanFrame> got =
		receiveFrames(witness, sent.size(), 5000, &longest_receive_ns);
	const std::int64_t after_ns = monotonicNs();
	ASSERT_EQ(got.size(), sent.size())
		<< "the second socket got " << got.size() << " of " << sent.size();
	for (std::size_t i = 0; i < sent.size(); ++i) {
		SCOPED_TRACE("frame " + std::to_string(i) + " " + candumpText(sent[i]));
		EXPECT_EQ(got[i].id, sent[i].id);
		EXPECT_EQ(got[i].extended, sent[i].extended);
		EXPECT_FALSE(got[i].fd);
		ASSERT_EQ(got[i].len, sent[i].len);
		EXPECT_TRUE(std::equal(got[i].data.begin(), got[i].data.begin() + got[i].len,
				       sent[i].data.begin()));
		/* Kernel reception time moved onto CLOCK_MONOTONIC: within the sending window. The
		 * move reads CLOCK_MONOTONIC, then CLOCK_REALTIME, inside receive(): it can only
		 * come out early, by the time between the two reads, which is less than that
		 * receive() call took (measured: a loaded guest may be descheduled in between). */
		EXPECT_GE(got[i].timestamp_ns, before_ns - longest_receive_ns)
			<< "longest receive() " << longest_receive_ns << " ns";
		EXPECT_LE(got[i].timestamp_ns, after_ns);
	}

	const CanStats stats = bus.stats();
	EXPECT_EQ(stats.tx_frames, sent.size());
	EXPECT_EQ(stats.tx_dropped, 0u);
	EXPECT_EQ(stats.tx_enobufs, 0u);
	EXPECT_EQ(stats.tx_errors, 0u);
	EXPECT_EQ(stats.tx_queued, 0u);
	EXPECT_EQ(witness.stats().rx_frames, sent.size());

	/* CAN_RAW_RECV_OWN_MSGS off: the sender's accept-all filter saw none of its own. */
	CanFrame own;
	EXPECT_FALSE(bus.receive(&own)) << "the sender received its own frame " << candumpText(own);
	EXPECT_EQ(bus.stats().rx_frames, 0u);

	const std::vector<std::string> logged = candump.stop();
	ASSERT_EQ(logged.size(), sent.size());
	for (std::size_t i = 0; i < sent.size(); ++i)
		EXPECT_EQ(logged[i], candumpText(sent[i])) << "frame " << i;
}

TEST(VcanSocketCan, FdFramesTravelPaddedToACanFdLength)
{
	Candump candump("vcan0", 2);
	ASSERT_TRUE(candump.ready());
	SocketCanBus witness("vcan0");
	openWitness(witness, true);

	SocketCanBus classic("vcan0");
	ASSERT_TRUE(classic.open({}, CanOptions{}).isOk()) << classic.lastError();
	CanFrame fd_frame;
	fd_frame.id = 0x456;
	fd_frame.fd = true;
	fd_frame.len = 10; /* goes as 12 bytes, the last two zero */
	for (int i = 0; i < 10; ++i)
		fd_frame.data[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(0xf0 + i);
	EXPECT_FALSE(classic.send(fd_frame)) << "an FD frame on a bus opened without fd";
	EXPECT_EQ(classic.stats().tx_errors, 1u);
	EXPECT_NE(classic.lastError().find("opened without fd"), std::string::npos)
		<< classic.lastError();

	SocketCanBus bus("vcan0");
	CanOptions options;
	options.fd = true;
	ASSERT_TRUE(bus.open({}, options).isOk()) << bus.lastError();
	ASSERT_TRUE(bus.send(fd_frame)) << bus.lastError();
	const CanFrame small = classicFrame(0x457, { 1, 2, 3 });
	ASSERT_TRUE(bus.send(small)) << bus.lastError();

	const std::vector<CanFrame> got = receiveFrames(witness, 2, 5000);
	ASSERT_EQ(got.size(), 2u);
	EXPECT_TRUE(got[0].fd);
	EXPECT_EQ(got[0].id, 0x456u);
	ASSERT_EQ(got[0].len, 12);
	for (int i = 0; i < 10; ++i)
		EXPECT_EQ(got[0].data[static_cast<std::size_t>(i)], 0xf0 + i);
	EXPECT_EQ(got[0].data[10], 0);
	EXPECT_EQ(got[0].data[11], 0);
	EXPECT_FALSE(got[1].fd) << "a classic frame from an FD socket stays classic";
	EXPECT_EQ(got[1].len, 3);

	/* candump -L: "456##<flags nibble><data>". The kernel may set CANFD_FDF (4); CANFD_BRS (1)
	 * must be clear: no bit rate switching. */
	CanFrame padded = fd_frame;
	padded.len = 12;
	const std::vector<std::string> logged = candump.stop();
	ASSERT_EQ(logged.size(), 2u);
	const std::string expected = candumpText(padded); /* flags written as 0 */
	const std::size_t flags_at = expected.find("##") + 2;
	ASSERT_GT(logged[0].size(), flags_at) << logged[0];
	const int flags = std::stoi(logged[0].substr(flags_at, 1), nullptr, 16);
	EXPECT_EQ(flags & 1, 0) << "bit rate switching is on: " << logged[0];
	EXPECT_EQ(logged[0].substr(0, flags_at), expected.substr(0, flags_at));
	EXPECT_EQ(logged[0].substr(flags_at + 1), expected.substr(flags_at + 1));
	EXPECT_EQ(logged[1], candumpText(small));
}

TEST(VcanSocketCan, KernelFiltersPassOnlyMatchingFramesFromCansend)
{
	/* 0x100..0x10f (11-bit only) and 0x18DAF100..0x18DAF1FF (29-bit only). */
	const CanFilter filters[] = { { 0x100, 0x7f0, false }, { 0x18daf100, 0x1fffff00, true } };
	SocketCanBus bus("vcan0");
	ASSERT_TRUE(bus.open(filters, CanOptions{}).isOk()) << bus.lastError();
	SocketCanBus deaf("vcan0");
	ASSERT_TRUE(deaf.open({}, CanOptions{}).isOk()) << deaf.lastError();
	SocketCanBus witness("vcan0");
	openWitness(witness);

	struct Case {
		const char *cansend;
		bool passes;
	};
	const Case cases[] = {
		{ "105#0102", true },
		{ "115#0102", false }, /* outside the 11-bit range */
		{ "10F#", true },
		{ "00000105#0102", false }, /* 29-bit id 0x105: not the 11-bit filter's kind */
		{ "105#R", false }, /* remote frame: never */
		{ "18DAF1AB#DEADBEEF", true },
		{ "18DAF2AB#DEADBEEF", false }, /* outside the 29-bit range */
		{ "1FFFFFFF#00", false },
		{ "7FF#00", false },
		{ "18DAF100#", true },
		{ "100#FFFFFFFFFFFFFFFF", true }, /* the last one: all arrived once it did */
	};
	std::vector<std::string> expected;
	for (const Case &c : cases) {
		mustRun(std::string("cansend vcan0 ") + c.cansend);
		if (c.passes)
			expected.push_back(c.cansend);
	}

	/* Every frame reached the accept-all witness (remote frames are not CanFrames). */
	EXPECT_EQ(receiveFrames(witness, std::size(cases) - 1, 5000).size(), std::size(cases) - 1);
	const std::vector<CanFrame> got = receiveFrames(bus, expected.size(), 5000);
	ASSERT_EQ(got.size(), expected.size());
	for (std::size_t i = 0; i < got.size(); ++i)
		EXPECT_EQ(candumpText(got[i]), expected[i]) << "frame " << i;
	CanFrame extra;
	EXPECT_FALSE(bus.receive(&extra))
		<< "a frame passed the filters that should not: " << candumpText(extra);
	EXPECT_EQ(bus.stats().rx_frames, expected.size());
	EXPECT_FALSE(deaf.receive(&extra))
		<< "an empty filter list received " << candumpText(extra);
	EXPECT_EQ(deaf.stats().rx_frames, 0u);
}

/* ------------------------------------------------------------------------- */
/* A slow qdisc on vcan0, set up over rtnetlink (as tc does; the arm64 guest's  */
/* busybox tc cannot add a tbf).                                                */

/* One rtnetlink traffic-control request; 0 or the kernel's errno. */
class TcRequest
{
public:
	TcRequest(std::uint16_t type, std::uint16_t flags, int ifindex, std::uint32_t handle,
		  std::uint32_t parent)
		: type_(type),
		  flags_(flags)
	{
		size_ = NLMSG_HDRLEN;
		tcmsg tc{};
		tc.tcm_family = AF_UNSPEC;
		tc.tcm_ifindex = ifindex;
		tc.tcm_handle = handle;
		tc.tcm_parent = parent;
		append(&tc, sizeof(tc));
	}

	void attribute(std::uint16_t type, const void *data, std::size_t size)
	{
		rtattr a{};
		a.rta_type = type;
		a.rta_len = static_cast<unsigned short>(RTA_LENGTH(size));
		append(&a, sizeof(a));
		append(data, size);
	}
	/* A nested attribute: begin() returns what end() needs. */
	std::size_t begin(std::uint16_t type)
	{
		const std::size_t at = size_;
		attribute(type, nullptr, 0);
		return at;
	}
	void end(std::size_t at)
	{
		const auto len = static_cast<unsigned short>(size_ - at);
		std::memcpy(buf_.data() + at + offsetof(rtattr, rta_len), &len, sizeof(len));
	}

	int send()
	{
		nlmsghdr h{};
		h.nlmsg_len = static_cast<std::uint32_t>(size_);
		h.nlmsg_type = type_;
		h.nlmsg_flags = static_cast<std::uint16_t>(flags_ | NLM_F_REQUEST | NLM_F_ACK);
		h.nlmsg_seq = 1;
		std::memcpy(buf_.data(), &h, sizeof(h));

		const int fd = ::socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_ROUTE);
		if (fd < 0)
			return errno;
		sockaddr_nl kernel{};
		kernel.nl_family = AF_NETLINK;
		int err = 0;
		if (overflow_) {
			err = EMSGSIZE;
		} else if (::sendto(fd, buf_.data(), size_, 0,
				    reinterpret_cast<const sockaddr *>(&kernel),
				    sizeof(kernel)) < 0) {
			err = errno;
		} else {
			alignas(nlmsghdr) std::array<char, 4096> reply;
			const ssize_t n = ::recv(fd, reply.data(), reply.size(), 0);
			nlmsghdr r{};
			nlmsgerr e{};
			if (n < static_cast<ssize_t>(NLMSG_HDRLEN + sizeof(e))) {
				err = n < 0 ? errno : EPROTO;
			} else {
				std::memcpy(&r, reply.data(), sizeof(r));
				std::memcpy(&e, reply.data() + NLMSG_HDRLEN, sizeof(e));
				err = r.nlmsg_type == NLMSG_ERROR ? -e.error : EPROTO;
			}
		}
		::close(fd);
		return err;
	}

private:
	void append(const void *data, std::size_t size)
	{
		if (size_ + RTA_ALIGN(size) > buf_.size()) {
			overflow_ = true;
			return;
		}
		if (size)
			std::memcpy(buf_.data() + size_, data, size);
		size_ += RTA_ALIGN(size);
	}

	std::uint16_t type_;
	std::uint16_t flags_;
	alignas(nlmsghdr) std::array<std::uint8_t, 512> buf_{};
	std::size_t size_ = 0;
	bool overflow_ = false;
};

/*
 * tbf at 1 kbit/s (a 16-byte classic frame every 128 ms) with 32 bytes (2 frames) of burst
 * in front of vcan0, its queue a pfifo as long as vcan0's txqueuelen (4): the same as
 *   ip link set vcan0 txqueuelen 4
 *   tc qdisc add dev vcan0 root handle 1: tbf rate 1kbit burst 32 latency 10s
 *   tc qdisc add dev vcan0 parent 1:1 handle 10: pfifo
 * Removed again (txqueuelen back to 1000) on destruction.
 */
class SlowQdisc
{
public:
	static constexpr int kTxQueueLen = 4;
	static constexpr int kBurstFrames = 2;
	static constexpr int kFramePeriodMs = 128;

	/* Why it cannot be set up here, or "" when it can. */
	static std::string unavailable()
	{
		struct stat st {
		};
		if (stat("/proc/net/psched", &st) != 0)
			return "this kernel has no traffic control (CONFIG_NET_SCHED, CONFIG_NET_SCH_TBF in "
			       "tests/vm/kernel/<arch>.fragment): without a slow qdisc vcan never refuses a frame";
		return "";
	}

	void setUp()
	{
		ifindex_ = static_cast<int>(if_nametoindex("vcan0"));
		ASSERT_GT(ifindex_, 0);
		ASSERT_NO_FATAL_FAILURE(setTxQueueLen(kTxQueueLen));

		tc_tbf_qopt parms{};
		parms.rate.rate = 1000 / 8; /* bytes/s */
		parms.rate.linklayer = TC_LINKLAYER_ETHERNET;
		parms.limit = 64; /* a bfifo until the pfifo replaces it */
		const std::uint32_t burst = 32; /* bytes */
		TcRequest tbf(RTM_NEWQDISC, NLM_F_CREATE | NLM_F_EXCL, ifindex_,
			      TC_H_MAKE(1u << 16, 0), TC_H_ROOT);
		tbf.attribute(TCA_KIND, "tbf", 4);
		const std::size_t options = tbf.begin(TCA_OPTIONS);
		tbf.attribute(TCA_TBF_PARMS, &parms, sizeof(parms));
		tbf.attribute(TCA_TBF_BURST, &burst, sizeof(burst));
		tbf.end(options);
		const int tbf_err = tbf.send();
		ASSERT_EQ(tbf_err, 0) << "adding tbf to vcan0: " << std::strerror(tbf_err);
		active_ = true;

		/* No options: its limit is the interface's txqueuelen. */
		TcRequest pfifo(RTM_NEWQDISC, NLM_F_CREATE | NLM_F_EXCL, ifindex_,
				TC_H_MAKE(0x10u << 16, 0), TC_H_MAKE(1u << 16, 1));
		pfifo.attribute(TCA_KIND, "pfifo", 6);
		const int pfifo_err = pfifo.send();
		ASSERT_EQ(pfifo_err, 0) << "adding pfifo under tbf: " << std::strerror(pfifo_err);
	}
	~SlowQdisc()
	{
		if (active_) {
			TcRequest del(RTM_DELQDISC, 0, ifindex_, 0, TC_H_ROOT);
			(void)del.send();
		}
		if (ifindex_ > 0)
			setTxQueueLen(1000);
	}

private:
	static void setTxQueueLen(int frames)
	{
		ifreq ifr{};
		std::snprintf(ifr.ifr_name, sizeof(ifr.ifr_name), "vcan0");
		ifr.ifr_qlen = frames;
		const int fd = ::socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_ROUTE);
		const int ret = fd < 0 ? -1 : ::ioctl(fd, SIOCSIFTXQLEN, &ifr);
		const int err = errno;
		if (fd >= 0)
			::close(fd);
		ASSERT_EQ(ret, 0) << "SIOCSIFTXQLEN vcan0 " << frames << ": " << std::strerror(err);
	}

	int ifindex_ = 0;
	bool active_ = false;
};

TEST(VcanSocketCan, SlowQdiscEnobufsQueueDropsOldestExpiresLateAndFlowsAgain)
{
	if (const std::string why = SlowQdisc::unavailable(); !why.empty())
		GTEST_SKIP() << why;
	SlowQdisc qdisc;
	ASSERT_NO_FATAL_FAILURE(qdisc.setUp());
	EXPECT_EQ(readFile("/sys/class/net/vcan0/tx_queue_len"),
		  std::to_string(SlowQdisc::kTxQueueLen) + "\n");
	/* tc as witness (iproute2's shows the pfifo's limit; busybox's only the kinds). */
	const std::string shown = run("tc qdisc show dev vcan0").output;
	EXPECT_NE(shown.find("tbf 1: root"), std::string::npos) << shown;
	EXPECT_NE(shown.find("pfifo 10: parent 1:1"), std::string::npos) << shown;
	if (run("tc -V").output.find("iproute2") != std::string::npos) {
		EXPECT_NE(shown.find("limit " + std::to_string(SlowQdisc::kTxQueueLen) + "p"),
			  std::string::npos)
			<< "the pfifo should be txqueuelen long:\n"
			<< shown;
	}

	SocketCanBus witness("vcan0");
	openWitness(witness);
	SocketCanBus bus("vcan0");
	constexpr int kDepth = 8;
	constexpr int kFrames = 40;
	/* Each frame may wait this long in our queue: three qdisc periods, so of the kDepth
	 * frames queued behind the full qdisc a few go out and the rest expire. */
	constexpr std::int64_t kMaxWaitMs = 3 * SlowQdisc::kFramePeriodMs;
	CanOptions options;
	options.tx_queue_depth = kDepth;
	ASSERT_TRUE(bus.open({}, options).isOk()) << bus.lastError();

	std::int64_t longest_send_ns = 0;
	int slow_sends = 0; /* those that took a qdisc period or longer */
	int refused_sends = 0;
	int taken_before_enobufs = -1;
	const std::int64_t start_ns = monotonicNs();
	for (int i = 0; i < kFrames; ++i) {
		const std::int64_t t0 = monotonicNs();
		CanFrame frame = numberedFrame(0x321, i);
		frame.deadline_ns = t0 + kMaxWaitMs * 1000000;
		if (!bus.send(frame))
			++refused_sends;
		const std::int64_t took_ns = monotonicNs() - t0;
		longest_send_ns = std::max(longest_send_ns, took_ns);
		slow_sends += took_ns >= SlowQdisc::kFramePeriodMs * 1000000LL;
		const CanStats s = bus.stats();
		if (taken_before_enobufs < 0 && s.tx_enobufs > 0)
			taken_before_enobufs = static_cast<int>(s.tx_frames);
	}
	const std::int64_t sending_ms = (monotonicNs() - start_ns) / 1000000;
	const CanStats after_sending = bus.stats();
	std::printf(
		"[          ] %d sends in %lld ms, longest %.2f ms; kernel took %d frames before the first "
		"ENOBUFS; %llu ENOBUFS, %llu dropped, %u queued\n",
		kFrames, static_cast<long long>(sending_ms),
		static_cast<double>(longest_send_ns) * 1e-6, taken_before_enobufs,
		static_cast<unsigned long long>(after_sending.tx_enobufs),
		static_cast<unsigned long long>(after_sending.tx_dropped), after_sending.tx_queued);

	/* send() never waits for room in the qdisc, which frees one frame per 128 ms. Measured
	 * against what waiting would cost in this run rather than against a fixed time (a loaded
	 * guest can lose a core for longer than a frame period at any moment): a send() that waited
	 * would take a qdisc period for every frame the kernel refused, so all 40 sends take less
	 * than half of that; and fewer than half of the refused sends took a period or more (every
	 * one would, waiting). The refused ones coming back at once, counted as drops, is checked
	 * below. */
	ASSERT_GT(after_sending.tx_enobufs, 0u) << "the kernel never refused a frame";
	ASSERT_GT(refused_sends, 0);
	EXPECT_LT(sending_ms, refused_sends * SlowQdisc::kFramePeriodMs / 2)
		<< refused_sends << " sends refused";
	EXPECT_LT(slow_sends, (refused_sends + 1) / 2)
		<< "sends that took a qdisc period or longer";
	/* The kernel took the burst and a txqueuelen of frames (plus what drained meanwhile). */
	EXPECT_GE(taken_before_enobufs, SlowQdisc::kTxQueueLen);
	EXPECT_LE(taken_before_enobufs, SlowQdisc::kTxQueueLen + SlowQdisc::kBurstFrames + 1 +
						sending_ms / SlowQdisc::kFramePeriodMs);
	/* The queue is full of the newest frames; the oldest were dropped and counted. */
	EXPECT_EQ(after_sending.tx_queued, static_cast<std::uint32_t>(kDepth));
	EXPECT_GT(after_sending.tx_dropped, 0u);
	EXPECT_EQ(static_cast<std::uint64_t>(refused_sends), after_sending.tx_dropped);
	EXPECT_EQ(after_sending.tx_frames + after_sending.tx_dropped + after_sending.tx_queued +
			  after_sending.tx_expired,
		  static_cast<std::uint64_t>(kFrames));
	EXPECT_EQ(after_sending.tx_errors, 0u);
	EXPECT_EQ(after_sending.state, CanState::ErrorActive);

	/* As the qdisc drains, poll() gets the queue out. */
	const int drain_ms =
		(kDepth + SlowQdisc::kTxQueueLen + 4) * SlowQdisc::kFramePeriodMs + 5000;
	std::vector<CanFrame> got;
	const bool drained = waitUntil(
		[&] {
			bus.poll();
			CanFrame f;
			while (witness.receive(&f))
				got.push_back(f);
			return bus.stats().tx_queued == 0 && got.size() >= bus.stats().tx_frames;
		},
		drain_ms);
	const CanStats after_drain = bus.stats();
	ASSERT_TRUE(drained) << after_drain.tx_queued << " frames still queued, " << got.size()
			     << " of " << after_drain.tx_frames << " arrived";
	EXPECT_GT(after_drain.tx_enobufs, after_sending.tx_enobufs)
		<< "poll() met the full qdisc too";
	EXPECT_EQ(after_drain.tx_dropped, after_sending.tx_dropped);
	/* Of the kDepth queued frames, those the qdisc took within kMaxWaitMs left; the others
	 * expired unsent. The qdisc frees a slot every period: at most three in time. */
	const std::uint64_t late_sent = after_drain.tx_frames - after_sending.tx_frames;
	EXPECT_EQ(late_sent + after_drain.tx_expired - after_sending.tx_expired,
		  static_cast<std::uint64_t>(after_sending.tx_queued));
	EXPECT_GE(after_drain.tx_expired, static_cast<std::uint64_t>(kDepth - 3));
	std::printf("[          ] after the stall: %llu queued frames sent in time, %llu expired\n",
		    static_cast<unsigned long long>(late_sent),
		    static_cast<unsigned long long>(after_drain.tx_expired));

	/* What arrived: the frames the kernel took at once, then the oldest of the newest kDepth
	 * that were still in time, in order; no expired frame. */
	std::vector<int> expected;
	for (std::uint64_t i = 0; i < after_sending.tx_frames; ++i)
		expected.push_back(static_cast<int>(i));
	for (int i = kFrames - kDepth; i < kFrames - kDepth + static_cast<int>(late_sent); ++i)
		expected.push_back(i);
	std::vector<int> seqs;
	for (const CanFrame &f : got)
		seqs.push_back(seqOf(f));
	EXPECT_EQ(seqs, expected);

	/* Drained: frames flow again at once, nothing queued or refused. */
	std::this_thread::sleep_for(std::chrono::milliseconds(SlowQdisc::kFramePeriodMs * 3));
	for (int i = 0; i < 2; ++i)
		EXPECT_TRUE(bus.send(numberedFrame(0x322, 100 + i)));
	const CanStats again = bus.stats();
	EXPECT_EQ(again.tx_frames, after_drain.tx_frames + 2);
	EXPECT_EQ(again.tx_queued, 0u);
	EXPECT_EQ(again.tx_enobufs, after_drain.tx_enobufs);
	const std::vector<CanFrame> later = receiveFrames(witness, 2, 5000);
	ASSERT_EQ(later.size(), 2u);
	EXPECT_EQ(seqOf(later[0]), 100);
	EXPECT_EQ(seqOf(later[1]), 101);
}

/* Poll the bus until it is ErrorActive (30 s: a hang guard only; it ends at the reopening). */
bool pollUntilUp(SocketCanBus &bus)
{
	return waitUntil(
		[&] {
			bus.poll();
			return bus.stats().state == CanState::ErrorActive;
		},
		30000);
}

/* An interface that does not exist at open(): Down, named with the ones present, joined when it
 * is added (the late can0 of a board whose CAN driver or adapter comes after dockposed). */
TEST(VcanSocketCan, MissingInterfaceIsWaitedForAndJoinedWhenAdded)
{
	SocketCanBus bus("vcan7");
	const auto status = bus.open(kAcceptAll, CanOptions{});
	ASSERT_TRUE(status.isOk()) << status.message();
	EXPECT_EQ(bus.lastError(),
		  "can: no CAN interface \"vcan7\" (CAN interfaces present: vcan0, vcan1); "
		  "waiting for it (retried every 500 ms)");
	EXPECT_EQ(bus.stats().state, CanState::Down);
	EXPECT_EQ(bus.fd(), -1);
	for (int i = 0; i < 2; ++i)
		EXPECT_TRUE(bus.send(numberedFrame(0x260, i)));
	EXPECT_EQ(bus.stats().tx_queued, 2u);
	EXPECT_EQ(bus.stats().tx_errors, 0u);
	bus.poll();
	EXPECT_EQ(bus.stats().state, CanState::Down);

	mustRun("ip link add dev vcan7 type vcan");
	bus.poll();
	mustRun("ip link set vcan7 up");
	SocketCanBus witness("vcan7");
	openWitness(witness);
	ASSERT_TRUE(pollUntilUp(bus)) << canStateName(bus.stats().state) << ": " << bus.lastError();
	EXPECT_EQ(bus.stats().restarts, 0u) << "joining late is no restart";
	EXPECT_GE(bus.fd(), 0);
	const std::vector<CanFrame> got = receiveFrames(witness, 2, 5000);
	ASSERT_EQ(got.size(), 2u) << "the frames queued while it was missing";
	EXPECT_EQ(seqOf(got[0]), 0);
	EXPECT_EQ(seqOf(got[1]), 1);
	mustRun("cansend vcan7 261#07");
	const std::vector<CanFrame> rx = receiveFrames(bus, 1, 5000);
	ASSERT_EQ(rx.size(), 1u) << "the filters of open() are on the late socket";
	EXPECT_EQ(rx[0].id, 0x261u);
}

/* What no interface coming up would fix stays an open() failure, never retried. */
TEST(VcanSocketCan, NotACanInterfaceIsRefused)
{
	SocketCanBus lo("lo");
	const auto not_can = lo.open({}, CanOptions{});
	ASSERT_FALSE(not_can.isOk());
	EXPECT_EQ(not_can.message(), "can: interface \"lo\" is not a CAN interface");
	EXPECT_EQ(lo.stats().state, CanState::Closed);
	EXPECT_FALSE(lo.send(classicFrame(0x100, { 1 })));
	EXPECT_EQ(lo.stats().tx_errors, 1u) << "a send on a closed bus is refused (CanBusBase)";
	lo.poll();
	EXPECT_EQ(lo.stats().state, CanState::Closed) << "nothing is retried after a failed open()";
}

/* An interface that exists but is down at open() (networkd has not configured it yet). */
TEST(VcanSocketCan, DownInterfaceIsWaitedForThenJoined)
{
	mustRun("ip link set vcan1 down");
	SocketCanBus bus("vcan1");
	const auto status = bus.open({}, CanOptions{});
	ASSERT_TRUE(status.isOk()) << status.message();
	EXPECT_EQ(bus.lastError(), "can: interface \"vcan1\" is down (ip link set vcan1 up); "
				   "waiting for it (retried every 500 ms)");
	EXPECT_EQ(bus.stats().state, CanState::Down);
	restoreVcan1();
	EXPECT_TRUE(pollUntilUp(bus)) << canStateName(bus.stats().state) << ": " << bus.lastError();
	EXPECT_EQ(bus.stats().restarts, 0u);
}

TEST(VcanSocketCan, InterfaceSetDownWhileOpenGoesDownAndComesBack)
{
	SocketCanBus bus("vcan1");
	ASSERT_TRUE(bus.open({}, CanOptions{}).isOk()) << bus.lastError();

	mustRun("ip link set vcan1 down");
	bus.poll();
	EXPECT_EQ(bus.stats().state, CanState::Down)
		<< canStateName(bus.stats().state) << ": " << bus.lastError();
	EXPECT_NE(bus.lastError().find("lost vcan1"), std::string::npos) << bus.lastError();
	EXPECT_EQ(bus.fd(), -1);
	for (int i = 0; i < 3; ++i)
		EXPECT_TRUE(bus.send(numberedFrame(0x200, i)));
	EXPECT_EQ(bus.stats().tx_queued, 3u);

	mustRun("ip link set vcan1 up");
	SocketCanBus witness("vcan1");
	openWitness(witness);
	/* (30 s: a hang guard only; the wait ends as soon as it reopens.) */
	EXPECT_TRUE(waitUntil(
		[&] {
			bus.poll();
			return bus.stats().state == CanState::ErrorActive;
		},
		30000))
		<< canStateName(bus.stats().state) << ": " << bus.lastError();
	EXPECT_EQ(bus.stats().restarts, 1u);
	const std::vector<CanFrame> got = receiveFrames(witness, 3, 5000);
	ASSERT_EQ(got.size(), 3u) << "the frames queued while it was down";
	for (int i = 0; i < 3; ++i)
		EXPECT_EQ(seqOf(got[static_cast<std::size_t>(i)]), i);
	EXPECT_EQ(bus.stats().tx_queued, 0u);
}

TEST(VcanSocketCan, InterfaceDeletedWhileOpenReopensWhenAddedAgain)
{
	const CanFilter filters[] = { { 0x240, 0x7f0, false } };
	SocketCanBus bus("vcan1");
	CanOptions options;
	options.tx_queue_depth = 4;
	ASSERT_TRUE(bus.open(filters, options).isOk()) << bus.lastError();

	mustRun("ip link del vcan1");
	bus.poll();
	const CanStats lost = bus.stats();
	EXPECT_EQ(lost.state, CanState::Down)
		<< canStateName(lost.state) << ": " << bus.lastError();
	EXPECT_NE(bus.lastError().find("lost vcan1"), std::string::npos) << bus.lastError();

	/* While it is gone: frames queue (the oldest dropped past the depth), poll() retries. */
	for (int i = 0; i < 6; ++i)
		bus.send(numberedFrame(0x201, i));
	EXPECT_EQ(bus.stats().tx_queued, 4u);
	EXPECT_EQ(bus.stats().tx_dropped, 2u);
	const std::int64_t gone_until_ns = monotonicNs() + 1200 * 1000000LL;
	while (monotonicNs() < gone_until_ns) {
		bus.poll();
		std::this_thread::sleep_for(std::chrono::milliseconds(50));
	}
	EXPECT_EQ(bus.stats().state, CanState::Down);
	EXPECT_EQ(bus.stats().restarts, 0u);
	EXPECT_NE(bus.lastError().find("no CAN interface \"vcan1\""), std::string::npos)
		<< "why the latest reopening failed: " << bus.lastError();

	mustRun("ip link add dev vcan1 type vcan");
	mustRun("ip link set vcan1 up");
	SocketCanBus witness("vcan1");
	openWitness(witness);
	const std::int64_t added_ns = monotonicNs();
	/* The gaps between our poll() calls and how long each took: what this guest delivered. */
	std::int64_t last_poll_end_ns = added_ns;
	std::int64_t longest_gap_ns = 0;
	std::int64_t longest_poll_ns = 0;
	ASSERT_TRUE(waitUntil(
		[&] {
			const std::int64_t t0 = monotonicNs();
			longest_gap_ns = std::max(longest_gap_ns, t0 - last_poll_end_ns);
			bus.poll();
			last_poll_end_ns = monotonicNs();
			longest_poll_ns = std::max(longest_poll_ns, last_poll_end_ns - t0);
			return bus.stats().state == CanState::ErrorActive;
		},
		30000))
		<< canStateName(bus.stats().state) << ": " << bus.lastError();
	/* Retried every 500 ms: the last failed attempt was before the interface came back (no
	 * poll() in between), so the one that succeeds is at most one interval after that, found
	 * by the first poll() after it (the longest gap between them, measured) and taking at
	 * most the longest poll(). */
	EXPECT_LE(last_poll_end_ns - added_ns,
		  SocketCanBus::kReopenInterval_ms * 1000000LL + longest_gap_ns + longest_poll_ns)
		<< "polls up to " << longest_gap_ns / 1000000 << " ms apart, each up to "
		<< longest_poll_ns / 1000000 << " ms";
	EXPECT_EQ(bus.stats().restarts, 1u);
	EXPECT_GE(bus.fd(), 0);

	const std::vector<CanFrame> got = receiveFrames(witness, 4, 5000);
	ASSERT_EQ(got.size(), 4u);
	for (int i = 0; i < 4; ++i)
		EXPECT_EQ(seqOf(got[static_cast<std::size_t>(i)]), i + 2)
			<< "the newest four of six";

	/* The reopened socket has the same kernel filters. */
	mustRun("cansend vcan1 250#01");
	mustRun("cansend vcan1 245#02");
	const std::vector<CanFrame> rx = receiveAll(bus, 300);
	ASSERT_EQ(rx.size(), 1u);
	EXPECT_EQ(rx[0].id, 0x245u);
	EXPECT_EQ(rx[0].data[0], 2);
}

} /* namespace */

class RestoreInterfaces : public ::testing::EmptyTestEventListener
{
	void OnTestEnd(const ::testing::TestInfo &) override
	{
		restoreVcan1();
		if (interfaceExists("vcan7"))
			(void)run("ip link del vcan7");
	}
};

int main(int argc, char **argv)
{
	::testing::InitGoogleTest(&argc, argv);
	if (!std::getenv("DOCKPOSE_VM_ARCH")) {
		std::fprintf(stderr,
			     "test_vm_socketcan: not inside a dockpose test VM; run it there: "
			     "scripts/vm run -- %s (or ctest -L vm)\n",
			     argv[0]);
		return 77;
	}
	if (!interfaceExists("vcan0") || !interfaceExists("vcan1")) {
		std::fprintf(stderr,
			     "test_vm_socketcan: the VM has no vcan0/vcan1 (tests/vm/guest-init.sh "
			     "creates them)\n");
		return 1;
	}
	::testing::UnitTest::GetInstance()->listeners().Append(new RestoreInterfaces);
	return RUN_ALL_TESTS();
}

/* SPDX-License-Identifier: MIT */
/*
 * The simulated CAN buses: FileCanBus (a candump -l log, read back by two
 * independent witnesses: python-can and can-utils' log2asc) and the
 * in-process LoopbackHub / LoopbackCanBus.
 */
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "hal/sim/file_can_bus.h"
#include "hal/sim/loopback_can_bus.h"

namespace dockpose::hal {
namespace {

namespace fs = std::filesystem;

CanFrame makeFrame(std::uint32_t id, std::initializer_list<std::uint8_t> bytes,
		   bool extended = false, bool fd = false)
{
	CanFrame f;
	f.id = id;
	f.extended = extended;
	f.fd = fd;
	f.len = static_cast<std::uint8_t>(bytes.size());
	std::size_t i = 0;
	for (std::uint8_t b : bytes)
		f.data[i++] = b;
	return f;
}

/* A frame with a counter in its first two bytes. */
CanFrame counted(std::uint32_t id, int n)
{
	return makeFrame(id, { static_cast<std::uint8_t>(n >> 8),
			       static_cast<std::uint8_t>(n & 0xff) });
}

int counterOf(const CanFrame &f)
{
	return (f.data[0] << 8) | f.data[1];
}

std::string hexOf(const CanFrame &f)
{
	std::string s;
	char b[3];
	for (int i = 0; i < f.len; ++i) {
		std::snprintf(b, sizeof(b), "%02X", f.data[i]);
		s += b;
	}
	return s;
}

class TempDir
{
public:
	TempDir()
	{
		std::string pattern =
			(fs::temp_directory_path() / "dockpose_sim_can_XXXXXX").string();
		if (mkdtemp(pattern.data()))
			path_ = pattern;
	}
	~TempDir()
	{
		std::error_code ec;
		if (!path_.empty())
			fs::remove_all(path_, ec);
	}
	const std::string &path() const { return path_; }

private:
	std::string path_;
};

/* Run a shell command; its standard output and exit status. */
struct CommandResult {
	std::string out;
	int status = -1;
};

CommandResult run(const std::string &command)
{
	CommandResult r;
	std::FILE *p = popen(command.c_str(), "r");
	if (!p)
		return r;
	char buf[4096];
	std::size_t n;
	while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0)
		r.out.append(buf, n);
	const int status = pclose(p);
	r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
	return r;
}

std::vector<std::string> lines(const std::string &text)
{
	std::vector<std::string> out;
	std::istringstream in(text);
	std::string line;
	while (std::getline(in, line))
		if (!line.empty())
			out.push_back(line);
	return out;
}

std::string readFile(const std::string &path)
{
	std::ifstream in(path);
	std::stringstream ss;
	ss << in.rdbuf();
	return ss.str();
}

double wallNow()
{
	timespec ts{};
	clock_gettime(CLOCK_REALTIME, &ts);
	return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/* The frames every witness test writes: standard, extended, empty, FD. */
std::vector<CanFrame> witnessFrames()
{
	return {
		makeFrame(0x305, { 0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77 }),
		makeFrame(0x1abcdef0, { 0xaa, 0xbb, 0xcc }, true),
		makeFrame(0x7ff, {}),
		makeFrame(0x001, { 0xfe }),
		makeFrame(0x00000123,
			  { 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x0a, 0x0b,
			    0x0c },
			  true, true),
		makeFrame(0x310, { 0xde, 0xad, 0xbe, 0xef }),
	};
}

class FileCanBusTest : public ::testing::Test
{
protected:
	void SetUp() override
	{
		ASSERT_FALSE(dir_.path().empty()) << "cannot create a temporary folder";
		log_ = dir_.path() + "/pose.log";
	}

	/* Write witnessFrames() to log_; returns the wall-clock window of the writing. */
	void writeWitnessLog(double *t_begin, double *t_end)
	{
		FileCanBus bus(log_, "can0");
		CanOptions options;
		options.fd = true;
		ASSERT_TRUE(bus.open({}, options).isOk()) << bus.lastError();
		*t_begin = wallNow();
		for (const CanFrame &f : witnessFrames())
			ASSERT_TRUE(bus.send(f)) << bus.lastError();
		bus.poll();
		*t_end = wallNow();
		const CanStats s = bus.stats();
		EXPECT_EQ(s.tx_frames, witnessFrames().size());
		EXPECT_EQ(s.tx_dropped, 0u);
		EXPECT_EQ(s.tx_errors, 0u);
		EXPECT_EQ(s.state, CanState::ErrorActive);
		bus.close();
		EXPECT_EQ(bus.stats().state, CanState::Closed);
	}

	TempDir dir_;
	std::string log_;
};

TEST_F(FileCanBusTest, WritesCandumpLogLines)
{
	double t0, t1;
	writeWitnessLog(&t0, &t1);
	const auto got = lines(readFile(log_));
	const std::vector<std::string> frames = { "305#0011223344556677",
						  "1ABCDEF0#AABBCC",
						  "7FF#",
						  "001#FE",
						  "00000123##00102030405060708090A0B0C",
						  "310#DEADBEEF" };
	ASSERT_EQ(got.size(), frames.size()) << readFile(log_);
	const std::regex line_re(R"(^\((\d+)\.(\d{6})\) can0 (\S+)$)");
	for (std::size_t i = 0; i < got.size(); ++i) {
		std::smatch m;
		ASSERT_TRUE(std::regex_match(got[i], m, line_re)) << got[i];
		EXPECT_EQ(m[3].str(), frames[i]);
		const double t = std::stod(m[1].str() + "." + m[2].str());
		EXPECT_GE(t, t0 - 1e-6) << got[i];
		EXPECT_LE(t, t1 + 1e-6) << got[i];
	}
}

TEST_F(FileCanBusTest, PythonCanReadsTheLogBackIdentically)
{
	ASSERT_EQ(access(DOCKPOSE_PYTHON, X_OK), 0)
		<< DOCKPOSE_PYTHON << " is missing: install Debian's python3 (scripts/setup)";
	const CommandResult probe = run(std::string(DOCKPOSE_PYTHON) + " -c 'import can' 2>&1");
	ASSERT_EQ(probe.status, 0)
		<< "python-can is missing (apt-get install python3-can): " << probe.out;

	double t0, t1;
	writeWitnessLog(&t0, &t1);
	/* Both readers: the canutils reader itself, and can.LogReader choosing it by the .log suffix. */
	const std::string script =
		"import can, sys\n"
		"for reader in (can.CanutilsLogReader(sys.argv[1]), can.LogReader(sys.argv[1])):\n"
		"    for m in reader:\n"
		"        print('%X %d %d %d %s %s %.6f' % (m.arbitration_id, m.is_extended_id, m.is_fd,\n"
		"              m.dlc, bytes(m.data).hex().upper() or '-', m.channel, m.timestamp))\n"
		"    print('--')\n";
	const std::string script_path = dir_.path() + "/read.py";
	std::ofstream(script_path) << script;
	const CommandResult r =
		run(std::string(DOCKPOSE_PYTHON) + " " + script_path + " " + log_ + " 2>&1");
	ASSERT_EQ(r.status, 0) << r.out;

	const auto out = lines(r.out);
	const auto frames = witnessFrames();
	ASSERT_EQ(out.size(), 2 * (frames.size() + 1)) << r.out;
	for (int pass = 0; pass < 2; ++pass) {
		const std::size_t base = static_cast<std::size_t>(pass) * (frames.size() + 1);
		for (std::size_t i = 0; i < frames.size(); ++i) {
			const CanFrame &f = frames[i];
			std::istringstream in(out[base + i]);
			std::string id, data, channel;
			int ext = -1, fd = -1, dlc = -1;
			double t = 0.0;
			in >> id >> ext >> fd >> dlc >> data >> channel >> t;
			char want_id[16];
			std::snprintf(want_id, sizeof(want_id), "%X", f.id);
			EXPECT_EQ(id, want_id) << out[base + i];
			EXPECT_EQ(ext, f.extended ? 1 : 0) << out[base + i];
			EXPECT_EQ(fd, f.fd ? 1 : 0) << out[base + i];
			EXPECT_EQ(dlc, f.len) << out[base + i];
			EXPECT_EQ(data, f.len ? hexOf(f) : "-") << out[base + i];
			EXPECT_EQ(channel, "can0");
			EXPECT_GE(t, t0 - 1e-5);
			EXPECT_LE(t, t1 + 1e-5);
		}
		EXPECT_EQ(out[base + frames.size()], "--");
	}
}

TEST_F(FileCanBusTest, CanUtilsLog2ascConvertsTheLog)
{
	const CommandResult which = run("command -v log2asc");
	ASSERT_EQ(which.status, 0) << "log2asc is missing (apt-get install can-utils)";

	double t0, t1;
	writeWitnessLog(&t0, &t1);
	const CommandResult r = run("log2asc -I " + log_ + " can0 2>&1");
	ASSERT_EQ(r.status, 0) << r.out;

	/* Frame lines: "<t> 1 <id>[x] Rx d <len> <bytes>" and "<t> CANFD 1 Rx <id>[x] <brs> <esi> <dlc> <len> <bytes> ...". */
	std::vector<std::string> ids, data;
	for (const std::string &line : lines(r.out)) {
		std::istringstream in(line);
		std::vector<std::string> tok;
		std::string t;
		while (in >> t)
			tok.push_back(t);
		if (tok.size() >= 6 && tok[1] == "1" && tok[3] == "Rx" && tok[4] == "d") {
			const int len = std::stoi(tok[5]);
			ASSERT_GE(tok.size(), 6u + static_cast<std::size_t>(len)) << line;
			ids.push_back(tok[2]);
			std::string d;
			for (int i = 0; i < len; ++i)
				d += tok[6 + static_cast<std::size_t>(i)];
			data.push_back(d);
		} else if (tok.size() >= 9 && tok[1] == "CANFD" && tok[3] == "Rx") {
			const int len = std::stoi(tok[8]);
			ASSERT_GE(tok.size(), 9u + static_cast<std::size_t>(len)) << line;
			ids.push_back(tok[4]);
			std::string d;
			for (int i = 0; i < len; ++i)
				d += tok[9 + static_cast<std::size_t>(i)];
			data.push_back(d);
		}
	}
	const auto frames = witnessFrames();
	ASSERT_EQ(ids.size(), frames.size()) << r.out;
	for (std::size_t i = 0; i < frames.size(); ++i) {
		char want_id[16];
		std::snprintf(want_id, sizeof(want_id), frames[i].extended ? "%Xx" : "%X",
			      frames[i].id);
		EXPECT_EQ(ids[i], want_id) << r.out;
		EXPECT_EQ(data[i], hexOf(frames[i])) << r.out;
	}
}

TEST_F(FileCanBusTest, LinesAppearAtEachPollForALiveReader)
{
	FileCanBus bus(log_, "vcan3");
	ASSERT_TRUE(bus.open({}, CanOptions{}).isOk()) << bus.lastError();
	ASSERT_TRUE(bus.send(counted(0x305, 1)));
	bus.poll();
	EXPECT_EQ(lines(readFile(log_)).size(), 1u) << "a poll() flushes the log";
	ASSERT_TRUE(bus.send(counted(0x305, 2)));
	bus.poll();
	const auto got = lines(readFile(log_));
	ASSERT_EQ(got.size(), 2u);
	EXPECT_NE(got[1].find(" vcan3 305#0002"), std::string::npos) << got[1];
}

TEST_F(FileCanBusTest, OpenTruncatesAnOldLog)
{
	std::ofstream(log_) << "(1.000000) can0 123#00\n(2.000000) can0 123#01\n";
	FileCanBus bus(log_);
	ASSERT_TRUE(bus.open({}, CanOptions{}).isOk()) << bus.lastError();
	ASSERT_TRUE(bus.send(counted(0x305, 7)));
	bus.close();
	const auto got = lines(readFile(log_));
	ASSERT_EQ(got.size(), 1u);
	EXPECT_NE(got[0].find("305#0007"), std::string::npos);
}

TEST_F(FileCanBusTest, FullQueueDropsOldestAndSendNeverBlocks)
{
	FileCanBus bus(log_);
	CanOptions options;
	options.tx_queue_depth = 4;
	ASSERT_TRUE(bus.open({}, options).isOk()) << bus.lastError();
	bus.setBandwidth(0); /* nothing leaves: the bus is saturated */
	int refused = 0;
	const auto start = std::chrono::steady_clock::now();
	for (int i = 0; i < 10; ++i)
		refused += bus.send(counted(0x305, i)) ? 0 : 1;
	const double elapsed_s =
		std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
	EXPECT_LT(elapsed_s, 5.0) << "send() must not wait for the bus";
	EXPECT_EQ(refused, 6) << "send() reports each frame that pushed an old one out";
	CanStats s = bus.stats();
	EXPECT_EQ(s.tx_dropped, 6u);
	EXPECT_EQ(s.tx_queued, 4u);
	EXPECT_EQ(s.tx_frames, 0u);
	bus.poll();
	EXPECT_EQ(bus.stats().tx_frames, 0u);

	bus.setBandwidth(3);
	bus.poll();
	s = bus.stats();
	EXPECT_EQ(s.tx_frames, 3u);
	EXPECT_EQ(s.tx_queued, 1u);
	EXPECT_EQ(lines(readFile(log_)).size(), 3u);
	bus.poll();
	s = bus.stats();
	EXPECT_EQ(s.tx_frames, 4u);
	EXPECT_EQ(s.tx_queued, 0u);

	/* The newest four survived, in order. */
	const auto got = lines(readFile(log_));
	ASSERT_EQ(got.size(), 4u);
	for (int i = 0; i < 4; ++i) {
		char want[32];
		std::snprintf(want, sizeof(want), " can0 305#%04X", 6 + i);
		EXPECT_NE(got[static_cast<std::size_t>(i)].find(want), std::string::npos)
			<< got[static_cast<std::size_t>(i)];
	}
}

TEST_F(FileCanBusTest, RejectsFramesItCannotSend)
{
	FileCanBus bus(log_);
	EXPECT_FALSE(bus.send(counted(0x305, 1))) << "send() before open()";
	EXPECT_EQ(bus.stats().state, CanState::Closed);
	EXPECT_EQ(bus.stats().tx_errors, 1u) << "a send on a closed bus is refused and counted";
	EXPECT_NE(bus.lastError().find("closed"), std::string::npos) << bus.lastError();
	ASSERT_TRUE(bus.open({}, CanOptions{}).isOk());
	CanFrame long_classic = counted(0x305, 1);
	long_classic.len = 9;
	EXPECT_FALSE(bus.send(long_classic));
	EXPECT_NE(bus.lastError().find("longer than 8"), std::string::npos) << bus.lastError();
	EXPECT_FALSE(bus.send(makeFrame(0x123, { 1 }, false, true)))
		<< "FD frame without FD enabled";
	EXPECT_NE(bus.lastError().find("FD"), std::string::npos) << bus.lastError();
	EXPECT_FALSE(bus.send(makeFrame(0x800, { 1 }))) << "standard id out of range";
	EXPECT_EQ(bus.stats().tx_errors, 3u) << "open() starts the counts afresh";
	bus.close();
	EXPECT_TRUE(lines(readFile(log_)).empty());
}

TEST_F(FileCanBusTest, UnwritablePathIsAClearError)
{
	{
		const std::string path = dir_.path() + "/no/such/folder/pose.log";
		FileCanBus bus(path);
		const Status s = bus.open({}, CanOptions{});
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("does not exist"), std::string::npos) << s.message();
		EXPECT_EQ(bus.lastError(), s.message());
		EXPECT_EQ(bus.stats().state, CanState::Closed);
	}
	{
		/* A folder where the file should be. */
		FileCanBus bus(dir_.path());
		const Status s = bus.open({}, CanOptions{});
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find(dir_.path()), std::string::npos) << s.message();
		EXPECT_NE(s.message().find("directory"), std::string::npos) << s.message();
	}
	{
		FileCanBus bus(log_, "bad name");
		const Status s = bus.open({}, CanOptions{});
		ASSERT_FALSE(s.isOk());
		EXPECT_NE(s.message().find("interface name"), std::string::npos) << s.message();
	}
}

TEST_F(FileCanBusTest, ReceivesInjectedFramesThroughTheFilters)
{
	FileCanBus bus(log_);
	/* Commands 0x310..0x31F (standard) and one extended id. */
	const CanFilter filters[] = { { 0x310, 0x7f0, false }, { 0x18daf110, 0x1fffffff, true } };
	ASSERT_TRUE(bus.open(filters, CanOptions{}).isOk());
	bus.inject(counted(0x311, 1));
	bus.inject(counted(0x305, 2)); /* not ours */
	bus.inject(makeFrame(0x311, { 0, 3 },
			     true)); /* extended 0x311: the standard filter does not apply */
	bus.inject(makeFrame(0x18daf110, { 0, 4 }, true));
	bus.inject(counted(0x31f, 5));
	bus.inject(counted(0x320, 6));

	std::vector<int> got;
	CanFrame f;
	while (bus.receive(&f)) {
		got.push_back(counterOf(f));
		EXPECT_NE(f.timestamp_ns, 0);
	}
	EXPECT_EQ(got, (std::vector<int>{ 1, 4, 5 }));
	EXPECT_EQ(bus.stats().rx_frames, 3u);
	EXPECT_TRUE(lines(readFile(log_)).empty()) << "received frames are not logged";

	/* Injected from another thread, beyond the receive queue's size. */
	std::thread injector([&] {
		for (int i = 0; i < 300; ++i)
			bus.inject(counted(0x312, i));
	});
	injector.join();
	got.clear();
	while (bus.receive(&f))
		got.push_back(counterOf(f));
	ASSERT_EQ(got.size(), FileCanBus::kRxCapacity);
	EXPECT_EQ(got.front(), 300 - static_cast<int>(FileCanBus::kRxCapacity))
		<< "the oldest are dropped";
	EXPECT_EQ(got.back(), 299);
	EXPECT_EQ(bus.rxDropped(), 300u - FileCanBus::kRxCapacity);
}

TEST_F(FileCanBusTest, NoFiltersReceivesNothing)
{
	FileCanBus bus(log_);
	ASSERT_TRUE(bus.open({}, CanOptions{}).isOk());
	bus.inject(counted(0x310, 1));
	CanFrame f;
	EXPECT_FALSE(bus.receive(&f));
}

/* ---- Loopback ---- */

TEST(LoopbackCanBus, TwoEndpointsExchangeFrames)
{
	auto hub = std::make_shared<LoopbackHub>();
	LoopbackCanBus a(hub, "a"), b(hub, "b");
	const CanFilter all[] = { { 0, 0, false } };
	ASSERT_TRUE(a.open(all, CanOptions{}).isOk());
	ASSERT_TRUE(b.open(all, CanOptions{}).isOk());
	EXPECT_EQ(a.stats().state, CanState::ErrorActive);

	ASSERT_TRUE(a.send(counted(0x305, 1)));
	ASSERT_TRUE(b.send(counted(0x310, 2)));
	ASSERT_TRUE(a.send(counted(0x306, 3)));

	CanFrame f;
	ASSERT_TRUE(b.receive(&f));
	EXPECT_EQ(f.id, 0x305u);
	EXPECT_EQ(counterOf(f), 1);
	EXPECT_GT(f.timestamp_ns, 0);
	ASSERT_TRUE(b.receive(&f));
	EXPECT_EQ(counterOf(f), 3);
	EXPECT_FALSE(b.receive(&f)) << "an endpoint does not hear itself";
	ASSERT_TRUE(a.receive(&f));
	EXPECT_EQ(f.id, 0x310u);
	EXPECT_FALSE(a.receive(&f));

	const auto traffic = hub->traffic();
	ASSERT_EQ(traffic.size(), 3u);
	EXPECT_EQ(counterOf(traffic[0]), 1);
	EXPECT_EQ(counterOf(traffic[1]), 2);
	EXPECT_EQ(counterOf(traffic[2]), 3);
	EXPECT_EQ(a.stats().tx_frames, 2u);
	EXPECT_EQ(b.stats().tx_frames, 1u);
	EXPECT_EQ(b.stats().rx_frames, 2u);
}

TEST(LoopbackCanBus, FiltersApplyPerEndpoint)
{
	auto hub = std::make_shared<LoopbackHub>();
	LoopbackCanBus sender(hub), commands(hub, "cmd"), extended(hub, "ext");
	const CanFilter none[] = { { 0, 0, false } };
	const CanFilter cmd[] = { { 0x310, 0x7f0, false } };
	const CanFilter ext[] = { { 0x18000000, 0x1f000000, true } };
	ASSERT_TRUE(sender.open(none, CanOptions{}).isOk());
	ASSERT_TRUE(commands.open(cmd, CanOptions{}).isOk());
	ASSERT_TRUE(extended.open(ext, CanOptions{}).isOk());

	ASSERT_TRUE(sender.send(counted(0x305, 1)));
	ASSERT_TRUE(sender.send(counted(0x315, 2)));
	ASSERT_TRUE(sender.send(makeFrame(0x18daf110, { 0, 3 }, true)));
	ASSERT_TRUE(sender.send(makeFrame(0x315, { 0, 4 }, true)));

	std::vector<int> got_cmd, got_ext;
	CanFrame f;
	while (commands.receive(&f))
		got_cmd.push_back(counterOf(f));
	while (extended.receive(&f))
		got_ext.push_back(counterOf(f));
	EXPECT_EQ(got_cmd, (std::vector<int>{ 2 }));
	EXPECT_EQ(got_ext, (std::vector<int>{ 3 }));
	EXPECT_EQ(hub->traffic().size(), 4u) << "filters only choose what an endpoint receives";
}

TEST(LoopbackCanBus, BlockedHubFillsTheQueueAndDropsOldest)
{
	auto hub = std::make_shared<LoopbackHub>();
	LoopbackCanBus a(hub), b(hub);
	const CanFilter all[] = { { 0, 0, false } };
	CanOptions options;
	options.tx_queue_depth = 4;
	ASSERT_TRUE(a.open(all, options).isOk());
	ASSERT_TRUE(b.open(all, CanOptions{}).isOk());

	hub->setBlocked(true);
	int refused = 0;
	for (int i = 0; i < 10; ++i)
		refused += a.send(counted(0x305, i)) ? 0 : 1;
	a.poll();
	EXPECT_EQ(refused, 6);
	CanStats s = a.stats();
	EXPECT_EQ(s.tx_dropped, 6u);
	EXPECT_EQ(s.tx_queued, 4u);
	EXPECT_EQ(s.tx_frames, 0u);
	CanFrame f;
	EXPECT_FALSE(b.receive(&f));
	EXPECT_TRUE(hub->traffic().empty());

	hub->setBlocked(false);
	a.poll();
	std::vector<int> got;
	while (b.receive(&f))
		got.push_back(counterOf(f));
	EXPECT_EQ(got, (std::vector<int>{ 6, 7, 8, 9 }));
	EXPECT_EQ(a.stats().tx_queued, 0u);
	EXPECT_EQ(a.stats().tx_frames, 4u);
}

TEST(LoopbackCanBus, BusOffIsReportedAndRecovered)
{
	auto hub = std::make_shared<LoopbackHub>();
	LoopbackCanBus a(hub), b(hub);
	const CanFilter all[] = { { 0, 0, false } };
	ASSERT_TRUE(a.open(all, CanOptions{}).isOk());
	ASSERT_TRUE(b.open(all, CanOptions{}).isOk());

	hub->setBusOff(true);
	EXPECT_EQ(a.stats().state, CanState::BusOff);
	EXPECT_EQ(b.stats().state, CanState::BusOff);
	EXPECT_EQ(a.stats().bus_off, 1u);
	ASSERT_TRUE(a.send(counted(0x305, 1)));
	a.poll();
	CanFrame f;
	EXPECT_FALSE(b.receive(&f)) << "nothing crosses a bus-off bus";
	EXPECT_EQ(a.stats().tx_queued, 1u);

	hub->setBusOff(false);
	CanStats s = a.stats();
	EXPECT_EQ(s.state, CanState::ErrorActive);
	EXPECT_EQ(s.bus_off, 1u);
	EXPECT_EQ(s.restarts, 1u);
	a.poll();
	ASSERT_TRUE(b.receive(&f));
	EXPECT_EQ(counterOf(f), 1);

	/* A later endpoint counts only what happens after it opened. */
	LoopbackCanBus c(hub);
	ASSERT_TRUE(c.open(all, CanOptions{}).isOk());
	EXPECT_EQ(c.stats().bus_off, 0u);
	c.close();
	EXPECT_EQ(c.stats().state, CanState::Closed);
}

TEST(LoopbackCanBus, EndpointsOnDifferentThreads)
{
	constexpr int kFrames = 2000;
	auto hub = std::make_shared<LoopbackHub>();
	LoopbackCanBus a(hub), b(hub);
	const CanFilter all[] = { { 0, 0, false } };
	ASSERT_TRUE(a.open(all, CanOptions{}).isOk());
	ASSERT_TRUE(b.open(all, CanOptions{}).isOk());

	std::atomic<bool> done{ false };
	int received = 0, out_of_order = 0;
	std::thread receiver([&] {
		int last = -1;
		CanFrame f;
		for (;;) {
			const bool finished = done.load();
			if (b.receive(&f)) {
				out_of_order += counterOf(f) <= last;
				last = counterOf(f);
				++received;
			} else if (finished) {
				break;
			} else {
				std::this_thread::yield();
			}
		}
	});
	for (int i = 0; i < kFrames; ++i)
		ASSERT_TRUE(a.send(counted(0x305, i)));
	done.store(true);
	receiver.join();
	EXPECT_EQ(out_of_order, 0);
	EXPECT_EQ(static_cast<std::uint64_t>(received) + b.rxDropped(),
		  static_cast<std::uint64_t>(kFrames));
	EXPECT_EQ(b.stats().rx_frames, static_cast<std::uint64_t>(kFrames))
		<< "rx_frames counts every frame through the filters, the dropped ones too";
	EXPECT_EQ(hub->trafficCount(), static_cast<std::uint64_t>(kFrames));
}

} /* namespace */
} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * FileCanBus: a CAN bus that writes every frame sent into a candump log
 * file (candump -l format), for demos and tests on a host without CAN.
 *
 * Each frame is one line:
 *
 *   (1700000000.123456) can0 305#0011223344556677
 *
 * with the wall-clock time of writing (CLOCK_REALTIME, seconds.microseconds),
 * the interface name, the id in uppercase hex (3 digits standard, 8 digits
 * extended) and the data bytes in uppercase hex; a CAN FD frame is written
 * "ID##<flags><data>" (flags 0). python-can's can.CanutilsLogReader /
 * can.LogReader and can-utils' log2asc and canplayer read it. Lines are
 * flushed once per poll(), so a reader can follow the file live.
 *
 * open() creates or truncates the file. send() goes through a
 * hal::CanTxQueue (depth CanOptions::tx_queue_depth) and writes what the
 * "bus" takes at once; poll() writes what is left and flushes. The file has
 * unlimited bandwidth unless setBandwidth() (test hook) caps the frames
 * written per poll() interval: then the queue fills, and the oldest frames
 * are dropped and counted (tx_dropped), as on a busy bus. send() never
 * blocks. A write error is counted (tx_errors) and reported by lastError().
 *
 * receive() returns frames given to inject() (test hook for commands, any
 * thread) that pass the filters given to open() (sim_can.h): at most
 * kRxCapacity wait; when full the oldest is dropped (rxDropped()).
 *
 * Threads: the frame thread owns the bus; stats(), inject() and rxDropped()
 * are safe from any thread. Allocates: open() (the queue, the file's
 * buffer, the filters); send(), poll(), receive(), inject() never.
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "hal/can_bus.h"
#include "hal/can_tx_queue.h"

namespace dockpose::hal {

class FileCanBus : public CanBus
{
public:
	static constexpr std::size_t kRxCapacity = 256;

	FileCanBus(std::string path, std::string interface_name = "can0");
	~FileCanBus() override;

	std::string name() const override;
	Status open(std::span<const CanFilter> filters, const CanOptions &options) override;
	void close() override;

	bool send(const CanFrame &frame) override;
	void poll() override;
	bool receive(CanFrame *frame) override;

	CanStats stats() const override;
	std::string lastError() const override;

	/* Test hook: a received frame (it still has to pass the filters). */
	void inject(const CanFrame &frame);
	/* Test hook: frames written per poll() interval; negative: unlimited (the default). */
	void setBandwidth(int frames_per_poll);
	/* Injected frames dropped from a full receive queue. */
	std::uint64_t rxDropped() const { return rx_dropped_.load(std::memory_order_relaxed); }

private:
	void pump();
	bool writeFrame(const CanFrame &frame);
	void setError(const char *what, int err);
	void publishQueue();

	std::string path_;
	std::string interface_;

	std::FILE *file_ = nullptr;
	std::vector<char> file_buffer_;
	CanOptions options_;
	CanTxQueue tx_;
	int frames_per_poll_ = -1;
	int budget_ = -1;
	char error_[256] = {};

	mutable std::mutex rx_mutex_; /* guards the receive side (inject from any thread) */
	bool rx_open_ = false;
	std::vector<CanFilter> filters_;
	std::vector<CanFrame> rx_ring_;
	std::size_t rx_head_ = 0;
	std::size_t rx_count_ = 0;

	std::atomic<std::uint64_t> tx_frames_{ 0 };
	std::atomic<std::uint64_t> tx_dropped_{ 0 };
	std::atomic<std::uint64_t> tx_errors_{ 0 };
	std::atomic<std::uint64_t> rx_frames_{ 0 };
	std::atomic<std::uint64_t> rx_dropped_{ 0 };
	std::atomic<std::uint32_t> tx_queued_{ 0 };
	std::atomic<CanState> state_{ CanState::Closed };
};

} /* namespace dockpose::hal */

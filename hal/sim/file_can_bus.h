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
 * open() creates or truncates the file. send() is CanBusBase's (the
 * transmit queue, CanOptions::tx_queue_depth deep) and writes what the
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
 * are safe from any thread. Allocates: the constructor, open() (the file's
 * buffer, the filters); send(), poll(), receive(), inject() never.
 */
#pragma once

#include <cstdint>
#include <cstdio>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "hal/can_bus_base.h"

namespace dockpose::hal {

class FileCanBus : public CanBusBase
{
public:
	static constexpr std::size_t kRxCapacity = kMaxRxDepth;

	FileCanBus(std::string path, std::string interface_name = "can0");
	~FileCanBus() override;

	Status open(std::span<const CanFilter> filters, const CanOptions &options) override;
	void close() override;
	void poll() override;

	/* Test hook: a received frame (it still has to pass the filters). */
	void inject(const CanFrame &frame);
	/* Test hook: frames written per poll() interval; negative: unlimited (the default). */
	void setBandwidth(int frames_per_poll);

private:
	void transmit() override;
	bool writeFrame(const CanFrame &frame);
	void writeFailed(int err);
	Status fail(const std::string &message);

	std::string path_;
	std::string interface_;

	std::FILE *file_ = nullptr;
	std::vector<char> file_buffer_;
	int frames_per_poll_ = -1;
	int budget_ = -1;

	mutable std::mutex filter_mutex_; /* guards filters_ (inject() from any thread) */
	std::vector<CanFilter> filters_;
};

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * The protocol's frames (firmware/protocol/dockpose_can.h: can::RawFrame,
 * can::FdFrame) as the hal's buses carry them (hal::CanFrame), both ways:
 * the one place the daemon, its tests, the soak and the fuzzers copy
 * between them.
 *
 * Allocates: never. Threads: pure functions, any thread.
 */
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "firmware/protocol/dockpose_can.h"
#include "hal/can_bus.h"

namespace dockpose::firmware {

/* A classic protocol frame to send; deadline_ns as hal::CanFrame's (0: never expires). */
inline hal::CanFrame toHalFrame(const can::RawFrame &raw, std::int64_t deadline_ns = 0)
{
	hal::CanFrame frame;
	frame.deadline_ns = deadline_ns;
	frame.id = raw.id;
	frame.len = raw.len;
	std::copy(raw.data.begin(), raw.data.end(), frame.data.begin());
	return frame;
}

/* DP_ReportFd to send: a CAN FD frame. */
inline hal::CanFrame toHalFrame(const can::FdFrame &fd, std::int64_t deadline_ns = 0)
{
	hal::CanFrame frame;
	frame.deadline_ns = deadline_ns;
	frame.fd = true;
	frame.id = fd.id;
	frame.len = fd.len;
	std::copy(fd.data.begin(), fd.data.end(), frame.data.begin());
	return frame;
}

/* A received frame as the classic decoder takes it: the id, the length as received (a frame
 * longer than 8 bytes keeps its length, so the decoder refuses it as WrongLength) and the
 * first bytes up to 8. */
inline can::RawFrame toRawFrame(const hal::CanFrame &frame)
{
	can::RawFrame raw;
	raw.id = frame.id;
	raw.len = frame.len;
	std::copy_n(frame.data.begin(), std::min<std::size_t>(frame.len, raw.data.size()),
		    raw.data.begin());
	return raw;
}

/* A received CAN FD frame as Decoder::feedFd() takes it. */
inline can::FdFrame toFdFrame(const hal::CanFrame &frame)
{
	can::FdFrame fd;
	fd.id = frame.id;
	fd.len = frame.len;
	std::copy_n(frame.data.begin(), std::min<std::size_t>(frame.len, fd.data.size()),
		    fd.data.begin());
	return fd;
}

/* A received frame into `decoder`: a CAN FD frame through feedFd(), a classic one through
 * feed(); arrival_us < 0: undated. */
inline can::Decoder::Event feedDecoder(can::Decoder &decoder, const hal::CanFrame &frame,
				       std::int64_t arrival_us = -1)
{
	if (frame.fd)
		return arrival_us < 0 ? decoder.feedFd(toFdFrame(frame))
				      : decoder.feedFd(toFdFrame(frame), arrival_us);
	return arrival_us < 0 ? decoder.feed(toRawFrame(frame))
			      : decoder.feed(toRawFrame(frame), arrival_us);
}

} /* namespace dockpose::firmware */

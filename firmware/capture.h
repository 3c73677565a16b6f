/* SPDX-License-Identifier: MIT */
/*
 * Frame capture for calibration: `dockposed --board B --capture DIR --frames N [--every K]`.
 *
 * The daemon runs as usual (the board's camera with its exposure and gain, the strobe in
 * the board file's mode, CAN status frames), and a FrameCapture, set as the daemon's frame
 * tap, writes every Kth usable frame to DIR as a binary PGM (frame-000000.pgm, ...): in
 * strobe mode "alternate" only the lit frames are usable (the unlit ones show no dots), in
 * the other modes every frame of the camera's size. After N frames it asks the daemon to
 * stop: the daemon then shuts down as on SIGTERM (LED off, a last status frame).
 *
 * Threads: onFrame() runs on the daemon's frame thread; done() and failed() may be read
 * from any thread. Allocates: the PGM bytes and the file name of each frame written (the
 * frame loop's no-allocation rule does not hold while capturing).
 */
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "algo/status.h"
#include "hal/camera.h"
#include "hal/strobe.h"

namespace dockpose::firmware {

/* What the daemon hands each accepted frame to (Daemon::setFrameTap). */
class FrameTap
{
public:
	virtual ~FrameTap() = default;
	/* A frame of the camera model's size and how it was lit; frame thread. */
	virtual void onFrame(const hal::Frame &frame, hal::Lighting lighting) = 0;
};

/*
 * Make DIR (and its parents) if it does not exist and check that a file can be created in
 * it. Errors name the directory and the reason ("cannot create ...: Permission denied").
 */
Status prepareCaptureDir(const std::string &dir);

class FrameCapture : public FrameTap
{
public:
	/*
	 * Write `frames` frames (>= 1), every `every`th usable one (>= 1), to `dir` (ready:
	 * prepareCaptureDir()); `only_lit`: keep only frames lit for their whole exposure
	 * (strobe mode alternate). Sets *stop (the daemon's stop request) when done or when a
	 * write failed.
	 */
	FrameCapture(std::string dir, int frames, int every, bool only_lit,
		     std::atomic<bool> *stop);

	void onFrame(const hal::Frame &frame, hal::Lighting lighting) override;

	/* Frames written so far. */
	int written() const { return written_.load(); }
	bool done() const { return written_.load() >= frames_; }
	/* The first write error, empty when none (read after the daemon stopped). */
	const std::string &error() const { return error_; }

	/* The file name of the i-th frame written: "frame-000012.pgm". */
	static std::string fileName(int index);

private:
	std::string dir_;
	int frames_;
	int every_;
	bool only_lit_;
	std::atomic<bool> *stop_;
	std::uint64_t usable_ = 0; /* usable frames seen (frame thread) */
	std::atomic<int> written_{ 0 };
	std::string error_; /* frame thread; read after it stopped */
};

} /* namespace dockpose::firmware */

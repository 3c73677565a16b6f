/* SPDX-License-Identifier: MIT */
/*
 * ReplayCamera: a simulated camera that plays back recorded frames, for tests,
 * demos and the sim board. Behaves like a real camera (see
 * sim_camera_base.h): own capture thread on a fixed frame grid at the
 * configured frame duration, bounded buffers, drops counted.
 *
 * The frames are the files frame_*.pgm of one folder (binary 8-bit PGM,
 * algo/io/pgm.h), in name order (so number them with leading zeros:
 * frame_000000.pgm, ...). All are read in configure(): every frame must
 * parse and have the same size, and the configured width/height must be 0 or
 * that size; otherwise configure() fails naming the file and the reason.
 *
 * Frame n of the stream shows file n (n modulo the count when looping;
 * sequence = n, so it keeps counting over loops). Without looping,
 * waitFrame() returns Stopped once the last frame has been taken. A replay
 * never skips a frame to keep up (it catches up late instead); frames are
 * lost only when the frame thread does not take them (queue drops).
 *
 * Allocates: configure() (every frame, the buffers); the capture loop and the
 * frame path never.
 */
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "algo/image.h"
#include "hal/sim/sim_camera_base.h"

namespace dockpose::hal {

class ReplayCamera : public SimCameraBase
{
public:
	ReplayCamera(std::string folder, bool loop);
	~ReplayCamera() override;

	std::string name() const override;
	Status configure(const CameraConfig &config) override;

	/* Frames read by configure(). */
	std::size_t frameCount() const { return frames_.size(); }

protected:
	bool produceFrame(const Exposure &exposure, Image *image) override;

private:
	std::string folder_;
	bool loop_;
	std::vector<Image> frames_;
};

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
/*
 * Proof that the frame path never touches the heap: global operator new /
 * delete and malloc / calloc / realloc are counted, and this executable is
 * compiled (all of algo included) with EIGEN_RUNTIME_NO_MALLOC so that any
 * Eigen heap allocation asserts. Frames are rendered up front; then the
 * pipeline runs in steady state — tracking, full search after reset(), lost
 * target, cluttered and empty frames — with the counters armed.
 */
#ifndef EIGEN_RUNTIME_NO_MALLOC
#error "test_no_alloc must be compiled with EIGEN_RUNTIME_NO_MALLOC"
#endif

#include <cstdio>
#include <cstdlib>
#include <vector>

#include <gtest/gtest.h>

#include "../common/counting_allocator.h"
#include "algo/pipeline.h"
#include "algo/synth/renderer.h"
#include "fixtures.h"

using namespace dockpose;
using dockpose::test::g_allocations;
using dockpose::test::g_armed;

namespace {

/* Run `frames` through the pipeline with the counters armed; return allocations. */
long allocationsWhile(Pipeline &pipeline, const std::vector<Image> &frames, bool reset_each,
		      int *found, int *windowed = nullptr)
{
	*found = 0;
	int roi = 0;
	g_allocations = 0;
	Eigen::internal::set_is_malloc_allowed(false);
	g_armed = true;
	for (const Image &frame : frames) {
		if (reset_each)
			pipeline.reset();
		const PoseResult &r = pipeline.process(frame.view());
		*found += r.found ? 1 : 0;
		roi += r.windows > 0 ? 1 : 0;
	}
	g_armed = false;
	if (windowed)
		*windowed = roi;
	Eigen::internal::set_is_malloc_allowed(true);
	return g_allocations.load();
}

} /* namespace */

TEST(NoAlloc, CountingHooksWork)
{
	g_allocations = 0;
	g_armed = true;
	auto *p = new int(3);
	void *q = std::malloc(16);
	g_armed = false;
	delete p;
	std::free(q);
	EXPECT_EQ(g_allocations.load(), 2);
}

TEST(NoAlloc, PipelineSteadyState)
{
	const TargetModel target = test::wedgeModel();
	const CameraIntrinsics cam = test::camera1456(); /* radial distortion only */
	FrameRenderer renderer(target, cam);

	/* A docking approach with clutter, a hidden LED, a lost target and an empty frame. */
	std::vector<Image> frames;
	for (int i = 0; i < 24; ++i) {
		RenderOptions o;
		o.reflections = (i % 4 == 1) ? 6 : 0;
		o.glints = (i % 4 == 2) ? 2 : 0;
		o.hot_pixels = 20;
		o.occlusion_mask = (i % 6 == 3) ? 0b000100u : 0u;
		Image img;
		const double range = 1800.0 - 60.0 * i;
		renderer.render(poseAt(cam, target, range, { 5.0, 10.0 - i, 3.0 }), o, 100 + i,
				&img);
		frames.push_back(std::move(img));
	}
	frames.emplace_back(cam.width, cam.height, 10); /* nothing in view */
	{
		RenderOptions o;
		o.occlusion_mask = 0b111111u;
		o.reflections = 10;
		Image img;
		renderer.render(poseAt(cam, target, 900.0, { 0, 0, 0 }), o, 7, &img);
		frames.push_back(std::move(img));
	}

	Pipeline pipeline(target, cam);
	int found = 0;
	/* Warm-up: one pass of everything (first-touch of every buffer). */
	for (const Image &f : frames)
		pipeline.process(f.view());
	pipeline.reset();

	int windowed = 0;
	EXPECT_EQ(allocationsWhile(pipeline, frames, false, &found, &windowed), 0) << "tracking";
	EXPECT_GE(found, 20);
	/* Most tracked frames read only the windows around the LEDs (the path above covered them). */
	EXPECT_GE(windowed, 12);
	EXPECT_EQ(allocationsWhile(pipeline, frames, true, &found), 0) << "full search every frame";
	EXPECT_GE(found, 20);
}

int main(int argc, char **argv)
{
	::testing::InitGoogleTest(&argc, argv);
	return RUN_ALL_TESTS();
}

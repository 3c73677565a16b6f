/* SPDX-License-Identifier: MIT */
/*
 * A frame as the pipeline gets it from the camera: written by the sensor's
 * DMA, in no cache. The benchmarks keep their frames in memory and read them
 * again and again, and this machine's last-level cache (~480 MB) would hold
 * them all; each frame is flushed before it is processed instead. Flushing
 * 1456x1088 bytes costs ~1 ms here, so it stays outside the timing.
 * Allocates: never. Threads: the caller's.
 */
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>

#include "algo/image.h"

namespace dockpose::bench {

/* Writes back and drops every cache line of img's pixels. */
inline void evict(const Image &img)
{
	const std::uint8_t *p = img.data();
	const std::size_t n = static_cast<std::size_t>(img.width()) * img.height();
#if defined(__x86_64__)
	for (std::size_t k = 0; k < n; k += 64)
		__builtin_ia32_clflush(p + k);
	__builtin_ia32_mfence();
#elif defined(__aarch64__)
	for (std::size_t k = 0; k < n; k += 64)
		asm volatile("dc civac, %0" : : "r"(p + k) : "memory");
	asm volatile("dsb sy" : : : "memory");
#else
	(void)p;
	(void)n;
#endif
}

/* evict(img), then body() timed: its seconds. */
template<typename Body>
double fresh(const Image &img, Body &&body)
{
	evict(img);
	const auto t0 = std::chrono::steady_clock::now();
	body();
	const auto t1 = std::chrono::steady_clock::now();
	return std::chrono::duration<double>(t1 - t0).count();
}

} /* namespace dockpose::bench */

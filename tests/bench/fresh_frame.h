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

/* Writes back and drops every cache line that holds a byte of img's pixels. */
inline void evict(const Image &img)
{
	constexpr std::uintptr_t kLine = 64;
	const std::size_t n = static_cast<std::size_t>(img.width()) * img.height();
	if (n == 0)
		return;
	/* From the line of the first byte to the line of the last (the pixels need not start one). */
	const std::uintptr_t first = reinterpret_cast<std::uintptr_t>(img.data()) & ~(kLine - 1);
	const std::uintptr_t last = reinterpret_cast<std::uintptr_t>(img.data() + n - 1);
	for (std::uintptr_t a = first; a <= last; a += kLine) {
		const auto *line = reinterpret_cast<const void *>(a);
#if defined(__x86_64__)
		__builtin_ia32_clflush(line);
#elif defined(__aarch64__)
		asm volatile("dc civac, %0" : : "r"(line) : "memory");
#else
		(void)line;
#endif
	}
#if defined(__x86_64__)
	__builtin_ia32_mfence();
#elif defined(__aarch64__)
	asm volatile("dsb sy" : : : "memory");
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

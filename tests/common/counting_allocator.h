/* SPDX-License-Identifier: MIT */
/*
 * Counting allocation hooks for the zero-allocation proofs (tests/algo/test_no_alloc,
 * tests/firmware/test_daemon_no_alloc): replacement global operator new / delete and an
 * interposed malloc / calloc / realloc (tests/common/allocation_hooks.h) that count calls
 * while armed, in every thread.
 *
 * Defines the replacement functions: include it in exactly one file of a test executable.
 */
#pragma once

#include <atomic>
#include <cstdlib>
#include <new>

namespace dockpose::test {

inline std::atomic<long> g_allocations{ 0 };
inline std::atomic<bool> g_armed{ false };

inline void countAllocation()
{
	if (g_armed.load(std::memory_order_relaxed))
		g_allocations.fetch_add(1, std::memory_order_relaxed);
}

/* Start counting from zero. */
inline void armAllocationCounter()
{
	g_allocations = 0;
	g_armed = true;
}

/* Stop counting; the allocations seen while armed. */
inline long disarmAllocationCounter()
{
	g_armed = false;
	return g_allocations.load();
}

} /* namespace dockpose::test */

#include "allocation_hooks.h"

/* What the hooks count: every allocation in every thread, while armed. */
void dockpose::test::onAllocation()
{
	countAllocation();
}

/* SPDX-License-Identifier: MIT */
/*
 * Counting allocation hooks for the zero-allocation proofs (tests/algo/test_no_alloc,
 * tests/firmware/test_daemon_no_alloc): replacement global operator new / delete and an
 * interposed malloc / calloc / realloc that count calls while armed, in every thread.
 *
 * Defines the replacement functions: include it in exactly one file of a test executable.
 */
#pragma once

/* The replacement operator delete frees what the replacement operator new took from malloc. */
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

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

extern "C" void *__libc_malloc(std::size_t);

/* Counting hooks: operator new and friends take memory from the C library directly. */
void *operator new(std::size_t n)
{
	dockpose::test::countAllocation();
	if (void *p = __libc_malloc(n ? n : 1))
		return p;
	throw std::bad_alloc();
}
void *operator new[](std::size_t n)
{
	dockpose::test::countAllocation();
	if (void *p = __libc_malloc(n ? n : 1))
		return p;
	throw std::bad_alloc();
}
void *operator new(std::size_t n, std::align_val_t a)
{
	dockpose::test::countAllocation();
	if (void *p = std::aligned_alloc(static_cast<std::size_t>(a),
					 (n + static_cast<std::size_t>(a) - 1) &
						 ~(static_cast<std::size_t>(a) - 1)))
		return p;
	throw std::bad_alloc();
}
void operator delete(void *p) noexcept
{
	std::free(p);
}
void operator delete[](void *p) noexcept
{
	std::free(p);
}
void operator delete(void *p, std::size_t) noexcept
{
	std::free(p);
}
void operator delete[](void *p, std::size_t) noexcept
{
	std::free(p);
}
void operator delete(void *p, std::align_val_t) noexcept
{
	std::free(p);
}
void operator delete(void *p, std::size_t, std::align_val_t) noexcept
{
	std::free(p);
}

/* malloc family: interpose and forward to the C library's implementation. */
extern "C" {
extern void *__libc_calloc(std::size_t, std::size_t);
extern void *__libc_realloc(void *, std::size_t);

void *malloc(std::size_t n)
{
	dockpose::test::countAllocation();
	return __libc_malloc(n);
}
void *calloc(std::size_t n, std::size_t m)
{
	dockpose::test::countAllocation();
	return __libc_calloc(n, m);
}
void *realloc(void *p, std::size_t n)
{
	dockpose::test::countAllocation();
	return __libc_realloc(p, n);
}
}

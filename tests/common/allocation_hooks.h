/* SPDX-License-Identifier: MIT */
/*
 * The replacement allocation functions of the zero-allocation proofs, written
 * once: global operator new (plain, array, nothrow, aligned) and delete, and
 * an interposed malloc / calloc / realloc. Each allocating function calls
 * dockpose::test::onAllocation() and then takes memory from the C library
 * directly (__libc_malloc and friends), so counting never recurses.
 *
 * The including file defines onAllocation() (what is counted, and for whom):
 * tests/common/counting_allocator.h counts every thread while armed,
 * tests/vm/test_vm_libcamera.cpp attributes each allocation to its caller.
 * It may define DOCKPOSE_ALLOC_HOOK before including (attributes for the
 * allocating hooks, e.g. a section whose frames a stack walk skips).
 *
 * Defines the replacement functions: include it in exactly one file of a test
 * executable. Allocates: what its callers ask for. Threads: any.
 */
#pragma once

/* The replacement operator delete frees what the replacement operator new took from malloc. */
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

#include <cstddef>
#include <cstdlib>
#include <new>

#ifndef DOCKPOSE_ALLOC_HOOK
#define DOCKPOSE_ALLOC_HOOK
#endif

namespace dockpose::test {
/* Called once per allocation, before the memory is taken; defined by the including file. */
void onAllocation();
} /* namespace dockpose::test */

extern "C" void *__libc_malloc(std::size_t);
extern "C" void *__libc_calloc(std::size_t, std::size_t);
extern "C" void *__libc_realloc(void *, std::size_t);

DOCKPOSE_ALLOC_HOOK void *operator new(std::size_t n)
{
	dockpose::test::onAllocation();
	if (void *p = __libc_malloc(n ? n : 1))
		return p;
	throw std::bad_alloc();
}
DOCKPOSE_ALLOC_HOOK void *operator new[](std::size_t n)
{
	dockpose::test::onAllocation();
	if (void *p = __libc_malloc(n ? n : 1))
		return p;
	throw std::bad_alloc();
}
DOCKPOSE_ALLOC_HOOK void *operator new(std::size_t n, const std::nothrow_t &) noexcept
{
	dockpose::test::onAllocation();
	return __libc_malloc(n ? n : 1);
}
DOCKPOSE_ALLOC_HOOK void *operator new[](std::size_t n, const std::nothrow_t &) noexcept
{
	dockpose::test::onAllocation();
	return __libc_malloc(n ? n : 1);
}
DOCKPOSE_ALLOC_HOOK void *operator new(std::size_t n, std::align_val_t a)
{
	dockpose::test::onAllocation();
	const auto align = static_cast<std::size_t>(a);
	if (void *p = std::aligned_alloc(align, (n + align - 1) & ~(align - 1)))
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

extern "C" {
DOCKPOSE_ALLOC_HOOK void *malloc(std::size_t n)
{
	dockpose::test::onAllocation();
	return __libc_malloc(n);
}
DOCKPOSE_ALLOC_HOOK void *calloc(std::size_t n, std::size_t m)
{
	dockpose::test::onAllocation();
	return __libc_calloc(n, m);
}
DOCKPOSE_ALLOC_HOOK void *realloc(void *p, std::size_t n)
{
	dockpose::test::onAllocation();
	return __libc_realloc(p, n);
}
}

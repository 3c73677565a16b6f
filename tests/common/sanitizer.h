/* SPDX-License-Identifier: MIT */
/*
 * DOCKPOSE_SANITIZED: 1 when this file is compiled with AddressSanitizer or
 * ThreadSanitizer, by GCC (__SANITIZE_ADDRESS__, __SANITIZE_THREAD__) or by
 * clang (which has only __has_feature). A sanitizer owns operator new and
 * malloc: the allocation-counting hooks (tests/common/allocation_hooks.h) are
 * left out there (TSan's runtime defines operator new too; an interposed
 * malloc beside ASan's made clang 14's ASan abort in its start-up), and the
 * zero-allocation proofs run in the unsanitized trees.
 */
#pragma once

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define DOCKPOSE_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define DOCKPOSE_SANITIZED 1
#endif
#endif
#ifndef DOCKPOSE_SANITIZED
#define DOCKPOSE_SANITIZED 0
#endif

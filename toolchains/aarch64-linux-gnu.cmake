# SPDX-License-Identifier: MIT
#
# Cross build for 64-bit Arm Linux with Debian's own cross toolchain (g++-aarch64-linux-gnu) and
# Debian multiarch for the target's libraries (packages installed as NAME:arm64 by scripts/setup).
# There is no separate sysroot: the arm64 libraries live beside the host's in / under
# /usr/lib/aarch64-linux-gnu, and architecture-independent headers and CMake packages (Eigen,
# nlohmann-json, CLI11) are shared with the host in /usr/include and /usr/share.
#
# Cross-built tests run on this machine under qemu-user (CMAKE_CROSSCOMPILING_EMULATOR), so
# `ctest --preset aarch64` works. qemu-user does not translate GPIO or V4L2 ioctls: tests that
# touch devices need the arm64 system VM instead and carry the ctest label "device".

set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)

set(DOCKPOSE_TARGET_TRIPLET aarch64-linux-gnu)
set(CMAKE_C_COMPILER ${DOCKPOSE_TARGET_TRIPLET}-gcc)
set(CMAKE_CXX_COMPILER ${DOCKPOSE_TARGET_TRIPLET}-g++)

# Multiarch: find_library, find_path and find_package(CONFIG) look in <prefix>/lib/<arch> and
# <prefix>/include/<arch> and never in the host's /usr/lib/x86_64-linux-gnu, so host packages
# that are not installed for arm64 (OpenCV, Google Benchmark) are simply not found.
set(CMAKE_LIBRARY_ARCHITECTURE ${DOCKPOSE_TARGET_TRIPLET})

# The cross compiler searches /usr/include but not the multiarch /usr/include/aarch64-linux-gnu,
# where arm64 -dev packages put their architecture-specific headers. -idirafter puts it after
# every system directory, so it only supplies headers that exist nowhere else and can never
# shadow the cross glibc or libstdc++ headers.
set(CMAKE_C_FLAGS_INIT "-idirafter /usr/include/${DOCKPOSE_TARGET_TRIPLET}")
set(CMAKE_CXX_FLAGS_INIT "-idirafter /usr/include/${DOCKPOSE_TARGET_TRIPLET}")

# Search the host root (multiarch) and the cross toolchain's own tree; programs (pkg-config,
# qemu, python) always come from the host.
set(CMAKE_FIND_ROOT_PATH / /usr/${DOCKPOSE_TARGET_TRIPLET})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

# pkg-config (libcamera, libgpiod for the firmware): only the arm64 .pc files and the
# architecture-independent ones, never the host's. The host pkg-config binary reads these
# variables when FindPkgConfig runs it at configure time.
set(ENV{PKG_CONFIG_LIBDIR}
	"/usr/lib/${DOCKPOSE_TARGET_TRIPLET}/pkgconfig:/usr/share/pkgconfig")
set(ENV{PKG_CONFIG_PATH} "")
unset(ENV{PKG_CONFIG_SYSROOT_DIR})

# Run cross-built programs (tests, gtest discovery) under qemu-user.
# The dynamic loader and libc must come from one glibc build. With the multiarch runtime installed
# (libc6:arm64, pulled in by libstdc++6:arm64; scripts/setup installs it) the program's own
# interpreter /lib/ld-linux-aarch64.so.1 and its libraries all come from there, so qemu needs no
# prefix. `-L /usr/aarch64-linux-gnu` would mix the cross toolchain's loader (libc6-arm64-cross)
# with multiarch's libc.so.6, two different builds; it is only used when there is no multiarch
# loader, and then every library comes from the cross toolchain's tree.
find_program(DOCKPOSE_QEMU_AARCH64 NAMES qemu-aarch64-static qemu-aarch64)
if(DOCKPOSE_QEMU_AARCH64)
	if(EXISTS /lib/ld-linux-aarch64.so.1)
		set(CMAKE_CROSSCOMPILING_EMULATOR "${DOCKPOSE_QEMU_AARCH64}")
	else()
		set(CMAKE_CROSSCOMPILING_EMULATOR
			"${DOCKPOSE_QEMU_AARCH64};-L;/usr/${DOCKPOSE_TARGET_TRIPLET}")
	endif()
else()
	message(WARNING "qemu-aarch64-static not found (run scripts/setup): "
		"cross-built tests cannot run on this machine")
endif()

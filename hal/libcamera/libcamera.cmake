# SPDX-License-Identifier: MIT
#
# Which libcamera the build uses (included by hal/CMakeLists.txt before it looks libcamera up):
#
#   DOCKPOSE_LIBCAMERA empty (the default presets): the system's, through pkg-config (Debian 12's
#     0.0.3, or a board OS's own libcamera-dev when building on the board).
#   DOCKPOSE_LIBCAMERA=TAG (an alias such as lc07 or lc05, or a tag; presets host-lc07, host-lc05,
#     aarch64-lc07): Raspberry Pi's libcamera built by scripts/libcamera-build for this build's
#     architecture (built at the first configure, minutes; cached outside the tree after that).
#     Its pkg-config files come first, so hal, the VM tests and the packaging all see it; the
#     programs built here find it through their build-tree RPATH, and it finds its IPA modules
#     under its own prefix. The tags, the aliases and the cache's place are scripts/libcamera-build's.
set(DOCKPOSE_LIBCAMERA "" CACHE STRING
	"libcamera to build against: empty for the system's, else a tag or alias of scripts/libcamera-build (lc05, lc07)")
# A tree whose DOCKPOSE_LIBCAMERA changes looks libcamera up again: FindPkgConfig keeps its
# results (and the library files it found) in the cache and would not notice the other
# pkg-config path.
if(NOT "${DOCKPOSE_LIBCAMERA}" STREQUAL "${_DOCKPOSE_LIBCAMERA_LOOKED_UP}")
	get_cmake_property(_dockpose_cache_variables CACHE_VARIABLES)
	foreach(variable IN LISTS _dockpose_cache_variables)
		if(variable MATCHES "^(__pkg_config_checked_|pkgcfg_lib_)(DOCKPOSE_VM_|DOCKPOSE_DEB_)?LIBCAMERA")
			unset(${variable} CACHE)
		endif()
	endforeach()
	set(_DOCKPOSE_LIBCAMERA_LOOKED_UP "${DOCKPOSE_LIBCAMERA}" CACHE INTERNAL "")
endif()
if(NOT DOCKPOSE_LIBCAMERA)
	set(DOCKPOSE_LIBCAMERA_PREFIX "" CACHE INTERNAL "Prefix of the libcamera scripts/libcamera-build made")
	return()
endif()
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
	set(_dockpose_libcamera_arch arm64)
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
	set(_dockpose_libcamera_arch amd64)
else()
	message(FATAL_ERROR "DOCKPOSE_LIBCAMERA: scripts/libcamera-build builds for amd64 and arm64, "
		"not ${CMAKE_SYSTEM_PROCESSOR}")
endif()
message(STATUS "libcamera: scripts/libcamera-build ${DOCKPOSE_LIBCAMERA} --arch ${_dockpose_libcamera_arch} "
	"(the first time: minutes)")
execute_process(
	COMMAND ${PROJECT_SOURCE_DIR}/scripts/libcamera-build ${DOCKPOSE_LIBCAMERA}
		--arch ${_dockpose_libcamera_arch}
	OUTPUT_VARIABLE _dockpose_libcamera_prefix OUTPUT_STRIP_TRAILING_WHITESPACE
	RESULT_VARIABLE _dockpose_libcamera_rc)
if(NOT _dockpose_libcamera_rc EQUAL 0 OR NOT EXISTS ${_dockpose_libcamera_prefix}/lib/pkgconfig/libcamera.pc)
	message(FATAL_ERROR "DOCKPOSE_LIBCAMERA=${DOCKPOSE_LIBCAMERA}: scripts/libcamera-build failed "
		"(exit ${_dockpose_libcamera_rc}; its messages above)")
endif()
set(DOCKPOSE_LIBCAMERA_PREFIX ${_dockpose_libcamera_prefix} CACHE INTERNAL
	"Prefix of the libcamera scripts/libcamera-build made")
# The process environment, for every pkg_check_modules of this configure run (the cross
# toolchain's PKG_CONFIG_LIBDIR stays: the rest still comes from the arm64 multiarch packages).
set(ENV{PKG_CONFIG_PATH} "${DOCKPOSE_LIBCAMERA_PREFIX}/lib/pkgconfig")
message(STATUS "libcamera: ${DOCKPOSE_LIBCAMERA_PREFIX}")

# SPDX-License-Identifier: MIT
#
# The real backends against real kernel drivers, in the test VMs (scripts/vm, docs/vm-tests.md):
#
#   test_vm_socketcan   SocketCanBus on vcan0/vcan1; candump, cansend, ip, tc as witnesses
#   test_vm_gpiod       GpiodStrobe on the gpio-sim chip "dockpose-sim"; gpioinfo and the
#                       chip's sysfs values as witnesses; dockposed itself on SIGTERM
#   test_vm_libcamera   LibcameraCamera on vimc; cam as witness; allocations in the frame path
#
# Each is one GoogleTest executable that works only inside a test VM (elsewhere it exits 77:
# skipped). They are never discovered or run on the host: each runs whole, in one VM, as one
# ctest test per architecture (label vm):
#
#   vm_x86_64_vcan_socketcan   vm_x86_64_gpiosim_gpiod   vm_x86_64_vimc_libcamera
#   vm_aarch64_vcan_socketcan  vm_aarch64_gpiosim_gpiod  vm_aarch64_vimc_libcamera
#
# dockpose_add_vm_test keeps only the ones of this build's architecture (the host build runs
# the x86_64 VM, the aarch64 cross build the arm64 VM).
#
# Include this file after tests/vm/CMakeLists.txt (which defines dockpose_add_vm_test).

if(NOT DOCKPOSE_BUILD_TESTS)
	return()
endif()
if(NOT COMMAND dockpose_add_vm_test)
	message(FATAL_ERROR "tests/vm/backends.cmake: include it after add_subdirectory(vm), "
		"which defines dockpose_add_vm_test")
endif()

if(NOT TARGET dockpose_hal_libcamera OR NOT TARGET dockpose_hal_gpiod OR
   NOT TARGET dockpose_hal_socketcan)
	message(STATUS "VM backend tests: left out (the boards built here do not wire libcamera, "
		"libgpiod and SocketCAN)")
	return()
endif()

find_package(GTest REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(DOCKPOSE_VM_LIBCAMERA REQUIRED IMPORTED_TARGET libcamera)
pkg_check_modules(DOCKPOSE_VM_LIBGPIOD REQUIRED IMPORTED_TARGET libgpiod)

set(_dockpose_vm_dir ${CMAKE_CURRENT_LIST_DIR})
get_filename_component(_dockpose_vm_source_dir ${CMAKE_CURRENT_LIST_DIR}/../.. ABSOLUTE)

# dockpose_vm_backend_test(TARGET CTEST_SUFFIX LIBRARIES...)
function(dockpose_vm_backend_test target suffix)
	add_executable(${target} ${_dockpose_vm_dir}/${target}.cpp)
	target_link_libraries(${target} PRIVATE ${ARGN} dockpose_hal GTest::gtest dockpose_warnings)
	target_compile_features(${target} PRIVATE cxx_std_20)
	set_target_properties(${target} PROPERTIES CXX_EXTENSIONS OFF)
	target_compile_definitions(${target} PRIVATE DOCKPOSE_SOURCE_DIR="${_dockpose_vm_source_dir}")
	foreach(arch x86_64 aarch64)
		dockpose_add_vm_test(vm_${arch}_${suffix} ${arch} ${target})
	endforeach()
endfunction()

dockpose_vm_backend_test(test_vm_socketcan vcan_socketcan dockpose_hal_socketcan)

dockpose_vm_backend_test(test_vm_gpiod gpiosim_gpiod dockpose_hal_gpiod PkgConfig::DOCKPOSE_VM_LIBGPIOD
	${CMAKE_DL_LIBS})
# What dockposed drives the strobe line to before it lets go of it: a preloaded probe that
# reads the gpio-sim line at the moment libgpiod releases it (same source, probe part only).
add_library(vm_gpiod_release_probe SHARED ${_dockpose_vm_dir}/test_vm_gpiod.cpp)
target_compile_features(vm_gpiod_release_probe PRIVATE cxx_std_20)
set_target_properties(vm_gpiod_release_probe PROPERTIES CXX_EXTENSIONS OFF)
string(REGEX MATCH "^[0-9]+" _dockpose_vm_gpiod_major "${DOCKPOSE_VM_LIBGPIOD_VERSION}")
target_compile_definitions(vm_gpiod_release_probe PRIVATE DOCKPOSE_VM_RELEASE_PROBE=1
	DOCKPOSE_GPIOD_MAJOR=${_dockpose_vm_gpiod_major})
target_link_libraries(vm_gpiod_release_probe PRIVATE ${CMAKE_DL_LIBS} dockpose_warnings)
target_compile_definitions(test_vm_gpiod PRIVATE DOCKPOSE_GPIOD_MAJOR=${_dockpose_vm_gpiod_major}
	DOCKPOSE_VM_RELEASE_PROBE_LIB="$<TARGET_FILE:vm_gpiod_release_probe>")
add_dependencies(test_vm_gpiod vm_gpiod_release_probe)
# dockposed with the vm board (board/vm) built in: the real daemon's SIGTERM shutdown (not
# under the sanitizers: the probe cannot be preloaded ahead of their runtime).
if(TARGET dockposed AND "vm" IN_LIST DOCKPOSE_BOARDS AND NOT DOCKPOSE_SANITIZE)
	target_compile_definitions(test_vm_gpiod PRIVATE DOCKPOSED="$<TARGET_FILE:dockposed>")
	add_dependencies(test_vm_gpiod dockposed)
endif()

dockpose_vm_backend_test(test_vm_libcamera vimc_libcamera dockpose_hal_libcamera PkgConfig::DOCKPOSE_VM_LIBCAMERA
	${CMAKE_DL_LIBS})
# The witness cam: the one of the libcamera built against when scripts/libcamera-build made it
# (DOCKPOSE_LIBCAMERA; its arm64 build has none), else the guest's on PATH (Debian's).
if(DOCKPOSE_LIBCAMERA_PREFIX AND EXISTS ${DOCKPOSE_LIBCAMERA_PREFIX}/bin/cam)
	# (meson installs it without an RPATH to its own lib/: run through the shell with the path)
	target_compile_definitions(test_vm_libcamera PRIVATE
		DOCKPOSE_VM_CAM="LD_LIBRARY_PATH=${DOCKPOSE_LIBCAMERA_PREFIX}/lib ${DOCKPOSE_LIBCAMERA_PREFIX}/bin/cam")
endif()
# Its counting malloc / operator new would replace the sanitizers' own.
if(DOCKPOSE_SANITIZE)
	target_compile_definitions(test_vm_libcamera PRIVATE DOCKPOSE_VM_NO_ALLOC_HOOKS=1)
endif()

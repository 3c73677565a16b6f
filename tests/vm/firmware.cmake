# SPDX-License-Identifier: MIT
#
# The whole firmware (dockposed) in the test VMs (tests/vm/firmware_vm.sh; docs/vm-tests.md,
# "Whole firmware in the VMs"). Included from tests/vm/CMakeLists.txt after its fixtures.
#
#   vm_x86_64_dockposed_vm_board        this build's dockposed on board/vm/board.json in the
#                                       x86_64 VM: vimc, gpio-sim, vcan0, commands on CAN
#   vm_aarch64_dockposed_vm_board       the same with the aarch64 build's dockposed in the
#                                       arm64 VM
#   vm_aarch64_replay_matches_x86_64    rendered frames of the target replayed by both builds;
#                                       their pose frames equal within the protocol's steps
#   vm_x86_64_dockposed_late_can        dockposed started before its CAN interface (can0)
#                                       exists; can0 created seconds later; poses then arrive
#   vm_x86_64_virtual_libcamera         (trees against Raspberry Pi's libcamera 0.7 only:
#                                       DOCKPOSE_LIBCAMERA lc07) the replay frames as JPEG
#                                       files played by libcamera's virtual pipeline to
#                                       dockposed's libcamera backend; its poses against the
#                                       replay camera's, image by image
#
# All three belong to the host build (not cross-compiling, x86_64): it has the x86_64
# dockposed, the dockpose tool that renders the frames, and the python that decodes the CAN
# logs. The aarch64 dockposed comes from DOCKPOSE_AARCH64_BUILD_DIR (the aarch64 preset's
# tree); a test that needs it and does not find it fails and says how to build it. In other
# builds (the aarch64 cross build) nothing is registered here.

set(DOCKPOSE_AARCH64_BUILD_DIR ${PROJECT_SOURCE_DIR}/build/aarch64 CACHE PATH
	"Build tree of the aarch64 preset, whose firmware/dockposed the aarch64 VM tests run")

if(CMAKE_CROSSCOMPILING OR NOT CMAKE_SYSTEM_PROCESSOR STREQUAL "x86_64")
	message(STATUS "VM firmware tests: left out (they run from the x86_64 host build)")
elseif(NOT TARGET dockposed OR NOT TARGET dockpose)
	message(STATUS "VM firmware tests: left out (no dockposed or dockpose target)")
elseif(NOT "vm" IN_LIST DOCKPOSE_BOARDS)
	message(STATUS "VM firmware tests: left out (the vm board is not in DOCKPOSE_BOARDS)")
else()
	set(_fw_script ${CMAKE_CURRENT_LIST_DIR}/firmware_vm.sh)
	set(_fw_aarch64 ${DOCKPOSE_AARCH64_BUILD_DIR}/firmware/dockposed)
	set(_fw_out ${CMAKE_CURRENT_BINARY_DIR}/firmware)
	math(EXPR _fw_ctest_timeout "${DOCKPOSE_VM_TIMEOUT_S} + 60")

	# _dockpose_fw_test(NAME FIXTURES ARGS...): firmware_vm.sh ARGS as a vm test needing FIXTURES.
	function(_dockpose_fw_test name fixtures)
		add_test(NAME ${name} COMMAND ${_fw_script} --timeout ${DOCKPOSE_VM_TIMEOUT_S} ${ARGN}
			WORKING_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
		# One VM at a time per test (TCG keeps a core busy), and one VM test at a time
		# (DOCKPOSE_VM_GUEST_LOCK, tests/vm/CMakeLists.txt): the firmware's timing is what the
		# guest delivers, and a second guest beside it halves that.
		set_tests_properties(${name} PROPERTIES
			LABELS vm
			FIXTURES_REQUIRED "${fixtures}"
			SKIP_RETURN_CODE 77
			TIMEOUT ${_fw_ctest_timeout}
			PROCESSORS 1
			RESOURCE_LOCK ${DOCKPOSE_VM_GUEST_LOCK})
	endfunction()

	_dockpose_fw_test(vm_x86_64_dockposed_vm_board vm_kernel_x86_64
		board x86_64 $<TARGET_FILE:dockposed> ${_fw_out}/x86_64-board)
	_dockpose_fw_test(vm_aarch64_dockposed_vm_board vm_kernel_aarch64
		board aarch64 ${_fw_aarch64} ${_fw_out}/aarch64-board)
	_dockpose_fw_test(vm_x86_64_dockposed_late_can vm_kernel_x86_64
		late-can x86_64 $<TARGET_FILE:dockposed> $<TARGET_FILE:dockpose> ${_fw_out}/x86_64-late-can)
	# A keyed sensor and the operator view's signed commands on one live bus (x86_64: the view's
	# HTTP API is driven with the host's curl, which the x86_64 guest has).
	_dockpose_fw_test(vm_x86_64_view_signed_commands vm_kernel_x86_64
		keyed-view $<TARGET_FILE:dockposed> $<TARGET_FILE:dockpose> ${_fw_out}/x86_64-keyed-view)
	_dockpose_fw_test(vm_aarch64_replay_matches_x86_64 "vm_kernel_x86_64;vm_kernel_aarch64"
		replay $<TARGET_FILE:dockposed> ${_fw_aarch64} $<TARGET_FILE:dockpose> ${_fw_out}/replay)
	# The virtual pipeline (in 0.5 and 0.7; scripts/libcamera-build enables it; tried on 0.7) plays JPEG
	# files as a camera; Debian's 0.0.3 has none. Its config file lies under the libcamera's
	# prefix, which the guest bind-mounts over.
	if(DOCKPOSE_LIBCAMERA MATCHES "^(lc07|v0[.]7[.])" AND DOCKPOSE_LIBCAMERA_PREFIX)
		_dockpose_fw_test(vm_x86_64_virtual_libcamera vm_kernel_x86_64
			virtual $<TARGET_FILE:dockposed> $<TARGET_FILE:dockpose> ${DOCKPOSE_LIBCAMERA_PREFIX}
			${_fw_out}/x86_64-virtual)
	endif()
endif()

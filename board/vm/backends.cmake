# SPDX-License-Identifier: MIT
# vm: the QEMU test board (scripts/vm): libcamera on vimc, libgpiod on gpio-sim, SocketCAN on vcan0.
target_link_libraries(dockpose_boards PUBLIC dockpose_hal_libcamera dockpose_hal_gpiod dockpose_hal_socketcan
	dockpose_hal_sim)

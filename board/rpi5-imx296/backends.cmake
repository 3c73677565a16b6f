# SPDX-License-Identifier: MIT
# rpi5-imx296: libcamera, libgpiod and SocketCAN.
target_link_libraries(dockpose_boards PUBLIC dockpose_hal_libcamera dockpose_hal_gpiod dockpose_hal_socketcan)

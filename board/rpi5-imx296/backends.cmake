# SPDX-License-Identifier: MIT
# rpi5-imx296: libcamera, libgpiod and SocketCAN (the hal backends it wires; see CMakeLists.txt).
set(DOCKPOSE_BOARD_BACKENDS libcamera gpiod socketcan)

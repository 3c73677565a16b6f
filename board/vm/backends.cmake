# SPDX-License-Identifier: MIT
# vm: the QEMU test board (scripts/vm): libcamera on vimc, libgpiod on gpio-sim, SocketCAN on vcan0.
set(DOCKPOSE_BOARD_BACKENDS libcamera gpiod socketcan sim)

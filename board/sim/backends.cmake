# SPDX-License-Identifier: MIT
# sim: the host's simulated board (synthetic or replayed frames, recording strobe, candump-log CAN).
set(DOCKPOSE_BOARD_BACKENDS sim)

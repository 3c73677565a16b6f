# SPDX-License-Identifier: MIT
# sim: the host's simulated board (synthetic or replayed frames, recording strobe, candump-log CAN).
target_link_libraries(dockpose_boards PUBLIC dockpose_hal_sim)

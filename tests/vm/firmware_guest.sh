#!/bin/sh
# SPDX-License-Identifier: MIT
#
# Guest half of the whole-firmware VM tests (tests/vm/firmware_vm.sh starts it with scripts/vm;
# docs/vm-tests.md, "Whole firmware in the VMs"). Runs dockposed on real drivers and records
# what the ecosystem's tools see, into OUT (the VM's share); the host checks it afterwards.
# POSIX sh (dash in the x86_64 guest, busybox in the arm64 one): no python here.
#
#   firmware_guest.sh board OUT DOCKPOSED BOARD RUN_S BAD_AT_S BAD_FRAME GOOD_AT_S GOOD_FRAME
#       dockposed --board BOARD --for RUN_S; BAD_AT_S and GOOD_AT_S seconds after its first
#       heartbeat, cansend BAD_FRAME and GOOD_FRAME (ID#HEX) on vcan0.
#   firmware_guest.sh replay OUT DOCKPOSED BOARD MAX_S
#       dockposed --board BOARD --for MAX_S (a replay board: it stops when the frames run out).
#
# Files in OUT:
#   can.log          candump -L vcan0, from before dockposed starts until after it exits
#   gpio.txt         "UPTIME_S VALUE" samples of the gpio-sim line dockposed drives
#                    ($DOCKPOSE_GPIO_SIM_DIR/sim_gpio3/value), polled with shell builtins only,
#                    and "UPTIME_S mark NAME" lines (start, running, bad-command,
#                    good-command, exit)
#   gpio-after.txt   the line's value read after dockposed exited (the line is released)
#   gpioinfo.txt     gpioinfo of the chip while dockposed holds the line
#   cam-list.txt     cam -l before the run (board: vimc must be listed)
#   dockposed.out, dockposed.err, dockposed.rc
# Exit status: 0 when everything ran (dockposed's own status is in dockposed.rc), 1 when a
# tool was missing or the recording could not be set up.
set -u

die() {
	echo "firmware_guest: $*" >&2
	exit 1
}

uptime_s() {
	read -r up _ </proc/uptime
	echo "$up"
}

mark() {
	echo "$(uptime_s) mark $1" >>"$OUT/gpio.txt"
}

# sleep_until T0 S: sleep until S seconds after uptime T0.
sleep_until() {
	while awk -v t0="$1" -v s="$2" -v now="$(uptime_s)" 'BEGIN { exit !(now < t0 + s) }'; do
		sleep 0.1
	done
}

mode=${1:-}
[ $# -ge 2 ] || die "usage: firmware_guest.sh board|replay OUT ..."
OUT=$2
DOCKPOSED=$3
BOARD=$4
case $mode in
board) [ $# -eq 9 ] || die "board: want OUT DOCKPOSED BOARD RUN_S BAD_AT_S BAD_FRAME GOOD_AT_S GOOD_FRAME" ;;
replay) [ $# -eq 5 ] || die "replay: want OUT DOCKPOSED BOARD MAX_S" ;;
*) die "unknown mode '$mode' (board or replay)" ;;
esac
[ -d "$OUT" ] || die "$OUT: no such folder"
[ -x "$DOCKPOSED" ] || die "$DOCKPOSED: not an executable"
for tool in candump cansend gpioinfo cam; do
	command -v "$tool" >/dev/null 2>&1 || die "$tool is not on PATH ($PATH)"
done
line_value=${DOCKPOSE_GPIO_SIM_DIR:?not in a dockpose VM (no DOCKPOSE_GPIO_SIM_DIR)}/sim_gpio3/value
[ -r "$line_value" ] || die "$line_value: cannot read the gpio-sim line"
cd "$OUT" || die "cannot cd to $OUT"
rm -f can.log gpio.txt gpio-after.txt gpioinfo.txt cam-list.txt dockposed.out dockposed.err dockposed.rc

if [ "$mode" = board ]; then
	cam -l >cam-list.txt 2>&1 || die "cam -l failed: $(cat cam-list.txt)"
fi

# candump first, and proven to be listening: a probe frame (id 0x7ff, not dockpose's) must
# come back before dockposed starts. candump flushes each line.
candump -L vcan0 >can.log 2>candump.err &
dump=$!
tries=0
until grep -q ' vcan0 7FF#' can.log 2>/dev/null; do
	[ $tries -lt 100 ] || die "candump on vcan0 never saw the probe frame: $(cat candump.err)"
	cansend vcan0 7FF#00 || die "cansend vcan0 failed"
	sleep 0.1
	tries=$((tries + 1))
done

# The LED line as the simulator sees it, about every 20 ms (a busy loop would starve the
# single-CPU guest; pulses are longer than that and the constant phase lasts seconds).
(
	while :; do
		read -r up _ </proc/uptime
		read -r v <"$line_value"
		echo "$up $v"
		sleep 0.02
	done >>gpio.txt
) &
poll=$!

mark start
"$DOCKPOSED" --board "$BOARD" --for "$5" >dockposed.out 2>dockposed.err &
daemon=$!

if [ "$mode" = board ]; then
	# The first heartbeat (id 0x306) says dockposed has started (its --for counts from
	# there; starting takes seconds in the arm64 guest): the commands are timed from it.
	until grep -q ' vcan0 306#' can.log; do
		kill -0 "$daemon" 2>/dev/null || break
		sleep 0.1
	done
	t0=$(uptime_s)
	mark running
	# While dockposed holds the line: the kernel's view of it.
	gpioinfo "$DOCKPOSE_GPIO_SIM_CHIP" >gpioinfo.txt 2>&1
	sleep_until "$t0" "$6"
	mark bad-command
	cansend vcan0 "$7" || echo "firmware_guest: cansend $7 failed" >&2
	sleep_until "$t0" "$8"
	mark good-command
	cansend vcan0 "$9" || echo "firmware_guest: cansend $9 failed" >&2
fi

wait "$daemon"
echo $? >dockposed.rc
mark exit
# Let candump take the last frames off the socket, then stop the recorders.
sleep 0.5
kill "$poll" 2>/dev/null
wait "$poll" 2>/dev/null
kill "$dump" 2>/dev/null
wait "$dump" 2>/dev/null
cat "$line_value" >gpio-after.txt 2>&1
exit 0

#!/bin/sh
# SPDX-License-Identifier: MIT
#
# Runs inside a dockpose test VM (scripts/vm run; ctest vm_x86_64_drivers, vm_aarch64_drivers):
# checks with the ecosystem's own tools that the kernel drivers the real backends use work and
# that the guest set them up as documented (docs/vm-tests.md):
#   SocketCAN  vcan0 and vcan1 are up; a frame sent with cansend on vcan0 reaches candump
#   GPIO       gpiodetect shows the gpio-sim chip $DOCKPOSE_GPIO_SIM_CHIP labelled dockpose-sim
#              with 8 lines; line 3 is named led-strobe; a line gpioset drives is seen by the
#              simulator ($DOCKPOSE_GPIO_SIM_DIR), a pull set in the simulator is read by gpioget
#   camera     `cam -l` lists the vimc camera, and cam captures frames from it
# Prints one line per check; exits 1 when any failed. POSIX sh (dash or busybox).
set -u

failures=0
ok() { echo "ok: $*"; }
fail() {
	echo "FAILED: $*" >&2
	failures=$((failures + 1))
}

scratch=$(mktemp -d) || exit 1

# --- SocketCAN ---
for can in vcan0 vcan1; do
	if ip link show "$can" 2>/dev/null | grep -q '[<,]UP[,>]'; then
		ok "$can is up"
	else
		fail "$can missing or down: $(ip link show "$can" 2>&1)"
	fi
done

candump -L -n 1 -T 10000 vcan0 >"$scratch/candump.log" 2>&1 &
dump=$!
# Send until candump has its frame: it may not be listening yet when the first one goes out.
# candump ends the loop (its frame, or -T: 10 s of silence once it listens, which our sends keep
# from happening); the count only guards a hang, however slowly the guest starts candump.
tries=0
while kill -0 "$dump" 2>/dev/null && [ $tries -lt 1000 ]; do
	cansend vcan0 123#DEADBEEF || fail "cansend vcan0 failed"
	sleep 0.25
	tries=$((tries + 1))
done
wait "$dump"
if grep -q ' vcan0 123#DEADBEEF$' "$scratch/candump.log"; then
	ok "cansend -> candump on vcan0: $(cat "$scratch/candump.log")"
else
	fail "candump on vcan0 did not see 123#DEADBEEF: $(cat "$scratch/candump.log")"
fi

# --- GPIO (gpio-sim) ---
chip=${DOCKPOSE_GPIO_SIM_CHIP:-}
sim=${DOCKPOSE_GPIO_SIM_DIR:-}
detect=$(gpiodetect 2>&1)
if [ -n "$chip" ] && echo "$detect" | grep -qx "$chip \[dockpose-sim\] (8 lines)"; then
	ok "gpiodetect: $chip [dockpose-sim] (8 lines)"
else
	fail "gpiodetect does not show '$chip [dockpose-sim] (8 lines)': $detect"
fi
if gpioinfo "$chip" 2>&1 | grep -Eq '^[[:space:]]+line[[:space:]]+3:[[:space:]]+"led-strobe"'; then
	ok "gpioinfo: line 3 is led-strobe"
else
	fail "gpioinfo $chip: line 3 is not named led-strobe: $(gpioinfo "$chip" 2>&1)"
fi
if [ "$(gpiofind led-strobe 2>&1)" = "$chip 3" ]; then
	ok "gpiofind led-strobe: $chip 3"
else
	fail "gpiofind led-strobe: '$(gpiofind led-strobe 2>&1)', expected '$chip 3'"
fi

# Output: gpio-sim shows a driven line's level in sim_gpioN/value while the line is held.
gpioset --mode=signal "$chip" 3=1 &
hold=$!
seen=
i=0
# Until the level shows or gpioset gave up (it exits on error); the count guards a hang only.
while [ $i -lt 1000 ] && kill -0 "$hold" 2>/dev/null; do
	seen=$(cat "$sim/sim_gpio3/value" 2>&1)
	[ "$seen" = 1 ] && break
	sleep 0.25
	i=$((i + 1))
done
kill "$hold" 2>/dev/null
wait "$hold" 2>/dev/null
if [ "$seen" = 1 ]; then
	ok "gpioset $chip 3=1 -> $sim/sim_gpio3/value = 1"
else
	fail "gpioset $chip 3=1: $sim/sim_gpio3/value is '$seen'"
fi

# Input: a pull set on the simulator's side is what gpioget reads.
for level in 1 0; do
	if [ $level = 1 ]; then pull='pull-up'; else pull='pull-down'; fi
	if echo $pull >"$sim/sim_gpio5/pull"; then
		got=$(gpioget "$chip" 5 2>&1)
		if [ "$got" = $level ]; then
			ok "$pull on sim_gpio5 -> gpioget $chip 5 = $level"
		else
			fail "$pull on sim_gpio5: gpioget $chip 5 = '$got'"
		fi
	else
		fail "cannot write $sim/sim_gpio5/pull"
	fi
done

# --- camera (vimc through libcamera) ---
list=$(cam -l 2>&1)
if echo "$list" | grep -q 'vimc'; then
	ok "cam -l lists vimc: $(echo "$list" | grep vimc)"
else
	fail "cam -l does not list vimc: $list"
fi
mkdir -p "$scratch/frames"
if cam -c 1 --capture=3 --file="$scratch/frames/" >"$scratch/cam.log" 2>&1; then
	n=$(ls "$scratch/frames" | wc -l)
	if [ "$n" -ge 3 ]; then
		ok "cam captured $n frames from vimc"
	else
		fail "cam --capture=3 wrote $n frames: $(cat "$scratch/cam.log")"
	fi
else
	fail "cam -c 1 --capture=3 failed: $(cat "$scratch/cam.log")"
fi

rm -rf "$scratch"
if [ $failures -ne 0 ]; then
	echo "$failures check(s) failed" >&2
	exit 1
fi
echo "all driver checks passed (${DOCKPOSE_VM_ARCH:-?})"

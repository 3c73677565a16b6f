#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# The whole firmware (dockposed) in the test VMs, against real kernel drivers: vimc through
# libcamera, gpio-sim through libgpiod, vcan through SocketCAN (docs/vm-tests.md, "Whole
# firmware in the VMs"; ctest tests from tests/vm/firmware.cmake). The host half: prepares
# the inputs, runs tests/vm/firmware_guest.sh in a VM with scripts/vm, then checks what the
# guest recorded with tests/vm/firmware_check.py (candecode and canmatrix, on the host: the
# arm64 guest has no python).
#
#   firmware_vm.sh [--timeout S] board ARCH DOCKPOSED OUT
#       dockposed on board/vm/board.json in the ARCH (x86_64 | aarch64) VM, a corrupt then a
#       good DP_Command on vcan0 while it runs; the phases last as many heartbeats and status
#       frames as set below, however long that takes the guest.
#   firmware_vm.sh [--timeout S] replay DOCKPOSED_X86_64 DOCKPOSED_AARCH64 DOCKPOSE_TOOL OUT
#       frames of the wedge target rendered with `dockpose render`, replayed by both builds in
#       their VMs on a replay variant of the vm board; their pose frames compared.
#   firmware_vm.sh [--timeout S] virtual DOCKPOSED DOCKPOSE_TOOL LIBCAMERA_PREFIX OUT
#       the real capture path on frames of the target (issue 13): the replay frames as JPEG
#       files, played by libcamera's virtual pipeline (LIBCAMERA_PREFIX: a libcamera with
#       it, Raspberry Pi's 0.7 here) to DOCKPOSED (x86_64, built against that libcamera) with
#       its libcamera backend in the x86_64 VM; the same PGM frames replayed in the same VM by
#       the replay camera; the two runs' pose frames compared image by image.
#   firmware_vm.sh [--timeout S] keyed-view DOCKPOSED DOCKPOSE_TOOL OUT
#       a sensor with a CAN key (the replay board, looping, with can.key_file) and the operator
#       view (`dockpose view --can vcan0 --allow-commands --key`) on the same vcan0 in the x86_64
#       VM: an unsigned command is refused, the view's signed command is applied, every MAC
#       verifies independently, and the view shows the authenticated pose the bus carried.
#   firmware_vm.sh [--timeout S] late-can ARCH DOCKPOSED DOCKPOSE_TOOL OUT
#       the CAN interface comes after dockposed: the replay board, looping, on can0, started in
#       the ARCH VM while can0 does not exist; can0 is created a few seconds later, and pose
#       frames must then arrive on it, with no restart of dockposed.
#
# OUT is emptied and used as the VMs' share; everything recorded stays there.
# Exit status: 0 passed, 1 failed, 77 the VM cannot run here (ctest: skipped).
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
REPO=$(cd "$HERE/../.." && pwd)
VM=$REPO/scripts/vm
GUEST=$HERE/firmware_guest.sh
CHECK=$HERE/firmware_check.py
BOARD=$REPO/board/vm/board.json

# The board run, in what dockposed sends (firmware_guest.sh; a slow guest takes longer, it does
# not get a shorter test). Heartbeats are at most heartbeat_hz (10) a second, so N heartbeats
# span at least N/10 s. On a free core this is about 12 s of dockposed.
ALT_HB=40           # alternate phase: 40 heartbeats (>= 3.9 s) before the first command
HOLD_HB=13          # after a corrupt command: 13 heartbeats, > the 1 s a fault bit is held
REJECT_TRIES=8      # corrupt commands until a later loop iteration sent a frame within the hold of one
CONST_HB=40         # constant phase: 40 heartbeats (>= 3.9 s) ...
CONST_REPORTS=10    # ... and 10 status frames of lit frames processed
# --for: a cap only (the guest stops dockposed with SIGTERM when the phases are over).
MAX_S=${DOCKPOSE_VM_FW_MAX_S:-240}
# The replay run: frames and their rate (low: the pipeline under TCG is slow, and the replay
# camera never skips a frame, it queues them).
REPLAY_FRAMES=30
REPLAY_RATE_HZ=10
# The virtual run: JPEG quality (Pillow's scale), the virtual camera's id, how many times the
# virtual pipeline shows each image (its ImageFrameGenerator::frameRepeat, 0.7), and the valid
# poses that end the run (the pipeline has no frame pacing: it makes frames as fast as they are
# asked for, so dockposed sees the images in a sampled order; 300 poses leave an image unseen
# with a chance of about 30 * (29/30)^300 = 1e-3).
VIRTUAL_JPEG_QUALITY=95
VIRTUAL_CAMERA_ID=dockpose-approach
VIRTUAL_REPEAT=4
VIRTUAL_REPORTS=300
# The late-can run: seconds dockposed runs without can0 after its start-up, and the valid poses
# on can0 that end it.
LATE_ABSENT_S=4
LATE_REPORTS=20
# The keyed run: the view's port in the guest (its own network stack: no clash with the host).
VIEW_PORT=8099

timeout_s=600

die() {
	echo "firmware_vm: $*" >&2
	exit 1
}

# elf_machine FILE: x86_64, aarch64 or something else, from the ELF header's e_machine.
elf_machine() {
	local m
	m=$(od -An -tx1 -j18 -N2 "$1" 2>/dev/null | tr -d ' \n')
	case $m in
	3e00) echo x86_64 ;;
	b700) echo aarch64 ;;
	*) echo "unknown (e_machine $m)" ;;
	esac
}

# need_dockposed ARCH FILE
need_dockposed() {
	local arch=$1 file=$2
	if [[ ! -x $file ]]; then
		if [[ $arch == aarch64 ]]; then
			die "no aarch64 dockposed at $file: build it first with" \
				"'cmake --preset aarch64 && cmake --build --preset aarch64 --target dockposed'" \
				"(scripts/test builds the aarch64 tree before it runs the vm label), or point" \
				"DOCKPOSE_AARCH64_BUILD_DIR at another aarch64 build"
		fi
		die "no dockposed at $file"
	fi
	local got
	got=$(elf_machine "$file")
	[[ $got == "$arch" ]] || die "$file is built for $got, not $arch"
}

# in_vm ARCH SHARE GUEST-ARGS...: run the guest script; 77 and harness errors end the test.
in_vm() {
	local arch=$1 share=$2
	shift 2
	local rc=0 start=$SECONDS
	echo "== $arch VM: firmware_guest.sh $1"
	"$VM" run --arch "$arch" --share "$share" --timeout "$timeout_s" -- "$GUEST" "$@" || rc=$?
	echo "== $arch VM: exit status $rc after $((SECONDS - start)) s"
	if [[ -f $share/dockposed.err ]]; then
		echo "-- dockposed's stderr:"
		cat "$share/dockposed.err"
	fi
	if [[ -f $share/hang.txt ]]; then
		echo "-- what hung in the guest (hang.txt):"
		cat "$share/hang.txt"
	fi
	case $rc in
	0) ;;
	77) echo "firmware_vm: the $arch VM cannot run here: skipped" >&2; exit 77 ;;
	*) die "the $arch guest failed (status $rc)" ;;
	esac
}

fresh_dir() {
	rm -rf -- "$1"
	mkdir -p -- "$1"
}

board_test() {
	[[ $# -eq 3 ]] || die "board: want ARCH DOCKPOSED OUT"
	local arch=$1 dockposed=$2 out=$3
	[[ $arch == arm64 ]] && arch=aarch64
	need_dockposed "$arch" "$dockposed"
	fresh_dir "$out"
	local bad good
	# Corrupt CRC, asks for strobe off: must be rejected and change nothing.
	bad=$("$CHECK" command --enable 1 --mode track --strobe off --alive 0 --bad-crc)
	# Good: search only, strobe constant.
	good=$("$CHECK" command --enable 1 --mode search_only --strobe constant --alive 1)
	echo "commands: corrupt $bad after $ALT_HB heartbeats (up to $REJECT_TRIES times, $HOLD_HB" \
		"heartbeats apart), then good $good; constant phase $CONST_HB heartbeats and" \
		"$CONST_REPORTS status frames; --for $MAX_S s as a cap"
	in_vm "$arch" "$out" board "$out" "$dockposed" "$BOARD" "$MAX_S" "$bad" "$good" \
		"$ALT_HB" "$HOLD_HB" "$REJECT_TRIES" "$CONST_HB" "$CONST_REPORTS"
	echo "== checks ($out)"
	"$CHECK" board "$out"
}

# render_frames TOOL OUT: the replayed approach, REPLAY_FRAMES frames into OUT/frames.
render_frames() {
	local tool=$1 out=$2 poses=() i
	# An approach: 1400 mm to 550 mm, drifting to the centre, rotations easing off.
	for ((i = 0; i < REPLAY_FRAMES; i++)); do
		poses+=("--pose=$(awk -v i=$i -v n=$REPLAY_FRAMES 'BEGIN {
			s = i / (n - 1)
			printf "%.1f,%.1f,%.1f,%.2f,%.2f,%.2f", 120 - 90 * s, -60 + 50 * s, 1400 - 850 * s,
				4 - 3 * s, 12 - 10 * s, -3 + 2.5 * s }')")
	done
	"$tool" render --target "$REPO/board/vm/target.json" --camera "$REPO/board/vm/camera-replay.json" \
		"${poses[@]}" --reflections 1 --hot-pixels 10 -o "$out/frames" >/dev/null ||
		die "dockpose render failed"
}

late_can_test() {
	[[ $# -eq 4 ]] || die "late-can: want ARCH DOCKPOSED DOCKPOSE_TOOL OUT"
	local arch=$1 dockposed=$2 tool=$3 out=$4
	[[ $arch == arm64 ]] && arch=aarch64
	need_dockposed "$arch" "$dockposed"
	[[ -x $tool ]] || die "no dockpose tool at $tool"
	fresh_dir "$out"
	render_frames "$tool" "$out"
	"$CHECK" replay-board --board "$BOARD" --camera "$REPO/board/vm/camera-replay.json" \
		--target "$REPO/board/vm/target.json" --frames "$out/frames" --rate "$REPLAY_RATE_HZ" \
		--loop --interface can0 -o "$out/board-late-can.json" || die "cannot write the late-can board"
	echo "late-can: replay board on can0 ($out/board-late-can.json), can0 created $LATE_ABSENT_S s" \
		"after dockposed's start-up; ends after $LATE_REPORTS valid poses on can0; --for $MAX_S s as a cap"
	in_vm "$arch" "$out" late-can "$out" "$dockposed" "$out/board-late-can.json" "$MAX_S" \
		"$LATE_ABSENT_S" "$LATE_REPORTS"
	echo "== checks ($out)"
	"$CHECK" late-can "$out"
}

virtual_test() {
	[[ $# -eq 4 ]] || die "virtual: want DOCKPOSED DOCKPOSE_TOOL LIBCAMERA_PREFIX OUT"
	local x86=$1 tool=$2 prefix=$3 out=$4
	need_dockposed x86_64 "$x86"
	[[ -x $tool ]] || die "no dockpose tool at $tool"
	[[ -d $prefix/share/libcamera/pipeline/virtual ]] ||
		die "$prefix has no virtual pipeline data folder (share/libcamera/pipeline/virtual)"
	fresh_dir "$out"
	mkdir -p "$out/replay" "$out/virtual"
	render_frames "$tool" "$out"
	"$CHECK" jpeg --frames "$out/frames" --quality "$VIRTUAL_JPEG_QUALITY" -o "$out/jpeg" ||
		die "cannot convert the frames to JPEG"
	"$CHECK" replay-board --board "$BOARD" --camera "$REPO/board/vm/camera-replay.json" \
		--target "$REPO/board/vm/target.json" --frames "$out/frames" --rate "$REPLAY_RATE_HZ" \
		-o "$out/board-replay.json" || die "cannot write the replay board"
	"$CHECK" virtual-board --board "$BOARD" --camera "$REPO/board/vm/camera-replay.json" \
		--target "$REPO/board/vm/target.json" --jpeg "$out/jpeg" --camera-id "$VIRTUAL_CAMERA_ID" \
		--yaml-dir "$out/virtual-yaml" -o "$out/board-virtual.json" || die "cannot write the virtual board"
	echo "rendered $REPLAY_FRAMES frames into $out/frames, JPEG (quality $VIRTUAL_JPEG_QUALITY) in" \
		"$out/jpeg; replay board $out/board-replay.json, virtual board $out/board-virtual.json" \
		"(camera $VIRTUAL_CAMERA_ID, $out/virtual-yaml/virtual.yaml); the virtual run ends after" \
		"$VIRTUAL_REPORTS valid poses"
	local max_s=$((REPLAY_FRAMES * 20 / REPLAY_RATE_HZ + 60))
	in_vm x86_64 "$out/replay" replay "$out/replay" "$x86" "$out/board-replay.json" "$max_s"
	in_vm x86_64 "$out/virtual" virtual "$out/virtual" "$x86" "$out/board-virtual.json" "$MAX_S" \
		"$prefix" "$out/virtual-yaml" "$VIRTUAL_REPORTS"
	echo "== checks ($out)"
	"$CHECK" virtual --truth "$out/frames/truth.jsonl" --frames "$REPLAY_FRAMES" --repeat "$VIRTUAL_REPEAT" \
		"$out/replay" "$out/virtual"
}

keyed_view_test() {
	[[ $# -eq 3 ]] || die "keyed-view: want DOCKPOSED DOCKPOSE_TOOL OUT"
	local x86=$1 tool=$2 out=$3
	need_dockposed x86_64 "$x86"
	[[ -x $tool ]] || die "no dockpose tool at $tool"
	fresh_dir "$out"
	render_frames "$tool" "$out"
	# A fresh key for this run (can.key_file: 32 hex digits, mode 0600, root's).
	local key
	key=$(od -An -tx1 -N16 /dev/urandom | tr -d ' \n')
	[[ ${#key} -eq 32 ]] || die "cannot read 16 random bytes"
	(umask 077 && echo "$key" >"$out/can.key")
	"$CHECK" replay-board --board "$BOARD" --camera "$REPO/board/vm/camera-replay.json" \
		--target "$REPO/board/vm/target.json" --frames "$out/frames" --rate "$REPLAY_RATE_HZ" \
		--loop --key-file "$out/can.key" --run-counter-file "$out/run-counter" \
		-o "$out/board-keyed.json" || die "cannot write the keyed board"
	local bare
	# Valid CRC, no MAC: search only, strobe alternate (a mode the run never otherwise shows).
	bare=$("$CHECK" command --enable 1 --mode search_only --strobe alternate --alive 0)
	echo "keyed-view: looping replay board with a key ($out/board-keyed.json); the view on port" \
		"$VIEW_PORT; unsigned command $bare, then the view's signed one; --for $MAX_S s as a cap"
	in_vm x86_64 "$out" keyed-view "$out" "$x86" "$out/board-keyed.json" "$MAX_S" "$tool" \
		"$out/can.key" "$VIEW_PORT" "$bare" "$HOLD_HB"
	echo "== checks ($out)"
	"$CHECK" keyed-view --key "$key" --bare "$bare" "$out"
}

replay_test() {
	[[ $# -eq 4 ]] || die "replay: want DOCKPOSED_X86_64 DOCKPOSED_AARCH64 DOCKPOSE_TOOL OUT"
	local x86=$1 arm=$2 tool=$3 out=$4
	need_dockposed x86_64 "$x86"
	need_dockposed aarch64 "$arm"
	[[ -x $tool ]] || die "no dockpose tool at $tool"
	fresh_dir "$out"
	mkdir -p "$out/x86_64" "$out/aarch64"
	render_frames "$tool" "$out"
	"$CHECK" replay-board --board "$BOARD" --camera "$REPO/board/vm/camera-replay.json" \
		--target "$REPO/board/vm/target.json" --frames "$out/frames" --rate "$REPLAY_RATE_HZ" \
		-o "$out/board-replay.json" || die "cannot write the replay board"
	echo "rendered $REPLAY_FRAMES frames into $out/frames; replay board $out/board-replay.json"

	# Runs until the frames run out (the replay camera queues frames, it never skips one, so a
	# slow guest only takes longer); --for only bounds a hang, with room for a guest 20 times
	# slower than real time.
	local max_s=$((REPLAY_FRAMES * 20 / REPLAY_RATE_HZ + 60))
	in_vm x86_64 "$out/x86_64" replay "$out/x86_64" "$x86" "$out/board-replay.json" "$max_s"
	in_vm aarch64 "$out/aarch64" replay "$out/aarch64" "$arm" "$out/board-replay.json" "$max_s"
	echo "== checks ($out)"
	"$CHECK" replay --truth "$out/frames/truth.jsonl" --frames "$REPLAY_FRAMES" "$out/x86_64" "$out/aarch64"
}

while [[ $# -gt 0 ]]; do
	case $1 in
	--timeout) timeout_s=${2:?--timeout needs seconds}; shift 2 ;;
	--) shift; break ;;
	-*) die "unknown option $1" ;;
	*) break ;;
	esac
done
[[ $# -ge 1 ]] || die "usage: firmware_vm.sh [--timeout S] board|replay|virtual|late-can|keyed-view ..."
cmd=$1
shift
case $cmd in
board) board_test "$@" ;;
replay) replay_test "$@" ;;
late-can) late_can_test "$@" ;;
virtual) virtual_test "$@" ;;
keyed-view) keyed_view_test "$@" ;;
*) die "unknown test '$cmd' (board, replay, virtual, late-can or keyed-view)" ;;
esac

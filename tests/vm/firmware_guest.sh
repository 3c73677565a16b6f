#!/bin/sh
# SPDX-License-Identifier: MIT
#
# Guest half of the whole-firmware VM tests (tests/vm/firmware_vm.sh starts it with scripts/vm;
# docs/vm-tests.md, "Whole firmware in the VMs"). Runs dockposed on real drivers and records
# what the ecosystem's tools see, into OUT (the VM's share); the host checks it afterwards.
# POSIX sh (dash in both guests): no python here.
#
#   firmware_guest.sh board OUT DOCKPOSED BOARD MAX_S BAD_FRAME GOOD_FRAME ALT_HB HOLD_HB TRIES CONST_HB CONST_REPORTS
#       dockposed --board BOARD --for MAX_S (a cap only: the guest stops it with SIGTERM).
#       The phases are counted in what dockposed itself sent on vcan0, not in seconds, so that a
#       slow guest (TCG on a loaded host) gets the same test, only longer:
#         alternate   until ALT_HB heartbeats were sent;
#         corrupt     cansend BAD_FRAME, then wait for HOLD_HB heartbeats after it (heartbeats
#                     are at least 1/heartbeat_hz apart, so HOLD_HB >= 12 outlasts the one
#                     second a fault bit is held); again, up to TRIES times, until a loop
#                     iteration that started after it sent a frame within the hold (what the
#                     host's check of COMMAND_REJECTED needs as a sample: at ~1.5 frames/s, as
#                     vimc under libcamera 0.7 in a TCG guest, an iteration takes about as long
#                     as the hold, so only some commands get one);
#         command     cansend GOOD_FRAME (search only, strobe constant), wait for the first
#                     heartbeat saying so;
#         constant    until CONST_HB heartbeats and CONST_REPORTS status frames in constant
#                     mode were sent; then SIGTERM.
#   firmware_guest.sh replay OUT DOCKPOSED BOARD MAX_S
#       dockposed --board BOARD --for MAX_S (a replay board: it stops when the frames run out).
#   firmware_guest.sh virtual OUT DOCKPOSED BOARD MAX_S LIBCAMERA_PREFIX YAML_DIR REPORTS
#       dockposed --board BOARD (its libcamera camera: a camera of libcamera's virtual pipeline)
#       until REPORTS status frames with a valid pose went out on vcan0; then SIGTERM. The
#       virtual pipeline reads its cameras from LIBCAMERA_PREFIX/share/libcamera/pipeline/
#       virtual/virtual.yaml only (no environment variable names another file), and the root
#       is read-only: YAML_DIR is bind-mounted there. It needs a dma-buf provider
#       (/dev/dma_heap/system or /dev/udmabuf: the kernel fragment's DMABUF_HEAPS_SYSTEM,
#       UDMABUF); which ones exist goes to dmabuf.txt, and LIBCAMERA_PREFIX/bin/cam -l (when
#       there is one) to cam-list.txt.
#   firmware_guest.sh keyed-view OUT DOCKPOSED BOARD MAX_S TOOL KEY PORT BARE HOLD_HB
#       dockposed --board BOARD (a looping replay board with a CAN key, can.key_file KEY) and the
#       operator view beside it on the same bus, `TOOL view --can vcan0 --allow-commands --key KEY
#       --port PORT` (x86_64 guest only: its root is the host's, with curl); once the view's
#       /api/state shows an authenticated pose (state-before.json): cansend BARE (an unsigned
#       command: refused) and HOLD_HB heartbeats; then POST /api/command (search only, strobe
#       constant; the reply in command-reply.json) and wait for the heartbeat saying so; HOLD_HB
#       more heartbeats, /api/state again (state-after.json); SIGTERM to the view (view.rc,
#       view.out, view.err) and to dockposed.
#   firmware_guest.sh late-can OUT DOCKPOSED BOARD MAX_S ABSENT_S REPORTS
#       the late CAN interface: BOARD (a looping replay board on can0) is started while can0
#       does not exist; once dockposed's start-up is over (its stderr has the board line), it
#       runs ABSENT_S more seconds without it (its frames go into its queue); then can0 is
#       added (a vcan), left down for a second, and set up; the run ends with SIGTERM when
#       REPORTS status frames with a valid pose went out on can0.
#       candump listens on every interface ("any"), so it sees can0 from its creation on.
#
# Files in OUT:
#   can.log          candump -L vcan0 (late-can: candump -L any), from before dockposed starts
#                    until after it exits
#   gpio.txt         "UPTIME_S VALUE" samples of the gpio-sim line dockposed drives
#                    ($DOCKPOSE_GPIO_SIM_DIR/sim_gpio3/value), polled with shell builtins only,
#                    and "UPTIME_S mark NAME" lines (start, running, bad-command,
#                    bad-command-sent (one pair per try), good-command, good-command-sent,
#                    changed, stop, exit; late-can: started, can0-added, can0-up, can0-probe,
#                    can0-probe-sent); a NAME and NAME-sent pair brackets a cansend, which
#                    ties candump's clock to /proc/uptime for the host's checks
#   gpio-after.txt   the line's value read after dockposed exited (the line is released)
#   gpioinfo.txt     gpioinfo of the chip while dockposed holds the line
#   cam-list.txt     cam -l before the run (board: vimc must be listed)
#   dockposed.out, dockposed.err, dockposed.rc
#   startup-hang.err only when dockposed's first start-up blocked (status 75) and it was
#                    restarted once: that run's stderr
#   hang.txt         only when something hung: what (dockposed past --for, past SIGTERM, or
#                    cam -l), with each of dockposed's threads' state, wchan and syscall
#                    (/proc) and the kernel log's tail; the host's checks fail on it
# Every wait is bounded: the phases end MAX_S + SLACK_S s after the start whatever they saw,
# and dockposed gets TERM_WAIT_S s to exit after SIGTERM before SIGKILL, so that a hang is
# reported with what hung instead of as the VM's timeout.
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

# can_after LINE: what dockposed sent after line LINE of can.log, as
#   "HEARTBEATS REJECTED CHANGED CONSTANT HELD"
# heartbeats (0x306); status (0x305) and heartbeat frames with COMMAND_REJECTED (fault bit 7:
# status byte 3, heartbeat byte 4); heartbeats saying SEARCH_ONLY and CONSTANT (byte 3: mode
# bit 3, strobe bits 4-5); status frames saying CONSTANT (byte 0 bits 6-7); HELD: status and
# heartbeat frames sent within 1 s (the fault hold, less candump's 2 ms) of when dockposed read
# the last command frame (0x310) by loop iterations that started after it: all but the first
# status frame and then the first heartbeat after it, which the iteration under way may still
# send, and the read came after those of them sent within 1 s of the command without the bit
# (the host's split_after and t_read in firmware_check.py). Little-endian bit numbering, as in
# firmware/protocol/dockpose.dbc. A line candump is still writing may be cut: a cut byte reads
# as at most 15, which sets none of these bits.
can_after() {
	awk -v from="$1" '
	function hex(s, i, v) {
		v = 0
		for (i = 1; i <= length(s); i++)
			v = v * 16 + index("0123456789ABCDEF", toupper(substr(s, i, 1))) - 1
		return v
	}
	NR > from {
		n = split($3, f, "#")
		if (n < 2)
			next
		t = substr($1, 2, length($1) - 2) + 0
		if (f[1] == "310") {
			t_cmd = t_read = t
			old = 0
			next
		}
		# old: 0 nothing since the command, 1 a status (the heartbeat of its iteration may
		# follow), 2 what the iteration under way may send is over. The hold counts from the
		# read, after any frame of the iteration under way without the bit (t_read).
		if (t_cmd && (f[1] == "305" || f[1] == "306")) {
			bit = hex(substr(f[2], f[1] == "306" ? 9 : 7, 2)) >= 128
			if (old == 0 || (old == 1 && f[1] == "306")) {
				old = old == 0 && f[1] == "305" ? 1 : 2
				if (!bit && t < t_cmd + 0.998)
					t_read = t
			} else {
				old = 2
				if (t < t_read + 0.998)
					held++
			}
		}
		if (f[1] == "306") {
			hb++
			b3 = hex(substr(f[2], 7, 2))
			if (hex(substr(f[2], 9, 2)) >= 128)
				rej++
			if (int(b3 / 8) % 2 == 1 && int(b3 / 16) % 4 == 1)
				changed++
		} else if (f[1] == "305") {
			if (hex(substr(f[2], 7, 2)) >= 128)
				rej++
			if (int(hex(substr(f[2], 1, 2)) / 64) % 4 == 1)
				constant++
		}
	}
	END { printf "%d %d %d %d %d\n", hb, rej, changed, constant, held }' can.log
}

# (dash has no floating point: whole seconds of /proc/uptime)
uptime_whole_s() {
	read -r up _ </proc/uptime
	echo "${up%.*}"
}

# hang_report PID WHAT: append to hang.txt what PID's threads are doing, and the kernel log.
# The syscall numbers are the guest's (aarch64: 98 futex, 29 ioctl, 73 ppoll; x86_64: 202
# futex, 16 ioctl, 7 poll, 271 ppoll); a wchan names the kernel function a thread sleeps in.
hang_report() {
	{
		echo "$(uptime_s) $2"
		for t in /proc/"$1"/task/*; do
			[ -d "$t" ] || continue
			read -r stat <"$t/stat" 2>/dev/null || stat='? ? ?'
			state=${stat##*) }
			echo "  thread ${t##*/} ($(cat "$t/comm" 2>/dev/null)): state ${state%% *}," \
				"wchan $(cat "$t/wchan" 2>/dev/null), syscall $(cat "$t/syscall" 2>/dev/null)"
		done
		echo "  kernel log, last lines:"
		dmesg 2>/dev/null | tail -n 30 | sed 's/^/    /'
	} >>"$OUT/hang.txt" 2>&1
}

# stop_pid PID NAME WHY: SIGTERM, up to TERM_WAIT_S s for PID to exit, else a hang report
# and SIGKILL.
stop_pid() {
	kill -TERM "$1" 2>/dev/null || return 0
	waited=0
	while kill -0 "$1" 2>/dev/null; do
		if [ $waited -ge $((TERM_WAIT_S * 10)) ]; then
			hang_report "$1" "$2 did not exit within $TERM_WAIT_S s of SIGTERM ($3); SIGKILL"
			kill -KILL "$1" 2>/dev/null
			return 1
		fi
		sleep 0.1
		waited=$((waited + 1))
	done
}

# stop_daemon WHY: stop_pid for dockposed.
stop_daemon() {
	stop_pid "$daemon" dockposed "$1"
}

# wait_valid_poses IFACE N FOR_S: until N status frames (0x305) with PoseValid (byte 0, bit 4)
# went out on IFACE, dockposed exited, or the run's deadline passed (then a hang report;
# FOR_S: dockposed's --for, for the report).
wait_valid_poses() {
	while [ "$(awk -v iface="$1" '$2 == iface { n = split($3, f, "#"); if (n >= 2 && f[1] == "305" &&
		int(index("0123456789ABCDEF", toupper(substr(f[2], 1, 1))) - 1) % 2 == 1) v++ }
		END { print v + 0 }' can.log)" -lt "$2" ]; do
		kill -0 "$daemon" 2>/dev/null || return 0
		if past_deadline; then
			hang_report "$daemon" "fewer than $2 valid poses on $1 $SLACK_S s past --for $3"
			return 0
		fi
		sleep 0.3
	done
}

# send_marked NAME FRAME: cansend FRAME on vcan0 between the marks NAME and NAME-sent (they tie
# candump's clock to /proc/uptime for the host's checks).
send_marked() {
	mark "$1"
	cansend vcan0 "$2" || echo "firmware_guest: cansend $2 failed" >&2
	mark "$1-sent"
}

can_lines() {
	wc -l <can.log | tr -d ' '
}

# wait_can LINE CONDITION: poll can_after LINE until CONDITION (an arithmetic expression of
# hb, rej, changed, constant, and samples: the lines of gpio.txt) holds or dockposed has
# exited (status 1) or the run's deadline passed (status 2: dockposed ran past its --for);
# leaves the counts in those names.
wait_can() {
	while :; do
		# shellcheck disable=SC2046 # five numbers
		set -- "$1" "$2" $(can_after "$1")
		# shellcheck disable=SC2034 # read by the CONDITION's arithmetic
		hb=$3 rej=$4 changed=$5 constant=$6 held=$7 samples=$(wc -l <gpio.txt)
		[ $(($2)) -ne 0 ] && return 0
		kill -0 "$daemon" 2>/dev/null || return 1
		past_deadline && return 2
		sleep 0.3
	done
}

# past_deadline: the run lasted MAX_S + SLACK_S s (dockposed's own --for is MAX_S).
past_deadline() {
	[ "$(uptime_whole_s)" -ge "$deadline_s" ]
}

SLACK_S=60
TERM_WAIT_S=30

mode=${1:-}
[ $# -ge 2 ] || die "usage: firmware_guest.sh board|replay|virtual|late-can|keyed-view OUT ..."
OUT=$2
DOCKPOSED=$3
BOARD=$4
case $mode in
board) [ $# -eq 12 ] || die "board: want OUT DOCKPOSED BOARD MAX_S BAD_FRAME GOOD_FRAME ALT_HB HOLD_HB TRIES CONST_HB CONST_REPORTS" ;;
replay) [ $# -eq 5 ] || die "replay: want OUT DOCKPOSED BOARD MAX_S" ;;
virtual) [ $# -eq 8 ] || die "virtual: want OUT DOCKPOSED BOARD MAX_S LIBCAMERA_PREFIX YAML_DIR REPORTS" ;;
late-can) [ $# -eq 7 ] || die "late-can: want OUT DOCKPOSED BOARD MAX_S ABSENT_S REPORTS" ;;
keyed-view) [ $# -eq 10 ] || die "keyed-view: want OUT DOCKPOSED BOARD MAX_S TOOL KEY PORT BARE HOLD_HB" ;;
*) die "unknown mode '$mode' (board, replay, virtual, late-can or keyed-view)" ;;
esac
if [ "$mode" = late-can ] && [ -e /sys/class/net/can0 ]; then
	die "can0 exists before the test: it must be created late"
fi
[ -d "$OUT" ] || die "$OUT: no such folder"
[ -x "$DOCKPOSED" ] || die "$DOCKPOSED: not an executable"
for tool in candump cansend gpioinfo cam; do
	command -v "$tool" >/dev/null 2>&1 || die "$tool is not on PATH ($PATH)"
done
line_value=${DOCKPOSE_GPIO_SIM_DIR:?not in a dockpose VM (no DOCKPOSE_GPIO_SIM_DIR)}/sim_gpio3/value
[ -r "$line_value" ] || die "$line_value: cannot read the gpio-sim line"
cd "$OUT" || die "cannot cd to $OUT"
rm -f can.log gpio.txt gpio-after.txt gpioinfo.txt cam-list.txt dockposed.out dockposed.err dockposed.rc hang.txt startup-hang.err dmabuf.txt \
	state-before.json state-after.json command-reply.json command-reply.err view.out view.err view.rc
if [ "$mode" = keyed-view ]; then
	command -v curl >/dev/null 2>&1 || die "curl is not on PATH ($PATH): keyed-view needs the x86_64 guest"
	[ -x "$6" ] || die "$6: not an executable (the dockpose tool)"
fi

if [ "$mode" = virtual ]; then
	lc_prefix=$6 yaml_dir=$7
	for dev in /dev/dma_heap/* /dev/udmabuf; do
		[ -c "$dev" ] && echo "$dev" >>dmabuf.txt
	done
	[ -s dmabuf.txt ] || die "no dma-buf provider (/dev/dma_heap/*, /dev/udmabuf): the kernel" \
		"lacks CONFIG_DMABUF_HEAPS_SYSTEM and CONFIG_UDMABUF"
	data=$lc_prefix/share/libcamera/pipeline/virtual
	[ -d "$data" ] || die "$data: no such folder (a libcamera without the virtual pipeline?)"
	mount --bind "$yaml_dir" "$data" || die "cannot bind-mount $yaml_dir on $data"
	if [ -x "$lc_prefix/bin/cam" ]; then
		rc=0
		# (installed without an RPATH: its libcamera is the prefix's)
		LD_LIBRARY_PATH=$lc_prefix/lib timeout "$TERM_WAIT_S" "$lc_prefix/bin/cam" -l >cam-list.txt 2>&1 || rc=$?
		[ $rc -eq 0 ] || die "$lc_prefix/bin/cam -l failed (status $rc): $(cat cam-list.txt)"
	fi
fi

if [ "$mode" = board ]; then
	rc=0
	timeout "$TERM_WAIT_S" cam -l >cam-list.txt 2>&1 || rc=$?
	if [ $rc -ne 0 ]; then
		echo "$(uptime_s) cam -l failed or hung (status $rc, ${TERM_WAIT_S} s at most)" >>hang.txt
		die "cam -l failed (status $rc): $(cat cam-list.txt)"
	fi
fi

# candump first, and proven to be listening: a probe frame (id 0x7ff, not dockpose's) must
# come back before dockposed starts. candump flushes each line.
dump_if=vcan0
[ "$mode" = late-can ] && dump_if=any
candump -L "$dump_if" >can.log 2>candump.err &
dump=$!
tries=0
# (However long candump takes to start here; the count only guards a hang.)
until grep -q ' vcan0 7FF#' can.log 2>/dev/null; do
	kill -0 "$dump" 2>/dev/null || die "candump on vcan0 exited: $(cat candump.err)"
	[ $tries -lt 1000 ] || die "candump on vcan0 never saw the probe frame: $(cat candump.err)"
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
deadline_s=$(($(uptime_whole_s) + $5 + SLACK_S))
"$DOCKPOSED" --board "$BOARD" --for "$5" >dockposed.out 2>dockposed.err &
daemon=$!

if [ "$mode" = late-can ]; then
	absent_s=$6 reports=$7
	# Started: start() logs the board line once camera, strobe and CAN are open (CAN Down: can0
	# is not there). No frame can be on any bus yet.
	until grep -q '^dockposed: board ' dockposed.err; do
		kill -0 "$daemon" 2>/dev/null || break
		past_deadline && break
		sleep 0.1
	done
	mark started
	# Running without its bus.
	sleep "$absent_s"
	ip link add dev can0 type vcan || die "ip link add dev can0 type vcan failed"
	mark can0-added
	sleep 1
	ip link set can0 up || die "ip link set can0 up failed"
	mark can0-up
	# A frame on can0 bracketed by marks ties candump's clock to /proc/uptime.
	mark can0-probe
	cansend can0 7FE#00 || echo "firmware_guest: cansend can0 failed" >&2
	mark can0-probe-sent
	wait_valid_poses can0 "$reports" "$5"
	mark stop
	stop_daemon "after $reports valid poses on can0"
fi

# The first heartbeat (id 0x306) says dockposed has started (starting takes seconds in the
# arm64 guest): the phases count from it. A start-up that blocked ends with status 75
# (dockposed --startup-timeout; libcamera's start has deadlocked now and then in the arm64
# guest, its threads all waiting on futexes): systemd would restart it (Restart=on-failure),
# and so does this script, once, keeping the first run's stderr in startup-hang.err.
restarted=0 reaped=0 rc=0
# (late-can: dockposed was started and stopped above, and never sends on vcan0.)
while [ "$mode" != late-can ]; do
	until grep -q ' vcan0 306#' can.log; do
		kill -0 "$daemon" 2>/dev/null || break
		past_deadline && break
		sleep 0.1
	done
	grep -q ' vcan0 306#' can.log && break
	kill -0 "$daemon" 2>/dev/null && break
	wait "$daemon" || rc=$?
	reaped=1
	if [ "$rc" -ne 75 ] || [ $restarted -ne 0 ]; then
		break
	fi
	restarted=1 reaped=0 rc=0
	mark restart-after-startup-hang
	cp dockposed.err startup-hang.err
	"$DOCKPOSED" --board "$BOARD" --for "$5" >dockposed.out 2>dockposed.err &
	daemon=$!
done

if [ "$mode" = board ]; then
	bad=$6 good=$7 alt_hb=$8 hold_hb=$9 reject_tries=${10} const_hb=${11} const_reports=${12}
	mark running
	# While dockposed holds the line: the kernel's view of it.
	gpioinfo "$DOCKPOSE_GPIO_SIM_CHIP" >gpioinfo.txt 2>&1
	# Alternate phase; and 30 samples of the line at least (a starved guest samples slowly; the
	# host's checks of the line are statistics over the samples taken).
	s0=$(wc -l <gpio.txt)
	wait_can 0 "hb >= $alt_hb && samples >= $s0 + 30"
	# Corrupt commands: rejected, until one has frames of later loop iterations within its hold
	# (the host checks that they carry COMMAND_REJECTED).
	try=0
	while [ $try -lt "$reject_tries" ]; do
		try=$((try + 1))
		from=$(can_lines)
		send_marked bad-command "$bad"
		wait_can "$from" "hb >= $hold_hb" || break
		[ "$held" -eq 0 ] || break
		echo "firmware_guest: try $try: no loop iteration after the command sent a frame within" \
			"its hold ($rej frame(s) carried COMMAND_REJECTED)" >&2
	done
	# The good command, and its effect.
	from=$(can_lines)
	send_marked good-command "$good"
	# (Gives up after 100 heartbeats, ten seconds at least: the host check says why.)
	wait_can "$from" "changed >= 1 || hb >= 100"
	mark changed
	# Constant phase.
	from=$(can_lines)
	s0=$(wc -l <gpio.txt)
	wait_can "$from" "(hb >= $const_hb && constant >= $const_reports && samples >= $s0 + 30) || hb >= 20 * $const_hb"
	if past_deadline; then
		hang_report "$daemon" "the phases were not over $SLACK_S s past --for $5 (heartbeats $hb)"
	fi
	mark stop
	stop_daemon "after the constant phase"
fi

if [ "$mode" = keyed-view ]; then
	tool=$6 key=$7 port=$8 bare=$9 hold_hb=${10}
	url=http://127.0.0.1:$port
	mark running
	"$tool" view --can vcan0 --allow-commands --key "$key" --port "$port" >view.out 2>view.err &
	view=$!
	# Up, and verifying the sensor: an authenticated heartbeat and a pose its MACs vouched for.
	until curl -sf --max-time 5 "$url/api/state" >state-before.json 2>/dev/null &&
		grep -q '"authenticated":true' state-before.json && grep -q '"t_mm":\[' state-before.json; do
		kill -0 "$view" 2>/dev/null || break
		kill -0 "$daemon" 2>/dev/null || break
		if past_deadline; then
			hang_report "$daemon" "the view never showed an authenticated pose ($SLACK_S s past --for $5)"
			break
		fi
		sleep 0.3
	done
	# An unsigned command with a valid CRC: refused (the sensor has a key).
	from=$(can_lines)
	send_marked bare-command "$bare"
	wait_can "$from" "hb >= $hold_hb"
	# The view's signed command, through its HTTP API as the page sends it.
	from=$(can_lines)
	mark view-command
	curl -sS --max-time 10 -X POST -H 'Content-Type: application/json' \
		-d '{"enable": true, "mode": "SEARCH_ONLY", "strobe": "CONSTANT"}' \
		"$url/api/command" >command-reply.json 2>command-reply.err
	mark view-command-sent
	# (Gives up after 100 heartbeats, ten seconds at least: the host check says why.)
	wait_can "$from" "changed >= 1 || hb >= 100"
	mark changed
	from=$(can_lines)
	wait_can "$from" "hb >= $hold_hb"
	curl -sf --max-time 5 "$url/api/state" >state-after.json 2>/dev/null
	mark stop
	stop_pid "$view" "dockpose view" "after its command"
	rc=0
	wait "$view" || rc=$?
	echo "$rc" >view.rc
	rc=0
	stop_daemon "after the view's command"
fi

if [ "$mode" = virtual ]; then
	reports=$8
	mark running
	wait_valid_poses vcan0 "$reports" "$5"
	mark stop
	stop_daemon "after $reports valid poses"
fi

# Replay: dockposed stops when the frames run out (or at --for). Either mode: a dockposed
# still running at the deadline hung somewhere.
while kill -0 "$daemon" 2>/dev/null && ! past_deadline; do
	sleep 0.3
done
if kill -0 "$daemon" 2>/dev/null; then
	hang_report "$daemon" "dockposed still running $SLACK_S s past its --for $5"
	stop_daemon "past the deadline"
fi
if [ $reaped -eq 0 ]; then
	wait "$daemon" || rc=$?
fi
echo "$rc" >dockposed.rc
mark exit
# Let candump take the last frames off the socket, then stop the recorders.
sleep 0.5
kill "$poll" 2>/dev/null
wait "$poll" 2>/dev/null
kill "$dump" 2>/dev/null
wait "$dump" 2>/dev/null
cat "$line_value" >gpio-after.txt 2>&1
exit 0

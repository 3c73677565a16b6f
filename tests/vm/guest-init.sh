#!/bin/sh
# SPDX-License-Identifier: MIT
#
# PID 1 of dockpose's test VMs, started by `scripts/vm run` (see docs/vm-tests.md). The root
# file system is the host's / over 9p, read-only. This script prepares the devices the real
# backends use, runs the command described in the control share and powers the VM off.
#
# The shell is dash: the host's on x86_64, an unpacked arm64 one on arm64 (the host's userland
# is amd64; the other commands are then busybox's applets until the arm64 tools are on PATH).
#
# From the kernel command line (the environment of PID 1):
#   DOCKPOSE_VM_ARCH      x86_64 or arm64
#   DOCKPOSE_VM_BUSYBOX   arm64: the static arm64 busybox
# From the control share (9p tag dockpose-ctl, mounted at /run/dockpose-vm):
#   config.sh   VM_SHARE (host directory shared read-write, mounted at the same path),
#               VM_CWD (the host's working directory), VM_USERLAND (arm64 tools tree),
#               VM_HOST_EPOCH (the host's time, for the guest's clock)
#   env.sh      the command's extra environment (--env)
#   argv.sh     `set -- COMMAND ARGS...`
# Written back: rc (the command's exit status), timing, setup-error (when preparing failed).
#
# The command runs with stdout on /dev/hvc0 and stderr on /dev/hvc1 (virtio consoles that
# scripts/vm copies to its own stdout and stderr); this script's own output goes to the
# kernel console, which scripts/vm keeps in a log.

CTL=/run/dockpose-vm
P9_OPTS=trans=virtio,version=9p2000.L,msize=262144

# The host's amd64 binaries cannot run in the arm64 guest: busybox's applets, until the arm64
# tools are on PATH.
if [ "$DOCKPOSE_VM_ARCH" = arm64 ]; then
	"$DOCKPOSE_VM_BUSYBOX" mount -t proc proc /proc
	"$DOCKPOSE_VM_BUSYBOX" mount -t tmpfs -o mode=0755 tmpfs /run
	"$DOCKPOSE_VM_BUSYBOX" mkdir -p /run/busybox/bin
	# A copy in /run: the tools tree may lie in the host's /tmp (DOCKPOSE_VM_CACHE there), which
	# the guest's own /tmp hides below until it is shown again.
	"$DOCKPOSE_VM_BUSYBOX" cp "$DOCKPOSE_VM_BUSYBOX" /run/busybox/busybox
	/run/busybox/busybox --install -s /run/busybox/bin
	PATH=/run/busybox/bin
else
	PATH=/usr/sbin:/usr/bin:/sbin:/bin
	mount -t proc proc /proc
	mount -t tmpfs -o mode=0755 tmpfs /run
fi
export PATH

uptime_s() { cut -d' ' -f1 /proc/uptime; }

# power_off: leave the VM; QEMU then exits (it runs with -no-reboot).
power_off() {
	sync
	if [ "$DOCKPOSE_VM_ARCH" = x86_64 ]; then
		# isa-debug-exit at port 0xf4: QEMU exits with (value << 1) | 1.
		v=${rc:-125}
		[ "$v" -le 127 ] || v=127
		printf "\\$(printf %o "$v")" | dd of=/dev/port bs=1 seek=244 count=1 2>/dev/null
	else
		poweroff -f # PSCI SYSTEM_OFF
	fi
	reboot -f -f 2>/dev/null || reboot -f
	exit "${rc:-125}" # PID 1 exiting panics the kernel; panic=-1 reboots, -no-reboot ends QEMU
}

# setup_failed MESSAGE: report MESSAGE to scripts/vm and power off.
setup_failed() {
	echo "vm guest: $*" >&2
	[ ! -f "$CTL/config.sh" ] || echo "$*" >>"$CTL/setup-error"
	rc=125
	power_off
}

mkdir -p "$CTL" && mount -t 9p -o "$P9_OPTS" dockpose-ctl "$CTL" ||
	setup_failed "cannot mount the control share"
. "$CTL/config.sh" || setup_failed "cannot read $CTL/config.sh"

mount -t sysfs sysfs /sys || setup_failed "cannot mount /sys"
[ -e /dev/null ] || mount -t devtmpfs devtmpfs /dev || setup_failed "cannot mount /dev"
mkdir -p /dev/shm && mount -t tmpfs -o mode=1777 tmpfs /dev/shm || setup_failed "cannot mount /dev/shm"
mount -t configfs configfs /sys/kernel/config || setup_failed "cannot mount configfs"

# /tmp: a tmpfs (the root is read-only). It hides the host's /tmp, so keep that reachable
# (read-only) at /run/host-tmp, and mount the share after the tmpfs.
mkdir -p /run/host-tmp && mount -o bind /tmp /run/host-tmp &&
	mount -t tmpfs -o mode=1777 tmpfs /tmp || setup_failed "cannot mount /tmp"
# The repository (scripts, test data, binaries), the working directory, the arm64 tools tree and
# the libcamera builds, when they live in the host's /tmp (a checkout there, a build tree there, a
# cache there): show them (read-only) at their own paths.
for dir in "$VM_REPO" "$VM_CWD" "${VM_USERLAND:-}" "${VM_LIBCAMERA:-}"; do
	case $dir in
	"" | /tmp) ;;
	/tmp/*)
		[ -n "$VM_REPO" ] && [ "$dir" != "$VM_REPO" ] && case $dir in "$VM_REPO"/*) continue ;; esac
		mkdir -p "$dir" && mount -o bind "/run/host-tmp/${dir#/tmp/}" "$dir" ||
			setup_failed "cannot show $dir"
		;;
	esac
done
# The share last: it may lie inside the repository shown above.
mkdir -p "$VM_SHARE" && mount -t 9p -o "$P9_OPTS" dockpose-share "$VM_SHARE" ||
	setup_failed "cannot mount the share at $VM_SHARE"

if [ "$DOCKPOSE_VM_ARCH" = arm64 ]; then
	# #!/bin/sh scripts, system() and popen() need an arm64 /bin/sh: dash, like the host's
	# (busybox's sh would run its own applets before the tools on PATH).
	mount -o bind "$VM_USERLAND/bin/dash" /bin/sh || setup_failed "cannot bind dash on /bin/sh"
fi

# No RTC driver: start the clock at the host's time (seconds off by the boot).
date -s "@$VM_HOST_EPOCH" >/dev/null 2>&1 || echo "vm guest: cannot set the date" >&2

ip link set lo up || setup_failed "cannot bring lo up"

# SocketCAN: vcan0 and vcan1, up.
for can in vcan0 vcan1; do
	ip link add dev "$can" type vcan && ip link set "$can" up ||
		setup_failed "cannot create $can (is CONFIG_CAN_VCAN in the kernel?)"
done

# gpio-sim: one chip labelled dockpose-sim, 8 lines, line 3 named led-strobe.
sim=/sys/kernel/config/gpio-sim/dockpose
{
	mkdir "$sim" "$sim/bank0" &&
		echo 8 >"$sim/bank0/num_lines" &&
		echo dockpose-sim >"$sim/bank0/label" &&
		mkdir "$sim/bank0/line3" &&
		echo led-strobe >"$sim/bank0/line3/name" &&
		echo 1 >"$sim/live"
} || setup_failed "cannot create the gpio-sim chip (is CONFIG_GPIO_SIM in the kernel?)"
DOCKPOSE_GPIO_SIM_CHIP=$(cat "$sim/bank0/chip_name")
DOCKPOSE_GPIO_SIM_DIR=/sys/devices/platform/$(cat "$sim/dev_name")/$DOCKPOSE_GPIO_SIM_CHIP
[ -d "$DOCKPOSE_GPIO_SIM_DIR" ] || setup_failed "gpio-sim: no $DOCKPOSE_GPIO_SIM_DIR"

# libcamera lists only devices udev has marked initialised, and there is no udevd: fake the
# udev database with an empty /run/udev/data/c<major>:<minor> for every character device.
mkdir -p /run/udev/data || setup_failed "cannot create /run/udev/data"
for dev in /sys/dev/char/*; do
	: >"/run/udev/data/c${dev##*/}"
done

# The command's environment.
unset TERM BOOT_IMAGE
export HOME=/tmp/home
mkdir -p "$HOME"
export USER=root LOGNAME=root
export LIBCAMERA_LOG_LEVELS='*:ERROR'
export DOCKPOSE_VM_ARCH DOCKPOSE_VM_SHARE="$VM_SHARE"
export DOCKPOSE_GPIO_SIM_CHIP DOCKPOSE_GPIO_SIM_DIR
if [ "$DOCKPOSE_VM_ARCH" = arm64 ]; then
	# The arm64 tools first, so candump, gpiodetect, cam... are the same names as on x86_64;
	# the libraries the host lacks for arm64 come from the same tree.
	PATH=$VM_USERLAND/usr/bin:$VM_USERLAND/usr/sbin:$VM_USERLAND/bin:$VM_USERLAND/sbin:/run/busybox/bin
	LD_LIBRARY_PATH=$(cat "$VM_USERLAND/.ld_library_path") ||
		setup_failed "no $VM_USERLAND/.ld_library_path"
	export LD_LIBRARY_PATH
else
	PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
fi

# Raw output: no CR added before LF on the virtio consoles. A tty's settings last only while
# it is open, so keep both open here (fds 3 and 4) and hand those to the command.
exec 3<>/dev/hvc0 4<>/dev/hvc1 ||
	setup_failed "no virtio consoles /dev/hvc0 and /dev/hvc1 (CONFIG_VIRTIO_CONSOLE?)"
stty -opost <&3 && stty -opost <&4 || setup_failed "cannot set the virtio consoles raw"

boot_s=$(uptime_s)
(
	. "$CTL/env.sh" || exit 125
	. "$CTL/argv.sh" || exit 125
	cd "$VM_CWD" || exit 125
	exec "$@"
) </dev/null >&3 2>&4 3>&- 4>&-
rc=$?
end_s=$(uptime_s)

echo "guest booted in ${boot_s} s, command ran $(awk "BEGIN { print $end_s - $boot_s }") s" \
	>"$CTL/timing"
echo "$rc" >"$CTL/rc.tmp" && mv "$CTL/rc.tmp" "$CTL/rc"
power_off

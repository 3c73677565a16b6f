#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# usage: harness-check.sh ARCH    (ctest vm_x86_64_harness, vm_aarch64_harness)
#
# Checks `scripts/vm run` itself, on the host: the command's stdout and stderr arrive apart
# and unchanged, its exit status is passed on, it runs in the host's working directory with
# --env and the documented environment, the share is writable at its own path, and --timeout
# stops the VM with status 124. Exits 77 when scripts/vm cannot run a VM here.
set -uo pipefail

arch=${1:?usage: harness-check.sh ARCH}
vm=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)/scripts/vm
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir "$tmp/share" "$tmp/cwd"

failures=0
fail() {
	echo "FAILED: $*" >&2
	failures=$((failures + 1))
}

# 1. Output, status, working directory, environment, share.
cd "$tmp/cwd" || exit 1
# shellcheck disable=SC2016 # expanded in the guest
"$vm" run --arch "$arch" --share "$tmp/share" --env "DOCKPOSE_CHECK=a 'b' \$c" -- sh -c '
	printf "out 1\nout 2\n"
	echo "err 1" >&2
	pwd
	echo "check=$DOCKPOSE_CHECK"
	echo "arch=$DOCKPOSE_VM_ARCH share=$DOCKPOSE_VM_SHARE"
	test -d "$DOCKPOSE_GPIO_SIM_DIR" && echo "sim dir ok"
	echo written >"$DOCKPOSE_VM_SHARE/from-guest"
	exit 42' >"$tmp/stdout" 2>"$tmp/stderr"
rc=$?
[[ $rc -ne 77 ]] || exit 77
[[ $rc -eq 42 ]] || fail "exit status $rc, expected 42"
expected=$(printf 'out 1\nout 2\n%s\ncheck=%s\narch=%s share=%s\nsim dir ok' \
	"$tmp/cwd" "a 'b' \$c" "$([[ $arch == x86_64 ]] && echo x86_64 || echo arm64)" "$tmp/share")
[[ $(<"$tmp/stdout") == "$expected" ]] ||
	fail "stdout differs; expected:"$'\n'"$expected"$'\n'"got:"$'\n'"$(cat -A "$tmp/stdout")"
grep -qx 'err 1' "$tmp/stderr" || fail "stderr lacks 'err 1': $(cat "$tmp/stderr")"
! grep -q 'out 1' "$tmp/stderr" || fail "stdout leaked into stderr"
[[ $(cat "$tmp/share/from-guest" 2>&1) == written ]] || fail "the share was not written"

# 2. --timeout stops the VM: not before the 5 s, and well before the command (120 s) would
# have ended by itself (both relative to the command, not to how fast this machine is).
start=$SECONDS
"$vm" run --arch "$arch" --timeout 5 -- sleep 120 >/dev/null 2>"$tmp/timeout.err"
rc=$?
took=$((SECONDS - start))
[[ $rc -eq 124 ]] || fail "timeout: exit status $rc, expected 124: $(cat "$tmp/timeout.err")"
grep -q 'timeout' "$tmp/timeout.err" || fail "timeout: no message: $(cat "$tmp/timeout.err")"
((took >= 4 && took < 120)) || fail "timeout: took $took s (--timeout 5, the command 120 s)"

if [[ $failures -ne 0 ]]; then
	echo "$failures harness check(s) failed ($arch)" >&2
	exit 1
fi
echo "scripts/vm run ($arch): output, status, cwd, env, share and timeout ok"

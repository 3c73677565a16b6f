#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Check the MACs of an authenticated dockpose CAN log independently of the C++ code.

Used by tests/firmware/test_can_auth.cpp. The signals come from canmatrix with
the DBC; the MAC is AES-128-CMAC from python3-cryptography (OpenSSL, but
another binding and none of dockpose_can.h); the grouping and the MAC input
are rebuilt from docs/can-protocol.md ("Authentication"):

  sensor frames since the previous DP_Auth form its group, but a frame that cannot
  continue the group (a DP_Heartbeat; a report frame of another sequence, or after
  a heartbeat's frames) starts a new one: the rest of the old group never came (a
  report cut short at its deadline), and it is dropped unverified; DP_Auth's MAC is the
  first 4 bytes of CMAC(key, b"DPA3" | base id (2 bytes LE) | per frame: id
  (2 bytes LE) + its 8 data bytes | freshness (8 bytes LE) | DP_Auth's byte 6);
  the freshness value is (DP_Freshness.FreshnessHigh << 16 | AuthFreshness) when
  the group holds a DP_Freshness, else the last value with its low 16 bits
  replaced (+ 0x10000 when that is not newer). DP_CommandAuth covers the
  DP_Command before it with the sensor freshness value it answers (the latest
  sensor value with its low 16 bits replaced, not newer than the latest).

Prints one JSON object: {"auth_ok": N, "auth_bad": N, "unsynced": N,
"command_ok": N, "command_bad": N, "bad_lines": [candump line numbers of
refused MAC frames]}. Exit 2 on usage errors.
"""

import argparse
import json
import logging
import re
import sys

DBC_BASE_ID = 0x300
LINE = re.compile(r"^\((\d+\.\d+)\) \S+ ([0-9A-Fa-f]{3})#([0-9A-Fa-f]{16})$")


def main():
	p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
	p.add_argument("--dbc", required=True)
	p.add_argument("--key", required=True, help="32 hex digits")
	p.add_argument("--base-id", default="0x300")
	p.add_argument("log")
	args = p.parse_args()
	base = int(args.base_id, 0)
	key = bytes.fromhex(args.key)

	logging.getLogger("canmatrix").setLevel(logging.ERROR)
	import canmatrix.formats
	from cryptography.hazmat.primitives.cmac import CMAC
	from cryptography.hazmat.primitives.ciphers import algorithms

	db = canmatrix.formats.loadp_flat(args.dbc, import_type="dbc")
	by_name = {f.name: f for f in db.frames}

	def decode(name, data):
		return {n: int(sig.raw_value) for n, sig in by_name[name].decode(data).items()}

	def mac32(message):
		c = CMAC(algorithms.AES(key))
		c.update(message)
		return int.from_bytes(c.finalize()[:4], "big")

	def mac_input(frames, freshness, byte6):
		out = b"DPA3" + base.to_bytes(2, "little")
		for ident, data in frames:
			out += ident.to_bytes(2, "little") + data
		return out + freshness.to_bytes(8, "little") + bytes([byte6])

	names = {}
	for f in db.frames:
		names[f.arbitration_id.id - DBC_BASE_ID + base] = f.name
	result = {"auth_ok": 0, "auth_bad": 0, "unsynced": 0, "command_ok": 0, "command_bad": 0,
			  "bad_lines": []}
	group = []
	kind, group_seq = None, None
	high = None
	last = None
	command = None
	with open(args.log) as log:
		for number, line in enumerate(log, 1):
			m = LINE.match(line.strip())
			if not m:
				continue
			ident = int(m.group(2), 16)
			data = bytes.fromhex(m.group(3))
			name = names.get(ident)
			if name is None:
				continue
			if name == "DP_Command":
				command = (ident, data)
			elif name == "DP_CommandAuth":
				s = decode(name, data)
				ok = False
				if command is not None and last is not None:
					echo = (last & ~0xffff) | s["CmdFreshness"]
					if echo > last:
						echo -= 0x10000
					ok = mac32(mac_input([command], echo, data[6])) == s["CmdMac"]
				result["command_ok" if ok else "command_bad"] += 1
				if not ok:
					result["bad_lines"].append(number)
				command = None
			elif name == "DP_Auth":
				s = decode(name, data)
				if high is not None:
					fv = (high << 16) | s["AuthFreshness"]
				elif last is not None:
					fv = (last & ~0xffff) | s["AuthFreshness"]
					if fv <= last:
						fv += 0x10000
				else:
					result["unsynced"] += 1
					group, high, kind = [], None, None
					continue
				if mac32(mac_input(group, fv, data[6])) == s["AuthMac"] and (last is None or fv > last):
					result["auth_ok"] += 1
					last = fv
				else:
					result["auth_bad"] += 1
					result["bad_lines"].append(number)
				group, high, kind = [], None, None
			else:
				seq = data[6] >> 4
				if name == "DP_Heartbeat":
					this, continues = "heartbeat", False
				elif name == "DP_Freshness":
					this, continues = "heartbeat", kind == "heartbeat"
				else:
					this, continues = "report", kind == "report" and seq == group_seq
				if group and not continues:
					group, high = [], None
				group.append((ident, data))
				kind, group_seq = this, seq
				if name == "DP_Freshness":
					high = decode(name, data)["FreshnessHigh"]
	print(json.dumps(result))
	return 0


if __name__ == "__main__":
	sys.exit(main())

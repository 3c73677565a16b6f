#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Decode a candump -l log with canmatrix alone: the independent check of the DBC.

Used by tests/firmware/test_can_protocol.cpp. Every signal value comes from
canmatrix's Frame.decode() with the DBC; nothing here knows the bit layout.
The log lines are split by hand (no python-can), so this checks the DBC
against the C++ encoder and nothing else.

Prints one JSON object per frame:
  {"line": N, "timestamp": T, "id": 773, "message": "DP_Status",
   "signals": {"State": 2.0, ...}, "raw": {"State": 2, ...}}
"message" is null for an id the DBC does not have. Exit 2 on errors.
"""

import argparse
import json
import logging
import sys

DBC_BASE_ID = 0x300


def main():
	p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
	p.add_argument("--dbc", required=True)
	p.add_argument("--base-id", default="0x300", help="the sensor's base id (remapped to 0x300)")
	p.add_argument("log")
	args = p.parse_args()
	base_id = int(args.base_id, 0)

	logging.getLogger("canmatrix").setLevel(logging.ERROR)
	try:
		import canmatrix
		import canmatrix.formats
	except ImportError as exc:
		print(f"canmatrix_decode: python3-canmatrix is missing: {exc}", file=sys.stderr)
		return 2
	try:
		db = canmatrix.formats.loadp_flat(args.dbc, import_type="dbc")
	except OSError as exc:
		print(f"canmatrix_decode: {args.dbc}: {exc.strerror}", file=sys.stderr)
		return 2
	if db is None or not db.frames:
		print(f"canmatrix_decode: {args.dbc}: no messages in the DBC", file=sys.stderr)
		return 2

	try:
		log = open(args.log, encoding="ascii")
	except OSError as exc:
		print(f"canmatrix_decode: {args.log}: {exc.strerror}", file=sys.stderr)
		return 2
	with log:
		for lineno, line in enumerate(log, 1):
			line = line.strip()
			if not line:
				continue
			try:
				stamp, _iface, frame_text = line.split()[:3]
				id_text, data_text = frame_text.split("#", 1)
				if data_text.startswith("#"):  # CAN FD: id##<flags><data>
					data_text = data_text[2:]
				can_id = int(id_text, 16)
				data = bytes.fromhex(data_text)
				timestamp = float(stamp.strip("()"))
			except ValueError:
				print(f"canmatrix_decode: {args.log}:{lineno}: not a candump -l line: {line!r}",
					  file=sys.stderr)
				return 2
			frame = db.frame_by_id(canmatrix.ArbitrationId(can_id - base_id + DBC_BASE_ID))
			obj = {"line": lineno, "timestamp": timestamp, "id": can_id, "message": None,
				   "signals": {}, "raw": {}}
			if frame is not None:
				obj["message"] = frame.name
				for name, sig in frame.decode(data).items():
					obj["signals"][name] = float(sig.phys_value)
					obj["raw"][name] = int(sig.raw_value)
			print(json.dumps(obj))
	return 0


if __name__ == "__main__":
	sys.exit(main())

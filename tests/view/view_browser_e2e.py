#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""dockpose view in a real browser (ctest view_browser_e2e, labels browser and e2e).

dockposed runs on the sim board with its preview on and its CAN frames going into a candump log;
`dockpose view --can-log LOG --port 0` follows that log; headless Chromium loads the page, driven
over the DevTools protocol (--remote-debugging-pipe, the standard library only). Checked from the
page's DOM and a screenshot:

  1. the page goes LIVE and shows a pose; the preview's camera frame counter moves, and a
     screenshot of the preview canvas is not blank (its grey levels spread);
  2. the sensor stopped (SIGTERM): the page says STALE within one second;
  3. the pose shown is the last valid pose in the CAN log, decoded independently with canmatrix
     and the DBC (the same frame counter; x, y, z within 0.05 mm, roll, pan, tilt within
     0.005 deg: the page shows the signals at their resolution);
  4. bad input: a malformed line, a truncated line, a frame with a bad CRC and one with a
     repeated alive counter appended to the log are each named on the page; the preview ring gone is named too; the server keeps answering;
  5. a second view whose preview ring is missing, and a third whose ring is not a preview ring
     (a file of zeros), name the problem on their pages.

Also: --shot URL PNG writes a screenshot of the page at URL (docs/img/operator-view.png).
Prints the measured figures (stale latency, page updates a second). Exit 0 pass, 1 fail.
"""

import argparse
import base64
import fcntl
import json
import os
import runpy
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
import zlib

DBC_BASE_ID = 0x300


class Browser:
	"""Headless Chromium over --remote-debugging-pipe: fd 3 in, fd 4 out, NUL-separated JSON."""

	def __init__(self, chromium, profile, width=1400, height=1000):
		os.makedirs(profile, exist_ok=True)
		# The child's ends at fds >= 10 first, so dup2 onto 3 and 4 cannot clobber them.
		to_child_r, self.to_child = (self._high(fd) for fd in os.pipe())
		self.from_child, from_child_w = (self._high(fd) for fd in os.pipe())

		def fds():
			os.dup2(to_child_r, 3)
			os.dup2(from_child_w, 4)

		self.proc = subprocess.Popen(
			[chromium, "--headless", "--no-sandbox", "--disable-gpu", "--remote-debugging-pipe",
			 "--no-first-run", "--no-default-browser-check", "--disable-extensions",
			 "--hide-scrollbars", f"--window-size={width},{height}",
			 f"--user-data-dir={profile}", "about:blank"],
			preexec_fn=fds, close_fds=False, stdout=subprocess.DEVNULL,
			stderr=open(os.path.join(profile, "chromium.log"), "w"))
		os.close(to_child_r)
		os.close(from_child_w)
		self.buffer = b""
		self.next_id = 0
		self.session = None

	@staticmethod
	def _high(fd):
		high = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10)
		os.close(fd)
		return high

	def call(self, method, params=None, session=True, timeout=30):
		self.next_id += 1
		msg = {"id": self.next_id, "method": method, "params": params or {}}
		if session and self.session:
			msg["sessionId"] = self.session
		os.write(self.to_child, json.dumps(msg).encode() + b"\0")
		deadline = time.time() + timeout
		while time.time() < deadline:
			while b"\0" in self.buffer:
				raw, self.buffer = self.buffer.split(b"\0", 1)
				reply = json.loads(raw)
				if reply.get("id") == self.next_id:
					if "error" in reply:
						raise RuntimeError(f"{method}: {reply['error']}")
					return reply.get("result", {})
			chunk = os.read(self.from_child, 1 << 20)
			if not chunk:
				raise RuntimeError("chromium closed its pipe")
			self.buffer += chunk
		raise RuntimeError(f"{method}: no answer in {timeout} s")

	def open(self, url):
		target = self.call("Target.createTarget", {"url": "about:blank"}, session=False)
		attached = self.call("Target.attachToTarget",
							 {"targetId": target["targetId"], "flatten": True}, session=False)
		self.session = attached["sessionId"]
		self.call("Page.enable")
		self.call("Page.navigate", {"url": url})

	def navigate(self, url):
		self.call("Page.navigate", {"url": url})

	def js(self, expression):
		r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
										   "awaitPromise": True})
		if "exceptionDetails" in r:
			raise RuntimeError(f"{expression}: {r['exceptionDetails']}")
		return r["result"].get("value")

	def text(self, element_id):
		return self.js(f"(document.getElementById({json.dumps(element_id)}) || {{}}).textContent")

	def screenshot(self, clip=None):
		params = {"format": "png", "captureBeyondViewport": True}
		if clip:
			params["clip"] = dict(clip, scale=1)
		return base64.b64decode(self.call("Page.captureScreenshot", params)["data"])

	def close(self):
		try:
			self.call("Browser.close", session=False, timeout=5)
		except (RuntimeError, OSError):
			pass
		try:
			self.proc.wait(timeout=10)
		except subprocess.TimeoutExpired:
			self.proc.kill()


def png_grey_levels(png):
	"""The luma of every pixel of an 8-bit RGB(A) PNG (a small decoder: zlib and the 5 filters)."""
	assert png[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
	pos, idat, width, height, ctype = 8, b"", 0, 0, 0
	while pos < len(png):
		n, kind = struct.unpack(">I4s", png[pos:pos + 8])
		body = png[pos + 8:pos + 8 + n]
		if kind == b"IHDR":
			width, height, depth, ctype = struct.unpack(">IIBB", body[:10])
			assert depth == 8 and ctype in (2, 6), f"PNG depth {depth} colour type {ctype}"
		elif kind == b"IDAT":
			idat += body
		pos += 12 + n
	bpp = 4 if ctype == 6 else 3
	raw = zlib.decompress(idat)
	stride = width * bpp
	prev = bytearray(stride)
	levels = []
	for y in range(height):
		f = raw[y * (stride + 1)]
		line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
		for i in range(stride):
			a = line[i - bpp] if i >= bpp else 0
			b = prev[i]
			c = prev[i - bpp] if i >= bpp else 0
			if f == 1:
				line[i] = (line[i] + a) & 255
			elif f == 2:
				line[i] = (line[i] + b) & 255
			elif f == 3:
				line[i] = (line[i] + (a + b) // 2) & 255
			elif f == 4:
				p = a + b - c
				pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
				line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
		for x in range(0, stride, bpp):
			levels.append((line[x] * 30 + line[x + 1] * 59 + line[x + 2] * 11) // 100)
		prev = line
	return levels


def last_valid_pose(log_path, dbc_path):
	"""The last report with PoseValid and its six pose frames, decoded by canmatrix alone.

	Like the project's decoder (the arm controller's), a report whose LatencyMs is above its
	default bound on a pose's age (50 ms) is not taken."""
	import logging
	logging.getLogger("canmatrix").setLevel(logging.ERROR)
	import canmatrix
	import canmatrix.formats
	db = canmatrix.formats.loadp_flat(dbc_path, import_type="dbc")
	names = {"DP_Translation", "DP_QuatA", "DP_QuatB", "DP_Angles", "DP_Sigma", "DP_Quality"}
	held = {}
	last = None
	with open(log_path, encoding="ascii", errors="replace") as log:
		for line in log:
			try:
				_stamp, _iface, frame_text = line.split()[:3]
				id_text, data_text = frame_text.split("#", 1)
				data = bytes.fromhex(data_text)
				frame = db.frame_by_id(canmatrix.ArbitrationId(int(id_text, 16)))
			except ValueError:
				continue
			if frame is None or len(data) != 8:
				continue
			signals = {k: float(v.phys_value) for k, v in frame.decode(data).items()}
			if frame.name in names:
				held[frame.name] = signals
			elif frame.name == "DP_Status":
				seq = signals["Sequence"]
				if signals["PoseValid"] == 1 and signals["LatencyMs"] <= 50.0 and all(
						n in held and held[n]["Sequence"] == seq for n in names):
					last = {"Tx": held["DP_Translation"]["Tx"], "Ty": held["DP_Translation"]["Ty"],
							"Tz": held["DP_Translation"]["Tz"], "Roll": held["DP_Angles"]["Roll"],
							"Pan": held["DP_Angles"]["Pan"], "Tilt": held["DP_Angles"]["Tilt"],
							"FrameCounter": int(held["DP_QuatB"]["FrameCounter"])}
				held = {}
	return last


def wait_for(what, predicate, timeout, step=0.05):
	deadline = time.time() + timeout
	while time.time() < deadline:
		value = predicate()
		if value:
			return value
		time.sleep(step)
	raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def start_view(dockpose, args, out_path):
	out = open(out_path, "w")
	proc = subprocess.Popen([dockpose, "view", *args, "--port", "0"], stdout=out,
							stderr=subprocess.STDOUT)

	def url():
		with open(out_path) as f:
			for line in f:
				if line.startswith("dockpose view: http://"):
					return line.split(": ", 1)[1].strip()
		if proc.poll() is not None:
			raise AssertionError(f"dockpose view exited {proc.returncode}: {open(out_path).read()}")
		return None
	return proc, wait_for("the view's URL", url, 10)


def get_json(url):
	with urllib.request.urlopen(url, timeout=5) as r:
		return json.loads(r.read())


def problem_names(browser):
	return browser.js("[...document.querySelectorAll('#problems li[data-name]')]"
					  ".map(li => li.dataset.name)")


def problem_detail(browser, name):
	return browser.js("(() => { const li = [...document.querySelectorAll('#problems li')]"
					  f".find(li => li.dataset.name === {json.dumps(name)});"
					  " return li ? li.querySelector('.detail').textContent : null; })()")


def problem_text(browser):
	return browser.js("document.getElementById('problems').innerText")


def run_test(args):
	work = tempfile.mkdtemp(prefix="dockpose-view-e2e.")
	procs = []
	browser = None
	ring = f"dockpose-view-e2e-{os.getpid()}"
	wrong_ring = f"{ring}-wrong"
	failures = []

	def check(ok, message):
		print(("ok    " if ok else "FAIL  ") + message, flush=True)
		if not ok:
			failures.append(message)

	try:
		board = json.load(open(os.path.join(args.source, "board/sim/board.json")))
		board["camera"]["intrinsics"] = os.path.join(args.source, "board/sim/camera.json")
		board["pipeline"]["target"] = os.path.join(args.source, "board/sim/target.json")
		board["camera"]["synthetic"]["loop"] = True
		board["preview"] = {"enabled": True, "name": ring}
		board["systemd"] = {"notify": False}
		board_path = os.path.join(work, "board.json")
		json.dump(board, open(board_path, "w"))
		log = os.path.join(work, "can.log")

		daemon = subprocess.Popen([args.dockposed, "--board", board_path, "--for", "60",
								   "--can-log", log],
								  stderr=open(os.path.join(work, "dockposed.err"), "w"))
		procs.append(daemon)
		def log_or_exit():
			if daemon.poll() is not None:
				raise AssertionError(f"dockposed exited {daemon.returncode}")
			return os.path.exists(log)
		wait_for("the CAN log", log_or_exit, 15)
		view, url = start_view(args.dockpose, ["--can-log", log, "--preview", ring, "--camera",
											   board["camera"]["intrinsics"]],
							   os.path.join(work, "view.out"))
		procs.append(view)
		print(f"view at {url}", flush=True)

		browser = Browser(args.chromium, os.path.join(work, "profile"))
		browser.open(url)

		# 1. live, a pose, the preview moving and not blank.
		wait_for("LIVE and a pose on the page",
				 lambda: browser.text("stale") == "LIVE" and browser.text("v-x") not in ("—", None),
				 20)
		check(True, f"the page is LIVE, state {browser.text('state')}, x = {browser.text('v-x')} mm")
		first = wait_for("a preview frame", lambda: browser.text("preview-frame").isdigit()
						 and int(browser.text("preview-frame")), 10)
		time.sleep(1.0)
		second = int(browser.text("preview-frame"))
		check(second > first, f"the preview updates: camera frame {first} then {second} a second later")
		u0 = int(browser.text("updates"))
		time.sleep(2.0)
		u1 = int(browser.text("updates"))
		rate = (u1 - u0) / 2.0
		hz = browser.js("document.body.dataset.eventsHz")
		check(rate > 5, f"the page is updated {rate:.1f} times a second by server-sent events "
			  f"(thinned to the page's {hz} frames/s; reports at {browser.text('rate')})")
		rect = browser.js("(() => { const r = document.getElementById('preview')"
						  ".getBoundingClientRect(); return {x: r.x, y: r.y, width: r.width,"
						  " height: r.height}; })()")
		shot = browser.screenshot(rect)
		open(os.path.join(work, "preview.png"), "wb").write(shot)
		levels = png_grey_levels(shot)
		mean = sum(levels) / len(levels)
		sd = (sum((v - mean) ** 2 for v in levels) / len(levels)) ** 0.5
		distinct = len(set(levels))
		check(sd > 5 and distinct > 20,
			  f"the preview's screenshot is not blank: {len(levels)} px, mean {mean:.1f}, "
			  f"sd {sd:.1f}, {distinct} grey levels")
		blobs = browser.js("document.getElementById('preview-status').textContent")
		check(blobs == "preview ring ok", f"the preview ring is read: '{blobs}'")

		# 2. the sensor stops: STALE within a second.
		daemon.send_signal(signal.SIGTERM)
		stopped = time.time()
		daemon.wait(timeout=10)
		last_line_time = os.path.getmtime(log)
		wait_for("STALE", lambda: browser.text("stale") == "STALE", 3, step=0.02)
		latency = time.time() - stopped
		latency_log = time.time() - last_line_time
		check(latency <= 1.0, f"STALE {latency * 1000:.0f} ms after SIGTERM to dockposed "
			  f"({latency_log * 1000:.0f} ms after its last CAN frame was written)")

		# 3. the pose shown is the log's last valid pose, decoded by canmatrix.
		want = last_valid_pose(log, os.path.join(args.source, "firmware/protocol/dockpose.dbc"))
		check(want is not None, "canmatrix finds a valid pose in the log")
		shown = {k: browser.text(e) for k, e in (("Tx", "v-x"), ("Ty", "v-y"), ("Tz", "v-z"),
												  ("Roll", "v-roll"), ("Pan", "v-pan"),
												  ("Tilt", "v-tilt"), ("FrameCounter", "frame"))}
		check(int(shown["FrameCounter"]) == want["FrameCounter"],
			  f"the page's pose is of camera frame {shown['FrameCounter']}, canmatrix's last valid "
			  f"pose of frame {want['FrameCounter']}")
		for k, tol in (("Tx", 0.05), ("Ty", 0.05), ("Tz", 0.05), ("Roll", 0.005), ("Pan", 0.005),
					   ("Tilt", 0.005)):
			check(abs(float(shown[k]) - want[k]) <= tol + 1e-9,
				  f"{k}: page {shown[k]}, canmatrix {want[k]:.4f} (within {tol})")

		# 4. bad input appended to the log: each named, the server keeps answering.
		status_line = None
		with open(log, encoding="ascii") as f:
			for line in f:
				if line.split()[2].startswith("305#"):
					status_line = line.split()
		data = bytearray.fromhex(status_line[2].split("#")[1])
		data[6] = (data[6] & 0xF0) | ((data[6] + 1) & 0x0F)  # the next alive counter
		# The CRC from candecode (the Python tools' one copy of CRC-8 SAE J1850).
		frame_crc = runpy.run_path(os.path.join(args.source, "scripts/candecode"))["frame_crc"]
		data[7] = frame_crc(0x305, data)
		data[7] ^= 0x5A  # and a CRC that does not match
		now = time.time()
		with open(log, "a") as f:
			f.write("this line is not candump\n")
			f.write(f"({now:.6f}) can0 305#00112\n")
			f.write(f"({now:.6f}) can0 305#{data.hex().upper()}\n")
			# The last status frame again: its alive counter repeats.
			f.write(f"({now:.6f}) can0 {status_line[2]}\n")
		for name in ("malformed log line", "truncated log line", "bad CRC",
					 "stale alive counter"):
			try:
				wait_for(f"'{name}' on the page", lambda n=name: n in (problem_names(browser) or []),
						 3)
				check(True, f"the page names '{name}'")
			except AssertionError as e:
				check(False, f"{e}: {problem_text(browser)}")
		wait_for("the preview ring's absence on the page",
				 lambda: "preview ring" in (problem_names(browser) or [])
				 and browser.text("preview-status") != "preview ring ok", 6)
		check(True, f"the page names the preview ring gone: '{browser.text('preview-status')}'")
		state = get_json(url + "api/state")
		check(view.poll() is None and state["stale"] is True,
			  "the server keeps running after the bad input (GET /api/state answers, stale)")
		for key in ("t_mm", "rpy_deg", "sigma_t_mm", "sigma_rpy_deg", "state", "faults", "leds",
					"rms_px", "frame", "age_ms"):
			check(key in state, f"/api/state has '{key}'")

		# 5. views whose ring is missing, and whose ring is not a preview ring.
		view2, url2 = start_view(args.dockpose, ["--can-log", log, "--preview", ring + "-none"],
								 os.path.join(work, "view2.out"))
		procs.append(view2)
		browser.navigate(url2)
		wait_for("the missing ring on the page",
				 lambda: "preview ring" in (problem_names(browser) or []), 10)
		text = problem_detail(browser, "preview ring")
		check("preview.enabled?" in text and browser.text("preview-status") == text,
			  f"a missing ring is named: preview ring: {text!r}")
		with open(f"/dev/shm/{wrong_ring}", "wb") as f:
			f.write(bytes(65536))
		view3, url3 = start_view(args.dockpose, ["--can-log", log, "--preview", wrong_ring],
								 os.path.join(work, "view3.out"))
		procs.append(view3)
		browser.navigate(url3)
		wait_for("the wrong ring on the page",
				 lambda: "preview ring" in (problem_names(browser) or []), 10)
		text = problem_detail(browser, "preview ring")
		check("not a preview ring" in text, f"a wrong ring is named: preview ring: {text!r}")
		check(view2.poll() is None and view3.poll() is None, "those servers keep running")
	except (AssertionError, RuntimeError, OSError, ImportError, ValueError, KeyError) as e:
		failures.append(f"{type(e).__name__}: {e}")
		print(f"FAIL  {type(e).__name__}: {e}", flush=True)
	finally:
		if browser:
			browser.close()
		for p in procs:
			if p.poll() is None:
				p.send_signal(signal.SIGTERM)
				try:
					p.wait(timeout=10)
				except subprocess.TimeoutExpired:
					p.kill()
		for p in procs[1:]:
			if p.returncode not in (0, None):
				failures.append(f"dockpose view exited {p.returncode}")
		try:
			os.unlink(f"/dev/shm/{wrong_ring}")
		except OSError:
			pass
		if failures:
			for name in ("dockposed.err", "view.out", "view2.out", "view3.out"):
				path = os.path.join(work, name)
				if os.path.exists(path):
					print(f"--- {name}:\n{open(path).read()[-2000:]}")
		else:
			shutil.rmtree(work, ignore_errors=True)
	print(f"{'FAILED' if failures else 'PASSED'}: {len(failures)} failure(s)")
	return 1 if failures else 0


def main():
	p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
	p.add_argument("--dockposed")
	p.add_argument("--dockpose")
	p.add_argument("--chromium", default="chromium")
	p.add_argument("--source", default=os.path.join(os.path.dirname(__file__), "../.."))
	p.add_argument("--shot", nargs=2, metavar=("URL", "PNG"),
				   help="only write a screenshot of the page at URL to PNG")
	p.add_argument("--shot-wait", type=float, default=4.0)
	args = p.parse_args()
	args.source = os.path.abspath(args.source)
	if args.shot:
		profile = tempfile.mkdtemp(prefix="dockpose-view-shot.")
		browser = Browser(args.chromium, profile, 1360, 1100)
		try:
			browser.open(args.shot[0])
			time.sleep(args.shot_wait)
			h = browser.js("document.documentElement.scrollHeight")
			open(args.shot[1], "wb").write(browser.screenshot(
				{"x": 0, "y": 0, "width": 1360, "height": h}))
		finally:
			browser.close()
			shutil.rmtree(profile, ignore_errors=True)
		return 0
	if not (args.dockposed and args.dockpose):
		p.error("--dockposed and --dockpose are needed (or --shot)")
	return run_test(args)


if __name__ == "__main__":
	sys.exit(main())

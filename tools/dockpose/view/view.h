/* SPDX-License-Identifier: MIT */
/*
 * dockpose view: the operator's page (docs/operator-view.md).
 *
 *   dockpose view [--can IFACE | --can-log FILE] [--preview NAME] [--bind ADDR]
 *                 [--port N] [--camera C.json] [--base-id ID]
 *                 [--allow-commands [--key FILE]]
 *
 * A web server (cpp-httplib) on ADDR:N (default 127.0.0.1:8080; --port 0 picks
 * a free port) serving one page (page.html, built into the binary) and:
 *
 *   GET  /                  the page
 *   GET  /api/state         the latest decoded state, JSON (ViewState::stateJson)
 *   GET  /api/events        the same as server-sent events, one per report, at most
 *                           ?max_hz=N a second (the page's frame rate; default 30),
 *                           at least every 100 ms (so age and stale move)
 *   GET  /api/history       the last 30 s of poses (ViewState::historyJson)
 *   GET  /api/preview.bin   the latest preview frame: a 4-byte little-endian
 *                           length, that many bytes of JSON (overlays, size),
 *                           then width x height grey pixels; 204 when none
 *   GET  /api/protocol      names and resolutions from dockpose_can.h
 *   GET  /api/config        what the server was started with (commands allowed, ...)
 *   POST /api/command       (--allow-commands with --can only) one DP_Command;
 *                           with --key FILE signed (DP_CommandAuth, see
 *                           command.h), and the sensor's frames verified with
 *                           the same key before the page shows them
 *
 * The URL is printed on stdout ("dockpose view: http://ADDR:PORT/") once the
 * socket is bound. SIGINT or SIGTERM stop it (exit 0).
 *
 * Threads: main (binds, then runs httplib's accept loop until stopped); the
 * CAN reader thread (follows the log or reads the socket, polls the preview
 * ring every 50 ms and reopens it when it is missing or has stopped moving);
 * a signal thread (sigtimedwait: stops the server); httplib's pool of kHttpThreads
 * workers, which answer requests and each hold one /api/events stream open.
 * Allocates: freely (a host tool), never in the sensor.
 *
 * Built only where cpp-httplib is found (tools/CMakeLists.txt): without it
 * (the aarch64 cross build) `dockpose view` says so and exits 2.
 */
#pragma once

#include <cstdint>
#include <string>

namespace dockpose::tool {

struct ViewArgs {
	std::string can_interface; /* --can */
	std::string can_log; /* --can-log */
	std::string preview = "dockpose-preview";
	std::string bind = "127.0.0.1";
	int port = 8080;
	std::string camera; /* --camera: intrinsics, to draw the target's axes */
	std::string base_id = "0x300";
	bool allow_commands = false;
	std::string key_file; /* --key: the CAN key, to sign commands */
};

/* Workers in httplib's pool: each open page holds one for its event stream. */
constexpr int kHttpThreads = 16;

/* Run the view until SIGINT / SIGTERM; the exit code (2: bad arguments). */
int runView(const ViewArgs &args);

} /* namespace dockpose::tool */

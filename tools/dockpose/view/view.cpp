/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/view/view.h"

#include <httplib.h>
#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "firmware/protocol/dockpose_can.h"
#include "tools/dockpose/view/can_input.h"
#include "tools/dockpose/view/candump.h"
#include "tools/dockpose/view/command.h"
#include "tools/dockpose/view/page.h"
#include "tools/dockpose/view/view_state.h"

namespace dockpose::tool {

namespace {

using nlohmann::json;

/* An event stream sends at least this often (age and stale move without reports). */
constexpr std::chrono::milliseconds kEventsEvery{ 100 };
constexpr double kDefaultEventsHz = 30.0;
/* A signed command waits this long at most for a sensor freshness value it may answer. */
constexpr std::chrono::milliseconds kFreshnessWait{ 300 };

void sendJson(httplib::Response &res, const json &j, int status = 200)
{
	res.status = status;
	res.set_header("Cache-Control", "no-store");
	res.set_content(j.dump(-1, ' ', false, json::error_handler_t::replace), "application/json");
}

} /* namespace */

int runView(const ViewArgs &args)
{
	if (!args.can_interface.empty() && !args.can_log.empty()) {
		std::fprintf(stderr, "dockpose view: --can and --can-log exclude each other\n");
		return 2;
	}
	if (!args.key_file.empty() && (!args.allow_commands || args.can_interface.empty())) {
		std::fprintf(stderr,
			     "dockpose view: --key %s signs commands: it needs --can IFACE "
			     "and --allow-commands\n",
			     args.key_file.c_str());
		return 2;
	}
	if (args.allow_commands && args.can_interface.empty()) {
		std::fprintf(stderr, "dockpose view: --allow-commands needs --can IFACE (a log "
				     "cannot carry a command to the sensor)\n");
		return 2;
	}
	if (args.port < 0 || args.port > 65535) {
		std::fprintf(stderr, "dockpose view: --port %d: not 0..65535\n", args.port);
		return 2;
	}
	char *end = nullptr;
	const unsigned long base_id = std::strtoul(args.base_id.c_str(), &end, 0);
	if (args.base_id.empty() || *end != '\0' || !can::validBaseId(base_id)) {
		std::fprintf(stderr, "dockpose view: --base-id %s: not an identifier up to 0x%X\n",
			     args.base_id.c_str(), can::kMaxBaseId);
		return 2;
	}

	ViewState state(static_cast<std::uint32_t>(base_id));
	if (!args.camera.empty()) {
		const Status camera = state.loadCamera(args.camera);
		if (!camera.isOk()) {
			std::fprintf(stderr, "dockpose view: %s\n", camera.message().c_str());
			return 2;
		}
	}
	CommandSender sender(static_cast<std::uint32_t>(base_id));
	if (!args.key_file.empty()) {
		const Status keyed = useCanKey(args.key_file, &state, &sender);
		if (!keyed.isOk()) {
			std::fprintf(stderr, "dockpose view: --key: %s\n", keyed.message().c_str());
			return 2;
		}
	}
	state.setSource(!args.can_log.empty()	      ? "can-log " + args.can_log
			: !args.can_interface.empty() ? "can " + args.can_interface
						      : "no CAN source (--can or --can-log)");
	if (args.can_log.empty() && args.can_interface.empty())
		state.problem("no CAN source",
			      "start dockpose view with --can IFACE or --can-log FILE",
			      realtimeUs());

	/* SIGINT / SIGTERM go to the signal thread only (blocked here, inherited by all). */
	sigset_t signals;
	sigemptyset(&signals);
	sigaddset(&signals, SIGINT);
	sigaddset(&signals, SIGTERM);
	pthread_sigmask(SIG_BLOCK, &signals, nullptr);
	/* A page closed mid-write must not kill the server. */
	signal(SIGPIPE, SIG_IGN);

	ViewInput input(args.can_log, args.can_interface, args.preview, &state);
	httplib::Server server;
	server.new_task_queue = [] {
		return new httplib::ThreadPool(kHttpThreads);
	};
	std::atomic<bool> stopping{ false };
	std::mutex command_mutex; /* POST /api/command: one command's frames at a time */

	const json config = {
		{ "source", !args.can_log.empty() ? "can-log" : "can" },
		{ "allow_commands", args.allow_commands },
		{ "signed_commands", sender.signing() },
		{ "preview", args.preview },
		{ "camera", !args.camera.empty() },
		{ "base_id", base_id },
	};

	server.Get("/", [](const httplib::Request &, httplib::Response &res) {
		res.set_header("Cache-Control", "no-store");
		res.set_content(kViewPage, "text/html; charset=utf-8");
	});
	server.Get("/api/state", [&](const httplib::Request &, httplib::Response &res) {
		sendJson(res, state.stateJson(realtimeUs()));
	});
	server.Get("/api/history", [&](const httplib::Request &, httplib::Response &res) {
		sendJson(res, state.historyJson(realtimeUs()));
	});
	server.Get("/api/protocol", [](const httplib::Request &, httplib::Response &res) {
		sendJson(res, ViewState::protocolJson());
	});
	server.Get("/api/config", [&](const httplib::Request &, httplib::Response &res) {
		sendJson(res, config);
	});
	server.Get("/api/preview.bin", [&](const httplib::Request &, httplib::Response &res) {
		std::string pixels;
		const json meta = state.previewJson(&pixels);
		res.set_header("Cache-Control", "no-store");
		if (meta.is_null()) {
			res.status = 204;
			return;
		}
		const std::string text = meta.dump();
		std::string body;
		body.reserve(4 + text.size() + pixels.size());
		const auto n = static_cast<std::uint32_t>(text.size());
		for (int i = 0; i < 4; ++i)
			body.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
		body += text;
		body += pixels;
		res.set_content(body, "application/octet-stream");
	});
	server.Get("/api/events", [&](const httplib::Request &req, httplib::Response &res) {
		double max_hz = kDefaultEventsHz;
		if (req.has_param("max_hz")) {
			const double hz = std::atof(req.get_param_value("max_hz").c_str());
			if (hz >= 1.0 && hz <= 240.0)
				max_hz = hz;
		}
		const auto min_gap =
			std::chrono::duration_cast<std::chrono::steady_clock::duration>(
				std::chrono::duration<double>(1.0 / max_hz));
		res.set_header("Cache-Control", "no-store");
		res.set_chunked_content_provider(
			"text/event-stream", [&state, &stopping, min_gap, seen = std::uint64_t{ 0 },
					      last = std::chrono::steady_clock::time_point{}](
						     std::size_t, httplib::DataSink &sink) mutable {
				if (stopping)
					return false;
				/* Thinned: no sooner than min_gap after the previous event. */
				const auto now = std::chrono::steady_clock::now();
				if (now - last < min_gap)
					std::this_thread::sleep_for(min_gap - (now - last));
				seen = state.waitForUpdate(seen, kEventsEvery);
				if (stopping || !sink.is_writable())
					return false;
				last = std::chrono::steady_clock::now();
				const std::string event =
					"data: " +
					state.stateJson(realtimeUs())
						.dump(-1, ' ', false,
						      json::error_handler_t::replace) +
					"\n\n";
				return sink.write(event.data(), event.size());
			});
	});
	server.Post("/api/command", [&](const httplib::Request &req, httplib::Response &res) {
		if (!args.allow_commands || input.socket() == nullptr) {
			sendJson(res,
				 { { "error",
				     "read-only: start with --can IFACE --allow-commands" } },
				 403);
			return;
		}
		const json body = json::parse(req.body, nullptr, false);
		can::CommandData cmd;
		const std::string error = body.is_discarded() ? "the body is not JSON"
							      : commandFromJson(body, &cmd);
		if (!error.empty()) {
			sendJson(res, { { "error", error } }, 400);
			return;
		}
		/* One command at a time, encoded and sent whole: a signed one's two frames must
		 * not interleave with another's, nor go out after a newer one. Signed: the newest
		 * sensor freshness value verified; one the last command answered already is
		 * waited out (the next DP_Auth comes within 100 ms). */
		const std::lock_guard<std::mutex> lock(command_mutex);
		can::RawFrame frames[can::kMaxCommandFrames];
		int count = 0;
		const auto deadline = std::chrono::steady_clock::now() + kFreshnessWait;
		std::uint64_t seen = 0;
		std::string refused = sender.encode(cmd, state.sensorFreshness(),
						    state.commandAliveOnBus(), frames, &count);
		while (!refused.empty() && !stopping &&
		       std::chrono::steady_clock::now() < deadline) {
			seen = state.waitForUpdate(seen, std::chrono::milliseconds(20));
			refused = sender.encode(cmd, state.sensorFreshness(),
						state.commandAliveOnBus(), frames, &count);
		}
		if (!refused.empty()) {
			sendJson(res, { { "error", "not sent: " + refused } }, 503);
			return;
		}
		json reply = { { "signed", sender.signing() } };
		for (int i = 0; i < count; ++i) {
			std::string send_error;
			if (!input.socket()->send(frames[i], &send_error)) {
				sendJson(res, { { "error", send_error } }, 503);
				return;
			}
			state.noteSent(frames[i]);
			reply[i == 0 ? "sent" : "mac_frame"] = candumpFrameText(frames[i]);
		}
		if (!sender.signing() && state.sensorAuthenticates())
			reply["warning"] =
				"the sensor authenticates commands (a CAN key): it refuses "
				"this unsigned one (start the view with --key FILE)";
		sendJson(res, reply);
	});
	server.set_exception_handler(
		[](const httplib::Request &, httplib::Response &res, const std::exception_ptr &ep) {
			std::string what = "unknown";
			try {
				std::rethrow_exception(ep);
			} catch (const std::exception &e) {
				what = e.what();
			} catch (...) {
			}
			sendJson(res, { { "error", "internal: " + what } }, 500);
		});

	int port = args.port;
	if (port == 0) {
		port = server.bind_to_any_port(args.bind);
		if (port < 0) {
			std::fprintf(stderr, "dockpose view: cannot bind %s (any port)\n",
				     args.bind.c_str());
			return 1;
		}
	} else if (!server.bind_to_port(args.bind, port)) {
		std::fprintf(stderr, "dockpose view: cannot bind %s:%d (in use?)\n",
			     args.bind.c_str(), port);
		return 1;
	}
	const bool v6 = args.bind.find(':') != std::string::npos;
	std::printf("dockpose view: http://%s%s%s:%d/\n", v6 ? "[" : "", args.bind.c_str(),
		    v6 ? "]" : "", port);
	std::fflush(stdout);

	input.start();
	/* The signal thread: after SIGINT / SIGTERM it stops the server, again every 200 ms
	 * until the accept loop has ended (a signal before the loop ran is not lost); it ends
	 * with the loop, whatever ended it. */
	std::atomic<bool> served{ false };
	std::thread signal_thread([&] {
		const timespec tick{ 0, 200000000 };
		while (!served) {
			if (sigtimedwait(&signals, nullptr, &tick) > 0) {
				stopping = true;
				state.wakeAll();
			}
			if (stopping)
				server.stop();
		}
	});
	const bool ok = server.listen_after_bind();
	served = true;
	signal_thread.join();
	const bool signalled = stopping;
	stopping = true;
	state.wakeAll();
	input.stop();
	return ok || signalled ? 0 : 1;
}

} /* namespace dockpose::tool */

/* SPDX-License-Identifier: MIT */
/*
 * systemd's notify protocol (sd_notify): READY=1 once the sensor runs,
 * WATCHDOG=1 from the frame loop at twice the watchdog rate (so a hung loop
 * gets the service restarted), STATUS= lines, STOPPING=1. A no-op when
 * NOTIFY_SOCKET is not set (started by hand or by tests) or when disabled in
 * the board file.
 *
 * Allocates: libsystemd may allocate inside sd_notify; called at most a few
 * times per second, never per pixel.
 */
#pragma once

#include <cstdint>

namespace dockpose::firmware {

class SystemdNotifier
{
public:
	explicit SystemdNotifier(bool enabled);

	void ready();
	void stopping();
	/* Free text shown by `systemctl status`. */
	void status(const char *text);
	/* Ping the watchdog if one is configured and half its interval has passed. */
	void watchdog(std::int64_t now_ns);

	bool active() const { return active_; }
	std::int64_t watchdogIntervalNs() const { return watchdog_ns_; }

private:
	bool active_ = false;
	std::int64_t watchdog_ns_ = 0;
	std::int64_t last_ping_ns_ = 0;
};

} /* namespace dockpose::firmware */

/* SPDX-License-Identifier: MIT */
#include "firmware/systemd_notify.h"

#include <cstdlib>
#include <string>

#include <systemd/sd-daemon.h>

namespace dockpose::firmware {

SystemdNotifier::SystemdNotifier(bool enabled)
{
	const char *socket = std::getenv("NOTIFY_SOCKET");
	active_ = enabled && socket && *socket;
	if (!active_)
		return;
	std::uint64_t usec = 0;
	if (sd_watchdog_enabled(0, &usec) > 0)
		watchdog_ns_ = static_cast<std::int64_t>(usec) * 1000;
}

void SystemdNotifier::ready()
{
	if (active_)
		sd_notify(0, "READY=1");
}

void SystemdNotifier::stopping()
{
	if (active_)
		sd_notify(0, "STOPPING=1");
}

void SystemdNotifier::status(const char *text)
{
	if (active_)
		sd_notify(0, (std::string("STATUS=") + text).c_str());
}

void SystemdNotifier::watchdog(std::int64_t now_ns)
{
	if (!active_ || watchdog_ns_ <= 0 || now_ns - last_ping_ns_ < watchdog_ns_ / 2)
		return;
	sd_notify(0, "WATCHDOG=1");
	last_ping_ns_ = now_ns;
}

} /* namespace dockpose::firmware */

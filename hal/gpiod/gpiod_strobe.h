/* SPDX-License-Identifier: MIT */
/*
 * GpiodStrobe: the LED strobe on one GPIO line through libgpiod.
 *
 * Built against libgpiod v1.6 (Debian 12, Raspberry Pi OS 12); a v2 branch
 * (DOCKPOSE_GPIOD_MAJOR >= 2) uses the v2 request API. The v2 branch was
 * only compile-checked against the v2 gpiod.h here, never linked or run.
 *
 * The chip is given as a name ("gpiochip0"), a number ("0"), a path
 * ("/dev/gpiochip0") or a label ("pinctrl-rp1", "gpio-sim.0-node0"): every
 * /dev/gpiochip* is opened and its label compared. The line is requested as
 * an output with the consumer name (shown by gpioinfo), driven off from the
 * request on, with the kernel's active-low flag when active_low, so "on" is
 * always logical 1 and the kernel inverts the physical level.
 *
 * forceOff() is async-signal-safe: it reads the handle from an atomic and
 * calls gpiod_line_set_value (v1.6) / gpiod_line_request_set_value (v2),
 * which in both libraries build the request on the stack and make exactly one
 * ioctl (GPIOHANDLE_SET_LINE_VALUES_IOCTL / GPIO_V2_LINE_SET_VALUES_IOCTL) on
 * the request's fd: no locks, no allocation (checked in libgpiod's
 * lib/core.c v1.6 and lib/line-request.c v2). errno is preserved. close()
 * detaches the handle first and waits for a forceOff running on another
 * thread before releasing the line. forceOff latches: set(true) fails ("was
 * forced off") until the next open(), and a set(true) racing with forceOff on
 * another thread switches off again, so the LED stays off on the way down.
 *
 * After close() the line is released. A real pin controller (pinctrl-rp1,
 * bcm2835) keeps driving the last level, which close() sets to off; gpio-sim
 * returns a released line to its pull (pull-down by default: physical low).
 * When the process dies without close() (SIGKILL) the kernel releases the
 * line the same way: wire the LED driver so that a released or reset pin
 * (its pull) means LED off.
 *
 * Threads: open, set, close from one thread at a time (the StrobeController
 * owns set); forceOff from anywhere, signal handlers included.
 * Allocates: open() and error results allocate; set(), isOn(), forceOff()
 * never.
 */
#pragma once

#include <atomic>
#include <string>
#include <utility>

#include "hal/status.h"
#include "hal/strobe.h"

namespace dockpose::hal {

class GpiodStrobe : public Strobe
{
public:
	/* chip: name, number, path or label; line: offset on the chip (>= 0). */
	GpiodStrobe(std::string chip, int line, bool active_low, std::string consumer = "dockpose");
	explicit GpiodStrobe(const StrobeLine &line, std::string consumer = "dockpose")
		: GpiodStrobe(line.chip, line.line, line.active_low, std::move(consumer))
	{
	}
	~GpiodStrobe() override;

	/* "gpiochip0 [pinctrl-rp1] line 17 (active-low)" once open, else the chip as given. */
	std::string name() const override;
	/* Find the chip, request the line as an output, off. Idempotent when open. */
	Status open() override;
	Status set(bool on) override;
	bool isOn() const override;
	void forceOff() noexcept override;
	void close() override;

private:
	std::string chip_arg_;
	int line_;
	bool active_low_;
	std::string consumer_;
	std::string chip_text_; /* "gpiochip0 [pinctrl-rp1]" once open */

	/* libgpiod objects: struct gpiod_chip, and struct gpiod_line (v1) or
	 * struct gpiod_line_request (v2). handle_ is what forceOff uses. */
	void *chip_ = nullptr;
	std::atomic<void *> handle_{ nullptr };
	std::atomic<int> force_users_{ 0 };
	std::atomic<bool> on_{ false };
	std::atomic<bool> forced_off_{ false };

	static_assert(std::atomic<void *>::is_always_lock_free);
	static_assert(std::atomic<int>::is_always_lock_free);
	static_assert(std::atomic<bool>::is_always_lock_free);
};

} /* namespace dockpose::hal */

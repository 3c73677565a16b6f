/* SPDX-License-Identifier: MIT */
/*
 * Strobe: the GPIO line that switches the infrared LEDs, and the
 * StrobeController that drives it for the frame loop.
 *
 * A Strobe backend only opens, sets and releases one output line. "On" means
 * LEDs lit; active-low wiring is the backend's business. The LED is off after
 * open(), after close(), and after forceOff(), which must be safe to call from
 * a signal handler (one syscall, no locks, no allocation) so fatal-signal
 * paths can switch the LEDs off before the process dies.
 *
 * Allocates: open() may allocate; set(), isOn(), forceOff() never.
 */
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "hal/ring_buffer.h"
#include "hal/status.h"

namespace dockpose::hal {

/* The GPIO line a strobe drives (the gpiod backend; a board's strobe section holds it). */
struct StrobeLine {
	std::string chip; /* chip name ("gpiochip0"), path, or label ("pinctrl-rp1") */
	int line = -1; /* line offset on the chip */
	bool active_low = false; /* the LED is on when the line is low */
};

class Strobe
{
public:
	virtual ~Strobe() = default;
	Strobe() = default;
	Strobe(const Strobe &) = delete;
	Strobe &operator=(const Strobe &) = delete;

	virtual std::string name() const = 0;
	/* Request the line as an output, driven off. */
	virtual Status open() = 0;
	/* Drive the LED on or off. Allocates: never. */
	virtual Status set(bool on) = 0;
	virtual bool isOn() const = 0;
	/* LED off now; async-signal-safe, never fails loudly. */
	virtual void forceOff() noexcept = 0;
	/* LED off, then release the line. Idempotent. */
	virtual void close() = 0;
};

/* How the LEDs were during a frame's exposure. */
enum class Lighting : std::uint8_t {
	Unlit, /* off for the whole exposure */
	Lit, /* on for the whole exposure */
	Mixed, /* switched during the exposure, or not known: do not use the frame */
};

const char *lightingName(Lighting lighting);

/*
 * StrobeController: one thread that owns the timing of a Strobe.
 *
 *  - constant on/off (setOn),
 *  - pulses scheduled at absolute CLOCK_MONOTONIC times (schedulePulse), which
 *    the frame loop aims at predicted exposures to light every other frame,
 *  - a dead-man switch: when the frame loop has not called kick() within the
 *    stall timeout, the LED goes off (and stays off until the next setOn or
 *    pulse after a kick), and stalled() reports it,
 *  - a history of the line's switching times, from which lighting() tells
 *    whether a frame's exposure window was lit, unlit or mixed.
 *
 * Allocates: start() creates the thread; every other call never allocates.
 */
class StrobeController
{
public:
	static constexpr int kMaxPulses = 8;
	static constexpr int kHistory = 64;

	StrobeController(Strobe *strobe, int stall_timeout_ms);
	~StrobeController();
	StrobeController(const StrobeController &) = delete;
	StrobeController &operator=(const StrobeController &) = delete;

	/* LED off, start the timing thread (the stall timer starts now; a mode set
	 * with setOn before start applies once started). stall_timeout_ms <= 0: no
	 * dead-man switch. Error when the LED cannot be switched off. */
	Status start();
	/* Cancel pulses, constant mode off, join the thread, LED off. Idempotent. */
	void stop();

	/* Constant on or off; cancels pending pulses. */
	void setOn(bool on);
	/* Light the LED from start_ns for duration_ns (CLOCK_MONOTONIC). False if the
	 * pulse queue is full, the pulse starts in the past, duration_ns <= 0, or the
	 * controller is stalled. Overlapping pulses light their union. */
	bool schedulePulse(std::int64_t start_ns, std::int64_t duration_ns);
	void cancelPulses();

	/* The frame loop is alive. */
	void kick();
	bool stalled() const { return stalled_.load(std::memory_order_relaxed); }
	std::uint64_t stallCount() const { return stall_count_.load(std::memory_order_relaxed); }

	/* Was the LED lit over [start_ns, end_ns]? Mixed when the history does not
	 * reach back, the window is not over yet, or a switch (with the uncertainty
	 * of the set() call) or a failed set touches it. */
	Lighting lighting(std::int64_t start_ns, std::int64_t end_ns) const;
	bool isOn() const;
	std::uint64_t switchCount() const { return switches_.load(std::memory_order_relaxed); }
	/* Errors from Strobe::set (counted, the last message kept). */
	std::uint64_t errorCount() const { return errors_.load(std::memory_order_relaxed); }
	/* The last Strobe::set error ("" when none). Allocates: the returned string. */
	std::string lastError() const;

private:
	struct Pulse {
		std::int64_t start_ns;
		std::int64_t end_ns;
	};
	/* One Strobe::set, which switched the line somewhere in [before_ns, after_ns]. */
	struct Switch {
		std::int64_t before_ns; /* just before the call */
		std::int64_t after_ns; /* when it returned */
		bool on; /* the level from then on */
		bool known; /* false after a failed set: the level is not known */
	};

	void run();
	/* Stall check, pulse bookkeeping, and drive the line to what it should be now. */
	void update(std::int64_t now_ns); /* with mutex_ held */
	bool wantOn(std::int64_t now_ns) const; /* with mutex_ held */
	std::int64_t nextEventNs(std::int64_t now_ns) const; /* with mutex_ held */
	/* Strobe::set and record it; force: call even when the line is believed there. */
	void drive(bool on, bool force); /* with mutex_ held */

	Strobe *strobe_;
	std::int64_t stall_timeout_ns_; /* <= 0: no dead-man switch */

	mutable std::mutex mutex_;
	std::condition_variable wake_;
	std::thread thread_;
	bool running_ = false;
	bool constant_on_ = false;
	bool line_on_ = false;
	bool line_known_ = false;
	std::int64_t retry_ns_ = 0; /* after a failed set, no new attempt before this */
	std::array<Pulse, kMaxPulses> pulses_{};
	int pulse_count_ = 0;
	RingBuffer<Switch, kHistory> history_; /* oldest first; a full history drops its oldest */
	std::int64_t last_kick_ns_ = 0;
	std::array<char, 160> last_error_{};

	std::atomic<bool> stalled_{ false };
	std::atomic<std::uint64_t> stall_count_{ 0 };
	std::atomic<std::uint64_t> switches_{ 0 };
	std::atomic<std::uint64_t> errors_{ 0 };
};

} /* namespace dockpose::hal */

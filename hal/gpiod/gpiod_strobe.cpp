/* SPDX-License-Identifier: MIT */
/*
 * GpiodStrobe: libgpiod backend of the LED strobe (see gpiod_strobe.h).
 */
#include "hal/gpiod/gpiod_strobe.h"

#include <gpiod.h>
#include <sched.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <utility>
#include <vector>

#ifndef DOCKPOSE_GPIOD_MAJOR
#error "DOCKPOSE_GPIOD_MAJOR must be set (hal/CMakeLists.txt reads it from pkg-config)"
#endif

namespace dockpose::hal {

namespace {

constexpr const char *kDevDir = "/dev";

struct ChipInfo {
	std::string name; /* kernel name, "gpiochip0" */
	std::string label; /* "pinctrl-rp1" */
	unsigned int num_lines = 0;
};

/* Name, label and line count of an open chip. False (errno set) on failure. */
bool chipInfo(gpiod_chip *chip, ChipInfo *out)
{
#if DOCKPOSE_GPIOD_MAJOR >= 2
	gpiod_chip_info *info = gpiod_chip_get_info(chip);
	if (!info)
		return false;
	out->name = gpiod_chip_info_get_name(info);
	out->label = gpiod_chip_info_get_label(info);
	out->num_lines = static_cast<unsigned int>(gpiod_chip_info_get_num_lines(info));
	gpiod_chip_info_free(info);
#else
	out->name = gpiod_chip_name(chip);
	out->label = gpiod_chip_label(chip);
	out->num_lines = gpiod_chip_num_lines(chip);
#endif
	return true;
}

std::string chipText(const ChipInfo &info)
{
	return info.name + " [" + info.label + "]";
}

/* One /dev/gpiochip* entry, opened once to read its label (or why it could not be). */
struct ScannedChip {
	std::string path;
	ChipInfo info;
	int error = 0; /* errno from opening it, 0 when info is valid */
};

bool isNumber(const std::string &s)
{
	return !s.empty() &&
	       std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

/* Every /dev/gpiochip<N>, in the order of N. */
std::vector<ScannedChip> scanChips()
{
	std::vector<ScannedChip> chips;
	std::error_code ec;
	std::filesystem::directory_iterator it(kDevDir, ec);
	for (; !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
		std::string file = it->path().filename().string();
		if (file.rfind("gpiochip", 0) != 0 || !isNumber(file.substr(8)))
			continue;
		ScannedChip chip;
		chip.path = it->path().string();
		chip.info.name = file;
		gpiod_chip *handle = gpiod_chip_open(chip.path.c_str());
		if (!handle) {
			chip.error = errno;
		} else {
			if (!chipInfo(handle, &chip.info))
				chip.error = errno;
			gpiod_chip_close(handle);
		}
		chips.push_back(std::move(chip));
	}
	/* "gpiochip<N>": order by N. */
	std::sort(chips.begin(), chips.end(), [](const ScannedChip &a, const ScannedChip &b) {
		return std::strtoul(a.info.name.c_str() + 8, nullptr, 10) <
		       std::strtoul(b.info.name.c_str() + 8, nullptr, 10);
	});
	return chips;
}

/* " (found: gpiochip0 [pinctrl-rp1], gpiochip1 [permission denied])" or the no-chips hint. */
std::string foundText(const std::vector<ScannedChip> &chips)
{
	if (chips.empty())
		return " (none found: does this kernel have GPIO character devices (CONFIG_GPIO_CDEV)?)";
	std::string text = " (found: ";
	for (std::size_t i = 0; i < chips.size(); i++) {
		if (i)
			text += ", ";
		if (chips[i].error == 0)
			text += chipText(chips[i].info);
		else if (chips[i].error == EACCES || chips[i].error == EPERM)
			text += chips[i].info.name + " [permission denied]";
		else
			text += chips[i].info.name + " [" + std::strerror(chips[i].error) + "]";
	}
	return text + ")";
}

std::string permissionText(const std::string &path)
{
	return "gpio: permission denied opening " + path +
	       " (run as root, or give the user access to it: the gpio group or a udev rule)";
}

/*
 * Open the chip the user named: a path, a number, a /dev name or a label.
 * On failure returns nullptr and sets *error.
 */
gpiod_chip *openChip(const std::string &arg, std::string *error)
{
	bool is_path = arg.find('/') != std::string::npos;
	bool is_name = arg.rfind("gpiochip", 0) == 0 && isNumber(arg.substr(8));
	std::string path;
	if (is_path)
		path = arg;
	else if (isNumber(arg))
		path = std::string(kDevDir) + "/gpiochip" + arg;
	else if (is_name)
		path = std::string(kDevDir) + "/" + arg;

	std::error_code ec;
	if (!is_path && (path.empty() || !std::filesystem::exists(path, ec))) {
		/* Not a device name: look for a chip with that label. */
		std::vector<ScannedChip> chips = scanChips();
		auto it = std::find_if(chips.begin(), chips.end(), [&arg](const ScannedChip &c) {
			return c.error == 0 && (c.info.label == arg || c.info.name == arg);
		});
		if (it == chips.end()) {
			*error = "gpio: no GPIO chip named or labelled \"" + arg + "\"" +
				 foundText(chips);
			return nullptr;
		}
		path = it->path;
	}

	gpiod_chip *chip = gpiod_chip_open(path.c_str());
	if (chip)
		return chip;

	int err = errno;
	switch (err) {
	case ENOENT:
		if (is_path)
			*error = "gpio: no GPIO chip at " + path + foundText(scanChips());
		else
			*error = "gpio: no GPIO chip named or labelled \"" + arg + "\"" +
				 foundText(scanChips());
		break;
	case EACCES:
	case EPERM:
		*error = permissionText(path);
		break;
	case ENOTTY:
	case ENODEV:
	case EISDIR:
	case EINVAL:
		*error = "gpio: " + path + " is not a GPIO character device" +
			 foundText(scanChips());
		break;
	default:
		*error = "gpio: cannot open " + path + ": " + std::strerror(err);
		break;
	}
	return nullptr;
}

/* Who holds a busy line, for the error message. */
std::string consumerOf(gpiod_chip *chip, unsigned int offset)
{
	std::string consumer;
#if DOCKPOSE_GPIOD_MAJOR >= 2
	gpiod_line_info *info = gpiod_chip_get_line_info(chip, offset);
	if (info) {
		const char *c = gpiod_line_info_get_consumer(info);
		if (c)
			consumer = c;
		gpiod_line_info_free(info);
	}
#else
	gpiod_line *line = gpiod_chip_get_line(chip, offset);
	if (line && gpiod_line_update(line) == 0) {
		const char *c = gpiod_line_consumer(line);
		if (c)
			consumer = c;
	}
#endif
	return consumer;
}

/* Drive the line; one ioctl in both library versions, async-signal-safe. */
int setLine(void *handle, unsigned int offset, bool on)
{
#if DOCKPOSE_GPIOD_MAJOR >= 2
	return gpiod_line_request_set_value(static_cast<gpiod_line_request *>(handle), offset,
					    on ? GPIOD_LINE_VALUE_ACTIVE
					       : GPIOD_LINE_VALUE_INACTIVE);
#else
	(void)offset;
	return gpiod_line_set_value(static_cast<gpiod_line *>(handle), on ? 1 : 0);
#endif
}

/*
 * Request the line as an output, off, active-low as asked. Returns the handle
 * for setLine (struct gpiod_line in v1, struct gpiod_line_request in v2), or
 * nullptr with errno set.
 */
void *requestLine(gpiod_chip *chip, unsigned int offset, bool active_low,
		  const std::string &consumer)
{
#if DOCKPOSE_GPIOD_MAJOR >= 2
	gpiod_line_settings *settings = gpiod_line_settings_new();
	gpiod_line_config *line_config = gpiod_line_config_new();
	gpiod_request_config *request_config = gpiod_request_config_new();
	gpiod_line_request *request = nullptr;
	int err = ENOMEM;
	if (settings && line_config && request_config) {
		if (gpiod_line_settings_set_direction(settings, GPIOD_LINE_DIRECTION_OUTPUT) == 0 &&
		    gpiod_line_settings_set_output_value(settings, GPIOD_LINE_VALUE_INACTIVE) ==
			    0) {
			gpiod_line_settings_set_active_low(settings, active_low);
			if (gpiod_line_config_add_line_settings(line_config, &offset, 1,
								settings) == 0) {
				gpiod_request_config_set_consumer(request_config, consumer.c_str());
				request =
					gpiod_chip_request_lines(chip, request_config, line_config);
			}
		}
		err = errno;
	}
	if (request_config)
		gpiod_request_config_free(request_config);
	if (line_config)
		gpiod_line_config_free(line_config);
	if (settings)
		gpiod_line_settings_free(settings);
	errno = err;
	return request;
#else
	gpiod_line *line = gpiod_chip_get_line(chip, offset);
	if (!line)
		return nullptr;
	gpiod_line_request_config config{};
	config.consumer = consumer.c_str();
	config.request_type = GPIOD_LINE_REQUEST_DIRECTION_OUTPUT;
	config.flags = active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
	if (gpiod_line_request(line, &config, 0) < 0)
		return nullptr;
	return line;
#endif
}

void releaseLine(void *handle)
{
#if DOCKPOSE_GPIOD_MAJOR >= 2
	gpiod_line_request_release(static_cast<gpiod_line_request *>(handle));
#else
	gpiod_line_release(static_cast<gpiod_line *>(handle));
#endif
}

} /* namespace */

GpiodStrobe::GpiodStrobe(std::string chip, int line, bool active_low, std::string consumer)
	: chip_arg_(std::move(chip)),
	  line_(line),
	  active_low_(active_low),
	  consumer_(std::move(consumer))
{
}

GpiodStrobe::~GpiodStrobe()
{
	close();
}

std::string GpiodStrobe::name() const
{
	std::string text = chip_text_.empty() ? "gpio \"" + chip_arg_ + "\"" : chip_text_;
	text += " line " + std::to_string(line_);
	if (active_low_)
		text += " (active-low)";
	return text;
}

Status GpiodStrobe::open()
{
	if (handle_.load())
		return Status::ok();
	if (line_ < 0)
		return Status::error("gpio: line " + std::to_string(line_) +
				     " is not a valid line offset (0 or more)");
	if (chip_arg_.empty())
		return Status::error("gpio: no GPIO chip given");
	if (consumer_.empty())
		return Status::error("gpio: empty consumer name");

	std::string error;
	gpiod_chip *chip = openChip(chip_arg_, &error);
	if (!chip)
		return Status::error(error);

	ChipInfo info;
	if (!chipInfo(chip, &info)) {
		int err = errno;
		gpiod_chip_close(chip);
		return Status::error("gpio: cannot read chip information of " + chip_arg_ + ": " +
				     std::strerror(err));
	}
	std::string text = chipText(info);
	unsigned int offset = static_cast<unsigned int>(line_);
	if (offset >= info.num_lines) {
		gpiod_chip_close(chip);
		return Status::error("gpio: " + text + " has " + std::to_string(info.num_lines) +
				     " lines; line " + std::to_string(line_) + " does not exist");
	}

	void *handle = requestLine(chip, offset, active_low_, consumer_);
	if (!handle) {
		int err = errno;
		std::string where = "line " + std::to_string(line_) + " on " + info.name;
		std::string message;
		if (err == EBUSY) {
			std::string consumer = consumerOf(chip, offset);
			message = "gpio: " + where + " is busy (used by " +
				  (consumer.empty()
					   ? std::string("an unnamed consumer or the kernel")
					   : "\"" + consumer + "\"") +
				  ")";
		} else if (err == EACCES || err == EPERM) {
			message = "gpio: permission denied requesting " + where + " (/dev/" +
				  info.name + ")";
		} else {
			message = "gpio: cannot request " + where +
				  " as an output: " + std::strerror(err);
		}
		gpiod_chip_close(chip);
		return Status::error(message);
	}

	chip_ = chip;
	chip_text_ = text;
	on_.store(false);
	forced_off_.store(false);
	handle_.store(handle);
	return Status::ok();
}

Status GpiodStrobe::set(bool on)
{
	void *handle = handle_.load();
	if (!handle)
		return Status::error("gpio: " + name() + " is not open");
	if (on && forced_off_.load())
		return Status::error("gpio: " + name() + " was forced off");
	if (setLine(handle, static_cast<unsigned int>(line_), on) < 0) {
		int err = errno;
		return Status::error("gpio: cannot set " + name() + ": " + std::strerror(err));
	}
	on_.store(on);
	/* A forceOff on another thread between the check and the ioctl must win. */
	if (on && forced_off_.load()) {
		(void)setLine(handle, static_cast<unsigned int>(line_), false);
		on_.store(false);
		return Status::error("gpio: " + name() + " was forced off");
	}
	return Status::ok();
}

bool GpiodStrobe::isOn() const
{
	return on_.load();
}

void GpiodStrobe::forceOff() noexcept
{
	int saved_errno = errno;
	forced_off_.store(true);
	/* Announce first, then look: close() waits for us once it has taken the handle. */
	force_users_.fetch_add(1);
	void *handle = handle_.load();
	if (handle && setLine(handle, static_cast<unsigned int>(line_), false) == 0)
		on_.store(false);
	force_users_.fetch_sub(1);
	errno = saved_errno;
}

void GpiodStrobe::close()
{
	void *handle = handle_.exchange(nullptr);
	if (handle) {
		/* A forceOff on another thread may still use the handle. */
		while (force_users_.load() != 0)
			sched_yield();
		(void)setLine(handle, static_cast<unsigned int>(line_), false);
		on_.store(false);
		releaseLine(handle);
	}
	if (chip_) {
		gpiod_chip_close(static_cast<gpiod_chip *>(chip_));
		chip_ = nullptr;
	}
	chip_text_.clear();
}

} /* namespace dockpose::hal */

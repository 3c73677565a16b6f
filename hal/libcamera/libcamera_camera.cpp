/* SPDX-License-Identifier: MIT */
/*
 * LibcameraCamera: hal::Camera on libcamera. See libcamera_camera.h.
 */
#include "hal/libcamera/libcamera_camera.h"

#include <poll.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <utility>

#include <libcamera/camera.h>
#include <libcamera/camera_manager.h>
#include <libcamera/control_ids.h>
#include <libcamera/controls.h>
#include <libcamera/formats.h>
#include <libcamera/framebuffer.h>
#include <libcamera/framebuffer_allocator.h>
#include <libcamera/geometry.h>
#include <libcamera/pixel_format.h>
#include <libcamera/request.h>
#include <libcamera/stream.h>

#include "hal/clock.h"
#include "hal/frame_queue.h"
#include "hal/libcamera/libcamera_compat.h"

namespace dockpose::hal {

namespace {

/* Runs its function when it goes out of scope (configure()'s one cleanup). */
template<typename F>
class ScopeExit
{
public:
	explicit ScopeExit(F f)
		: f_(std::move(f))
	{
	}
	~ScopeExit() { f_(); }
	ScopeExit(const ScopeExit &) = delete;
	ScopeExit &operator=(const ScopeExit &) = delete;

private:
	F f_;
};

namespace lc = libcamera;

constexpr std::uint32_t fourcc(char a, char b, char c, char d)
{
	return static_cast<std::uint32_t>(static_cast<unsigned char>(a)) |
	       (static_cast<std::uint32_t>(static_cast<unsigned char>(b)) << 8) |
	       (static_cast<std::uint32_t>(static_cast<unsigned char>(c)) << 16) |
	       (static_cast<std::uint32_t>(static_cast<unsigned char>(d)) << 24);
}

struct FourccLayout {
	std::uint32_t fourcc;
	PixelLayout layout;
};

/* Formats with an 8-bit intensity plane first, by libcamera (DRM) fourcc. */
constexpr std::array<FourccLayout, 18> kFourccLayouts{ {
	{ fourcc('R', '8', ' ', ' '), PixelLayout::Gray8 }, /* R8 (V4L2 GREY) */
	{ fourcc('Y', 'U', '1', '2'), PixelLayout::YUV420 }, /* YUV420 */
	{ fourcc('Y', 'V', '1', '2'), PixelLayout::YUV420 }, /* YVU420: same Y plane */
	{ fourcc('Y', 'U', '1', '6'), PixelLayout::YUV420 }, /* YUV422 planar: same Y plane */
	{ fourcc('N', 'V', '1', '2'), PixelLayout::NV12 },
	{ fourcc('N', 'V', '2', '1'), PixelLayout::NV21 },
	{ fourcc('N', 'V', '1', '6'), PixelLayout::NV12 }, /* NV16: same Y plane */
	{ fourcc('N', 'V', '6', '1'), PixelLayout::NV21 }, /* NV61: same Y plane */
	{ fourcc('Y', 'U', 'Y', 'V'), PixelLayout::YUYV },
	{ fourcc('Y', 'V', 'Y', 'U'), PixelLayout::YUYV }, /* YVYU: Y at even bytes too */
	{ fourcc('U', 'Y', 'V', 'Y'), PixelLayout::UYVY },
	{ fourcc('V', 'Y', 'U', 'Y'), PixelLayout::UYVY }, /* VYUY: Y at odd bytes too */
	{ fourcc('R', 'G', '2', '4'), PixelLayout::RGB888 }, /* RGB888: bytes B, G, R */
	{ fourcc('B', 'G', '2', '4'), PixelLayout::BGR888 }, /* BGR888: bytes R, G, B */
	{ fourcc('X', 'R', '2', '4'), PixelLayout::XRGB8888 }, /* bytes B, G, R, X */
	{ fourcc('A', 'R', '2', '4'), PixelLayout::XRGB8888 }, /* ARGB8888: bytes B, G, R, A */
	{ fourcc('X', 'B', '2', '4'), PixelLayout::XBGR8888 }, /* bytes R, G, B, X */
	{ fourcc('A', 'B', '2', '4'), PixelLayout::XBGR8888 }, /* ABGR8888: bytes R, G, B, A */
} };

static_assert(fourcc('R', '8', ' ', ' ') == lc::formats::R8.fourcc());
static_assert(fourcc('Y', 'U', '1', '2') == lc::formats::YUV420.fourcc());
static_assert(fourcc('Y', 'V', '1', '2') == lc::formats::YVU420.fourcc());
static_assert(fourcc('Y', 'U', '1', '6') == lc::formats::YUV422.fourcc());
static_assert(fourcc('N', 'V', '1', '2') == lc::formats::NV12.fourcc());
static_assert(fourcc('N', 'V', '2', '1') == lc::formats::NV21.fourcc());
static_assert(fourcc('N', 'V', '1', '6') == lc::formats::NV16.fourcc());
static_assert(fourcc('N', 'V', '6', '1') == lc::formats::NV61.fourcc());
static_assert(fourcc('Y', 'U', 'Y', 'V') == lc::formats::YUYV.fourcc());
static_assert(fourcc('Y', 'V', 'Y', 'U') == lc::formats::YVYU.fourcc());
static_assert(fourcc('U', 'Y', 'V', 'Y') == lc::formats::UYVY.fourcc());
static_assert(fourcc('V', 'Y', 'U', 'Y') == lc::formats::VYUY.fourcc());
static_assert(fourcc('R', 'G', '2', '4') == lc::formats::RGB888.fourcc());
static_assert(fourcc('B', 'G', '2', '4') == lc::formats::BGR888.fourcc());
static_assert(fourcc('X', 'R', '2', '4') == lc::formats::XRGB8888.fourcc());
static_assert(fourcc('A', 'R', '2', '4') == lc::formats::ARGB8888.fourcc());
static_assert(fourcc('X', 'B', '2', '4') == lc::formats::XBGR8888.fourcc());
static_assert(fourcc('A', 'B', '2', '4') == lc::formats::ABGR8888.fourcc());

constexpr int kMaxRequests = 16; /* FrameQueue capacity */
constexpr std::size_t kMaxReadyFrames = 1; /* completed frames waiting for the frame thread */

std::string joinIds(const std::vector<std::string> &ids)
{
	std::string s;
	for (const auto &id : ids) {
		if (!s.empty())
			s += ", ";
		s += id;
	}
	return s;
}

std::string errnoText(int err)
{
	return std::strerror(err < 0 ? -err : err);
}

/*
 * The process's one CameraManager (libcamera aborts on a second one), started
 * by the first user and stopped when the last one goes.
 */
struct SharedManager {
	std::mutex mutex;
	std::unique_ptr<lc::CameraManager> manager;
	int users = 0;
};

SharedManager &sharedManager()
{
	static SharedManager shared;
	return shared;
}

Status acquireManager(lc::CameraManager **out)
{
	SharedManager &s = sharedManager();
	std::lock_guard lock(s.mutex);
	if (!s.manager) {
		auto manager = std::make_unique<lc::CameraManager>();
		const int ret = manager->start();
		/*
		 * -ENODEV: no media device at all. libcamera's sysfs enumerator (a
		 * libcamera built without udev, as scripts/libcamera-build's) fails
		 * the start then, where the udev one starts with no camera: the same
		 * situation, so the same message.
		 */
		if (ret == -ENODEV) {
			std::size_t none = 0;
			return Status::error(selectCamera({}, "", 0, &none).message() +
					     " (camera manager: " + errnoText(ret) + ")");
		}
		if (ret < 0)
			return Status::error("libcamera: camera manager failed to start: " +
					     errnoText(ret));
		s.manager = std::move(manager);
	}
	++s.users;
	*out = s.manager.get();
	return Status::ok();
}

void releaseManager()
{
	SharedManager &s = sharedManager();
	std::lock_guard lock(s.mutex);
	if (s.users > 0 && --s.users == 0 && s.manager) {
		s.manager->stop();
		s.manager.reset();
	}
}

/* exposure_us and analogue gain in one word, so readers never see half an update. */
std::uint64_t packControls(std::int32_t exposure_us, float gain)
{
	return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(exposure_us)) << 32) |
	       std::bit_cast<std::uint32_t>(gain);
}

std::pair<std::int32_t, float> unpackControls(std::uint64_t packed)
{
	return { static_cast<std::int32_t>(static_cast<std::uint32_t>(packed >> 32)),
		 std::bit_cast<float>(static_cast<std::uint32_t>(packed & 0xffffffffu)) };
}

std::string sizesText(const lc::StreamFormats &formats, const lc::PixelFormat &format)
{
	const std::vector<lc::Size> sizes = formats.sizes(format);
	if (!sizes.empty() && sizes.size() <= 16) {
		std::string s;
		for (const auto &size : sizes) {
			if (!s.empty())
				s += ", ";
			s += size.toString();
		}
		return s;
	}
	return formats.range(format).toString();
}

} /* namespace */

/* -------------------------------------------------------------------------- */
/* Pure helpers */

std::optional<PixelLayout> pixelLayoutForFourcc(std::uint32_t fourcc, std::uint64_t modifier)
{
	if (modifier != 0)
		return std::nullopt;
	for (const auto &entry : kFourccLayouts)
		if (entry.fourcc == fourcc)
			return entry.layout;
	return std::nullopt;
}

int pixelLayoutCost(PixelLayout layout)
{
	switch (layout) {
	case PixelLayout::Gray8:
		return 0;
	case PixelLayout::YUV420:
	case PixelLayout::NV12:
	case PixelLayout::NV21:
		return 1;
	case PixelLayout::YUYV:
	case PixelLayout::UYVY:
		return 2;
	case PixelLayout::RGB888:
	case PixelLayout::BGR888:
	case PixelLayout::XRGB8888:
	case PixelLayout::XBGR8888:
		return 3;
	}
	return 4;
}

Status selectCamera(const std::vector<std::string> &ids, const std::string &id, int index,
		    std::size_t *chosen)
{
	if (ids.empty())
		return Status::error(
			"libcamera: no cameras found (is the sensor connected and enabled, "
			"e.g. camera_auto_detect=1 / dtoverlay=imx296?)");
	if (!id.empty()) {
		const auto it = std::find(ids.begin(), ids.end(), id);
		if (it == ids.end())
			return Status::error("libcamera: no camera with id \"" + id +
					     "\" (cameras: " + joinIds(ids) + ")");
		*chosen = static_cast<std::size_t>(it - ids.begin());
		return Status::ok();
	}
	if (index < 0 || static_cast<std::size_t>(index) >= ids.size())
		return Status::error("libcamera: camera index " + std::to_string(index) +
				     " out of range (" + std::to_string(ids.size()) +
				     (ids.size() == 1 ? " camera: " : " cameras: ") + joinIds(ids) +
				     ")");
	*chosen = static_cast<std::size_t>(index);
	return Status::ok();
}

Status checkCameraConfig(const CameraConfig &config)
{
	if (config.buffer_count < 2 || config.buffer_count > kMaxRequests)
		return Status::error("libcamera: buffer_count " +
				     std::to_string(config.buffer_count) + " out of range (2.." +
				     std::to_string(kMaxRequests) + ")");
	if (config.width < 0 || config.height < 0 || (config.width == 0) != (config.height == 0))
		return Status::error("libcamera: frame size " + std::to_string(config.width) + "x" +
				     std::to_string(config.height) +
				     " invalid (both > 0, or both 0 for the sensor's default)");
	if (config.exposure_us <= 0)
		return Status::error("libcamera: exposure_us " +
				     std::to_string(config.exposure_us) + " must be > 0");
	if (!std::isfinite(config.analogue_gain) || config.analogue_gain < 1.0)
		return Status::error("libcamera: analogue_gain " +
				     std::to_string(config.analogue_gain) + " must be >= 1.0");
	const int duration_us = config.frameDurationUs();
	if (duration_us < 0)
		return Status::error("libcamera: frame_rate_hz " +
				     std::to_string(config.frame_rate_hz) + " must be >= 0");
	if (duration_us > 0 && config.exposure_us > duration_us)
		return Status::error(
			"libcamera: exposure_us " + std::to_string(config.exposure_us) +
			" exceeds the frame duration " + std::to_string(duration_us) +
			" us (frame_rate_hz " + std::to_string(config.frame_rate_hz) + ")");
	return Status::ok();
}

/* -------------------------------------------------------------------------- */
/* Impl */

class LibcameraCamera::Impl
{
public:
	Impl();
	~Impl();
	Impl(const Impl &) = delete;
	Impl &operator=(const Impl &) = delete;

	Status configure(const CameraConfig &config);
	/* configure()'s steps; each records its failure with fail(), configure() tears down. */
	Status acquireCamera(const CameraConfig &config);
	Status chooseFormat(const CameraConfig &config);
	Status allocateBuffers();
	void probeControls();
	Status start();
	void stop();
	/* Everything configure() built; the CameraManager reference too when release_manager. */
	void teardown(bool release_manager);

	WaitResult waitFrame(Frame *frame, int timeout_ms);
	void releaseFrame(const Frame &frame);
	Status setControls(int exposure_us, double analogue_gain);

	Status fail(std::string message);
	std::string lastError() const;

	/* Slot (= request = buffer) states. */
	enum : int {
		kIdle,
		kQueued,
		kReady,
		kHeld
	};

	struct Slot {
		std::unique_ptr<lc::Request> request;
		lc::FrameBuffer *buffer = nullptr;
		const std::uint8_t *plane = nullptr; /* first plane, mapped */
		std::vector<std::uint8_t> intensity; /* converted frame (non-zero-copy formats) */
		std::atomic<int> state{ kIdle };
	};

	struct Mapping {
		int fd = -1;
		void *address = nullptr;
		std::size_t length = 0;
	};

	/* libcamera's thread. */
	void requestCompleted(lc::Request *request);
	void cameraDisconnected();

	void wake();
	void drainEventFd();
	bool queueSlot(std::size_t index); /* requeue_mutex_ held, running_ */
	void recycleFromCallback(std::int32_t index);
	void requeueIdle(); /* frame thread */
	void applyPendingControls(lc::Request *request);
	bool fillFrame(std::size_t index, Frame *frame);
	void drainQueue();
	Status mapBuffers(const std::vector<std::unique_ptr<lc::FrameBuffer>> &buffers,
			  std::size_t count);

private:
	friend class LibcameraCamera; /* its accessors read the configuration */

	/* Configuration (control thread). */
	lc::CameraManager *manager_ = nullptr;
	std::shared_ptr<lc::Camera> camera_;
	bool acquired_ = false;
	bool connected_ = false;
	std::string camera_id_;
	std::unique_ptr<lc::CameraConfiguration> config_;
	lc::Stream *stream_ = nullptr;
	std::unique_ptr<lc::FrameBufferAllocator> allocator_;
	std::vector<Mapping> mappings_;
	std::unique_ptr<Slot[]> slots_;
	std::size_t slot_count_ = 0;
	bool configured_ = false;
	bool started_ = false;
	CameraConfig camera_config_;

	PixelLayout layout_ = PixelLayout::Gray8;
	std::string format_name_;
	int width_ = 0;
	int height_ = 0;
	int stride_ = 0;
	std::size_t frame_bytes_ = 0; /* bytes of the first plane a frame needs */

	bool has_ae_enable_ = false;
	bool has_exposure_ = false;
	bool has_gain_ = false;
	bool has_frame_duration_ = false;
	compat::ManualModes manual_modes_; /* libcamera >= 0.5 */

	/* Shared between threads. */
	int event_fd_ = -1;
	FrameQueue<kMaxRequests> queue_;
	std::mutex
		requeue_mutex_; /* orders queueRequest() against stop(); never waited on by libcamera's thread */
	std::atomic<bool> running_{ false };
	std::atomic<bool> disconnected_{ false };
	std::atomic<bool> recycle_pending_{ false };
	std::atomic<std::uint64_t> controls_packed_{ 0 };
	std::atomic<std::uint32_t> controls_generation_{ 0 };
	std::atomic<std::uint32_t> applied_generation_{ 0 };
	std::atomic<std::uint64_t> frames_{ 0 };
	std::atomic<std::uint64_t> dropped_{ 0 };
	std::atomic<std::uint64_t> errors_{ 0 };
	std::atomic<std::uint64_t> requests_queued_{ 0 };
	std::atomic<std::uint64_t> queue_failures_{ 0 };

	mutable std::mutex error_mutex_;
	std::string last_error_;
};

LibcameraCamera::Impl::Impl()
{
	event_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	controls_packed_.store(packControls(camera_config_.exposure_us,
					    static_cast<float>(camera_config_.analogue_gain)));
}

LibcameraCamera::Impl::~Impl()
{
	teardown(true);
	if (event_fd_ >= 0)
		::close(event_fd_);
}

Status LibcameraCamera::Impl::fail(std::string message)
{
	{
		std::lock_guard lock(error_mutex_);
		last_error_ = message;
	}
	return Status::error(std::move(message));
}

std::string LibcameraCamera::Impl::lastError() const
{
	if (disconnected_.load())
		return "libcamera: camera \"" + camera_id_ + "\" unplugged";
	std::lock_guard lock(error_mutex_);
	return last_error_;
}

void LibcameraCamera::Impl::wake()
{
	const std::uint64_t one = 1;
	/* Non-blocking; fails only if the counter would overflow, and then the fd is readable anyway. */
	if (::write(event_fd_, &one, sizeof(one)) < 0) {
	}
}

void LibcameraCamera::Impl::drainEventFd()
{
	std::uint64_t count = 0;
	if (::read(event_fd_, &count, sizeof(count)) < 0) {
	}
}

Status
LibcameraCamera::Impl::mapBuffers(const std::vector<std::unique_ptr<lc::FrameBuffer>> &buffers,
				  std::size_t count)
{
	for (std::size_t i = 0; i < count; ++i) {
		const lc::FrameBuffer *buffer = buffers[i].get();
		const auto &planes = buffer->planes();
		if (planes.empty())
			return fail("libcamera: buffer " + std::to_string(i) + " has no planes");

		/* Map each dmabuf once, as a whole; planes sharing an fd are offsets into it. */
		for (const auto &plane : planes) {
			const int fd = plane.fd.get();
			if (fd < 0)
				return fail("libcamera: buffer " + std::to_string(i) +
					    " has a plane without a dmabuf");
			const bool mapped =
				std::any_of(mappings_.begin(), mappings_.end(),
					    [fd](const Mapping &m) { return m.fd == fd; });
			if (mapped)
				continue;
			std::size_t length = 0;
			const off_t end = ::lseek(fd, 0, SEEK_END);
			if (end > 0) {
				length = static_cast<std::size_t>(end);
			} else {
				for (const auto &p : planes)
					if (p.fd.get() == fd)
						length = std::max<std::size_t>(
							length,
							static_cast<std::size_t>(
								p.offset == lc::FrameBuffer::Plane::
											kInvalidOffset
									? 0
									: p.offset) +
								p.length);
			}
			void *address = ::mmap(nullptr, length, PROT_READ, MAP_SHARED, fd, 0);
			if (address == MAP_FAILED)
				return fail("libcamera: mmap of buffer " + std::to_string(i) +
					    " (" + std::to_string(length) +
					    " bytes) failed: " + errnoText(errno));
			mappings_.push_back(Mapping{ fd, address, length });
		}

		const auto &first = planes[0];
		const auto mapping =
			std::find_if(mappings_.begin(), mappings_.end(),
				     [&first](const Mapping &m) { return m.fd == first.fd.get(); });
		const std::size_t offset =
			first.offset == lc::FrameBuffer::Plane::kInvalidOffset ? 0 : first.offset;
		if (offset + first.length > mapping->length)
			return fail("libcamera: plane 0 of buffer " + std::to_string(i) +
				    " (offset " + std::to_string(offset) + ", " +
				    std::to_string(first.length) +
				    " bytes) lies outside its dmabuf (" +
				    std::to_string(mapping->length) + " bytes)");
		if (first.length < frame_bytes_)
			return fail("libcamera: plane 0 of buffer " + std::to_string(i) +
				    " holds " + std::to_string(first.length) + " bytes, a " +
				    std::to_string(width_) + "x" + std::to_string(height_) + " " +
				    format_name_ + " frame with stride " + std::to_string(stride_) +
				    " needs " + std::to_string(frame_bytes_));
		slots_[i].plane = static_cast<const std::uint8_t *>(mapping->address) + offset;
	}
	return Status::ok();
}

/* configure(), step 1: pick the camera by id or index, acquire it, connect its signals. */
Status LibcameraCamera::Impl::acquireCamera(const CameraConfig &config)
{
	/* Pick the camera. */
	std::vector<std::string> ids;
	for (const auto &camera : manager_->cameras())
		ids.push_back(camera->id());
	std::sort(ids.begin(), ids.end());
	std::size_t chosen = 0;
	if (Status s = selectCamera(ids, config.id, config.index, &chosen); !s)
		return fail(s.message());
	camera_id_ = ids[chosen];
	camera_ = manager_->get(camera_id_);
	if (!camera_)
		return fail("libcamera: camera \"" + camera_id_ + "\" disappeared");
	if (const int ret = camera_->acquire(); ret < 0)
		return fail("libcamera: cannot acquire camera \"" + camera_id_ + "\"" +
			    (ret == -EBUSY ? " (in use by another process?)" : "") + ": " +
			    errnoText(ret));
	acquired_ = true;
	camera_->requestCompleted.connect(this, &Impl::requestCompleted);
	camera_->disconnected.connect(this, &Impl::cameraDisconnected);
	connected_ = true;
	return Status::ok();
}

/*
 * configure(), step 2: one processed stream in the cheapest format with an
 * 8-bit intensity plane, at the asked size; the camera configured with it.
 */
Status LibcameraCamera::Impl::chooseFormat(const CameraConfig &config)
{
	for (const lc::StreamRole role :
	     { lc::StreamRole::VideoRecording, lc::StreamRole::Viewfinder }) {
		const std::vector<lc::StreamRole> roles{ role };
		config_ = camera_->generateConfiguration(roles);
		if (config_ && !config_->empty())
			break;
	}
	if (!config_ || config_->empty())
		return fail("libcamera: camera \"" + camera_id_ + "\" offers no processed stream");
	lc::StreamConfiguration &stream_config = config_->at(0);
	const std::vector<lc::PixelFormat> offered = stream_config.formats().pixelformats();
	std::optional<lc::PixelFormat> best;
	int best_cost = std::numeric_limits<int>::max();
	for (const auto &format : offered) {
		const auto layout = pixelLayoutForFourcc(format.fourcc(), format.modifier());
		if (!layout)
			continue;
		const int cost = pixelLayoutCost(*layout);
		/* Ties: the pipeline's own default first, else the order offered. */
		if (cost < best_cost ||
		    (cost == best_cost && format == stream_config.pixelFormat)) {
			best = format;
			best_cost = cost;
		}
	}
	if (!best) {
		std::string names;
		for (const auto &format : offered)
			names += (names.empty() ? "" : ", ") + format.toString();
		return fail("libcamera: camera \"" + camera_id_ +
			    "\" offers no format with an 8-bit intensity plane (offers: " + names +
			    ")");
	}
	stream_config.pixelFormat = *best;
	if (config.width > 0)
		stream_config.size = lc::Size(static_cast<unsigned int>(config.width),
					      static_cast<unsigned int>(config.height));
	stream_config.bufferCount = static_cast<unsigned int>(config.buffer_count);

	if (config_->validate() == lc::CameraConfiguration::Invalid)
		return fail("libcamera: camera \"" + camera_id_ + "\" rejects the configuration " +
			    stream_config.toString());
	const auto layout = pixelLayoutForFourcc(stream_config.pixelFormat.fourcc(),
						 stream_config.pixelFormat.modifier());
	if (!layout)
		return fail("libcamera: camera \"" + camera_id_ + "\" adjusted the format to " +
			    stream_config.pixelFormat.toString() +
			    ", which has no 8-bit intensity plane");
	if (config.width > 0 &&
	    (stream_config.size.width != static_cast<unsigned int>(config.width) ||
	     stream_config.size.height != static_cast<unsigned int>(config.height))) {
		return fail("libcamera: camera \"" + camera_id_ + "\" cannot deliver " +
			    std::to_string(config.width) + "x" + std::to_string(config.height) +
			    " " + best->toString() + " (nearest " + stream_config.size.toString() +
			    "; sizes: " +
			    sizesText(stream_config.formats(), stream_config.pixelFormat) + ")");
	}
	if (const int ret = camera_->configure(config_.get()); ret < 0)
		return fail("libcamera: configuring camera \"" + camera_id_ + "\" as " +
			    stream_config.toString() + " failed: " + errnoText(ret));

	layout_ = *layout;
	format_name_ = stream_config.pixelFormat.toString();
	width_ = static_cast<int>(stream_config.size.width);
	height_ = static_cast<int>(stream_config.size.height);
	stride_ = static_cast<int>(stream_config.stride);
	stream_ = stream_config.stream();
	if (stride_ < minStrideBytes(layout_, width_))
		return fail("libcamera: stream stride " + std::to_string(stride_) +
			    " is too small for " + std::to_string(width_) + " " + format_name_ +
			    " pixels");
	frame_bytes_ = static_cast<std::size_t>(stride_) * static_cast<std::size_t>(height_ - 1) +
		       static_cast<std::size_t>(minStrideBytes(layout_, width_));
	return Status::ok();
}

/* configure(), step 3: buffers, their mappings and one request each, once. */
Status LibcameraCamera::Impl::allocateBuffers()
{
	allocator_ = std::make_unique<lc::FrameBufferAllocator>(camera_);
	const int allocated = allocator_->allocate(stream_);
	if (allocated <= 0)
		return fail("libcamera: allocating buffers for camera \"" + camera_id_ +
			    "\" failed: " +
			    (allocated < 0 ? errnoText(allocated) : std::string("no buffers")));
	const auto &buffers = allocator_->buffers(stream_);
	slot_count_ = std::min<std::size_t>(buffers.size(), kMaxRequests);
	slots_ = std::make_unique<Slot[]>(slot_count_);
	if (Status s = mapBuffers(buffers, slot_count_); !s)
		return s;
	for (std::size_t i = 0; i < slot_count_; ++i) {
		Slot &slot = slots_[i];
		slot.buffer = buffers[i].get();
		slot.request = camera_->createRequest(i);
		if (!slot.request)
			return fail("libcamera: cannot create request " + std::to_string(i));
		if (const int ret = slot.request->addBuffer(stream_, slot.buffer); ret < 0)
			return fail("libcamera: cannot add buffer " + std::to_string(i) +
				    " to its request: " + errnoText(ret));
		if (!isZeroCopy(layout_))
			slot.intensity.assign(static_cast<std::size_t>(width_) *
						      static_cast<std::size_t>(height_),
					      0);
	}
	return Status::ok();
}

/* configure(), step 4: which of the controls dockpose sets the camera lists. */
void LibcameraCamera::Impl::probeControls()
{
	/*
	 * find(), not count(): ControlInfoMap::count(id) only asks the id map, and
	 * pipelines such as vimc build their map over libcamera's global id map
	 * (controls::controls), so count() says 1 for every control libcamera knows.
	 */
	const lc::ControlInfoMap &controls = camera_->controls();
	const auto lists = [&controls](const lc::ControlId &control) {
		return controls.find(control.id()) != controls.end();
	};
	has_ae_enable_ = lists(lc::controls::AeEnable);
	has_exposure_ = lists(lc::controls::ExposureTime);
	has_gain_ = lists(lc::controls::AnalogueGain);
	has_frame_duration_ = lists(lc::controls::FrameDurationLimits);
	manual_modes_ = compat::listedManualModes(controls);
}

Status LibcameraCamera::Impl::configure(const CameraConfig &config)
{
	/* Releases the manager too: a single user restarts it, so cameras are enumerated afresh. */
	teardown(true);
	{
		std::lock_guard lock(error_mutex_);
		last_error_.clear();
	}

	if (Status s = checkCameraConfig(config); !s)
		return fail(s.message());
	if (event_fd_ < 0)
		return fail("libcamera: eventfd: " + errnoText(errno));
	camera_config_ = config;

	if (Status s = acquireManager(&manager_); !s) {
		manager_ = nullptr;
		return fail(s.message());
	}

	/*
	 * From here on, whatever fails tears down what was taken so far: one
	 * cleanup on every early return (the message is recorded first, as fail()
	 * is evaluated before the cleanup runs).
	 */
	bool configured = false;
	const ScopeExit cleanup([&] {
		if (!configured)
			teardown(false);
	});
	if (Status s = acquireCamera(config); !s)
		return s;
	if (Status s = chooseFormat(config); !s)
		return s;
	if (Status s = allocateBuffers(); !s)
		return s;
	probeControls();

	controls_packed_.store(
		packControls(config.exposure_us, static_cast<float>(config.analogue_gain)));
	frames_.store(0);
	dropped_.store(0);
	errors_.store(0);
	requests_queued_.store(0);
	queue_failures_.store(0);
	configured_ = true;
	configured = true;
	return Status::ok();
}

Status LibcameraCamera::Impl::start()
{
	if (!configured_)
		return fail("libcamera: start() before a successful configure()");
	if (disconnected_.load())
		return fail("libcamera: camera \"" + camera_id_ + "\" unplugged");
	if (started_)
		return Status::ok();

	drainQueue();
	drainEventFd();

	lc::ControlList controls(camera_->controls());
	const auto [exposure_us, gain] = unpackControls(controls_packed_.load());
	if (has_ae_enable_)
		controls.set(lc::controls::AeEnable, false);
	compat::setManualModes(manual_modes_, &controls);
	if (has_exposure_)
		controls.set(lc::controls::ExposureTime, exposure_us);
	if (has_gain_)
		controls.set(lc::controls::AnalogueGain, gain);
	if (const std::int64_t duration_us = camera_config_.frameDurationUs();
	    has_frame_duration_ && duration_us > 0) {
		const std::int64_t limits[2] = { duration_us, duration_us };
		controls.set(lc::controls::FrameDurationLimits,
			     lc::Span<const std::int64_t, 2>(limits));
	}
	applied_generation_.store(controls_generation_.load());

	if (const int ret = camera_->start(&controls); ret < 0)
		return fail("libcamera: starting camera \"" + camera_id_ +
			    "\" failed: " + errnoText(ret));
	started_ = true;

	std::size_t queued = 0;
	{
		std::lock_guard lock(requeue_mutex_);
		running_.store(true);
		for (std::size_t i = 0; i < slot_count_; ++i)
			if (queueSlot(i))
				++queued;
	}
	const bool none_held = std::none_of(slots_.get(), slots_.get() + slot_count_,
					    [](const Slot &s) { return s.state.load() == kHeld; });
	if (queued == 0 && none_held) {
		stop();
		return fail("libcamera: camera \"" + camera_id_ + "\" accepted no request");
	}
	return Status::ok();
}

void LibcameraCamera::Impl::stop()
{
	{
		std::lock_guard lock(requeue_mutex_);
		running_.store(false);
	}
	if (started_) {
		/* Blocks until libcamera's thread has completed every request (cancelled). */
		camera_->stop();
		started_ = false;
	}
	drainQueue();
	wake(); /* a waiting frame thread returns Stopped */
}

void LibcameraCamera::Impl::drainQueue()
{
	std::int32_t index;
	while (queue_.pop(&index))
		if (index >= 0 && static_cast<std::size_t>(index) < slot_count_)
			slots_[index].state.store(kIdle);
}

void LibcameraCamera::Impl::teardown(bool release_manager)
{
	stop();
	if (camera_ && connected_) {
		camera_->requestCompleted.disconnect(this);
		camera_->disconnected.disconnect(this);
		connected_ = false;
	}
	configured_ = false;
	slots_.reset(); /* the requests, before the buffers they reference */
	slot_count_ = 0;
	for (const auto &m : mappings_)
		::munmap(m.address, m.length);
	mappings_.clear();
	if (allocator_) {
		if (stream_)
			allocator_->free(stream_);
		allocator_.reset();
	}
	stream_ = nullptr;
	config_.reset();
	if (camera_) {
		if (acquired_)
			camera_->release();
		acquired_ = false;
		camera_.reset();
	}
	if (manager_ && release_manager) {
		releaseManager();
		manager_ = nullptr;
	}
	disconnected_.store(false);
	recycle_pending_.store(false);
	width_ = height_ = stride_ = 0;
	frame_bytes_ = 0;
	format_name_.clear();
	camera_id_.clear();
}

/* Caller holds requeue_mutex_. */
bool LibcameraCamera::Impl::queueSlot(std::size_t index)
{
	if (!running_.load())
		return false;
	Slot &slot = slots_[index];
	int expected = kIdle;
	if (!slot.state.compare_exchange_strong(expected, kQueued))
		return false;
	lc::Request *request = slot.request.get();
	request->reuse(lc::Request::ReuseBuffers);
	applyPendingControls(request);
	if (camera_->queueRequest(request) < 0) {
		slot.state.store(kIdle);
		queue_failures_.fetch_add(1, std::memory_order_relaxed);
		return false;
	}
	requests_queued_.fetch_add(1, std::memory_order_relaxed);
	return true;
}

void LibcameraCamera::Impl::applyPendingControls(lc::Request *request)
{
	const std::uint32_t generation = controls_generation_.load(std::memory_order_acquire);
	std::uint32_t applied = applied_generation_.load(std::memory_order_relaxed);
	if (generation == applied)
		return;
	/* Exactly one request carries each change, whichever thread queues first. */
	if (!applied_generation_.compare_exchange_strong(applied, generation))
		return;
	const auto [exposure_us, gain] =
		unpackControls(controls_packed_.load(std::memory_order_acquire));
	lc::ControlList &controls = request->controls();
	if (has_exposure_)
		controls.set(lc::controls::ExposureTime, exposure_us);
	if (has_gain_)
		controls.set(lc::controls::AnalogueGain, gain);
}

/* libcamera's thread: never blocks, never allocates (in this class). */
void LibcameraCamera::Impl::requestCompleted(lc::Request *request)
{
	const std::uint64_t cookie = request->cookie();
	if (cookie >= slot_count_)
		return;
	const auto index = static_cast<std::int32_t>(cookie);
	Slot &slot = slots_[cookie];
	if (request->status() == lc::Request::RequestCancelled || !running_.load()) {
		slot.state.store(kIdle);
		return;
	}
	slot.state.store(kReady);
	if (const auto dropped = queue_.push(index))
		recycleFromCallback(*dropped);
	/* Keep only the newest frames waiting: the older ones go back to the camera at once. */
	std::int32_t oldest;
	while (queue_.size() > kMaxReadyFrames && queue_.pop(&oldest)) {
		if (oldest == index) {
			/* The frame thread took the older one meanwhile: this one is the newest, keep it. */
			if (const auto dropped = queue_.push(index))
				recycleFromCallback(*dropped);
			break;
		}
		dropped_.fetch_add(1, std::memory_order_relaxed);
		recycleFromCallback(oldest);
	}
	wake();
}

void LibcameraCamera::Impl::recycleFromCallback(std::int32_t index)
{
	if (index < 0 || static_cast<std::size_t>(index) >= slot_count_)
		return;
	slots_[index].state.store(kIdle);
	/* Never wait here: if the frame thread or stop() holds the lock, the frame thread requeues it. */
	std::unique_lock lock(requeue_mutex_, std::try_to_lock);
	if (!lock.owns_lock() || !queueSlot(static_cast<std::size_t>(index)))
		recycle_pending_.store(true);
}

void LibcameraCamera::Impl::requeueIdle()
{
	std::lock_guard lock(requeue_mutex_);
	for (std::size_t i = 0; i < slot_count_; ++i)
		queueSlot(i);
}

void LibcameraCamera::Impl::cameraDisconnected()
{
	disconnected_.store(true);
	wake();
}

bool LibcameraCamera::Impl::fillFrame(std::size_t index, Frame *frame)
{
	Slot &slot = slots_[index];
	const lc::FrameMetadata &metadata = slot.buffer->metadata();
	if (metadata.status != lc::FrameMetadata::FrameSuccess)
		return false;
	const auto planes = metadata.planes();
	if (planes.empty() || planes[0].bytesused < frame_bytes_)
		return false; /* truncated */

	if (isZeroCopy(layout_)) {
		frame->image = ImageView{ slot.plane, width_, height_, stride_ };
	} else {
		if (!toIntensity(slot.plane, width_, height_, stride_, layout_,
				 slot.intensity.data(), width_))
			return false;
		frame->image = ImageView{ slot.intensity.data(), width_, height_, width_ };
	}

	const lc::ControlList &result = slot.request->metadata();
	const auto [requested_exposure_us, requested_gain] =
		unpackControls(controls_packed_.load());
	const std::int32_t exposure_us =
		result.get(lc::controls::ExposureTime).value_or(requested_exposure_us);
	const std::int64_t sensor_ns =
		result.get(lc::controls::SensorTimestamp)
			.value_or(static_cast<std::int64_t>(metadata.timestamp));
	frame->sequence = metadata.sequence;
	frame->timestamp_ns = exposureStartNs(sensor_ns, exposure_us);
	frame->exposure_us = exposure_us;
	frame->analogue_gain = result.get(lc::controls::AnalogueGain).value_or(requested_gain);
	frame->slot = static_cast<std::int32_t>(index);
	return true;
}

WaitResult LibcameraCamera::Impl::waitFrame(Frame *frame, int timeout_ms)
{
	if (!frame) {
		static_cast<void>(fail("libcamera: waitFrame() without a Frame"));
		return WaitResult::Error;
	}
	const std::int64_t deadline_ns =
		timeout_ms < 0 ? 0
			       : monotonicNs() + static_cast<std::int64_t>(timeout_ms) * 1000000;
	for (;;) {
		if (disconnected_.load())
			return WaitResult::Error;
		if (!running_.load())
			return WaitResult::Stopped;
		if (recycle_pending_.exchange(false))
			requeueIdle();

		std::int32_t index;
		if (queue_.pop(&index)) {
			if (index < 0 || static_cast<std::size_t>(index) >= slot_count_)
				continue;
			slots_[index].state.store(kHeld);
			if (fillFrame(static_cast<std::size_t>(index), frame)) {
				frames_.fetch_add(1, std::memory_order_relaxed);
				return WaitResult::Frame;
			}
			errors_.fetch_add(1, std::memory_order_relaxed);
			Frame failed;
			failed.slot = index;
			releaseFrame(failed);
			continue;
		}

		int wait_ms = -1;
		if (timeout_ms >= 0) {
			const std::int64_t left_ns = deadline_ns - monotonicNs();
			if (left_ns <= 0)
				return WaitResult::Timeout;
			wait_ms = static_cast<int>((left_ns + 999999) / 1000000);
		}
		pollfd pfd{ event_fd_, POLLIN, 0 };
		const int ret = ::poll(&pfd, 1, wait_ms);
		if (ret < 0 && errno != EINTR) {
			static_cast<void>(fail("libcamera: poll: " + errnoText(errno)));
			return WaitResult::Error;
		}
		if (ret > 0)
			drainEventFd();
	}
}

void LibcameraCamera::Impl::releaseFrame(const Frame &frame)
{
	if (frame.slot < 0 || static_cast<std::size_t>(frame.slot) >= slot_count_)
		return;
	Slot &slot = slots_[frame.slot];
	int expected = kHeld;
	if (!slot.state.compare_exchange_strong(expected, kIdle))
		return; /* not handed out (released twice, or stale) */
	std::lock_guard lock(requeue_mutex_);
	queueSlot(static_cast<std::size_t>(frame.slot));
}

Status LibcameraCamera::Impl::setControls(int exposure_us, double analogue_gain)
{
	if (exposure_us <= 0)
		return Status::error("libcamera: exposure_us " + std::to_string(exposure_us) +
				     " must be > 0");
	if (!std::isfinite(analogue_gain) || analogue_gain < 1.0)
		return Status::error("libcamera: analogue_gain " + std::to_string(analogue_gain) +
				     " must be >= 1.0");
	controls_packed_.store(packControls(exposure_us, static_cast<float>(analogue_gain)),
			       std::memory_order_release);
	controls_generation_.fetch_add(1, std::memory_order_acq_rel);
	return Status::ok();
}

/* -------------------------------------------------------------------------- */
/* LibcameraCamera */

LibcameraCamera::LibcameraCamera()
	: impl_(std::make_unique<Impl>())
{
}

LibcameraCamera::~LibcameraCamera() = default;

std::string LibcameraCamera::name() const
{
	return impl_->camera_id_.empty() ? std::string("libcamera")
					 : "libcamera " + impl_->camera_id_;
}

Status LibcameraCamera::configure(const CameraConfig &config)
{
	return impl_->configure(config);
}

Status LibcameraCamera::start()
{
	return impl_->start();
}

void LibcameraCamera::stop()
{
	impl_->stop();
}

int LibcameraCamera::width() const
{
	return impl_->width_;
}

int LibcameraCamera::height() const
{
	return impl_->height_;
}

WaitResult LibcameraCamera::waitFrame(Frame *frame, int timeout_ms)
{
	return impl_->waitFrame(frame, timeout_ms);
}

void LibcameraCamera::releaseFrame(const Frame &frame)
{
	impl_->releaseFrame(frame);
}

Status LibcameraCamera::setControls(int exposure_us, double analogue_gain)
{
	return impl_->setControls(exposure_us, analogue_gain);
}

CameraStats LibcameraCamera::stats() const
{
	CameraStats s;
	s.frames = impl_->frames_.load();
	s.dropped = impl_->dropped_.load() + impl_->queue_.drops();
	s.errors = impl_->errors_.load();
	return s;
}

std::string LibcameraCamera::lastError() const
{
	return impl_->lastError();
}

std::string LibcameraCamera::pixelFormatName() const
{
	return impl_->format_name_;
}

int LibcameraCamera::strideBytes() const
{
	return impl_->stride_;
}

bool LibcameraCamera::zeroCopy() const
{
	return impl_->configured_ && isZeroCopy(impl_->layout_);
}

std::size_t LibcameraCamera::requestCount() const
{
	return impl_->slot_count_;
}

std::uint64_t LibcameraCamera::requestsQueued() const
{
	return impl_->requests_queued_.load();
}

std::uint64_t LibcameraCamera::queueFailures() const
{
	return impl_->queue_failures_.load();
}

bool LibcameraCamera::manualControlsSupported() const
{
	return impl_->has_exposure_ && impl_->has_gain_;
}

} /* namespace dockpose::hal */

/* SPDX-License-Identifier: MIT */
#include "firmware/preview.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <type_traits>

#include "hal/clock.h"

namespace dockpose::firmware {

static_assert(std::is_standard_layout_v<PreviewFrame>, "PreviewFrame is copied by bytes");
static_assert(std::is_standard_layout_v<PreviewRing>);

namespace {

/* The bytes of a frame after its sequence: what the seqlock guards. */
constexpr std::size_t kBodyOffset = offsetof(PreviewFrame, frame_counter);
constexpr std::size_t kBodyBytes = sizeof(PreviewFrame) - kBodyOffset;

std::uint8_t *body(PreviewFrame *f)
{
	return reinterpret_cast<std::uint8_t *>(f) + kBodyOffset;
}

const std::uint8_t *body(const PreviewFrame *f)
{
	return reinterpret_cast<const std::uint8_t *>(f) + kBodyOffset;
}

} /* namespace */

std::string previewShmName(const std::string &name)
{
	return "/" + name;
}

int previewFactor(int full_width, int width)
{
	if (width <= 0 || full_width <= width)
		return 1;
	return (full_width + width - 1) / width;
}

void downscaleBox(const ImageView &in, int factor, std::uint8_t *out, int out_width, int out_height)
{
	if (factor <= 1) {
		for (int y = 0; y < out_height; ++y)
			std::memcpy(out + static_cast<std::ptrdiff_t>(y) * out_width, in.row(y),
				    static_cast<std::size_t>(out_width));
		return;
	}
	/* Factor 2, the common case, in two loops the compiler vectorises: the two rows' rounded
	 * mean, then each pair's (the mean of the block to within one level). */
	if (factor == 2) {
		std::uint8_t rows[2 * kMaxPreviewWidth];
		const int n = std::min(out_width, kMaxPreviewWidth);
		for (int y = 0; y < out_height; ++y) {
			const std::uint8_t *__restrict r0 = in.row(2 * y);
			const std::uint8_t *__restrict r1 = in.row(2 * y + 1);
			for (int x = 0; x < 2 * n; ++x)
				rows[x] = static_cast<std::uint8_t>((r0[x] + r1[x] + 1) >> 1);
			std::uint8_t *__restrict o =
				out + static_cast<std::ptrdiff_t>(y) * out_width;
			for (std::ptrdiff_t x = 0; x < n; ++x)
				o[x] = static_cast<std::uint8_t>(
					(rows[2 * x] + rows[2 * x + 1] + 1) >> 1);
		}
		return;
	}
	/* Otherwise row by row into column sums, then the means. */
	const std::uint32_t area =
		static_cast<std::uint32_t>(factor) * static_cast<std::uint32_t>(factor);
	std::uint32_t sums[kMaxPreviewWidth];
	const int n = std::min(out_width, kMaxPreviewWidth);
	for (int y = 0; y < out_height; ++y) {
		std::fill(sums, sums + n, 0u);
		for (int dy = 0; dy < factor; ++dy) {
			const std::uint8_t *__restrict r = in.row(y * factor + dy);
			for (std::ptrdiff_t x = 0; x < n; ++x) {
				std::uint32_t s = 0;
				for (std::ptrdiff_t dx = 0; dx < factor; ++dx)
					s += r[x * factor + dx];
				sums[x] += s;
			}
		}
		std::uint8_t *__restrict o = out + static_cast<std::ptrdiff_t>(y) * out_width;
		for (int x = 0; x < n; ++x)
			o[x] = static_cast<std::uint8_t>((sums[x] + area / 2) / area);
	}
}

PreviewWriter::~PreviewWriter()
{
	close();
}

hal::Status PreviewWriter::open(const std::string &name, int full_width, int full_height, int width)
{
	close();
	if (width < 16 || width > kMaxPreviewWidth)
		return hal::Status::error("preview: width " + std::to_string(width) +
					  " is outside [16, " + std::to_string(kMaxPreviewWidth) +
					  "]");
	factor_ = previewFactor(full_width, width);
	width_ = full_width / factor_;
	height_ = full_height / factor_;
	if (width_ <= 0 || height_ <= 0 ||
	    static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) >
		    kMaxPreviewPixels)
		return hal::Status::error("preview: a " + std::to_string(full_width) + "x" +
					  std::to_string(full_height) + " frame at width " +
					  std::to_string(width) + " does not fit the preview's " +
					  std::to_string(kMaxPreviewWidth) + "x" +
					  std::to_string(kMaxPreviewHeight) + " pixels");
	shm_name_ = previewShmName(name);
	const int fd = shm_open(shm_name_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
	if (fd < 0)
		return hal::Status::error("preview: cannot create shared memory " + shm_name_ +
					  ": " + std::strerror(errno));
	/* Readers may be allowed more than the umask gives; the mode is the documented one. */
	(void)fchmod(fd, 0644);
	if (ftruncate(fd, sizeof(PreviewRing)) != 0) {
		const int err = errno;
		::close(fd);
		return hal::Status::error("preview: cannot size " + shm_name_ + " to " +
					  std::to_string(sizeof(PreviewRing)) +
					  " bytes: " + std::strerror(err));
	}
	void *map = mmap(nullptr, sizeof(PreviewRing), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
	const int err = errno;
	::close(fd);
	if (map == MAP_FAILED)
		return hal::Status::error("preview: cannot map " + shm_name_ + ": " +
					  std::strerror(err));
	/* Invalidate first, so that a reader of a segment left by an earlier run sees nothing
	 * half set up; then the header, then the magic last. */
	auto *ring = static_cast<PreviewRing *>(map);
	ring->magic = 0;
	std::atomic_thread_fence(std::memory_order_release);
	ring->version = kPreviewVersion;
	ring->slots = kPreviewSlots;
	ring->frame_bytes = sizeof(PreviewFrame);
	ring->published.store(0, std::memory_order_relaxed);
	for (PreviewFrame &f : ring->frame)
		f.seq.store(0, std::memory_order_relaxed);
	std::atomic_thread_fence(std::memory_order_release);
	ring->magic = kPreviewMagic;
	ring_ = ring;
	return hal::Status::ok();
}

void PreviewWriter::close()
{
	if (!ring_)
		return;
	munmap(ring_, sizeof(PreviewRing));
	ring_ = nullptr;
	shm_unlink(shm_name_.c_str());
}

std::uint64_t PreviewWriter::published() const
{
	return ring_ ? ring_->published.load(std::memory_order_acquire) : 0;
}

void PreviewWriter::publish(const ImageView &image, std::uint64_t frame_counter,
			    std::int64_t timestamp_ns, const Pipeline &pipeline,
			    const PoseResult *result, PreviewStatus status)
{
	if (!accepts(image))
		return;
	PreviewSnapshot snapshot;
	previewSnapshot(&snapshot, frame_counter, timestamp_ns, image.width, image.height, pipeline,
			result, status);
	publish(snapshot, image, pipeline.target(), pipeline.camera());
}

void PreviewWriter::publish(const PreviewSnapshot &snapshot, const ImageView &image,
			    const TargetModel &target, const CameraModel &camera)
{
	if (!beginPublish(snapshot, image, target, camera))
		return;
	(void)publishRows(height_); /* every row in one step: published */
}

bool PreviewWriter::beginPublish(const PreviewSnapshot &snapshot, const ImageView &image,
				 const TargetModel &target, const CameraModel &camera)
{
	if (!accepts(image))
		return false;
	PreviewFrame &f = beginSlot();
	describe(&f, snapshot, target, camera);
	slot_ = &f;
	image_ = image;
	next_row_ = 0;
	return true;
}

bool PreviewWriter::publishRows(int rows)
{
	if (!slot_)
		return true;
	const int y0 = next_row_;
	const int n = std::clamp(rows, 1, height_ - y0);
	/* The band of frame rows that makes preview rows [y0, y0 + n). */
	const ImageView band{ image_.row(y0 * factor_), image_.width, n * factor_,
			      image_.stride_bytes };
	downscaleBox(band, factor_, slot_->pixels + static_cast<std::ptrdiff_t>(y0) * width_,
		     width_, n);
	next_row_ = y0 + n;
	if (next_row_ < height_)
		return false;
	slot_->published_ns = hal::monotonicNs();
	endSlot(*slot_);
	slot_ = nullptr;
	image_ = ImageView{};
	return true;
}

int PreviewWriter::rowsPerBlock() const
{
	const int per_row = std::max(1, factor_ * factor_ * width_);
	return std::max(1, kPreviewBlockPixels / per_row);
}

bool PreviewWriter::accepts(const ImageView &image) const
{
	return ring_ && image.valid() && image.width / factor_ >= width_ &&
	       image.height / factor_ >= height_;
}

PreviewFrame &PreviewWriter::beginSlot()
{
	const std::uint64_t n = ring_->published.load(std::memory_order_relaxed);
	PreviewFrame &f = ring_->frame[n % kPreviewSlots];
	const std::uint64_t seq = f.seq.load(std::memory_order_relaxed);
	f.seq.store(seq + 1, std::memory_order_relaxed); /* odd: being written */
	std::atomic_thread_fence(std::memory_order_release);
	return f;
}

void PreviewWriter::endSlot(PreviewFrame &f)
{
	const std::uint64_t n = ring_->published.load(std::memory_order_relaxed);
	std::atomic_thread_fence(std::memory_order_release);
	f.seq.store(f.seq.load(std::memory_order_relaxed) + 1,
		    std::memory_order_relaxed); /* even again: stable */
	ring_->published.store(n + 1, std::memory_order_release);
}

void previewSnapshot(PreviewSnapshot *out, std::uint64_t frame_counter, std::int64_t timestamp_ns,
		     int image_width, int image_height, const Pipeline &pipeline,
		     const PoseResult *result, PreviewStatus status)
{
	PreviewSnapshot &s = *out;
	s.frame_counter = frame_counter;
	s.timestamp_ns = timestamp_ns;
	s.full_width = static_cast<std::uint16_t>(image_width);
	s.full_height = static_cast<std::uint16_t>(image_height);
	s.status = status;
	s.pose_status = static_cast<std::uint8_t>(result ? result->status : PoseStatus::NoFrame);
	s.found = result && result->found;
	s.tracked = s.found && result->tracked;
	s.leds_used = s.found ? result->leds_used : 0;
	s.led_mask = s.found ? result->led_mask : 0;
	if (s.found) {
		for (int r = 0; r < 3; ++r)
			for (int c = 0; c < 3; ++c)
				s.R[3 * r + c] = result->R(r, c);
		for (int i = 0; i < 3; ++i) {
			s.t_mm[i] = result->t_mm[i];
			s.rpy_deg[i] = result->rpy_deg[i];
			s.sigma_t_mm[i] = result->sigma_t_mm[i];
			s.sigma_rpy_deg[i] = result->sigma_rpy_deg[i];
		}
		s.q_wxyz[0] = result->q.w();
		s.q_wxyz[1] = result->q.x();
		s.q_wxyz[2] = result->q.y();
		s.q_wxyz[3] = result->q.z();
		s.rms_px = result->rms_px;
		s.log10_nfa = result->log10_nfa;
	}

	const auto &blobs = pipeline.blobs();
	s.blob_count =
		static_cast<std::uint32_t>(std::min<std::size_t>(blobs.size(), kMaxCandidates));
	for (std::uint32_t i = 0; i < s.blob_count; ++i) {
		PreviewBlob &b = s.blobs[i];
		b.u_px = static_cast<float>(blobs[i].u_px);
		b.v_px = static_cast<float>(blobs[i].v_px);
		b.area_px = static_cast<float>(blobs[i].area_px);
		b.peak = blobs[i].peak;
		b.matched = 0;
	}
}

void PreviewWriter::describe(PreviewFrame *out, const PreviewSnapshot &s, const TargetModel &model,
			     const CameraModel &camera) const
{
	PreviewFrame &f = *out;
	f.frame_counter = s.frame_counter;
	f.timestamp_ns = s.timestamp_ns;
	f.width = static_cast<std::uint16_t>(width_);
	f.height = static_cast<std::uint16_t>(height_);
	f.full_width = s.full_width;
	f.full_height = s.full_height;
	f.state = s.status.state;
	f.faults = s.status.faults;

	const bool found = s.found;
	f.found = found ? 1 : 0;
	f.pose_status = s.pose_status;
	f.tracked = s.tracked ? 1 : 0;
	f.leds_used = s.leds_used;
	f.led_mask = s.led_mask;
	for (int i = 0; i < 3; ++i) {
		f.t_mm[i] = found ? s.t_mm[i] : 0.0;
		f.rpy_deg[i] = found ? s.rpy_deg[i] : 0.0;
		f.sigma_t_mm[i] = found ? s.sigma_t_mm[i] : 0.0;
		f.sigma_rpy_deg[i] = found ? s.sigma_rpy_deg[i] : 0.0;
	}
	for (int i = 0; i < 4; ++i)
		f.q_wxyz[i] = found ? s.q_wxyz[i] : (i == 0 ? 1.0 : 0.0);
	f.rms_px = found ? s.rms_px : 0.0;
	f.log10_nfa = found ? s.log10_nfa : 0.0;

	f.blob_count = s.blob_count;
	std::copy(s.blobs, s.blobs + s.blob_count, f.blobs);

	Eigen::Matrix3d R;
	for (int r = 0; r < 3; ++r)
		for (int c = 0; c < 3; ++c)
			R(r, c) = s.R[3 * r + c];
	const Eigen::Vector3d t(s.t_mm[0], s.t_mm[1], s.t_mm[2]);
	f.led_count = static_cast<std::uint32_t>(model.points_mm.size());
	for (std::uint32_t i = 0; i < f.led_count; ++i) {
		PreviewLed &led = f.leds[i];
		led.index = static_cast<std::uint8_t>(i);
		led.matched = found && (s.led_mask & (1u << i)) ? 1 : 0;
		led.visible = 0;
		led.u_px = led.v_px = 0.0f;
		if (!found)
			continue;
		Eigen::Vector2d uv;
		if (!camera.project(R * model.points_mm[i] + t, &uv))
			continue;
		led.u_px = static_cast<float>(uv.x());
		led.v_px = static_cast<float>(uv.y());
		led.visible = camera.inImage(uv) ? 1 : 0;
		if (!led.matched)
			continue;
		/* The blob the LED was matched to: the nearest to its projection (the pose's rms is
		 * a fraction of a pixel, the blobs pixels apart). */
		double best = std::numeric_limits<double>::max();
		std::uint32_t best_i = f.blob_count;
		for (std::uint32_t k = 0; k < f.blob_count; ++k) {
			const double du = static_cast<double>(s.blobs[k].u_px) - uv.x();
			const double dv = static_cast<double>(s.blobs[k].v_px) - uv.y();
			const double d2 = du * du + dv * dv;
			if (d2 < best) {
				best = d2;
				best_i = k;
			}
		}
		if (best_i < f.blob_count)
			f.blobs[best_i].matched = 1;
	}
	f.face_count = static_cast<std::uint32_t>(model.faces.size());
	for (std::uint32_t i = 0; i < f.face_count; ++i)
		for (int k = 0; k < 4; ++k)
			f.faces[i][k] = static_cast<std::uint8_t>(model.faces[i][k]);
}

PreviewReader::~PreviewReader()
{
	close();
}

hal::Status PreviewReader::open(const std::string &name)
{
	close();
	const std::string shm = previewShmName(name);
	const int fd = shm_open(shm.c_str(), O_RDONLY | O_CLOEXEC, 0);
	if (fd < 0)
		return hal::Status::error(
			"preview " + shm + ": " + std::strerror(errno) +
			(errno == ENOENT ? " (is dockposed running with preview.enabled?)" : ""));
	struct stat st {
	};
	if (fstat(fd, &st) != 0 || st.st_size != static_cast<off_t>(sizeof(PreviewRing))) {
		::close(fd);
		return hal::Status::error("preview " + shm + ": " +
					  std::to_string(static_cast<long long>(st.st_size)) +
					  " bytes, not a preview ring of this version (" +
					  std::to_string(sizeof(PreviewRing)) + " bytes)");
	}
	void *map = mmap(nullptr, sizeof(PreviewRing), PROT_READ, MAP_SHARED, fd, 0);
	const int err = errno;
	::close(fd);
	if (map == MAP_FAILED)
		return hal::Status::error("preview " + shm + ": cannot map: " + std::strerror(err));
	const auto *ring = static_cast<const PreviewRing *>(map);
	if (ring->magic != kPreviewMagic || ring->version != kPreviewVersion ||
	    ring->slots != kPreviewSlots || ring->frame_bytes != sizeof(PreviewFrame)) {
		munmap(map, sizeof(PreviewRing));
		return hal::Status::error("preview " + shm +
					  ": not a dockpose preview ring of version " +
					  std::to_string(kPreviewVersion));
	}
	ring_ = ring;
	return hal::Status::ok();
}

void PreviewReader::close()
{
	if (!ring_)
		return;
	munmap(const_cast<PreviewRing *>(ring_), sizeof(PreviewRing));
	ring_ = nullptr;
}

std::uint64_t PreviewReader::latest(PreviewFrame *out, std::uint64_t after) const
{
	if (!ring_)
		return 0;
	for (int attempt = 0; attempt < 8; ++attempt) {
		const std::uint64_t n = ring_->published.load(std::memory_order_acquire);
		if (n == 0 || n <= after)
			return 0;
		const PreviewFrame &f = ring_->frame[(n - 1) % kPreviewSlots];
		const std::uint64_t before = f.seq.load(std::memory_order_acquire);
		if (before & 1u)
			continue;
		std::memcpy(body(out), body(&f), kBodyBytes);
		std::atomic_thread_fence(std::memory_order_acquire);
		if (f.seq.load(std::memory_order_relaxed) == before &&
		    ring_->published.load(std::memory_order_relaxed) - n < kPreviewSlots) {
			out->seq.store(before, std::memory_order_relaxed);
			return n;
		}
	}
	return 0;
}

} /* namespace dockpose::firmware */

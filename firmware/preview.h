/* SPDX-License-Identifier: MIT */
/*
 * The operator preview: every Nth camera frame, downscaled, with what the
 * pipeline found in it (candidate blobs, matched LEDs with their model index,
 * the model's faces and every LED projected from the pose, the pose, its σ,
 * the sensor state), published into a fixed-size POSIX shared-memory ring
 * (/dev/shm/<name>) that readers (`dockpose view`) map read-only.
 *
 * Each slot is a seqlock: the writer makes its sequence odd, writes, makes it
 * even; a reader copies a slot and keeps the copy only when the sequence was
 * the same even value before and after. The writer never waits for a reader,
 * and a reader can never stop the writer (it cannot write the mapping).
 *
 * The layout is plain data of fixed size (PreviewRing), version
 * kPreviewVersion; a reader refuses another magic, version or size.
 *
 * Threads: a PreviewWriter belongs to one writer thread at a time (the frame
 * thread, or the PreviewWorker's thread, to which the frame thread hands a
 * PreviewSnapshot); a PreviewReader to its reader's thread; any number of
 * processes may read.
 */
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>

#include "algo/capacities.h"
#include "algo/image.h"
#include "algo/pipeline.h"
#include "hal/status.h"

namespace dockpose::firmware {

constexpr std::uint32_t kPreviewMagic = 0x56505044; /* "DPPV" */
constexpr std::uint32_t kPreviewVersion = 1;
/* Slots in the ring: a reader that copies one while the writer fills the next is never torn. */
constexpr int kPreviewSlots = 4;
/* The largest preview image: 640 x 512 pixels (preview.width is at most 640). */
constexpr int kMaxPreviewWidth = 640;
constexpr int kMaxPreviewHeight = 512;
constexpr std::size_t kMaxPreviewPixels =
	static_cast<std::size_t>(kMaxPreviewWidth) * kMaxPreviewHeight;
/*
 * The frame pixels a staged publish step reads (PreviewWriter::publishRows()):
 * about 16 KB, a few µs of downscale, the most a PreviewWorker step runs on
 * after the frame loop turns busy (640x480 at 320 px: 12 preview rows).
 */
constexpr int kPreviewBlockPixels = 16384;

static_assert(std::atomic<std::uint64_t>::is_always_lock_free,
	      "the seqlock needs a lock-free 64-bit atomic in shared memory");

/* A candidate blob, in full-frame pixels. */
struct PreviewBlob {
	float u_px = 0.0f, v_px = 0.0f;
	float area_px = 0.0f;
	std::uint8_t peak = 0;
	std::uint8_t matched = 0; /* 1: the nearest blob to a matched LED's projection */
	std::uint8_t reserved[2] = {};
};

/* A model LED projected from the pose, in full-frame pixels. */
struct PreviewLed {
	float u_px = 0.0f, v_px = 0.0f;
	std::uint8_t index = 0; /* model LED index */
	std::uint8_t matched = 0; /* 1: in the pose's led_mask */
	std::uint8_t visible = 0; /* 1: in front of the camera and inside the image */
	std::uint8_t reserved = 0;
};

/* One published frame. Read it only through PreviewReader (the seqlock). */
struct PreviewFrame {
	std::atomic<std::uint64_t> seq{ 0 }; /* even: stable; odd: being written */
	std::uint64_t frame_counter = 0; /* the camera frame's sequence number */
	std::int64_t timestamp_ns = 0; /* its exposure start, CLOCK_MONOTONIC */
	std::int64_t published_ns = 0; /* when it was published, CLOCK_MONOTONIC */
	std::uint16_t width = 0, height = 0; /* the preview image */
	std::uint16_t full_width = 0, full_height = 0; /* the camera frame */
	std::uint8_t state = 0; /* can::SensorState */
	std::uint8_t faults = 0; /* can::fault bits */
	std::uint8_t pose_status = 0; /* PoseStatus */
	std::uint8_t found = 0;
	std::uint8_t tracked = 0;
	std::uint8_t reserved[3] = {};
	std::int32_t leds_used = 0;
	std::uint32_t led_mask = 0;
	double t_mm[3] = {}, q_wxyz[4] = {}, rpy_deg[3] = {};
	double sigma_t_mm[3] = {}, sigma_rpy_deg[3] = {};
	double rms_px = 0.0, log10_nfa = 0.0;
	std::uint32_t blob_count = 0;
	PreviewBlob blobs[kMaxCandidates];
	std::uint32_t led_count = 0; /* the model's LEDs (projected only when found) */
	PreviewLed leds[kMaxLeds];
	std::uint32_t face_count = 0; /* the model's faces: LED indices in cyclic order */
	std::uint8_t faces[kMaxFaces][4] = {};
	std::uint8_t pixels[kMaxPreviewPixels]; /* width x height, row-major, stride = width */
};

struct PreviewRing {
	std::uint32_t magic = 0; /* kPreviewMagic once the writer set it up */
	std::uint32_t version = 0;
	std::uint32_t slots = 0;
	std::uint32_t frame_bytes = 0; /* sizeof(PreviewFrame) */
	/* The number of frames published so far; the latest is slot (published - 1) % slots. */
	std::atomic<std::uint64_t> published{ 0 };
	PreviewFrame frame[kPreviewSlots];
};

/* What the sensor reports with a frame: its state and fault bits. */
struct PreviewStatus {
	std::uint8_t state = 0;
	std::uint8_t faults = 0;
};

/*
 * What the preview takes of one frame from the frame thread: the frame's
 * identity, the sensor's status, the pose and the candidate blobs of the
 * pipeline's last process(). Plain data of fixed size (about 1.3 KB): copying
 * it is all the frame thread pays for a preview frame handed to the worker;
 * the LEDs are projected and the matched blobs marked from it later
 * (PreviewWriter::publish(const PreviewSnapshot &, ...)).
 */
struct PreviewSnapshot {
	std::uint64_t frame_counter = 0;
	std::int64_t timestamp_ns = 0;
	std::uint16_t full_width = 0, full_height = 0;
	PreviewStatus status;
	std::uint8_t pose_status = 0; /* PoseStatus */
	bool found = false; /* the pose fields below are set only when found */
	bool tracked = false;
	std::int32_t leds_used = 0;
	std::uint32_t led_mask = 0;
	double R[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 }; /* target to camera, row-major */
	double t_mm[3] = {}, q_wxyz[4] = { 1, 0, 0, 0 }, rpy_deg[3] = {};
	double sigma_t_mm[3] = {}, sigma_rpy_deg[3] = {};
	double rms_px = 0.0, log10_nfa = 0.0;
	std::uint32_t blob_count = 0;
	PreviewBlob blobs[kMaxCandidates]; /* .matched 0: set when described */
};

/*
 * Fill *out from `pipeline`'s last process() on an image_width x
 * image_height frame and `result` (nullptr: no pose). The blobs are copied
 * only up to their count. Allocates: never. The pipeline's thread.
 */
void previewSnapshot(PreviewSnapshot *out, std::uint64_t frame_counter, std::int64_t timestamp_ns,
		     int image_width, int image_height, const Pipeline &pipeline,
		     const PoseResult *result, PreviewStatus status);

/*
 * The shared-memory name of preview.name (a POSIX name: "/" + name).
 * Allocates: the string.
 */
std::string previewShmName(const std::string &name);

/*
 * Downscale `in` by an integer box factor into out (out_width x out_height =
 * in / factor, rounded down), the mean of each factor x factor block.
 * Allocates: never.
 */
void downscaleBox(const ImageView &in, int factor, std::uint8_t *out, int out_width,
		  int out_height);

/* The integer box factor that brings `full_width` to at most `width`: ceil(full / width). */
int previewFactor(int full_width, int width);

class PreviewWriter
{
public:
	PreviewWriter() = default;
	PreviewWriter(const PreviewWriter &) = delete;
	PreviewWriter &operator=(const PreviewWriter &) = delete;
	~PreviewWriter();

	/*
	 * Create (or take over) /dev/shm/<name>, size it to a PreviewRing, map
	 * it; frames of full_width x full_height are published at most `width`
	 * pixels wide. Mode 0644: any local user may watch. Allocates: here
	 * (the mapping), never after.
	 */
	hal::Status open(const std::string &name, int full_width, int full_height, int width);
	/* Unmap and unlink the segment (readers that have it mapped keep their copy). */
	void close();
	bool isOpen() const { return ring_ != nullptr; }
	/* The preview image's size (after open()). */
	int width() const { return width_; }
	int height() const { return height_; }

	/*
	 * Publish one frame: the image downscaled, the blobs and the pose of
	 * `pipeline`'s last process() (which must have been run on this frame),
	 * `result` the pose (nullptr: no pose this frame). Allocates: never.
	 * Frame thread.
	 */
	void publish(const ImageView &image, std::uint64_t frame_counter, std::int64_t timestamp_ns,
		     const Pipeline &pipeline, const PoseResult *result, PreviewStatus status);
	/*
	 * Publish `snapshot`'s frame: `image` (the frame it was taken of)
	 * downscaled, the snapshot, the model's faces and its LEDs projected
	 * from the pose with `camera` (and the blob nearest each matched LED's
	 * projection marked matched). `target` and `camera`: the models of the
	 * pipeline the snapshot came from. Allocates: never. The one writer
	 * thread (firmware/preview_worker.h), never at the same time as another
	 * publish().
	 */
	void publish(const PreviewSnapshot &snapshot, const ImageView &image,
		     const TargetModel &target, const CameraModel &camera);

	/*
	 * The same publish in steps, for a writer that stops between them (the
	 * PreviewWorker does its pixel work only while the frame loop is idle).
	 * beginPublish() takes the next slot, projects the LEDs and describes
	 * the snapshot into it (as publish()); publishRows() downscales the next
	 * `rows` preview rows (at least one) of `image`, which must stay valid
	 * and unchanged until the last row is done; it returns true when that
	 * was the last row and the frame is published (counted, visible to
	 * readers). Until then the slot is invisible: readers copy the newest
	 * published slot, never the one being written, so a writer paused
	 * between steps for any time tears nothing. beginPublish() false: the
	 * image is not of the ring's size, nothing begun. Allocates: never. The
	 * one writer thread, never interleaved with another publish().
	 */
	bool beginPublish(const PreviewSnapshot &snapshot, const ImageView &image,
			  const TargetModel &target, const CameraModel &camera);
	bool publishRows(int rows);
	/*
	 * Preview rows per publishRows() step that read about
	 * kPreviewBlockPixels frame pixels (at least 1). Allocates: never. The
	 * writer's thread, after open().
	 */
	int rowsPerBlock() const;

	std::uint64_t published() const;

private:
	bool accepts(const ImageView &image) const;
	/* Everything of a frame but its pixels and published_ns, into *out. */
	void describe(PreviewFrame *out, const PreviewSnapshot &s, const TargetModel &model,
		      const CameraModel &camera) const;
	/* The next slot, its sequence made odd; endSlot() makes it even and counts it. */
	PreviewFrame &beginSlot();
	void endSlot(PreviewFrame &f);

	PreviewRing *ring_ = nullptr;
	std::string shm_name_;
	int factor_ = 1;
	int width_ = 0, height_ = 0;
	/* The publish under way (beginPublish() to the last publishRows()). */
	PreviewFrame *slot_ = nullptr;
	ImageView image_;
	int next_row_ = 0; /* the next preview row to downscale */
};

class PreviewReader
{
public:
	PreviewReader() = default;
	PreviewReader(const PreviewReader &) = delete;
	PreviewReader &operator=(const PreviewReader &) = delete;
	~PreviewReader();

	/* Map /dev/shm/<name> read-only; an error names the segment and why. Allocates: here. */
	hal::Status open(const std::string &name);
	void close();
	bool isOpen() const { return ring_ != nullptr; }

	/*
	 * Copy the latest published frame into *out when there is one newer
	 * than `after` (a count from published()); retried while the writer
	 * overwrites it. Returns the count of the frame copied, 0 when there is
	 * none newer (or it could not be read untorn in a few tries).
	 * Allocates: never. *out must not be shared with another thread.
	 */
	std::uint64_t latest(PreviewFrame *out, std::uint64_t after = 0) const;

private:
	const PreviewRing *ring_ = nullptr;
};

} /* namespace dockpose::firmware */

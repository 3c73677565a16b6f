/* SPDX-License-Identifier: MIT */
/*
 * `dockpose solve` as a whole process against the same work in-process
 * (host-release): kFrames 1456x1088 frames of the wedge (6 LEDs, the clutter
 * of bench_pipeline) as PGM files in a temporary directory, solved
 *  (1) in-process: each file read (open + read(2) into one buffer + close)
 *      and Pipeline::process() after reset() (solve handles every image cold);
 *  (2) as a process: `dockpose solve -t wedge.json -c cam1456.json FILES...`
 *      started with posix_spawn, stdout to a file, until it has exited:
 *      start-up, the JSON files, the Pipeline's buffers, every line out.
 * ratio = (2) / (1), goal <= 2 (issue 8). Argument 1: the same frames with
 * LED 0 hidden (the correspondence search dominates there). map_ms, for
 * comparison with read_ms: what mapping each file (mmap, a byte per page,
 * munmap) would cost instead of read(2)'s copy.
 *
 * Every measurement reads a set of files of its own, written just before
 * and read once: no file is read twice. They are in the page cache from the
 * write (dropping it needs root and would disturb everyone else on the
 * machine), so "the file read" is a copy from the page cache for both.
 */
#include <fcntl.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "algo/io/model_json.h"
#include "algo/io/pgm.h"
#include "algo/pipeline.h"
#include "algo/synth/renderer.h"

extern char **environ;

using namespace dockpose;
namespace fs = std::filesystem;

namespace {

constexpr int kFrames = 120;
#ifdef DOCKPOSE_TOOL
const char *const kTool = DOCKPOSE_TOOL;
#else
const char *const kTool = nullptr; /* no dockpose target in this build */
#endif
const std::string kData = DOCKPOSE_TEST_DATA;
const std::string kTarget = kData + "/wedge.json";
const std::string kCamera = kData + "/cam1456.json";

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start)
{
	return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Scene {
	TargetModel target;
	CameraIntrinsics camera;
	std::vector<std::string> pgm; /* the encoded files, written anew for every set */
};

/* kFrames frames of a slow approach, rendered once (as bench_pipeline's, across 300 mm). */
const Scene &scene(bool hidden_led)
{
	static std::unique_ptr<Scene> scenes[2];
	std::unique_ptr<Scene> &s = scenes[hidden_led ? 1 : 0];
	if (s)
		return *s;
	s = std::make_unique<Scene>();
	s->target = loadTargetModel(kTarget).value();
	s->camera = loadCameraIntrinsics(kCamera).value();
	FrameRenderer renderer(s->target, s->camera);
	Image img;
	RenderTruth truth;
	for (int i = 0; i < kFrames; ++i) {
		RenderOptions o;
		o.reflections = 6;
		o.glints = 2;
		o.hot_pixels = 20;
		o.noise_sigma = 2.0;
		o.gradient = 20.0;
		o.occlusion_mask = hidden_led ? 1u : 0u;
		renderer.render(poseAt(s->camera, s->target, 1200.0 - 2.5 * i,
				       { 8.0 - 0.05 * i, -10.0 + 0.08 * i, 5.0 }, 0.45 + 0.0005 * i,
				       0.5),
				o, 1000 + static_cast<std::uint64_t>(i), &img, &truth);
		s->pgm.push_back(encodePgm(img.view()));
	}
	return *s;
}

/* A fresh directory of the scene's files; removed with the object. */
class FrameSet
{
public:
	FrameSet(const Scene &scene, const std::string &tag, int count)
	{
		dir_ = fs::temp_directory_path() /
		       ("dockpose_bench_solve_" + std::to_string(static_cast<long>(::getpid())) +
			"_" + tag + "_" + std::to_string(serial_++));
		fs::remove_all(dir_);
		fs::create_directories(dir_);
		for (int i = 0; i < count; ++i) {
			char name[32];
			std::snprintf(name, sizeof(name), "frame_%04d.pgm", i);
			paths_.push_back((dir_ / name).string());
			const std::string &bytes = scene.pgm[static_cast<std::size_t>(i)];
			std::ofstream out(paths_.back(), std::ios::binary | std::ios::trunc);
			out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
		}
	}
	~FrameSet()
	{
		std::error_code ec;
		fs::remove_all(dir_, ec);
	}

	const std::vector<std::string> &paths() const { return paths_; }
	std::string file(const char *name) const { return (dir_ / name).string(); }

private:
	static inline int serial_ = 0;
	fs::path dir_;
	std::vector<std::string> paths_;
};

struct InProcess {
	double read_s = 0, pipeline_s = 0;
	int found = 0;
};

/* (1): read every file into one buffer, solve it cold. */
InProcess solveInProcess(const Scene &scene, const FrameSet &set, Pipeline *pipeline)
{
	const std::size_t pixels = static_cast<std::size_t>(scene.camera.width) *
				   static_cast<std::size_t>(scene.camera.height);
	const std::size_t capacity = pixels + 4096;
	static std::unique_ptr<std::uint8_t[]> buffer(new std::uint8_t[capacity]);
	InProcess r;
	for (const std::string &path : set.paths()) {
		const Clock::time_point t0 = Clock::now();
		const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
		std::size_t have = 0;
		for (ssize_t n;
		     fd >= 0 && (n = ::read(fd, buffer.get() + have, capacity - have)) > 0;)
			have += static_cast<std::size_t>(n);
		if (fd >= 0)
			::close(fd);
		if (have < pixels) {
			r.found = -1;
			return r;
		}
		/* writePgm's header, then the pixels. */
		const ImageView view{ buffer.get() + (have - pixels), scene.camera.width,
				      scene.camera.height, scene.camera.width };
		const Clock::time_point t1 = Clock::now();
		pipeline->reset();
		r.found += pipeline->process(view).found ? 1 : 0;
		const Clock::time_point t2 = Clock::now();
		r.read_s += std::chrono::duration<double>(t1 - t0).count();
		r.pipeline_s += std::chrono::duration<double>(t2 - t1).count();
	}
	return r;
}

/* For comparison: mapping each file (mmap, one byte read per page, munmap) instead of read(2). */
double mapFiles(const FrameSet &set)
{
	double seconds = 0;
	std::uint64_t sum = 0;
	for (const std::string &path : set.paths()) {
		const Clock::time_point t0 = Clock::now();
		const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
		struct stat st;
		if (fd < 0 || ::fstat(fd, &st) != 0 || st.st_size <= 0) {
			if (fd >= 0)
				::close(fd);
			return -1;
		}
		const std::size_t size = static_cast<std::size_t>(st.st_size);
		void *map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
		::close(fd);
		if (map == MAP_FAILED)
			return -1;
		const auto *bytes = static_cast<const std::uint8_t *>(map);
		for (std::size_t k = 0; k < size; k += 4096)
			sum += bytes[k];
		::munmap(map, size);
		seconds += secondsSince(t0);
	}
	benchmark::DoNotOptimize(sum);
	return seconds;
}

struct ProcessRun {
	double seconds = 0;
	int status = -1;
	int lines = 0, found = 0;
	std::string error;
};

/* (2): the tool on the set's files, stdout to a file; counts its lines afterwards. */
ProcessRun solveProcess(const FrameSet &set, std::size_t count)
{
	ProcessRun r;
	std::vector<std::string> args = { kTool, "solve", "-t", kTarget, "-c", kCamera };
	for (std::size_t i = 0; i < count; ++i)
		args.push_back(set.paths()[i]);
	std::vector<char *> argv;
	for (std::string &a : args)
		argv.push_back(a.data());
	argv.push_back(nullptr);
	const std::string out = set.file("solve.jsonl"), err = set.file("solve.err");

	posix_spawn_file_actions_t actions;
	posix_spawn_file_actions_init(&actions);
	posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
					 0644);
	posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
					 0644);
	const Clock::time_point start = Clock::now();
	pid_t pid = -1;
	const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
	int status = 0;
	if (rc == 0)
		::waitpid(pid, &status, 0);
	r.seconds = secondsSince(start);
	posix_spawn_file_actions_destroy(&actions);
	if (rc != 0) {
		r.error = std::string("cannot start ") + argv[0] + ": " + std::strerror(rc);
		return r;
	}
	r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
	std::ifstream in(out);
	for (std::string line; std::getline(in, line);) {
		++r.lines;
		r.found += line.find("\"found\": true") != std::string::npos ? 1 : 0;
	}
	if (r.status != 0 || r.lines != static_cast<int>(count)) {
		std::ifstream e(err);
		std::string text((std::istreambuf_iterator<char>(e)),
				 std::istreambuf_iterator<char>());
		r.error = "dockpose solve exited " + std::to_string(r.status) + " with " +
			  std::to_string(r.lines) + " lines: " + text.substr(0, 300);
	}
	return r;
}

void solveProcessVsInProcess(benchmark::State &state)
{
	if (!kTool) {
		state.SkipWithError(
			"the dockpose tool is not built here (DOCKPOSE_TOOL undefined)");
		return;
	}
	const bool hidden_led = state.range(0) != 0;
	const Scene &s = scene(hidden_led);
	Pipeline pipeline(s.target, s.camera);
	double read_s = 0, map_s = 0, pipeline_s = 0, process_s = 0, one_frame_s = 0;
	int found_in = 0, found_tool = 0, runs = 0;
	for (auto _ : state) {
		InProcess in;
		{
			const FrameSet set(s, "in", kFrames);
			in = solveInProcess(s, set, &pipeline);
		}
		if (in.found < 0) {
			state.SkipWithError("a frame file was shorter than its pixels");
			return;
		}
		double mapped = 0;
		{
			const FrameSet set(s, "map", kFrames);
			mapped = mapFiles(set);
		}
		if (mapped < 0) {
			state.SkipWithError("cannot map a frame file");
			return;
		}
		ProcessRun tool, one;
		{
			const FrameSet set(s, "tool", kFrames);
			tool = solveProcess(set, kFrames);
		}
		{
			/* Start-up and one frame: what the process costs beyond the frames. */
			const FrameSet set(s, "one", 1);
			one = solveProcess(set, 1);
		}
		if (!tool.error.empty() || !one.error.empty()) {
			state.SkipWithError((tool.error.empty() ? one.error : tool.error).c_str());
			return;
		}
		state.SetIterationTime(tool.seconds);
		read_s += in.read_s;
		map_s += mapped;
		pipeline_s += in.pipeline_s;
		process_s += tool.seconds;
		one_frame_s += one.seconds;
		found_in += in.found;
		found_tool += tool.found;
		++runs;
	}
	const double frames = static_cast<double>(runs) * kFrames;
	state.counters["read_ms"] = 1e3 * read_s / frames;
	state.counters["map_ms"] = 1e3 * map_s / frames;
	state.counters["pipeline_ms"] = 1e3 * pipeline_s / frames;
	state.counters["in_process_ms"] = 1e3 * (read_s + pipeline_s) / frames;
	state.counters["process_ms"] = 1e3 * process_s / frames;
	state.counters["one_frame_process_ms"] = 1e3 * one_frame_s / runs;
	state.counters["ratio"] = process_s / (read_s + pipeline_s);
	state.counters["found_in"] = found_in / frames;
	state.counters["found_tool"] = found_tool / frames;
}

} /* namespace */

/* Per frame, in milliseconds: read_ms + pipeline_ms = in_process_ms (1), process_ms (2). */
BENCHMARK(solveProcessVsInProcess)
	->ArgName("hidden_led")
	->Arg(0)
	->Iterations(1)
	->Repetitions(5)
	->ReportAggregatesOnly(true)
	->UseManualTime()
	->Unit(benchmark::kMillisecond);
BENCHMARK(solveProcessVsInProcess)
	->ArgName("hidden_led")
	->Arg(1)
	->Iterations(1)
	->Repetitions(1)
	->UseManualTime()
	->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();

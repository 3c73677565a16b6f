/* SPDX-License-Identifier: MIT */
/*
 * The pixel stages on a 1456 x 1088 frame with 14 small bright spots, an
 * ambient gradient and read noise:
 *  - readPass: the sum of all bytes (vectorised), the memory floor;
 *  - thresholdAuto: Thresholder::compute (automatic level);
 *  - detectAuto / detectFixed: BlobDetector::detect (threshold + label +
 *    measure + filter) with the automatic and with a fixed level;
 *  - openCv...: cv::threshold + cv::connectedComponentsWithStats (8-connected,
 *    one thread), the reference, where OpenCV is found.
 * After the table, the time of each relative to readPass.
 */
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#ifdef DOCKPOSE_HAVE_OPENCV
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#endif

#include "algo/blob_detector.h"
#include "algo/image.h"

using namespace dockpose;

namespace {

constexpr int kWidth = 1456;
constexpr int kHeight = 1088;
constexpr int kSpots = 14;

/* background 12 + 10 levels across, noise sigma 2, 14 spots of peak 60..230 and sigma 1..1.6 px */
const Image &frame()
{
	static const Image image = [] {
		Image img(kWidth, kHeight);
		std::mt19937 rng(1);
		std::normal_distribution<double> noise(0.0, 2.0);
		std::uniform_real_distribution<double> u(40.0, kWidth - 40.0),
			v(40.0, kHeight - 40.0);
		std::uniform_real_distribution<double> peak(60.0, 230.0), sigma(1.0, 1.6);
		struct Spot {
			double u, v, peak, sigma;
		};
		std::vector<Spot> spots;
		spots.reserve(kSpots);
		for (int i = 0; i < kSpots; ++i)
			spots.push_back({ u(rng), v(rng), peak(rng), sigma(rng) });
		for (int y = 0; y < kHeight; ++y) {
			for (int x = 0; x < kWidth; ++x) {
				double val = 12.0 + 10.0 * (x - kWidth / 2.0) / kWidth + noise(rng);
				for (const Spot &s : spots) {
					const double dx = x - s.u, dy = y - s.v;
					if (dx * dx + dy * dy < 100.0)
						val += s.peak *
						       std::exp(-0.5 * (dx * dx + dy * dy) /
								(s.sigma * s.sigma));
				}
				img.at(x, y) = static_cast<std::uint8_t>(
					std::clamp(std::lround(val), 0L, 255L));
			}
		}
		return img;
	}();
	return image;
}

using U8x16 = std::uint8_t __attribute__((vector_size(16)));
using U16x8 = std::uint16_t __attribute__((vector_size(16)));

/* Sum of all bytes: per 16 bytes one load and three vector operations. */
std::uint64_t sumBytes(const ImageView &img)
{
	const U16x8 low = { 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff };
	std::uint64_t total = 0;
	for (int y = 0; y < img.height; ++y) {
		const std::uint8_t *p = img.row(y);
		int x = 0;
		while (x + 16 <= img.width) {
			U16x8 acc = {};
			/* each lane gains at most 510 per block: flush before 65535 */
			for (int n = 0; n < 128 && x + 16 <= img.width; ++n, x += 16) {
				U8x16 v;
				std::memcpy(&v, p + x, sizeof(v));
				const U16x8 h = std::bit_cast<U16x8>(v);
				acc += (h & low) + (h >> 8);
			}
			for (int i = 0; i < 8; ++i)
				total += acc[i];
		}
		for (; x < img.width; ++x)
			total += p[x];
	}
	return total;
}

void readPass(benchmark::State &state)
{
	const ImageView view = frame().view();
	while (state.KeepRunning()) {
		std::uint64_t s = sumBytes(view);
		benchmark::DoNotOptimize(s);
	}
	state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * kWidth * kHeight);
}
BENCHMARK(readPass)->Unit(benchmark::kMicrosecond);

void thresholdAuto(benchmark::State &state)
{
	const ImageView view = frame().view();
	Thresholder th(kWidth, kHeight, ThresholdConfig{});
	ThresholdStats stats;
	while (state.KeepRunning()) {
		const ThresholdMap &map = th.compute(view, &stats);
		benchmark::DoNotOptimize(&map);
	}
	state.counters["level_min"] = stats.level_min;
	state.counters["level_max"] = stats.level_max;
	state.counters["noise_sigma"] = stats.noise_sigma;
	state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * kWidth * kHeight);
}
BENCHMARK(thresholdAuto)->Unit(benchmark::kMicrosecond);

void detectBench(benchmark::State &state, const ThresholdConfig &cfg)
{
	const ImageView view = frame().view();
	BlobDetector det(kWidth, kHeight, cfg, BlobFilterConfig{});
	StaticVector<Blob, kMaxCandidates> blobs;
	BlobStats stats;
	while (state.KeepRunning()) {
		const bool ok = det.detect(view, &blobs, &stats);
		benchmark::DoNotOptimize(ok);
		benchmark::DoNotOptimize(blobs.data());
	}
	state.counters["blobs"] = static_cast<double>(blobs.size());
	state.counters["components"] = stats.components;
	state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * kWidth * kHeight);
}

void detectAuto(benchmark::State &state)
{
	detectBench(state, ThresholdConfig{});
}
BENCHMARK(detectAuto)->Unit(benchmark::kMicrosecond);

void detectFixed(benchmark::State &state)
{
	ThresholdConfig cfg;
	cfg.mode = ThresholdMode::Fixed;
	cfg.fixed_level = 30;
	detectBench(state, cfg);
}
BENCHMARK(detectFixed)->Unit(benchmark::kMicrosecond);

#ifdef DOCKPOSE_HAVE_OPENCV
void openCvThresholdComponents(benchmark::State &state)
{
	cv::setNumThreads(1);
	const Image &img = frame();
	const cv::Mat src(kHeight, kWidth, CV_8UC1, const_cast<std::uint8_t *>(img.data()),
			  static_cast<std::size_t>(kWidth));
	cv::Mat binary, labels, stats, centroids;
	int n = 0;
	while (state.KeepRunning()) {
		cv::threshold(src, binary, 29, 255, cv::THRESH_BINARY); /* v > 29: v >= 30 */
		n = cv::connectedComponentsWithStats(binary, labels, stats, centroids, 8, CV_32S);
		benchmark::DoNotOptimize(n);
	}
	state.counters["components"] = n - 1; /* label 0 is the background */
	state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * kWidth * kHeight);
}
BENCHMARK(openCvThresholdComponents)->Unit(benchmark::kMicrosecond);

/* The threshold alone, to split the above. */
void openCvThresholdOnly(benchmark::State &state)
{
	cv::setNumThreads(1);
	const Image &img = frame();
	const cv::Mat src(kHeight, kWidth, CV_8UC1, const_cast<std::uint8_t *>(img.data()),
			  static_cast<std::size_t>(kWidth));
	cv::Mat binary;
	while (state.KeepRunning()) {
		cv::threshold(src, binary, 29, 255, cv::THRESH_BINARY);
		benchmark::DoNotOptimize(binary.data);
	}
	state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * kWidth * kHeight);
}
BENCHMARK(openCvThresholdOnly)->Unit(benchmark::kMicrosecond);
#endif

/*
 * Console output, plus the fastest wall-clock and CPU time per iteration of
 * every benchmark over its repetitions (run with --benchmark_repetitions=N
 * on a busy machine; CPU time is the steadier figure there).
 */
class RatioReporter : public benchmark::ConsoleReporter
{
public:
	void ReportRuns(const std::vector<Run> &reports) override
	{
		ConsoleReporter::ReportRuns(reports);
		for (const Run &run : reports) {
			if (run.run_type != Run::RT_Iteration || run.error_occurred ||
			    run.iterations == 0)
				continue;
			const double n = static_cast<double>(run.iterations);
			const double real = run.real_accumulated_time / n;
			const double cpu = run.cpu_accumulated_time / n;
			auto [it, fresh] =
				times_.try_emplace(run.run_name.function_name, Times{ real, cpu });
			if (!fresh) {
				it->second.real = std::min(it->second.real, real);
				it->second.cpu = std::min(it->second.cpu, cpu);
			}
		}
	}

	void printRatios() const
	{
		const auto read = times_.find("readPass");
		if (read == times_.end() || read->second.real <= 0.0 || read->second.cpu <= 0.0)
			return;
		std::printf(
			"\nRelative to the read pass (fastest of the repetitions; read pass %.2f GB/s wall):\n",
			kWidth * kHeight / read->second.real * 1e-9);
		std::printf("  %-30s %10s %7s %10s %7s\n", "", "wall us", "ratio", "cpu us",
			    "ratio");
		for (const auto &[name, t] : times_)
			std::printf("  %-30s %10.1f %6.2fx %10.1f %6.2fx\n", name.c_str(),
				    t.real * 1e6, t.real / read->second.real, t.cpu * 1e6,
				    t.cpu / read->second.cpu);
	}

private:
	struct Times {
		double real, cpu;
	};
	std::map<std::string, Times> times_;
};

} /* namespace */

int main(int argc, char **argv)
{
	benchmark::Initialize(&argc, argv);
	if (benchmark::ReportUnrecognizedArguments(argc, argv))
		return 1;
	frame(); /* render outside the timings */
	RatioReporter reporter;
	benchmark::RunSpecifiedBenchmarks(&reporter);
	reporter.printRatios();
	benchmark::Shutdown();
	return 0;
}

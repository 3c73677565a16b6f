/* SPDX-License-Identifier: MIT */
#include "tools/dockpose/calibrate.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <utility>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "algo/blob_detector.h"
#include "algo/camera_model.h"
#include "algo/io/model_json.h"
#include "algo/io/pgm.h"
#include "algo/threshold.h"

namespace dockpose::tool {

namespace {

using json = nlohmann::json;

/* The image is cut into kCoverageCells x kCoverageCells cells for the coverage check. */
constexpr int kCoverageCells = 4;
/* Dots should reach this fraction of the distance from the principal point to the farthest
 * image corner: beyond the dots, k1 and k2 are extrapolated. */
constexpr double kMinCornerReach = 0.8;
/* Fewer frames than this are enough to solve but leave the 1 sigmas optimistic. */
constexpr int kFewFrames = 10;

const char *typeName(const json &j)
{
	switch (j.type()) {
	case json::value_t::null:
		return "null";
	case json::value_t::boolean:
		return "a boolean";
	case json::value_t::string:
		return "a string";
	case json::value_t::array:
		return "an array";
	case json::value_t::object:
		return "an object";
	case json::value_t::number_integer:
	case json::value_t::number_unsigned:
		return "an integer";
	case json::value_t::number_float:
		return "a number";
	default:
		return "a value of another kind";
	}
}

Status readGridInt(const json &doc, const char *key, const std::string &source, int *out)
{
	const auto it = doc.find(key);
	if (it == doc.end())
		return Status::error(source + ": key '" + key + "' is missing (an integer >= 2)");
	if (!it->is_number_integer())
		return Status::error(source + ": '" + key + "' must be an integer, not " +
				     typeName(*it));
	const auto value = it->get<long long>();
	if (value < 2 || value > 1000)
		return Status::error(source + ": '" + key + "' must be 2..1000, not " + it->dump());
	*out = static_cast<int>(value);
	return Status::ok();
}

/* The product's blobs of one frame: centroids of the dot-like ones, in pixels. */
struct Dots {
	std::vector<cv::KeyPoint> keypoints;
	int components = 0; /* connected components above the threshold */
	bool overflow = false;
};

/*
 * Threshold and label the frame with the product's detector (algo/blob_detector.h) and keep
 * the components a dot of this grid can be: larger than a speck, smaller than its cell of the
 * frame (the grid's dots do not overlap), not a streak and not sparse (the product's own shape
 * limits). Every component is measured, without the pipeline's cap on candidates.
 */
Dots findDots(BlobDetector *detector, const ImageView &image, const GridSpec &grid)
{
	const BlobFilterConfig shape; /* the product's defaults: elongation, fill, speck size */
	const double max_area_px = static_cast<double>(image.width) * image.height / grid.count();
	ThresholdStats threshold;
	const ThresholdMap &map = detector->thresholder().compute(image, &threshold);
	Dots dots;
	const bool labelled = detector->label(image, map, [&](const BlobMoments &m) {
		++dots.components;
		if (static_cast<int>(m.area) < std::max(shape.min_area_px, 3) ||
		    m.area > max_area_px)
			return;
		const Blob b = BlobDetector::measure(m, threshold.noise_sigma, threshold.noise_gain,
						     detector->thresholder().contrast());
		if (b.elongation > shape.max_elongation || b.fill < shape.min_fill)
			return;
		const float size = static_cast<float>(2.0 * std::sqrt(b.area_px / M_PI));
		dots.keypoints.emplace_back(static_cast<float>(b.u_px), static_cast<float>(b.v_px),
					    size, -1.0F, static_cast<float>(b.weight));
	});
	dots.overflow = !labelled;
	return dots;
}

/* findCirclesGrid's "blob detector": hands over the product's centroids. */
class CentroidFeeder : public cv::Feature2D
{
public:
	explicit CentroidFeeder(std::vector<cv::KeyPoint> keypoints)
		: keypoints_(std::move(keypoints))
	{
	}
	void detect(cv::InputArray, std::vector<cv::KeyPoint> &keypoints, cv::InputArray) override
	{
		keypoints = keypoints_;
	}

private:
	std::vector<cv::KeyPoint> keypoints_;
};

struct Frame {
	std::string path;
	std::vector<cv::Point2f> centres; /* grid order */
	double rms_px = 0.0;
};

std::string fixed(double v, int decimals)
{
	char text[64];
	std::snprintf(text, sizeof(text), "%.*f", decimals, v);
	return text;
}

std::string isoDateUtc()
{
	const std::time_t now = std::time(nullptr);
	std::tm utc{};
	gmtime_r(&now, &utc);
	char text[32];
	std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &utc);
	return text;
}

struct Solution {
	cv::Mat camera_matrix;
	cv::Mat distortion;
	cv::Mat sigma; /* stdDeviationsIntrinsics: fx fy cx cy k1 k2 p1 p2 k3 ... */
	double rms_px = 0.0;
};

Solution solve(const GridSpec &grid, std::vector<Frame> *frames, cv::Size size)
{
	std::vector<cv::Point3f> object;
	for (const Eigen::Vector3d &p : grid.points())
		object.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), 0.0F);
	std::vector<std::vector<cv::Point3f>> object_points(frames->size(), object);
	std::vector<std::vector<cv::Point2f>> image_points;
	for (const Frame &f : *frames)
		image_points.push_back(f.centres);
	Solution s;
	std::vector<cv::Mat> rvecs, tvecs;
	cv::Mat sigma_extrinsics, per_view;
	/* k3 fixed to 0: OpenCV's model is then the product's Brown-Conrady k1 k2 p1 p2. */
	const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100,
					1e-12);
	s.rms_px = cv::calibrateCamera(object_points, image_points, size, s.camera_matrix,
				       s.distortion, rvecs, tvecs, s.sigma, sigma_extrinsics,
				       per_view, cv::CALIB_FIX_K3, criteria);
	for (std::size_t i = 0; i < frames->size(); ++i)
		(*frames)[i].rms_px = per_view.at<double>(static_cast<int>(i));
	return s;
}

double median(std::vector<double> v)
{
	std::sort(v.begin(), v.end());
	const std::size_t n = v.size();
	return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/*
 * The coverage of the image by the dots of the frames used: the border cells of a
 * kCoverageCells x kCoverageCells grid that no dot falls in, and how far out the dots reach
 * as a fraction of the farthest corner's distance from the principal point.
 */
void reportCoverage(const std::vector<Frame> &frames, cv::Size size, double cx, double cy)
{
	std::array<std::array<int, kCoverageCells>, kCoverageCells> cells{};
	double reach_px = 0.0;
	for (const Frame &f : frames)
		for (const cv::Point2f &p : f.centres) {
			const double x = static_cast<double>(p.x), y = static_cast<double>(p.y);
			const int c = std::clamp(static_cast<int>(x * kCoverageCells / size.width),
						 0, kCoverageCells - 1);
			const int r = std::clamp(static_cast<int>(y * kCoverageCells / size.height),
						 0, kCoverageCells - 1);
			++cells[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)];
			reach_px = std::max(reach_px, std::hypot(x - cx, y - cy));
		}
	double corner_px = 0.0;
	for (const double u : { 0.0, static_cast<double>(size.width) })
		for (const double v : { 0.0, static_cast<double>(size.height) })
			corner_px = std::max(corner_px, std::hypot(u - cx, v - cy));
	std::string empty;
	int empty_count = 0;
	for (int r = 0; r < kCoverageCells; ++r)
		for (int c = 0; c < kCoverageCells; ++c) {
			const bool border = r == 0 || c == 0 || r == kCoverageCells - 1 ||
					    c == kCoverageCells - 1;
			if (!border ||
			    cells[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)])
				continue;
			empty += (empty.empty() ? "" : " ") + std::string("(row ") +
				 std::to_string(r) + ", col " + std::to_string(c) + ")";
			++empty_count;
		}
	const double reach = reach_px / corner_px;
	std::printf("coverage: dots in %d of %d border cells of a %dx%d grid of the image; they "
		    "reach %.0f %% of the way to the farthest corner\n",
		    4 * (kCoverageCells - 1) - empty_count, 4 * (kCoverageCells - 1),
		    kCoverageCells, kCoverageCells, 100.0 * reach);
	if (empty_count > 0)
		std::printf("warning: no dot in the border cell(s) %s: k1 and k2 are not well "
			    "determined there; add views with the grid in those corners/edges\n",
			    empty.c_str());
	if (reach < kMinCornerReach)
		std::printf("warning: the dots reach only %.0f %% of the corner radius (less than "
			    "%.0f %%): k1 and k2 are extrapolated beyond; add views with dots in "
			    "the corners\n",
			    100.0 * reach, 100.0 * kMinCornerReach);
}

} /* namespace */

std::vector<Eigen::Vector3d> GridSpec::points() const
{
	std::vector<Eigen::Vector3d> out;
	for (int i = 0; i < rows; ++i)
		for (int j = 0; j < cols; ++j) {
			const double x = layout == Layout::Symmetric ? j * spacing_mm
								     : (2 * j + i % 2) * spacing_mm;
			out.emplace_back(x, i * spacing_mm, 0.0);
		}
	return out;
}

double GridSpec::pitchMm() const
{
	/* Asymmetric: the nearest neighbour is diagonal, sqrt(2) x spacing. */
	return layout == Layout::Symmetric ? spacing_mm : std::sqrt(2.0) * spacing_mm;
}

Result<GridSpec> parseGridSpec(const std::string &json_text, const std::string &source)
{
	json doc;
	try {
		doc = json::parse(json_text);
	} catch (const json::exception &e) {
		return Status::error(source + ": not valid JSON: " + e.what());
	}
	if (!doc.is_object())
		return Status::error(source + ": the grid file must be a JSON object, not " +
				     std::string(typeName(doc)));
	for (auto it = doc.begin(); it != doc.end(); ++it)
		if (it.key() != "rows" && it.key() != "cols" && it.key() != "spacing_mm" &&
		    it.key() != "layout")
			return Status::error(source + ": unknown key '" + it.key() +
					     "' (a grid has rows, cols, spacing_mm, layout)");
	GridSpec grid;
	if (Status s = readGridInt(doc, "rows", source, &grid.rows); !s)
		return s;
	if (Status s = readGridInt(doc, "cols", source, &grid.cols); !s)
		return s;
	const auto spacing = doc.find("spacing_mm");
	if (spacing == doc.end())
		return Status::error(source + ": key 'spacing_mm' is missing (mm between dots)");
	if (!spacing->is_number())
		return Status::error(source + ": 'spacing_mm' must be a number, not " +
				     typeName(*spacing));
	grid.spacing_mm = spacing->get<double>();
	if (!(std::isfinite(grid.spacing_mm) && grid.spacing_mm > 0.0 &&
	      grid.spacing_mm <= 10000.0))
		return Status::error(source + ": 'spacing_mm' must be in (0, 10000] mm, not " +
				     spacing->dump());
	const auto layout = doc.find("layout");
	if (layout != doc.end()) {
		if (!layout->is_string())
			return Status::error(
				source + R"(: 'layout' must be "symmetric" or "asymmetric", not )" +
				typeName(*layout));
		const std::string name = layout->get<std::string>();
		if (name == "symmetric")
			grid.layout = GridSpec::Layout::Symmetric;
		else if (name == "asymmetric")
			grid.layout = GridSpec::Layout::Asymmetric;
		else
			return Status::error(
				source +
				R"(: 'layout' must be "symmetric" or "asymmetric", not ")" + name +
				"\"");
	}
	if (grid.layout == GridSpec::Layout::Symmetric && grid.rows == grid.cols)
		return Status::error(source + ": a symmetric grid needs rows != cols (" +
				     std::to_string(grid.rows) + " x " + std::to_string(grid.cols) +
				     " looks the same turned by 90 degrees)");
	return grid;
}

Result<GridSpec> loadGridSpec(const std::string &path)
{
	Result<std::string> text = readFileContents(path);
	if (!text)
		return text.status();
	return parseGridSpec(text.value(), path);
}

int runCalibrate(const CalibrateArgs &args)
{
	Result<GridSpec> loaded = loadGridSpec(args.grid_path);
	if (!loaded) {
		std::fprintf(stderr, "dockpose calibrate: %s\n", loaded.message().c_str());
		return 2;
	}
	const GridSpec grid = loaded.value();
	const bool symmetric = grid.layout == GridSpec::Layout::Symmetric;
	const cv::Size pattern(grid.cols, grid.rows);
	const int flags = symmetric ? cv::CALIB_CB_SYMMETRIC_GRID : cv::CALIB_CB_ASYMMETRIC_GRID;

	std::vector<Frame> frames;
	cv::Size size;
	std::unique_ptr<BlobDetector> detector;
	bool unreadable = false;
	for (const std::string &path : args.images) {
		Result<Image> image = readPgm(path);
		if (!image) {
			std::fprintf(stderr, "dockpose calibrate: %s\n", image.message().c_str());
			unreadable = true;
			continue;
		}
		const ImageView view = image->view();
		if (!detector) {
			size = cv::Size(view.width, view.height);
			detector = std::make_unique<BlobDetector>(
				view.width, view.height, ThresholdConfig{}, BlobFilterConfig{});
		} else if (view.width != size.width || view.height != size.height) {
			std::fprintf(
				stderr,
				"dockpose calibrate: %s: skipped: %dx%d, not the first image's "
				"%dx%d\n",
				path.c_str(), view.width, view.height, size.width, size.height);
			continue;
		}
		Dots dots = findDots(detector.get(), view, grid);
		if (dots.overflow) {
			std::fprintf(
				stderr,
				"dockpose calibrate: %s: skipped: too many bright components to "
				"label (%d): not a grid on a dark background\n",
				path.c_str(), dots.components);
			continue;
		}
		const std::size_t found = dots.keypoints.size();
		if (found < static_cast<std::size_t>(grid.count())) {
			std::fprintf(stderr,
				     "dockpose calibrate: %s: skipped: %zu dot(s) found, the %dx%d "
				     "grid has %d (the whole grid must be in view)\n",
				     path.c_str(), found, grid.rows, grid.cols, grid.count());
			continue;
		}
		const cv::Mat mat(view.height, view.width, CV_8UC1,
				  const_cast<std::uint8_t *>(view.data),
				  static_cast<std::size_t>(view.stride_bytes));
		std::vector<cv::Point2f> centres;
		const cv::Ptr<cv::FeatureDetector> feeder(
			std::make_shared<CentroidFeeder>(std::move(dots.keypoints)));
		/* OpenCV's grid finder first (tolerates extra blobs), then its clustering
		 * (tolerates stronger perspective and distortion, but not blobs among the dots). */
		const bool ordered = cv::findCirclesGrid(mat, pattern, centres, flags, feeder) ||
				     cv::findCirclesGrid(mat, pattern, centres,
							 flags | cv::CALIB_CB_CLUSTERING, feeder);
		if (!ordered || centres.size() != static_cast<std::size_t>(grid.count())) {
			std::fprintf(stderr,
				     "dockpose calibrate: %s: skipped: %zu dots found but no %dx%d "
				     "%s grid among them\n",
				     path.c_str(), found, grid.rows, grid.cols,
				     symmetric ? "symmetric" : "asymmetric");
			continue;
		}
		frames.push_back({ path, std::move(centres), 0.0 });
	}
	if (static_cast<int>(frames.size()) < kMinFrames) {
		std::fprintf(stderr,
			     "dockpose calibrate: the grid was found in %zu frame(s); at least %d "
			     "are needed (docs/calibration.md: 15-25 views)\n",
			     frames.size(), kMinFrames);
		return 1;
	}

	Solution s = solve(grid, &frames, size);
	for (int round = 0; round < kMaxOutlierRounds; ++round) {
		std::vector<double> rms;
		rms.reserve(frames.size());
		for (const Frame &f : frames)
			rms.push_back(f.rms_px);
		const double limit = kOutlierFactor * median(rms);
		std::vector<Frame> kept;
		for (Frame &f : frames) {
			if (f.rms_px > limit)
				std::printf(
					"dropped %s: rms %.3f px > %.0f x the median (%.3f px)\n",
					f.path.c_str(), f.rms_px, kOutlierFactor,
					limit / kOutlierFactor);
			else
				kept.push_back(std::move(f));
		}
		if (kept.size() == frames.size()) {
			frames = std::move(kept);
			break;
		}
		frames = std::move(kept);
		if (static_cast<int>(frames.size()) < kMinFrames) {
			std::fprintf(stderr,
				     "dockpose calibrate: only %zu frame(s) left after dropping "
				     "outliers; at least %d are needed\n",
				     frames.size(), kMinFrames);
			return 1;
		}
		s = solve(grid, &frames, size);
	}
	for (const Frame &f : frames)
		std::printf("frame %s: %d dots, rms %.3f px\n", f.path.c_str(), grid.count(),
			    f.rms_px);

	CameraIntrinsics k;
	k.width = size.width;
	k.height = size.height;
	k.fx = s.camera_matrix.at<double>(0, 0);
	k.fy = s.camera_matrix.at<double>(1, 1);
	k.cx = s.camera_matrix.at<double>(0, 2);
	k.cy = s.camera_matrix.at<double>(1, 2);
	const double *d = s.distortion.ptr<double>();
	k.k1 = d[0];
	k.k2 = d[1];
	k.p1 = d[2];
	k.p2 = d[3];
	const double *sd = s.sigma.ptr<double>();
	k.sigma = { sd[0], sd[1], sd[2], sd[3], sd[4], sd[5], sd[6], sd[7] };

	struct Parameter {
		const char *name;
		double value, sigma;
		int decimals;
	} const parameters[] = {
		{ "fx", k.fx, k.sigma.fx, 3 }, { "fy", k.fy, k.sigma.fy, 3 },
		{ "cx", k.cx, k.sigma.cx, 3 }, { "cy", k.cy, k.sigma.cy, 3 },
		{ "k1", k.k1, k.sigma.k1, 5 }, { "k2", k.k2, k.sigma.k2, 5 },
		{ "p1", k.p1, k.sigma.p1, 6 }, { "p2", k.p2, k.sigma.p2, 6 },
	};
	std::printf("%zu frame(s) used of %zu image(s); rms %.3f px\n", frames.size(),
		    args.images.size(), s.rms_px);
	for (const Parameter &p : parameters)
		std::printf("  %s = %s +- %s (1 sigma)\n", p.name,
			    fixed(p.value, p.decimals).c_str(), fixed(p.sigma, p.decimals).c_str());
	reportCoverage(frames, size, k.cx, k.cy);
	if (static_cast<int>(frames.size()) < kFewFrames)
		std::printf("warning: %zu frames; with fewer than %d the 1 sigmas are optimistic\n",
			    frames.size(), kFewFrames);
	if (Status v = k.validate(); !v) {
		std::fprintf(stderr,
			     "dockpose calibrate: the solution is not a usable camera: %s\n",
			     v.message().c_str());
		return 1;
	}

	nlohmann::ordered_json out;
	out["width"] = k.width;
	out["height"] = k.height;
	for (const Parameter &p : parameters)
		out[p.name] = p.value;
	out["rms_px"] = s.rms_px;
	nlohmann::ordered_json sigma;
	for (const Parameter &p : parameters)
		sigma[p.name] = p.sigma;
	out["sigma"] = sigma;
	out["frames"] = frames.size();
	out["date"] = isoDateUtc();
	const std::string text = out.dump(2) + "\n";
	/* The product must read what was written. */
	if (Result<CameraIntrinsics> check = parseCameraIntrinsics(text, args.output_path);
	    !check) {
		std::fprintf(stderr, "dockpose calibrate: %s\n", check.message().c_str());
		return 1;
	}
	std::ofstream file(args.output_path);
	file << text;
	file.close();
	if (!file) {
		std::fprintf(stderr, "dockpose calibrate: %s: cannot write\n",
			     args.output_path.c_str());
		return 1;
	}
	std::printf("wrote %s\n", args.output_path.c_str());
	return unreadable ? 1 : 0;
}

} /* namespace dockpose::tool */

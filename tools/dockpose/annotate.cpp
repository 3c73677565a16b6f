/* SPDX-License-Identifier: MIT */
/*
 * Annotated debug frames: see annotate.h.
 */
#include "tools/dockpose/annotate.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>

#include <Eigen/Core>

namespace dockpose::annotate {

RgbImage::RgbImage(int width, int height)
	: width_(std::max(0, width)),
	  height_(std::max(0, height)),
	  bytes_(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 3u, 0)
{
}

RgbImage RgbImage::fromGrey(const ImageView &grey)
{
	if (!grey.valid())
		return {};
	RgbImage out(grey.width, grey.height);
	std::uint8_t *p = out.bytes_.data();
	for (int y = 0; y < grey.height; ++y) {
		const std::uint8_t *row = grey.row(y);
		for (int x = 0; x < grey.width; ++x) {
			*p++ = row[x];
			*p++ = row[x];
			*p++ = row[x];
		}
	}
	return out;
}

void RgbImage::set(int x, int y, Rgb colour)
{
	if (x < 0 || y < 0 || x >= width_ || y >= height_)
		return;
	std::uint8_t *p =
		bytes_.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) +
				 static_cast<std::size_t>(x)) *
					3u;
	p[0] = colour.r;
	p[1] = colour.g;
	p[2] = colour.b;
}

Rgb RgbImage::at(int x, int y) const
{
	const std::uint8_t *p =
		bytes_.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) +
				 static_cast<std::size_t>(x)) *
					3u;
	return { p[0], p[1], p[2] };
}

void stamp(RgbImage *image, int x, int y, Rgb colour, int thickness_px)
{
	const int t = std::max(1, thickness_px);
	const int lo = -(t - 1) / 2;
	for (int dy = lo; dy < lo + t; ++dy)
		for (int dx = lo; dx < lo + t; ++dx)
			image->set(x + dx, y + dy, colour);
}

void drawLine(RgbImage *image, int x0, int y0, int x1, int y1, Rgb colour, int thickness_px)
{
	/* Bresenham, all octants: err = dx + dy with dy <= 0. */
	const int dx = std::abs(x1 - x0), sx = x0 < x1 ? 1 : -1;
	const int dy = -std::abs(y1 - y0), sy = y0 < y1 ? 1 : -1;
	int err = dx + dy;
	for (;;) {
		stamp(image, x0, y0, colour, thickness_px);
		if (x0 == x1 && y0 == y1)
			break;
		const int e2 = 2 * err;
		if (e2 >= dy) {
			err += dy;
			x0 += sx;
		}
		if (e2 <= dx) {
			err += dx;
			y0 += sy;
		}
	}
}

void drawCircle(RgbImage *image, int cx, int cy, int radius_px, Rgb colour, int thickness_px)
{
	/* Midpoint circle: one octant computed, eight mirrored. */
	int x = std::max(1, radius_px);
	int y = 0;
	int err = 1 - x;
	while (x >= y) {
		const int px[8] = { x, y, -y, -x, -x, -y, y, x };
		const int py[8] = { y, x, x, y, -y, -x, -x, -y };
		for (int i = 0; i < 8; ++i)
			stamp(image, cx + px[i], cy + py[i], colour, thickness_px);
		++y;
		if (err < 0) {
			err += 2 * y + 1;
		} else {
			--x;
			err += 2 * (y - x) + 1;
		}
	}
}

void drawCross(RgbImage *image, int cx, int cy, int arm_px, Rgb colour, int thickness_px)
{
	drawLine(image, cx - arm_px, cy, cx + arm_px, cy, colour, thickness_px);
	drawLine(image, cx, cy - arm_px, cx, cy + arm_px, colour, thickness_px);
}

void drawBorder(RgbImage *image, int width_px, Rgb colour)
{
	const int w = image->width(), h = image->height();
	const int b = std::min({ width_px, w, h });
	for (int y = 0; y < h; ++y) {
		const bool full_row = y < b || y >= h - b;
		for (int x = 0; x < w; ++x)
			if (full_row || x < b || x >= w - b)
				image->set(x, y, colour);
	}
}

Style Style::fromWidth(int width_px)
{
	Style s;
	s.stroke_px = std::max(1, (width_px + 600) / 1000);
	s.led_radius_px = std::max(6, width_px / 100);
	s.cross_arm_px = std::max(4, width_px / 180);
	s.border_px = std::max(4, width_px / 100);
	return s;
}

namespace {

int pixelIndex(double coordinate_px)
{
	return static_cast<int>(std::lround(coordinate_px));
}

/*
 * The projection of a camera-frame point, if it is in front of the camera,
 * where the lens model is still monotonic (far off axis the radial polynomial
 * folds back into the frame) and not far outside the image.
 */
bool projectNear(const CameraModel &camera, const Eigen::Vector3d &p_mm, Eigen::Vector2d *uv)
{
	if (!camera.project(p_mm, uv) || !uv->allFinite())
		return false;
	const CameraIntrinsics &k = camera.intrinsics();
	const double r2 = (p_mm.x() * p_mm.x() + p_mm.y() * p_mm.y()) / (p_mm.z() * p_mm.z());
	if (1.0 + 3.0 * k.k1 * r2 + 5.0 * k.k2 * r2 * r2 <= 0.0)
		return false;
	const double margin = 0.5 * std::max(k.width, k.height);
	return camera.inImage(*uv, -margin);
}

} /* namespace */

void annotateFrame(RgbImage *image, const CameraModel &camera, const TargetModel &target,
		   const StaticVector<Blob, kMaxCandidates> &blobs, const PoseResult &result,
		   const Style &style)
{
	if (result.found) {
		StaticVector<Eigen::Vector3d, kMaxFaces> normals;
		target.frontNormals(&normals);

		/*
		 * Faces first, so the LED circles and blob crosses stay on top; the
		 * frame before the faces restores the inside of each circle, so the
		 * edges stop at the circles and the LED spots stay visible.
		 */
		const RgbImage frame = *image;
		std::uint32_t facing_leds = 0;
		for (std::size_t f = 0; f < target.faces.size(); ++f) {
			const std::array<int, 4> &face = target.faces[f];
			Eigen::Vector3d centre = Eigen::Vector3d::Zero();
			for (int i : face)
				centre += target.points_mm[static_cast<std::size_t>(i)];
			centre /= 4.0;
			const Eigen::Vector3d normal_c = result.R * normals[f];
			const Eigen::Vector3d centre_c = result.R * centre + result.t_mm;
			const bool facing = normal_c.dot(centre_c) < 0.0;
			if (facing)
				for (int i : face)
					facing_leds |= 1u << i;
			const Rgb colour = facing ? kGreen : kDarkGreen;
			for (int e = 0; e < 4; ++e) {
				const Eigen::Vector3d a =
					target.points_mm[static_cast<std::size_t>(face[e])];
				const Eigen::Vector3d b = target.points_mm[static_cast<std::size_t>(
					face[(e + 1) % 4])];
				/* The edge as a polyline: lens distortion bends straight lines. */
				Eigen::Vector2d prev;
				bool have_prev = false;
				for (int s = 0; s <= style.edge_segments; ++s) {
					const double w =
						static_cast<double>(s) / style.edge_segments;
					const Eigen::Vector3d p =
						result.R * (a + w * (b - a)) + result.t_mm;
					Eigen::Vector2d uv;
					const bool ok = projectNear(camera, p, &uv);
					if (ok && have_prev)
						drawLine(image, pixelIndex(prev.x()),
							 pixelIndex(prev.y()), pixelIndex(uv.x()),
							 pixelIndex(uv.y()), colour,
							 style.stroke_px);
					prev = uv;
					have_prev = ok;
				}
			}
		}

		for (std::size_t i = 0; i < target.points_mm.size(); ++i) {
			const bool matched = (result.led_mask >> i) & 1u;
			Eigen::Vector2d uv;
			if (!projectNear(camera, result.R * target.points_mm[i] + result.t_mm, &uv))
				continue;
			const bool predicted = camera.inImage(uv) && ((facing_leds >> i) & 1u);
			if (!matched && !predicted)
				continue;
			const int cx = pixelIndex(uv.x()), cy = pixelIndex(uv.y());
			const int inner = style.led_radius_px - style.stroke_px;
			for (int y = cy - inner; y <= cy + inner; ++y)
				for (int x = cx - inner; x <= cx + inner; ++x)
					if (x >= 0 && y >= 0 && x < frame.width() &&
					    y < frame.height() &&
					    (x - cx) * (x - cx) + (y - cy) * (y - cy) <=
						    inner * inner)
						image->set(x, y, frame.at(x, y));
			drawCircle(image, cx, cy, style.led_radius_px, matched ? kGreen : kRed,
				   style.stroke_px);
		}
	}

	for (const Blob &blob : blobs)
		drawCross(image, pixelIndex(blob.u_px), pixelIndex(blob.v_px), style.cross_arm_px,
			  kYellow, style.stroke_px);

	if (!result.found)
		drawBorder(image, style.border_px, kRed);
}

std::string writePpm(const std::string &path, const RgbImage &image)
{
	std::ofstream out(path, std::ios::binary | std::ios::trunc);
	if (!out)
		return path + ": cannot create: " + std::strerror(errno);
	out << "P6\n" << image.width() << ' ' << image.height() << "\n255\n";
	out.write(reinterpret_cast<const char *>(image.bytes().data()),
		  static_cast<std::streamsize>(image.bytes().size()));
	out.close();
	if (!out)
		return path + ": write failed";
	return {};
}

} /* namespace dockpose::annotate */

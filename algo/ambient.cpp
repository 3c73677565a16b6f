/* SPDX-License-Identifier: MIT */
#include "algo/ambient.h"

namespace dockpose {

bool subtractAmbient(const ImageView &lit, const ImageView &unlit, std::uint8_t *out,
		     int out_stride_bytes)
{
	if (!lit.valid() || !unlit.valid() || !out || lit.width != unlit.width ||
	    lit.height != unlit.height || out_stride_bytes < lit.width)
		return false;
	for (int y = 0; y < lit.height; ++y) {
		const std::uint8_t *a = lit.row(y);
		const std::uint8_t *b = unlit.row(y);
		std::uint8_t *o = out + static_cast<std::ptrdiff_t>(y) * out_stride_bytes;
		/* Written so GCC vectorises it (a saturating subtract per byte). */
		for (int x = 0; x < lit.width; ++x) {
			const int d = a[x] - b[x];
			o[x] = static_cast<std::uint8_t>(d > 0 ? d : 0);
		}
	}
	return true;
}

} /* namespace dockpose */

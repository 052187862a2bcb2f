// The PNG encoder behind every PNG lfnet writes (views, grids, EPIs, the viewer's pictures):
// each row filtered with Sub, the image data compressed by libdeflate at its fastest level
// (docs/performance.md, "End to end": 2.7 times faster than zlib's level 1 on a 16-bit view, and
// files 3 % smaller). Reading stays with OpenImageIO.
#pragma once

#include <cstdint>
#include <string>

namespace lfnet::io {

// The bytes of a PNG file holding `samples`: height x width pixels of `channels` interleaved
// samples (1 grey, 2 grey and alpha, 3 RGB, 4 RGBA), row-major, `bits` 8 (uint8_t) or 16
// (uint16_t, in the machine's byte order).
std::string encode_png_samples(const void* samples, int64_t height, int64_t width, int64_t channels,
                               int bits);

}  // namespace lfnet::io

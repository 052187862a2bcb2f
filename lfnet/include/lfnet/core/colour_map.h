// The one colour map of lfnet's pictures (disparity maps, the viewer's error maps): viridis, as
// matplotlib draws it (scripts/figures.py uses matplotlib's own).
#pragma once

#include <torch/types.h>

#include <array>
#include <cstdint>
#include <vector>

namespace lfnet {

// Values in [0, 1] of any shape S to RGB (3, S...) float32 in [0, 1]; values outside are
// clamped, NaN maps to 0.
torch::Tensor viridis(const torch::Tensor& values);

// The map as `levels` 8-bit RGB entries from 0 to 1, for pages that colour on their own.
std::vector<std::array<uint8_t, 3>> viridis_table(int levels = 256);

}  // namespace lfnet

// A Phi's angular responses as tiles, for the documentation and `lfnet simulate --plot-weights`
// (drawn by scripts/figures.py, kind "weights").
#pragma once

#include <torch/types.h>

#include <array>
#include <cstdint>
#include <vector>

#include "lfnet/optics/phi.h"

namespace lfnet::optics {

// One tile per (pixel, measurement): the weights M_n(u, v) of measurement n at a pixel, as a
// U x V picture of its views (u down, v across). Columns are the measurements; rows the first
// `pixels` pixels of the top row of the sensor (x = 0, 1, ...), capped at the period, so
// periodic models show how the code moves; a period of T x T pixels with T^2 <= `pixels` (an
// ASP tile of 2 x 2) shows all of them, row by row. A model with one pixel pattern wraps its
// measurements into rows of `wrap` (unused places are 0.5). Random projections show the
// matrix row of measurement n at pixel (0, x): U x V views of the whole b x b block each, with
// a line of 1 between views.
struct WeightTiles {
  torch::Tensor tiles;          // (rows, columns, h, w) float64 in [0, 1]
  bool signed_weights = false;  // values are 0.5 + 0.5 w / max|w| (else w / max w)
  bool wrapped = false;         // one pixel's measurements in rows of `wrap`
  int64_t wrap = 0;
  std::vector<std::array<int64_t, 2>> pixels;  // (y, x) of each row's pixel (not when wrapped)
};
WeightTiles weight_tiles(const Phi& phi, int64_t pixels = 4, int64_t wrap = 5);

}  // namespace lfnet::optics

// Pictures of a Phi's angular responses, for the documentation and `lfnet simulate
// --plot-weights`.
#pragma once

#include <torch/types.h>

#include <cstdint>

#include "lfnet/optics/phi.h"

namespace lfnet::optics {

// One tile per (pixel, measurement): the weights M_n(u, v) of measurement n at a pixel, as a
// U x V picture of its views (u down, v across), each view `scale` x `scale` pixels. Columns
// are the measurements; rows the first `pixels` pixels of the top row of the sensor (x = 0,
// 1, ...), capped at the period, so periodic models show how the code moves. A model with one
// pixel pattern wraps its measurements into rows of `wrap`. Random projections show the
// matrix row of measurement n at pixel (0, x): U x V views of the whole b x b block each.
// Non-negative weights map to [0, 1] by the largest weight; signed ones to 0.5 + 0.5 w / max|w|.
// Tiles are separated by blue lines. Returns an RGB image (3, H, W) float32 in [0, 1].
torch::Tensor weights_image(const Phi& phi, int64_t scale = 16, int64_t pixels = 4,
                            int64_t wrap = 5);

}  // namespace lfnet::optics

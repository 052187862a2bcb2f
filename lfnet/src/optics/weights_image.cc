#include "lfnet/optics/weights_image.h"

#include <torch/torch.h>

#include <algorithm>

#include "lfnet/core/error.h"

namespace lfnet::optics {

WeightTiles weight_tiles(const Phi& phi, int64_t pixels, int64_t wrap) {
  LFNET_CHECK(pixels >= 1 && wrap >= 1, "weight_tiles: pixels and wrap must be >= 1");
  const int64_t n = phi.measurements(), u = phi.rows(), v = phi.cols();
  WeightTiles out;
  out.wrap = wrap;
  if (phi.local()) {
    const int64_t t = phi.period();
    // The whole period when it fits, row by row; else the first pixels of the top row.
    const int64_t p = std::min(pixels, t), h = t > 1 && t * t <= pixels ? t : 1;
    auto w = phi.pixel_weights(0, 0, h, p, torch::kFloat64).reshape({n, u, v, h * p});
    w = w / w.max();
    auto views = w.permute({3, 0, 1, 2});  // (h p, N, U, V)
    for (int64_t y = 0; y < h; ++y) {
      for (int64_t x = 0; x < p; ++x) out.pixels.push_back({y, x});
    }
    if (p == 1 && n > wrap) {  // wrap one pixel's measurements into rows
      const int64_t rows = (n + wrap - 1) / wrap;
      auto padded = torch::full({rows * wrap, u, v}, 0.5, torch::kFloat64);
      padded.slice(0, 0, n).copy_(views[0]);
      views = padded.view({rows, wrap, u, v});
      out.wrapped = true;
      out.pixels.clear();
    }
    out.tiles = views.contiguous();
    return out;
  }
  const int64_t b = phi.block();
  auto a = phi.patch_matrix(0, 0, b, b, torch::kFloat64).view({n, b, b, u, v, b, b});
  const int64_t p = std::min(pixels, b);
  for (int64_t x = 0; x < p; ++x) out.pixels.push_back({0, x});
  auto rows = a.select(1, 0).slice(1, 0, p).permute({1, 0, 2, 3, 4, 5});  // (p, N, U, V, b, b)
  rows = 0.5 + 0.5 * rows / rows.abs().max();
  // (p, N, U, V, b, b) -> (p, N, U b, V b), a line of 1 between views.
  auto framed = torch::ones({p, n, u, v, b + 1, b + 1}, torch::kFloat64);
  framed.slice(4, 0, b).slice(5, 0, b).copy_(rows);
  out.tiles = framed.permute({0, 1, 2, 4, 3, 5})
                  .reshape({p, n, u * (b + 1), v * (b + 1)})
                  .slice(2, 0, u * (b + 1) - 1)
                  .slice(3, 0, v * (b + 1) - 1)
                  .contiguous();
  out.signed_weights = true;
  return out;
}

}  // namespace lfnet::optics

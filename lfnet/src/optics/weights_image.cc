#include "lfnet/optics/weights_image.h"

#include <torch/torch.h>

#include <algorithm>

#include "lfnet/core/error.h"

namespace lfnet::optics {

torch::Tensor weights_image(const Phi& phi, int64_t scale, int64_t pixels, int64_t wrap) {
  LFNET_CHECK(scale >= 1 && pixels >= 1 && wrap >= 1,
              "weights_image: scale, pixels and wrap "
              "must be >= 1");
  const int64_t n = phi.measurements(), u = phi.rows(), v = phi.cols();
  constexpr int64_t kGap = 3;
  // tiles: (rows of tiles, columns of tiles, tile height, tile width)
  torch::Tensor tiles;
  if (phi.local()) {
    const int64_t p = std::min(pixels, phi.period());
    auto w = phi.pixel_weights(0, 0, 1, p, torch::kFloat64).select(3, 0);  // (N, U, V, p)
    w = w / w.max();
    auto views = w.permute({3, 0, 1, 2});  // (p, N, U, V)
    views = views.repeat_interleave(scale, 2).repeat_interleave(scale, 3);
    if (p == 1 && n > wrap) {  // wrap one pixel's measurements into rows
      const int64_t rows = (n + wrap - 1) / wrap;
      auto padded = torch::full({rows * wrap, u * scale, v * scale}, 0.5, torch::kFloat64);
      padded.slice(0, 0, n).copy_(views[0]);
      views = padded.view({rows, wrap, u * scale, v * scale});
    }
    tiles = views;
  } else {
    const int64_t b = phi.block(), k = std::max<int64_t>(2, scale / b);
    auto a = phi.patch_matrix(0, 0, b, b, torch::kFloat64).view({n, b, b, u, v, b, b});
    const int64_t p = std::min(pixels, b);
    auto rows = a.select(1, 0).slice(1, 0, p).permute({1, 0, 2, 3, 4, 5});  // (p, N, U, V, b, b)
    rows = 0.5 + 0.5 * rows / rows.abs().max();
    // (p, N, U, V, b, b) -> (p, N, U b, V b), a gap of one white pixel between views.
    auto framed = torch::ones({p, n, u, v, b + 1, b + 1}, torch::kFloat64);
    framed.slice(4, 0, b).slice(5, 0, b).copy_(rows);
    tiles = framed.permute({0, 1, 2, 4, 3, 5})
                .reshape({p, n, u * (b + 1), v * (b + 1)})
                .slice(2, 0, u * (b + 1) - 1)
                .slice(3, 0, v * (b + 1) - 1)
                .repeat_interleave(k, 2)
                .repeat_interleave(k, 3);
  }
  const int64_t tr = tiles.size(0), tc = tiles.size(1), th = tiles.size(2), tw = tiles.size(3);
  // Grey tiles on a blue background, so the separators never look like weights.
  auto background = torch::tensor({0.35, 0.55, 0.85}, torch::kFloat64).view({3, 1, 1});
  auto image = background.repeat({1, tr * (th + kGap) - kGap, tc * (tw + kGap) - kGap});
  for (int64_t i = 0; i < tr; ++i) {
    for (int64_t j = 0; j < tc; ++j) {
      image.slice(1, i * (th + kGap), i * (th + kGap) + th)
          .slice(2, j * (tw + kGap), j * (tw + kGap) + tw)
          .copy_(tiles[i][j].unsqueeze(0).expand({3, th, tw}));
    }
  }
  return image.to(torch::kFloat32);
}

}  // namespace lfnet::optics

// Rasterising textures and shapes onto a layer's canvas (internal to the scene library).
#pragma once

#include <ATen/Parallel.h>
#include <torch/types.h>

#include <algorithm>
#include <cstdint>

#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"

namespace lfnet::scene::detail {

// A layer's canvas: the image grown by `margin` px on every side, so that shifting it into any
// view never reads past its border. Canvas pixel (i, j) is image pixel (y, x) = (i - margin,
// j - margin). A window of it (top, left, rows, cols) rasterises part of the same canvas.
struct Canvas {
  int64_t image_height = 0;
  int64_t image_width = 0;
  int64_t margin = 0;
  int64_t top = 0;    // first canvas row of this window
  int64_t left = 0;   // first canvas column of this window
  int64_t rows = -1;  // window size; -1: to the canvas' far edge
  int64_t cols = -1;
  int64_t height() const { return rows >= 0 ? rows : image_height + 2 * margin - top; }
  int64_t width() const { return cols >= 0 ? cols : image_width + 2 * margin - left; }
  // Window pixel (i, j) is image pixel (i - origin_y(), j - origin_x()).
  int64_t origin_y() const { return margin - top; }
  int64_t origin_x() const { return margin - left; }
  Canvas window(int64_t row0, int64_t col0, int64_t nrows, int64_t ncols) const {
    Canvas c = *this;
    c.top = top + row0;
    c.left = left + col0;
    c.rows = nrows;
    c.cols = ncols;
    return c;
  }
};

// The texture's colours on the canvas, (C, Hc, Wc) float32 in [0, 1]; C = 3, or 1 (luma) when
// `color` is false. `seed` is the layer's default seed.
torch::Tensor render_texture(const TextureSpec& texture, const Canvas& canvas, bool color,
                             uint64_t seed, const RenderOptions& options);

// The shape's alpha on the canvas, (Hc, Wc) float32 in [0, 1].
torch::Tensor render_alpha(const ShapeSpec& shape, const Canvas& canvas);

// Smooth value noise of unit variance (averaged over positions): random lattice values at
// spacing `spacing` px, offset by (offset_x, offset_y) lattice cells, interpolated by a cubic
// B-spline. Added times `amplitude` into `field` (Hc, Wc).
void add_value_noise(torch::Tensor& field, const Canvas& canvas, double spacing, double offset_x,
                     double offset_y, uint64_t seed, double amplitude);

// Runs fn(begin, end) over items [0, n), in parallel only when the work (n items of about
// `cost` elementary operations each) pays for waking threads: small scenes and small layers run
// many short loops, and on a busy machine a thread wake-up costs more than they do.
template <typename Fn>
void parallel_items(int64_t n, int64_t cost, const Fn& fn) {
  constexpr int64_t kMinWork = int64_t{1} << 18;
  const int64_t grain = std::max<int64_t>(1, kMinWork / std::max<int64_t>(1, cost));
  at::parallel_for(0, n, grain, fn);
}

// Rec. 601 luma of a colour.
inline double luma(const Rgb& c) { return 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]; }

}  // namespace lfnet::scene::detail

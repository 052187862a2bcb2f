#include "lfnet/core/patches.h"

#include <torch/nn/functional/fold.h>

#include "lfnet/core/error.h"
#include "lfnet/core/file_backed.h"
#include "lfnet/core/light_field.h"

namespace lfnet {

std::vector<int64_t> patch_origins(int64_t extent, int64_t size, int64_t stride) {
  LFNET_CHECK(size >= 1 && stride >= 1, "patch size and stride must be positive (size ", size,
              ", stride ", stride, ")");
  LFNET_CHECK(extent >= size, "a light field of ", extent, " pixels is smaller than one patch of ",
              size);
  std::vector<int64_t> origins;
  for (int64_t o = 0; o + size <= extent; o += stride) origins.push_back(o);
  if (origins.back() + size < extent) origins.push_back(extent - size);
  return origins;
}

PatchGrid::PatchGrid(int64_t height, int64_t width, int64_t patch_h, int64_t patch_w,
                     int64_t stride)
    : height_(height),
      width_(width),
      patch_h_(patch_h),
      patch_w_(patch_w),
      stride_(stride),
      ys_(patch_origins(height, patch_h, stride)),
      xs_(patch_origins(width, patch_w, stride)) {}

namespace {
// Pixel indices covered by the given origins: (n * size) as one flat tensor.
torch::Tensor covered(const std::vector<int64_t>& origins, int64_t begin, int64_t end,
                      int64_t size) {
  auto o = torch::tensor(std::vector<int64_t>(origins.begin() + begin, origins.begin() + end));
  return (o.unsqueeze(1) + torch::arange(size).unsqueeze(0)).reshape({-1});
}
}  // namespace

torch::Tensor PatchGrid::extract(const torch::Tensor& lf, int64_t row_begin,
                                 int64_t row_end) const {
  LFNET_CHECK(
      lf.dim() == axis::kRank && lf.size(axis::kH) == height_ && lf.size(axis::kW) == width_,
      "patch grid of ", height_, "x", width_, " applied to a light field of another size");
  LFNET_CHECK(row_begin >= 0 && row_begin <= row_end && row_end <= rows(), "patch rows [",
              row_begin, ", ", row_end, ") outside [0, ", rows(), ")");
  const int64_t c = lf.size(axis::kC), u = lf.size(axis::kU), v = lf.size(axis::kV);
  const int64_t ny = row_end - row_begin, nx = cols();
  auto rows_idx = covered(ys_, row_begin, row_end, patch_h_);
  auto cols_idx = covered(xs_, 0, nx, patch_w_);
  auto sel = lf.index_select(axis::kH, rows_idx).index_select(axis::kW, cols_idx);
  // (C, U, V, ny, h, nx, w) -> (C, ny, nx, U, V, h, w)
  return sel.view({c, u, v, ny, patch_h_, nx, patch_w_})
      .permute({0, 3, 5, 1, 2, 4, 6})
      .reshape({c * ny * nx, u, v, patch_h_, patch_w_});
}

namespace {

// Maximal runs of evenly spaced origins: (first index, count, step); a grid's origins are one
// run, then at most one origin flush with the edge.
struct OriginRun {
  int64_t first, count, step;
};

std::vector<OriginRun> origin_runs(const std::vector<int64_t>& origins, int64_t begin,
                                   int64_t end) {
  std::vector<OriginRun> runs;
  for (int64_t i = begin; i < end;) {
    const auto at = [&](int64_t k) { return origins[static_cast<size_t>(k)]; };
    const int64_t step = i + 1 < end ? at(i + 1) - at(i) : 1;
    int64_t j = i + 1;
    while (j < end && at(j) - at(j - 1) == step) ++j;
    runs.push_back({i, j - i, step});
    i = j;
  }
  return runs;
}

}  // namespace

Stitcher::Stitcher(const PatchGrid& grid, int64_t channels, int64_t rows, int64_t cols,
                   const torch::Tensor& weight, bool coded)
    : grid_(grid), channels_(channels), rows_(rows), cols_(cols), coded_(coded) {
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  if (weight.defined()) {
    LFNET_CHECK(
        weight.dim() == 2 && weight.size(0) == grid.patch_h() && weight.size(1) == grid.patch_w(),
        "stitching window must be (h, w) = (", grid.patch_h(), ", ", grid.patch_w(), ")");
    weight_ = weight.to(torch::kFloat64).contiguous();
    window_ = true;
  } else {
    weight_ = torch::ones({grid.patch_h(), grid.patch_w()}, opts);
  }
  // Codes of a large light field are file-backed, and finished rows leave memory
  // (core/file_backed.h).
  out_ = coded
             ? file_backed_empty({channels, rows, cols, grid.height(), grid.width()}, torch::kInt16)
             : torch::empty({channels, rows, cols, grid.height(), grid.width()});
  sum_ = torch::zeros({channels * rows * cols, 0, grid.width()}, opts);
  count_ = torch::zeros({1, 0, grid.width()}, opts);
}

void Stitcher::flush(int64_t until) {
  const int64_t w = grid_.width(), n = until - top_;
  if (n <= 0) return;
  LFNET_CHECK(count_.size(1) >= n, "stitching left pixels without any estimate");
  auto count = count_.slice(1, 0, n);
  LFNET_CHECK(count.min().item<double>() > 0, "stitching left pixels without any estimate");
  auto rows = (sum_.slice(1, 0, n) / count).reshape({channels_, rows_, cols_, n, w});
  out_.slice(3, top_, until).copy_(coded_ ? encode_codes(rows) : rows);
  page_out(out_);  // every row above `until` is final
  sum_ = sum_.slice(1, n);
  count_ = count_.slice(1, n);
  top_ = until;
}

void Stitcher::add(const torch::Tensor& patches, int64_t row_begin, int64_t row_end) {
  const int64_t ny = row_end - row_begin, nx = grid_.cols();
  const int64_t h = grid_.patch_h(), w = grid_.patch_w(), width = grid_.width();
  LFNET_CHECK(patches.dim() == 5 && patches.size(0) == channels_ * ny * nx &&
                  patches.size(1) == rows_ && patches.size(2) == cols_ && patches.size(3) == h &&
                  patches.size(4) == w,
              "stitching expected ", channels_ * ny * nx, " patches of ", rows_, "x", cols_, "x", h,
              "x", w);
  LFNET_CHECK(row_begin >= next_row_ && row_end <= grid_.rows() && ny > 0,
              "stitching adds patch rows in order: rows ", row_begin, "..", row_end - 1,
              " after rows up to ", next_row_ - 1);
  next_row_ = row_end;
  // Image rows above this band's first patch are final: no later patch reaches them.
  const auto& ys = grid_.ys();
  flush(ys[static_cast<size_t>(row_begin)]);
  // Grow the buffer down to the band's last image row.
  const int64_t bottom = ys[static_cast<size_t>(row_end - 1)] + h;
  const int64_t held = sum_.size(1), wanted = bottom - top_;
  if (wanted > held) {
    auto opts = torch::TensorOptions().dtype(torch::kFloat64);
    sum_ = torch::cat({sum_, torch::zeros({sum_.size(0), wanted - held, width}, opts)}, 1);
    count_ = torch::cat({count_, torch::zeros({1, wanted - held, width}, opts)}, 1);
  }
  // (C, ny, nx, U, V, h, w) -> (C, U, V, h, w, ny, nx): fold's (col2im) layout, a view
  const auto src =
      patches.reshape({channels_, ny, nx, rows_, cols_, h, w}).permute({0, 3, 4, 5, 6, 1, 2});
  const auto weight = weight_.view({1, h, w, 1, 1}).expand({1, h, w, ny, nx});
  // A run of evenly spaced origins is a strided sliding window: fold adds its patches.
  const auto& xs = grid_.xs();
  for (const auto& ry : origin_runs(ys, row_begin, row_end)) {
    for (const auto& rx : origin_runs(xs, 0, nx)) {
      const int64_t y0 = ys[static_cast<size_t>(ry.first)] - top_;
      const int64_t x0 = xs[static_cast<size_t>(rx.first)];
      const int64_t iy = ry.first - row_begin;
      const int64_t out_h = ry.step * (ry.count - 1) + h, out_w = rx.step * (rx.count - 1) + w;
      const auto fold =
          torch::nn::functional::FoldFuncOptions({out_h, out_w}, {h, w}).stride({ry.step, rx.step});
      const auto add = [&](torch::Tensor& buffer, const torch::Tensor& block, bool weigh) {
        const auto run =
            block.slice(-2, iy, iy + ry.count).slice(-1, rx.first, rx.first + rx.count);
        // float64 in one pass, (..., h, w, my, mx) -> (1, ... h w, my mx)
        auto cols = torch::empty(run.sizes(), run.options().dtype(torch::kFloat64)).copy_(run);
        if (weigh) cols.mul_(weight_.view({h, w, 1, 1}));
        buffer.slice(1, y0, y0 + out_h)
            .slice(2, x0, x0 + out_w)
            .add_(torch::nn::functional::fold(cols.view({1, -1, ry.count * rx.count}), fold)[0]);
      };
      add(sum_, src, window_);
      add(count_, weight, false);
    }
  }
}

torch::Tensor Stitcher::result() {
  flush(grid_.height());
  LFNET_CHECK(top_ == grid_.height(), "stitching left pixels without any estimate");
  return out_;
}

}  // namespace lfnet

#include "lfnet/core/patches.h"

#include "lfnet/core/error.h"

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

Stitcher::Stitcher(const PatchGrid& grid, int64_t channels, int64_t rows, int64_t cols,
                   torch::Tensor weight)
    : grid_(grid), channels_(channels), rows_(rows), cols_(cols) {
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  if (weight.defined()) {
    LFNET_CHECK(
        weight.dim() == 2 && weight.size(0) == grid.patch_h() && weight.size(1) == grid.patch_w(),
        "stitching window must be (h, w) = (", grid.patch_h(), ", ", grid.patch_w(), ")");
    weight_ = weight.to(torch::kFloat64).reshape({-1}).contiguous();
  } else {
    weight_ = torch::ones({grid.patch_h() * grid.patch_w()}, opts);
  }
  sum_ = torch::zeros({channels, rows, cols, grid.height() * grid.width()}, opts);
  count_ = torch::zeros({grid.height() * grid.width()}, opts);
}

torch::Tensor Stitcher::flat_indices(int64_t row_begin, int64_t row_end) const {
  const int64_t h = grid_.patch_h(), w = grid_.patch_w();
  auto ys = torch::tensor(
      std::vector<int64_t>(grid_.ys().begin() + row_begin, grid_.ys().begin() + row_end));
  auto xs = torch::tensor(grid_.xs());
  // (ny, nx, h, w) flat pixel indices y * W + x
  auto y = ys.view({-1, 1, 1, 1}) + torch::arange(h).view({1, 1, h, 1});
  auto x = xs.view({1, -1, 1, 1}) + torch::arange(w).view({1, 1, 1, w});
  return (y * grid_.width() + x).reshape({-1});
}

void Stitcher::add(const torch::Tensor& patches, int64_t row_begin, int64_t row_end) {
  const int64_t ny = row_end - row_begin, nx = grid_.cols();
  const int64_t h = grid_.patch_h(), w = grid_.patch_w();
  LFNET_CHECK(patches.dim() == 5 && patches.size(0) == channels_ * ny * nx &&
                  patches.size(1) == rows_ && patches.size(2) == cols_ && patches.size(3) == h &&
                  patches.size(4) == w,
              "stitching expected ", channels_ * ny * nx, " patches of ", rows_, "x", cols_, "x", h,
              "x", w);
  auto idx = flat_indices(row_begin, row_end);
  // (C, ny, nx, U, V, h, w) -> (C, U, V, ny * nx * h * w), weighted
  auto src = patches.to(torch::kFloat64)
                 .view({channels_, ny * nx, rows_, cols_, h * w})
                 .mul(weight_)
                 .permute({0, 2, 3, 1, 4})
                 .reshape({channels_, rows_, cols_, -1});
  sum_.index_add_(3, idx, src);
  count_.index_add_(0, idx, weight_.repeat({ny * nx}));
}

torch::Tensor Stitcher::result() const {
  LFNET_CHECK(count_.min().item<double>() > 0, "stitching left pixels without any estimate");
  return (sum_ / count_)
      .to(torch::kFloat32)
      .view({channels_, rows_, cols_, grid_.height(), grid_.width()});
}

}  // namespace lfnet

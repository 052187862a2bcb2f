#include "lfnet/core/patches.h"

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

Stitcher::Stitcher(const PatchGrid& grid, int64_t channels, int64_t rows, int64_t cols,
                   const torch::Tensor& weight, bool coded)
    : grid_(grid), channels_(channels), rows_(rows), cols_(cols), coded_(coded) {
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  if (weight.defined()) {
    LFNET_CHECK(
        weight.dim() == 2 && weight.size(0) == grid.patch_h() && weight.size(1) == grid.patch_w(),
        "stitching window must be (h, w) = (", grid.patch_h(), ", ", grid.patch_w(), ")");
    weight_ = weight.to(torch::kFloat64).reshape({-1}).contiguous();
  } else {
    weight_ = torch::ones({grid.patch_h() * grid.patch_w()}, opts);
  }
  // Codes of a large light field are file-backed, and finished rows leave memory
  // (core/file_backed.h).
  out_ = coded
             ? file_backed_empty({channels, rows, cols, grid.height(), grid.width()}, torch::kInt16)
             : torch::empty({channels, rows, cols, grid.height(), grid.width()});
  sum_ = torch::zeros({channels, rows, cols, 0}, opts);
  count_ = torch::zeros({0}, opts);
}

void Stitcher::flush(int64_t until) {
  const int64_t w = grid_.width(), n = until - top_;
  if (n <= 0) return;
  LFNET_CHECK(count_.size(0) >= n * w, "stitching left pixels without any estimate");
  auto count = count_.slice(0, 0, n * w);
  LFNET_CHECK(count.min().item<double>() > 0, "stitching left pixels without any estimate");
  auto rows = (sum_.slice(3, 0, n * w) / count).reshape({channels_, rows_, cols_, n, w});
  out_.slice(3, top_, until).copy_(coded_ ? encode_codes(rows) : rows);
  page_out(out_);  // every row above `until` is final
  sum_ = sum_.slice(3, n * w);
  count_ = count_.slice(0, n * w);
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
  const int64_t held = sum_.size(3) / width, wanted = bottom - top_;
  if (wanted > held) {
    auto opts = torch::TensorOptions().dtype(torch::kFloat64);
    sum_ = torch::cat(
        {sum_, torch::zeros({channels_, rows_, cols_, (wanted - held) * width}, opts)}, 3);
    count_ = torch::cat({count_, torch::zeros({(wanted - held) * width}, opts)}, 0);
  }
  // Flat indices into the buffer, whose first row is image row top_.
  auto yb =
      torch::tensor(std::vector<int64_t>(ys.begin() + row_begin, ys.begin() + row_end)) - top_;
  auto xs = torch::tensor(grid_.xs());
  auto y = yb.view({-1, 1, 1, 1}) + torch::arange(h).view({1, 1, h, 1});
  auto x = xs.view({1, -1, 1, 1}) + torch::arange(w).view({1, 1, 1, w});
  auto idx = (y * width + x).reshape({-1});
  // (C, ny, nx, U, V, h, w) -> (C, U, V, ny * nx * h * w), weighted
  auto src = patches.to(torch::kFloat64)
                 .reshape({channels_, ny * nx, rows_, cols_, h * w})
                 .mul(weight_)
                 .permute({0, 2, 3, 1, 4})
                 .reshape({channels_, rows_, cols_, -1});
  sum_.index_add_(3, idx, src);
  count_.index_add_(0, idx, weight_.repeat({ny * nx}));
}

torch::Tensor Stitcher::result() {
  flush(grid_.height());
  LFNET_CHECK(top_ == grid_.height(), "stitching left pixels without any estimate");
  return out_;
}

}  // namespace lfnet

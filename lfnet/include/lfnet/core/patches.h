// Patch grids: extraction of (U, V, h, w) patches at any stride and stitching by averaging.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <vector>

#include "lfnet/core/light_field.h"

namespace lfnet {

// Patch origins along one axis: 0, s, 2s, ... while the patch fits, plus one last patch flush
// with the far border when the regular ones leave pixels uncovered. Requires size <= extent.
std::vector<int64_t> patch_origins(int64_t extent, int64_t size, int64_t stride);

// The spatial grid of patches of size (h, w) at stride s over an H x W light field.
class PatchGrid {
 public:
  PatchGrid(int64_t height, int64_t width, int64_t patch_h, int64_t patch_w, int64_t stride);

  int64_t height() const { return height_; }
  int64_t width() const { return width_; }
  int64_t patch_h() const { return patch_h_; }
  int64_t patch_w() const { return patch_w_; }
  int64_t stride() const { return stride_; }
  const std::vector<int64_t>& ys() const { return ys_; }
  const std::vector<int64_t>& xs() const { return xs_; }
  int64_t rows() const { return static_cast<int64_t>(ys_.size()); }
  int64_t cols() const { return static_cast<int64_t>(xs_.size()); }
  int64_t size() const { return rows() * cols(); }

  // Patches of patch rows [row_begin, row_end) of every channel of `lf`, shape
  // (C * n, U, V, h, w), channel-major then row-major over origins. Streaming callers take a
  // band of rows at a time so memory is bounded by the band, not the light field.
  torch::Tensor extract(const torch::Tensor& lf, int64_t row_begin, int64_t row_end) const;
  torch::Tensor extract(const torch::Tensor& lf) const { return extract(lf, 0, rows()); }

 private:
  int64_t height_, width_, patch_h_, patch_w_, stride_;
  std::vector<int64_t> ys_, xs_;
};

// Accumulates patch estimates and averages every estimate of a pixel. Sums are kept in
// float64, so stitching identical copies reproduces the values exactly. Patch rows are added in
// order; the sums are held only for the image rows that later patch rows may still reach, and
// each finished row goes straight into the float32 result, so stitching holds the light field
// about once, not three times.
class Stitcher {
 public:
  // `channels`, `rows`, `cols`: the light field's C, U, V. `weight` (h, w), optional: a
  // spatial window applied to every patch estimate (e.g. to soften patch seams). `coded`: the
  // result holds 16-bit codes (int16, clamped to [0, 1]; core/light_field.h), half the memory.
  Stitcher(const PatchGrid& grid, int64_t channels, int64_t rows, int64_t cols,
           const torch::Tensor& weight = {}, bool coded = false);

  // Adds patches of patch rows [row_begin, row_end) in the layout `PatchGrid::extract` gives.
  // row_begin must not be below the row_end of an earlier call.
  void add(const torch::Tensor& patches, int64_t row_begin, int64_t row_end);

  // The averaged light field (C, U, V, H, W), float32 or codes. Every pixel must have been covered.
  // Nothing may be added after it.
  torch::Tensor result();

 private:
  // Averages the buffered image rows [top_, until) into out_ and drops them from the buffer.
  void flush(int64_t until);

  const PatchGrid grid_;
  int64_t channels_, rows_, cols_;
  torch::Tensor weight_;  // (h, w) float64
  bool window_ = false;   // weight_ is a window, not ones
  bool coded_;
  torch::Tensor out_;     // (C, U, V, H, W) float32, or int16 codes
  int64_t next_row_ = 0;  // the first patch row not added yet
  int64_t top_ = 0;       // the first image row not in out_ yet: the buffer's first row
  torch::Tensor sum_;     // (C U V, buffer rows, W) float64
  torch::Tensor count_;   // (1, buffer rows, W) float64
};

}  // namespace lfnet

// The light field: the one place that defines lfnet's tensor layout (docs/conventions.md).
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <string>

namespace lfnet {

// Axis positions of a light field tensor of shape (C, U, V, H, W).
//   C: colour channels (1 or 3); U: angular rows (vertical parallax, theta);
//   V: angular columns (horizontal parallax, phi); H, W: spatial rows and columns.
namespace axis {
constexpr int64_t kC = 0;
constexpr int64_t kU = 1;
constexpr int64_t kV = 2;
constexpr int64_t kH = 3;
constexpr int64_t kW = 4;
constexpr int64_t kRank = 5;
}  // namespace axis

// Inclusive-exclusive range of angular indices, 0-based.
struct AngularRange {
  int64_t begin = 0;
  int64_t end = 0;
  int64_t size() const { return end - begin; }
};

// A 4D light field (plus colour): float32 values in [0, 1], shape (C, U, V, H, W).
class LightField {
 public:
  LightField() = default;
  // Takes a tensor of shape (C, U, V, H, W); converts it to contiguous float32.
  explicit LightField(const torch::Tensor& data);

  const torch::Tensor& data() const { return data_; }
  torch::Tensor& data() { return data_; }

  int64_t channels() const { return data_.size(axis::kC); }
  int64_t rows() const { return data_.size(axis::kU); }    // U
  int64_t cols() const { return data_.size(axis::kV); }    // V
  int64_t height() const { return data_.size(axis::kH); }  // H
  int64_t width() const { return data_.size(axis::kW); }   // W
  bool defined() const { return data_.defined(); }

  // One sub-aperture view (C, H, W); u, v are 0-based.
  torch::Tensor view(int64_t u, int64_t v) const;

  // Luma Y = 0.299 R + 0.587 G + 0.114 B; a grey light field is returned unchanged.
  LightField grey() const;

  // The views [u.begin, u.end) x [v.begin, v.end).
  LightField window(AngularRange u, AngularRange v) const;

  // The central n x n views, following the paper's protocol for even grids (docs/conventions.md).
  LightField central(int64_t n) const;

  // Angular mean of every pixel, broadcast back to every view: what a conventional camera
  // records; the `no-parallax` baseline.
  LightField angular_mean() const;

  // "CxUxVxHxW" for messages.
  std::string shape_string() const;

 private:
  torch::Tensor data_;
};

// 16-bit codes: a value in [0, 1] held as the int16 k - 32768, k = floor(65535 value + 1/2),
// half the memory of float32 and exactly what a 16-bit image file holds (docs/performance.md,
// "Peak memory"). encode_codes clamps to [0, 1] and rounds as 16-bit image writers do;
// decode_codes gives float32 k * float32(1 / 65535), as 16-bit image readers do.
torch::Tensor encode_codes(const torch::Tensor& values);
torch::Tensor decode_codes(const torch::Tensor& codes);

// The views of a light field (C, U, V, H, W) held either as float32 values (a LightField) or as
// 16-bit codes, one float32 view at a time: what scores, writers and previews read, so that a
// large estimate need not be held in float32. Codes may be file-backed (core/file_backed.h):
// then the pages of a view, or band of rows, leave memory once it has been read.
class LightFieldViews {
 public:
  LightFieldViews() = default;            // none: undefined, as a default LightField
  LightFieldViews(const LightField& lf);  // NOLINT(google-explicit-constructor): a view of it
  // A (C, U, V, H, W) tensor of float32 values or of int16 codes.
  explicit LightFieldViews(const torch::Tensor& data);

  bool coded() const { return data_.scalar_type() == torch::kInt16; }
  int64_t channels() const { return data_.size(axis::kC); }
  int64_t rows() const { return data_.size(axis::kU); }
  int64_t cols() const { return data_.size(axis::kV); }
  int64_t height() const { return data_.size(axis::kH); }
  int64_t width() const { return data_.size(axis::kW); }

  // View (u, v) as float32 (C, H, W); u, v are 0-based.
  torch::Tensor view(int64_t u, int64_t v) const;
  // Rows [y0, y1) of view (u, v) as float32 (C, y1 - y0, W).
  torch::Tensor view_rows(int64_t u, int64_t v, int64_t y0, int64_t y1) const;
  // View (u, v) as the unsigned 16-bit values k of its codes, in an int16 (C, H, W) tensor of
  // the same bits (LibTorch has no uint16): what a 16-bit file holds. Coded views only.
  torch::Tensor view_bits(int64_t u, int64_t v) const;
  // The whole light field in float32 (a copy when coded).
  LightField decode() const;
  // The tensor as held: float32 values or int16 codes.
  const torch::Tensor& raw() const { return data_; }
  // The views [u.begin, u.end) x [v.begin, v.end), not copied (LightField::window's check).
  LightFieldViews window(AngularRange u, AngularRange v) const;
  std::string shape_string() const;

 private:
  torch::Tensor data_;
};

// The 0-based start of the central n views out of `total`: views 3..7 (1-based) of 9, 2..6 of
// 8 and of 7, 6..10 of 14. For an even excess the window sits one view before the centre.
int64_t central_start(int64_t total, int64_t n);

// Parses an angular window "R0:R1,C0:C1" of 1-based inclusive view indices, e.g. "3:7,3:7".
std::pair<AngularRange, AngularRange> parse_views(const std::string& text);

}  // namespace lfnet

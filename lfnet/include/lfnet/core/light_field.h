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

// The 0-based start of the central n views out of `total`: views 3..7 (1-based) of 9, 2..6 of
// 8 and of 7, 6..10 of 14. For an even excess the window sits one view before the centre.
int64_t central_start(int64_t total, int64_t n);

// Parses an angular window "R0:R1,C0:C1" of 1-based inclusive view indices, e.g. "3:7,3:7".
std::pair<AngularRange, AngularRange> parse_views(const std::string& text);

}  // namespace lfnet

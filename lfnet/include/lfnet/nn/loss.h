// Training losses (docs/training.md): the paper's view-weighted L2, plain L2 and L1.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"

namespace lfnet::nn {

// The paper's angular weights generalised to any U x V grid: W(u, v) = sqrt(1 + |u - uc| +
// |v - vc| - d0), with (uc, vc) = ((U - 1) / 2, (V - 1) / 2) and d0 the smallest |u - uc| +
// |v - vc| of the grid (0 for odd sizes, so the centre view weighs 1; for even sizes the
// central views weigh 1). For 5 x 5 this is exactly the paper's table: sqrt5 in the corners,
// 2 beside them, sqrt3 at the edge centres and the diagonal neighbours, sqrt2 next to the
// centre, 1 at the centre. (The table is sqrt(1 + L1 distance), not a Euclidean distance:
// (0, 2) and (1, 1) both weigh sqrt3.) Returns (U, V) float32.
torch::Tensor view_weights(int64_t rows, int64_t cols);

// The losses by kind.
enum class LossKind {
  kWeightedL2,  // sum over views of W(u, v) * ||l - l_hat||^2 (the paper's)
  kL2,          // squared error, every view alike
  kL1,          // absolute error
};

// How element losses become one number.
enum class LossReduction {
  kMean,  // divided by the number of elements: a weighted mean squared (or absolute) error
  kSum,   // summed over views and pixels of each patch, averaged over the batch (the paper's)
};

// By name: "weighted_l2", "l2", "l1"; "mean", "sum" (core/enum_names.h).
std::string to_string(LossKind value);
std::string to_string(LossReduction value);
LossKind from_string(const std::string& name, LossKind);
LossReduction from_string(const std::string& name, LossReduction);

// Which loss and how it is reduced; strict JSON (LossOptions::from_json).
struct LossOptions {
  LossKind name = LossKind::kWeightedL2;           // weighted_l2, l2 or l1
  LossReduction reduction = LossReduction::kMean;  // mean or sum
  // Noise-aware training (dataset.noise_range): a patch measured with noise sigma weighs
  // noise_scale / (noise_scale + sigma), so that noisy patches, whose errors are larger, do not
  // drown the nearly noiseless ones. 0: every patch weighs 1.
  double noise_scale = 0.0;

  template <typename Fields>
  void fields(Fields& f) {
    f("name", name);
    f("reduction", reduction);
    f("noise_scale", noise_scale, Range::closed(0, 1e3));
  }
  static LossOptions from_json(const nlohmann::json& j, const std::string& path = "$");
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
  // Throws ConfigError naming the bad field.
  void validate() const;
};

// A reconstruction loss for patches laid out (B, ..., U, V, h, w): the views are dimensions
// -4 and -3, anything before them (batch, channel) is summed or averaged alike.
class ReconstructionLoss {
 public:
  ReconstructionLoss(const LossOptions& options, int64_t rows, int64_t cols);

  // Scalar loss of `prediction` against `target` (same shape). `noise`: the patches' noise
  // sigmas (B), which weigh them when options().noise_scale > 0; undefined: no noise.
  torch::Tensor operator()(const torch::Tensor& prediction, const torch::Tensor& target,
                           const torch::Tensor& noise = {}) const;

  const LossOptions& options() const { return options_; }
  // The (U, V) weights in use: view_weights for weighted_l2, ones otherwise.
  const torch::Tensor& weights() const { return weights_; }

 private:
  LossOptions options_;
  LossKind kind_;
  LossReduction reduction_;
  int64_t rows_, cols_;
  torch::Tensor weights_;  // (U, V, 1, 1)
};

}  // namespace lfnet::nn

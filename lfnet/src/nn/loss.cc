#include "lfnet/nn/loss.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"

namespace lfnet::nn {

torch::Tensor view_weights(int64_t rows, int64_t cols) {
  LFNET_CHECK_AS(ConfigError, rows > 0 && cols > 0, "view_weights: the angular size must be ",
                 "positive, got ", rows, " x ", cols);
  const double uc = 0.5 * static_cast<double>(rows - 1);
  const double vc = 0.5 * static_cast<double>(cols - 1);
  auto dist = [&](int64_t u, int64_t v) {
    return std::abs(static_cast<double>(u) - uc) + std::abs(static_cast<double>(v) - vc);
  };
  double d0 = std::numeric_limits<double>::infinity();
  for (int64_t u = 0; u < rows; ++u) {
    for (int64_t v = 0; v < cols; ++v) d0 = std::min(d0, dist(u, v));
  }
  auto w = torch::empty({rows, cols}, torch::kFloat64);
  auto acc = w.accessor<double, 2>();
  for (int64_t u = 0; u < rows; ++u) {
    for (int64_t v = 0; v < cols; ++v) acc[u][v] = std::sqrt(1.0 + dist(u, v) - d0);
  }
  return w.to(torch::kFloat32);
}

LossOptions LossOptions::from_json(const nlohmann::json& j, const std::string& path) {
  LossOptions options;
  JsonReader reader(j, path);
  options.read(reader);
  reader.finish();
  return options;
}

void LossOptions::read(JsonReader& reader) {
  read_fields(reader, *this);
  LFNET_CHECK_AS(ConfigError, noise_scale >= 0 && std::isfinite(noise_scale),
                 reader.path_of("noise_scale"), ": must be >= 0, got ", noise_scale);
}

nlohmann::json LossOptions::to_json() const { return fields_to_json(*this); }

void LossOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, noise_scale >= 0 && std::isfinite(noise_scale),
                 "loss.noise_scale must be >= 0, got ", noise_scale);
}

namespace {
constexpr EnumName<LossKind> kLossKinds[] = {
    {LossKind::kWeightedL2, "weighted_l2"}, {LossKind::kL2, "l2"}, {LossKind::kL1, "l1"}};
constexpr EnumName<LossReduction> kReductions[] = {{LossReduction::kMean, "mean"},
                                                   {LossReduction::kSum, "sum"}};
}  // namespace

std::string to_string(LossKind value) { return name_of(value, kLossKinds); }
std::string to_string(LossReduction value) { return name_of(value, kReductions); }
LossKind from_string(const std::string& name, LossKind) { return value_of(name, kLossKinds); }
LossReduction from_string(const std::string& name, LossReduction) {
  return value_of(name, kReductions);
}

ReconstructionLoss::ReconstructionLoss(const LossOptions& options, int64_t rows, int64_t cols)
    : options_(options),
      kind_(options.name),
      reduction_(options.reduction),
      rows_(rows),
      cols_(cols) {
  weights_ = kind_ == LossKind::kWeightedL2 ? view_weights(rows, cols)
                                            : torch::ones({rows, cols}, torch::kFloat32);
  weights_ = weights_.view({rows, cols, 1, 1});
}

torch::Tensor ReconstructionLoss::operator()(const torch::Tensor& prediction,
                                             const torch::Tensor& target,
                                             const torch::Tensor& noise) const {
  LFNET_CHECK(prediction.sizes() == target.sizes(), "loss: prediction ", prediction.sizes(),
              " and target ", target.sizes(), " differ in shape");
  LFNET_CHECK(prediction.dim() >= 5 && prediction.size(-4) == rows_ && prediction.size(-3) == cols_,
              "loss: expected patches (B, ..., ", rows_, ", ", cols_, ", h, w), got ",
              prediction.sizes());
  auto diff = prediction - target;
  auto err = kind_ == LossKind::kL1 ? diff.abs() : diff.square();
  if (kind_ == LossKind::kWeightedL2) err = err * weights_.to(err.options());
  if (options_.noise_scale > 0 && noise.defined()) {
    LFNET_CHECK(noise.numel() == prediction.size(0), "loss: ", noise.numel(),
                " noise sigmas for a batch of ", prediction.size(0));
    std::vector<int64_t> shape(static_cast<size_t>(err.dim()), 1);
    shape[0] = prediction.size(0);
    auto weight = options_.noise_scale / (noise.to(err.options()) + options_.noise_scale);
    err = err * weight.view(shape);
  }
  auto total = err.sum();
  if (reduction_ == LossReduction::kMean) return total / static_cast<double>(err.numel());
  return total / static_cast<double>(prediction.size(0));
}

}  // namespace lfnet::nn

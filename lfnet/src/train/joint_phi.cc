#include "lfnet/train/joint_phi.h"

#include "lfnet/core/error.h"
#include "lfnet/nn/architecture.h"

namespace lfnet::train {

torch::Tensor simulate_patches(const torch::Tensor& weights, const torch::Tensor& target,
                               const torch::Tensor& phase) {
  LFNET_CHECK_AS(ConfigError, weights.dim() == 5 && weights.size(3) == weights.size(4),
                 "simulate_patches: a code is (N, U, V, T, T), got ", weights.sizes());
  LFNET_CHECK_AS(ConfigError,
                 target.dim() == 6 && target.size(1) == 1 && target.size(2) == weights.size(1) &&
                     target.size(3) == weights.size(2),
                 "simulate_patches: patches are (B, 1, U, V, h, w) for the code's views, got ",
                 target.sizes());
  const int64_t b = target.size(0), h = target.size(4), w = target.size(5), t = weights.size(3);
  const auto ph = phase.defined() ? phase.to(torch::kCPU) : torch::zeros({b}, torch::kInt64);
  std::vector<torch::Tensor> rows;
  rows.reserve(static_cast<size_t>(b));
  for (int64_t i = 0; i < b; ++i) {
    const int64_t p = ph[i].item<int64_t>();
    const auto on = torch::TensorOptions().dtype(torch::kInt64).device(weights.device());
    const auto ys = (torch::arange(h, on) + p / t).remainder(t),
               xs = (torch::arange(w, on) + p % t).remainder(t);
    const auto patch_weights = weights.index_select(3, ys).index_select(4, xs);  // (N, U, V, h, w)
    rows.push_back((patch_weights * target[i]).sum({1, 2}).reshape({-1}));
  }
  return torch::stack(rows);
}

torch::Tensor joint_forward(nn::LightFieldNet& net, const torch::Tensor& weights,
                            const Batch& batch, uint64_t noise_seed) {
  LFNET_CHECK_AS(ConfigError, net->architecture().learns_code(), "the ", net->architecture().name(),
                 " architecture cannot learn a code with the net (the lfnet architecture can)");
  auto y = simulate_patches(weights, batch.target, batch.phase);
  if (batch.noise.defined()) {
    auto gen = at::detail::createCPUGenerator(noise_seed);
    const auto draws = at::randn(y.sizes(), gen, y.options().device(torch::kCPU)).to(y.device());
    y = y + draws * batch.noise.to(y.options()).unsqueeze(1);
  }
  // The net reads the code's pseudo-inverse for this forward pass only.
  const auto kept = net->pixel_pinv;
  // In float64, as set_phi computes them, so training sees the inverses inference will use.
  net->pixel_pinv =
      nn::pixel_pseudo_inverses(weights.to(torch::kFloat64), net->options().pinv_lambda)
          .to(weights.scalar_type());
  torch::Tensor out;
  try {
    out = net->forward(y, batch.phase, batch.noise);
  } catch (...) {
    net->pixel_pinv = kept;
    throw;
  }
  net->pixel_pinv = kept;
  return out;
}

torch::Tensor joint_loss(nn::LightFieldNet& net, const nn::LearnedPhi& code, const Batch& batch,
                         const nn::ReconstructionLoss& loss, uint64_t noise_seed) {
  return loss(joint_forward(net, code->weights(), batch, noise_seed), batch.target, batch.noise);
}

}  // namespace lfnet::train

#include "lfnet/nn/conv4d.h"

#include <torch/torch.h>

#include <cmath>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet::nn {

Conv4dAlgorithm parse_conv4d_algorithm(const std::string& name) {
  if (name == "stacked") return Conv4dAlgorithm::kStacked;
  if (name == "fused_output") return Conv4dAlgorithm::kFusedOutput;
  if (name == "fused_input") return Conv4dAlgorithm::kFusedInput;
  if (name == "auto") return Conv4dAlgorithm::kAuto;
  throw ConfigError("unknown Conv4d algorithm '" + name +
                    "' (known: stacked, fused_output, fused_input, auto)");
}

std::string to_string(Conv4dAlgorithm algorithm) {
  switch (algorithm) {
    case Conv4dAlgorithm::kStacked:
      return "stacked";
    case Conv4dAlgorithm::kFusedOutput:
      return "fused_output";
    case Conv4dAlgorithm::kFusedInput:
      return "fused_input";
    case Conv4dAlgorithm::kAuto:
      return "auto";
  }
  return "?";
}

double conv4d_flops(int64_t batch, int64_t in_channels, int64_t out_channels, int64_t u, int64_t v,
                    int64_t h, int64_t w, int64_t kernel) {
  const double k2 = static_cast<double>(kernel * kernel);
  return 2.0 * static_cast<double>(batch * u * v * h * w) *
         static_cast<double>(in_channels * out_channels) * k2 * k2;
}

namespace {

void check_arguments(const torch::Tensor& x, const torch::Tensor& weight,
                     const torch::Tensor& bias) {
  LFNET_CHECK(x.dim() == 6, "conv4d: input must be 6-D (B, U, Cin, V, h, w), got ", x.sizes());
  LFNET_CHECK(weight.dim() == 6, "conv4d: weight must be (Cout, Cin, K, K, K, K), got ",
              weight.sizes());
  const int64_t k = weight.size(2);
  LFNET_CHECK(k % 2 == 1 && weight.size(3) == k && weight.size(4) == k && weight.size(5) == k,
              "conv4d: the kernel must be K x K x K x K with K odd, got ", weight.sizes());
  LFNET_CHECK(x.size(2) == weight.size(1), "conv4d: input has ", x.size(2),
              " channels but the weight expects ", weight.size(1));
  LFNET_CHECK(x.scalar_type() == weight.scalar_type(), "conv4d: input is ", x.scalar_type(),
              " but the weight is ", weight.scalar_type());
  if (bias.defined()) {
    LFNET_CHECK(bias.dim() == 1 && bias.size(0) == weight.size(0), "conv4d: bias must be (",
                weight.size(0), "), got ", bias.sizes());
  }
}

torch::Tensor conv3d(const torch::Tensor& x, const torch::Tensor& w, const torch::Tensor& b,
                     int64_t pad) {
  return torch::conv3d(x, w, b, /*stride=*/1, /*padding=*/pad);
}

// The batch extent of a reshape: -1 (inferred) for a nonempty batch, so that a traced graph
// (nn/script.cc exports the branches that way) serves every batch size; 0 for an empty batch,
// which -1 cannot express.
int64_t batch_extent(int64_t b) { return b > 0 ? -1 : 0; }

// out[:, u] += y[:, u + s] wherever both exist (y's u range is the full U).
void add_shifted(torch::Tensor& out, const torch::Tensor& y, int64_t s) {
  const int64_t n = out.size(1) - std::abs(s);
  if (n <= 0) return;
  out.narrow(1, std::max<int64_t>(0, -s), n).add_(y.narrow(1, std::max<int64_t>(0, s), n));
}

torch::Tensor stacked(const torch::Tensor& x, const torch::Tensor& weight,
                      const torch::Tensor& bias) {
  const int64_t b = batch_extent(x.size(0)), u = x.size(1);
  const int64_t cout = weight.size(0), k = weight.size(2), p = k / 2;
  auto tail = x.sizes().slice(3).vec();
  auto shape_out = [&](int64_t n) {
    std::vector<int64_t> s{b, n, cout};
    s.insert(s.end(), tail.begin(), tail.end());
    return s;
  };
  auto out = conv3d(x.flatten(0, 1), weight.select(2, p), bias, p).view(shape_out(u));
  for (int64_t i = 0; i < k; ++i) {
    const int64_t s = i - p, n = u - std::abs(s);
    if (s == 0 || n <= 0) continue;
    auto src = x.narrow(1, std::max<int64_t>(0, s), n).flatten(0, 1);
    auto y = conv3d(src, weight.select(2, i), {}, p).view(shape_out(n));
    out.narrow(1, std::max<int64_t>(0, -s), n).add_(y);
  }
  return out;
}

torch::Tensor fused_output(const torch::Tensor& x, const torch::Tensor& weight,
                           const torch::Tensor& bias) {
  const int64_t b = batch_extent(x.size(0)), u = x.size(1), cin = x.size(2);
  const int64_t cout = weight.size(0), k = weight.size(2), p = k / 2;
  auto tail = x.sizes().slice(3).vec();
  std::vector<int64_t> y_shape{b, u, k, cout};
  y_shape.insert(y_shape.end(), tail.begin(), tail.end());
  // (Cout, Cin, Ku, ...) -> (Ku * Cout, Cin, Kv, Kh, Kw): output block i is offset i along u.
  auto wk = weight.permute({2, 0, 1, 3, 4, 5}).reshape({k * cout, cin, k, k, k});
  auto y = conv3d(x.flatten(0, 1), wk, {}, p).view(y_shape);
  auto out =
      bias.defined() ? y.select(2, p) + bias.view({1, 1, cout, 1, 1, 1}) : y.select(2, p).clone();
  for (int64_t i = 0; i < k; ++i) {
    if (i != p) add_shifted(out, y.select(2, i), i - p);
  }
  return out;
}

torch::Tensor fused_input(const torch::Tensor& x, const torch::Tensor& weight,
                          const torch::Tensor& bias) {
  const int64_t b = batch_extent(x.size(0)), u = x.size(1), cin = x.size(2);
  const int64_t cout = weight.size(0), k = weight.size(2), p = k / 2;
  // Zero-pad u, then stack the K u-shifted windows as channel blocks (im2col along u only).
  auto xp = torch::constant_pad_nd(x, {0, 0, 0, 0, 0, 0, 0, 0, p, p});
  std::vector<torch::Tensor> shifted;
  shifted.reserve(k);
  for (int64_t i = 0; i < k; ++i) shifted.push_back(xp.narrow(1, i, u));
  auto tail = x.sizes().slice(3).vec();
  std::vector<int64_t> out_shape{b, u, cout};
  out_shape.insert(out_shape.end(), tail.begin(), tail.end());
  // (B, U, K, Cin, ...) -> (B U, K Cin, ...)
  auto cols = torch::stack(shifted, 2).flatten(0, 1).flatten(1, 2);
  auto wk = weight.permute({0, 2, 1, 3, 4, 5}).reshape({cout, k * cin, k, k, k});
  return conv3d(cols, wk, bias, p).view(out_shape);
}

}  // namespace

// oneDNN's Conv3d is efficient when both channel counts are moderate and poor when one side
// has a single channel; stacking the u-offsets onto that side (K channels) is what helps
// there. Measured on a 2-core AVX-512 CPU (docs/training.md, section 2).
Conv4dAlgorithm resolve_conv4d_algorithm(Conv4dAlgorithm algorithm, int64_t in_channels,
                                         int64_t out_channels) {
  if (algorithm != Conv4dAlgorithm::kAuto) return algorithm;
  if (out_channels == 1) return Conv4dAlgorithm::kFusedOutput;
  if (in_channels == 1) return Conv4dAlgorithm::kFusedInput;
  return Conv4dAlgorithm::kStacked;
}

torch::Tensor conv4d_u_major(const torch::Tensor& x, const torch::Tensor& weight,
                             const torch::Tensor& bias, Conv4dAlgorithm algorithm) {
  check_arguments(x, weight, bias);
  switch (resolve_conv4d_algorithm(algorithm, weight.size(1), weight.size(0))) {
    case Conv4dAlgorithm::kStacked:
      return stacked(x, weight, bias);
    case Conv4dAlgorithm::kFusedOutput:
      return fused_output(x, weight, bias);
    default:
      return fused_input(x, weight, bias);
  }
}

torch::Tensor conv4d(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias,
                     Conv4dAlgorithm algorithm) {
  LFNET_CHECK(x.dim() == 6, "conv4d: input must be 6-D (B, Cin, U, V, h, w), got ", x.sizes());
  return conv4d_u_major(x.transpose(1, 2), weight, bias, algorithm).transpose(1, 2).contiguous();
}

Conv4dImpl::Conv4dImpl(const Conv4dOptions& options) : options_(options) {
  LFNET_CHECK_AS(ConfigError, options.in_channels > 0 && options.out_channels > 0,
                 "Conv4d: channel counts must be positive, got ", options.in_channels, " -> ",
                 options.out_channels);
  LFNET_CHECK_AS(ConfigError, options.kernel > 0 && options.kernel % 2 == 1,
                 "Conv4d: the kernel size must be odd and positive, got ", options.kernel);
  const int64_t k = options.kernel;
  weight = register_parameter(
      "weight", torch::empty({options.out_channels, options.in_channels, k, k, k, k}));
  if (options.bias) bias = register_parameter("bias", torch::empty({options.out_channels}));
  reset_parameters();
}

void Conv4dImpl::reset_parameters() {
  torch::NoGradGuard no_grad;
  const double fan_in = static_cast<double>(weight[0].numel());
  const double bound = 1.0 / std::sqrt(fan_in);
  weight.uniform_(-bound, bound);
  if (bias.defined()) bias.uniform_(-bound, bound);
}

torch::Tensor Conv4dImpl::forward(const torch::Tensor& x) {
  return conv4d(x, weight, bias, options_.algorithm);
}

torch::Tensor Conv4dImpl::forward_u_major(const torch::Tensor& x) {
  return conv4d_u_major(x, weight, bias, options_.algorithm);
}

}  // namespace lfnet::nn

// 4D convolution over light-field patches (docs/training.md): a K x K x K x K kernel over
// (u, v, y, x) with same padding, computed with 3D convolutions over (v, y, x).
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/pimpl.h>
#include <torch/types.h>

#include <cstdint>
#include <string>

namespace lfnet::nn {

// How a 4D convolution is mapped onto LibTorch's 3D convolution. All give the same result
// (to float rounding); they differ in speed (see docs/training.md for measurements).
enum class Conv4dAlgorithm {
  kStacked,      // K Conv3d calls, one per offset along u, on shifted slices, summed
  kFusedOutput,  // one Conv3d with K * Cout output channels, then K shifted sums along u
  kFusedInput,   // the K u-shifted copies of the input stacked as K * Cin channels, one Conv3d
  kAuto,         // the fastest for the channel counts, as measured on a 2-core AVX-512 CPU
};

// "stacked", "fused_output", "fused_input", "auto"; anything else is a ConfigError.
Conv4dAlgorithm parse_conv4d_algorithm(const std::string& name);
std::string to_string(Conv4dAlgorithm algorithm);
inline Conv4dAlgorithm from_string(const std::string& name, Conv4dAlgorithm) {
  return parse_conv4d_algorithm(name);
}

// The algorithm a layer of Cin -> Cout channels runs: `algorithm` itself unless kAuto.
Conv4dAlgorithm resolve_conv4d_algorithm(Conv4dAlgorithm algorithm, int64_t in_channels,
                                         int64_t out_channels);

// 4D convolution, stride 1, same padding (kernel / 2 zeros on every side of every axis).
// x: (B, Cin, U, V, h, w); weight: (Cout, Cin, K, K, K, K) with K odd; bias: (Cout) or
// undefined. Returns (B, Cout, U, V, h, w). Differentiable in x, weight and bias.
torch::Tensor conv4d(const torch::Tensor& x, const torch::Tensor& weight,
                     const torch::Tensor& bias = {},
                     Conv4dAlgorithm algorithm = Conv4dAlgorithm::kAuto);

// The same in the u-major layout that stacked layers keep between them, which saves two
// transposes per layer: x (B, U, Cin, V, h, w) -> (B, U, Cout, V, h, w).
torch::Tensor conv4d_u_major(const torch::Tensor& x, const torch::Tensor& weight,
                             const torch::Tensor& bias = {},
                             Conv4dAlgorithm algorithm = Conv4dAlgorithm::kAuto);

// Multiply-adds of one 4D convolution, counted at every output position (border zeros
// included), times 2: the FLOP count that GFLOP/s figures refer to.
double conv4d_flops(int64_t batch, int64_t in_channels, int64_t out_channels, int64_t u, int64_t v,
                    int64_t h, int64_t w, int64_t kernel);

// The shape of a Conv4d layer.
struct Conv4dOptions {
  int64_t in_channels = 1;   // Cin
  int64_t out_channels = 1;  // Cout
  int64_t kernel = 3;        // K, odd: the paper's 3 x 3 x 3 x 3
  bool bias = true;          // learn a bias per output channel
  Conv4dAlgorithm algorithm = Conv4dAlgorithm::kAuto;
};

// A 4D convolution layer. Registered tensors (the checkpoint schema): "weight"
// (Cout, Cin, K, K, K, K) and, when options.bias, "bias" (Cout). Initialised like
// torch.nn.Conv3d: uniform in +-1/sqrt(fan_in) (Kaiming-uniform with a = sqrt(5)),
// fan_in = Cin K^4.
class Conv4dImpl : public torch::nn::Module {
 public:
  explicit Conv4dImpl(const Conv4dOptions& options);

  // x: (B, Cin, U, V, h, w) -> (B, Cout, U, V, h, w).
  torch::Tensor forward(const torch::Tensor& x);
  // x: (B, U, Cin, V, h, w) -> (B, U, Cout, V, h, w).
  torch::Tensor forward_u_major(const torch::Tensor& x);

  // Draws new weights and biases from the default generator.
  void reset_parameters();

  const Conv4dOptions& options() const { return options_; }
  torch::Tensor weight, bias;

 private:
  Conv4dOptions options_;
};
TORCH_MODULE(Conv4d);

}  // namespace lfnet::nn

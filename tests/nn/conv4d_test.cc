#include "lfnet/nn/conv4d.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <functional>
#include <random>

#include "lfnet/core/error.h"
#include "support/test_support.h"

namespace {

using lfnet::nn::Conv4dAlgorithm;

const std::vector<Conv4dAlgorithm> kAlgorithms = {
    Conv4dAlgorithm::kStacked, Conv4dAlgorithm::kFusedOutput, Conv4dAlgorithm::kFusedInput,
    Conv4dAlgorithm::kAuto};

// Direct 4D convolution in float64, written independently of Conv3d: for every kernel offset
// (a, b, c, d), out[o, u, v, y, x] += w[o, i, a, b, c, d] * xpad[i, u + a, v + b, y + c, x + d].
torch::Tensor naive_conv4d(const torch::Tensor& x, const torch::Tensor& w, const torch::Tensor& b) {
  auto xd = x.to(torch::kFloat64), wd = w.to(torch::kFloat64);
  const int64_t k = w.size(2), p = k / 2;
  const int64_t n = x.size(0), u = x.size(2), v = x.size(3), h = x.size(4), ww = x.size(5);
  auto xp = torch::constant_pad_nd(xd, {p, p, p, p, p, p, p, p});
  auto out = torch::zeros({n, w.size(0), u, v, h, ww}, torch::kFloat64);
  for (int64_t a = 0; a < k; ++a) {
    for (int64_t bb = 0; bb < k; ++bb) {
      for (int64_t c = 0; c < k; ++c) {
        for (int64_t d = 0; d < k; ++d) {
          auto window = xp.narrow(2, a, u).narrow(3, bb, v).narrow(4, c, h).narrow(5, d, ww);
          auto tap = wd.select(5, d).select(4, c).select(3, bb).select(2, a);  // (Cout, Cin)
          out += torch::einsum("oi,niuvyx->nouvyx", {tap, window});
        }
      }
    }
  }
  if (b.defined()) out += b.to(torch::kFloat64).view({1, -1, 1, 1, 1, 1});
  return out;
}

}  // namespace

TEST_CASE("Conv4d equals a direct 4D convolution on random shapes", "[nn][conv4d]") {
  std::mt19937 rng(7);
  auto pick = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  for (int trial = 0; trial < 12; ++trial) {
    const int64_t k = trial < 2 ? 1 : (trial == 11 ? 5 : 3);
    const int64_t n = pick(1, 3), cin = pick(1, 5), cout = pick(1, 5);
    // Angular sizes down to 1 and 2 exercise kernels wider than the axis.
    const int64_t u = pick(1, 5), v = pick(1, 5), h = pick(1, 7), w = pick(1, 7);
    torch::manual_seed(100 + trial);
    auto x = torch::rand({n, cin, u, v, h, w}) * 2 - 1;
    auto weight = (torch::rand({cout, cin, k, k, k, k}) * 2 - 1) / std::sqrt(cin * k * k * k * k);
    auto bias = trial % 3 == 0 ? torch::Tensor() : torch::rand({cout});
    auto want = naive_conv4d(x, weight, bias);
    for (auto algorithm : kAlgorithms) {
      INFO("trial " << trial << " algorithm " << lfnet::nn::to_string(algorithm) << " x "
                    << x.sizes() << " weight " << weight.sizes());
      auto got = lfnet::nn::conv4d(x, weight, bias, algorithm);
      REQUIRE(got.scalar_type() == torch::kFloat32);
      lfnet::test::require_close(got, want, 1e-5);
    }
  }
}

TEST_CASE("Conv4d matches the direct convolution on a default-sized batch", "[nn][conv4d]") {
  torch::manual_seed(3);
  auto x = torch::rand({4, 6, 5, 5, 9, 9});
  auto weight = torch::randn({5, 6, 3, 3, 3, 3}) * 0.05;
  auto bias = torch::randn({5});
  auto want = naive_conv4d(x, weight, bias);
  for (auto algorithm : kAlgorithms) {
    INFO(lfnet::nn::to_string(algorithm));
    lfnet::test::require_close(lfnet::nn::conv4d(x, weight, bias, algorithm), want, 1e-5);
  }
}

TEST_CASE("Conv4d gradients equal central finite differences in double", "[nn][conv4d]") {
  torch::manual_seed(11);
  auto x0 = torch::randn({2, 2, 3, 2, 3, 4}, torch::kFloat64);
  auto w0 = torch::randn({3, 2, 3, 3, 3, 3}, torch::kFloat64) * 0.2;
  auto b0 = torch::randn({3}, torch::kFloat64);
  auto g = torch::randn({2, 3, 3, 2, 3, 4}, torch::kFloat64);  // dL/d(out), L = <out, g>
  const double eps = 1e-6;
  for (auto algorithm : kAlgorithms) {
    INFO(lfnet::nn::to_string(algorithm));
    auto x = x0.clone().requires_grad_(true), w = w0.clone().requires_grad_(true),
         b = b0.clone().requires_grad_(true);
    (lfnet::nn::conv4d(x, w, b, algorithm) * g).sum().backward();
    torch::NoGradGuard no_grad;
    auto loss = [&](const torch::Tensor& xx, const torch::Tensor& ww, const torch::Tensor& bb) {
      return (lfnet::nn::conv4d(xx, ww, bb, algorithm) * g).sum().item<double>();
    };
    // Perturbs each element of `t` (a copy of one argument) and compares with `grad`.
    auto check = [&](const torch::Tensor& base, const torch::Tensor& grad,
                     const std::function<double(const torch::Tensor&)>& eval) {
      auto numeric = torch::zeros_like(base);
      auto flat = base.clone().reshape({-1});
      for (int64_t i = 0; i < flat.numel(); ++i) {
        const double keep = flat[i].item<double>();
        flat[i] = keep + eps;
        const double up = eval(flat.view(base.sizes()));
        flat[i] = keep - eps;
        const double down = eval(flat.view(base.sizes()));
        flat[i] = keep;
        numeric.view({-1})[i] = (up - down) / (2 * eps);
      }
      lfnet::test::require_close(grad, numeric, 1e-6, 1e-6);
    };
    check(x0, x.grad(), [&](const torch::Tensor& t) { return loss(t, w0, b0); });
    check(w0, w.grad(), [&](const torch::Tensor& t) { return loss(x0, t, b0); });
    check(b0, b.grad(), [&](const torch::Tensor& t) { return loss(x0, w0, t); });
  }
}

TEST_CASE("the u-major entry point is the transposed convolution", "[nn][conv4d]") {
  torch::manual_seed(5);
  auto x = torch::rand({2, 3, 4, 5, 6, 3});
  auto w = torch::randn({2, 3, 3, 3, 3, 3}) * 0.1;
  auto b = torch::randn({2});
  auto want = lfnet::nn::conv4d(x, w, b);
  auto got = lfnet::nn::conv4d_u_major(x.transpose(1, 2).contiguous(), w, b).transpose(1, 2);
  lfnet::test::require_close(got, want, 1e-6);
}

TEST_CASE("the Conv4d module registers weight and bias and initialises like Conv3d",
          "[nn][conv4d]") {
  lfnet::nn::Conv4dOptions options;
  options.in_channels = 4;
  options.out_channels = 6;
  lfnet::nn::Conv4d conv(options);
  auto params = conv->named_parameters();
  REQUIRE(params.size() == 2);
  CHECK(params["weight"].sizes() == torch::IntArrayRef({6, 4, 3, 3, 3, 3}));
  CHECK(params["bias"].sizes() == torch::IntArrayRef({6}));
  const double bound = 1.0 / std::sqrt(4.0 * 81.0);
  CHECK(conv->weight.abs().max().item<double>() <= bound);
  CHECK(conv->weight.abs().max().item<double>() > 0.9 * bound);
  auto x = torch::rand({3, 4, 5, 5, 9, 9});
  lfnet::test::require_close(conv(x), naive_conv4d(x, conv->weight, conv->bias), 1e-5);

  options.bias = false;
  CHECK(lfnet::nn::Conv4d(options)->named_parameters().size() == 1);
}

TEST_CASE("Conv4d rejects bad kernels and inputs with clear messages", "[nn][conv4d]") {
  lfnet::nn::Conv4dOptions options;
  options.kernel = 4;
  CHECK_THROWS_AS(lfnet::nn::Conv4d(options), lfnet::ConfigError);
  CHECK_THROWS_WITH(lfnet::nn::Conv4d(options), Catch::Contains("odd"));
  auto w = torch::zeros({2, 3, 3, 3, 3, 3});
  CHECK_THROWS_WITH(lfnet::nn::conv4d(torch::zeros({1, 2, 5, 5, 9, 9}), w),
                    Catch::Contains("3 channels but") || Catch::Contains("expects 3"));
  CHECK_THROWS_WITH(lfnet::nn::conv4d(torch::zeros({2, 5, 5, 9, 9}), w), Catch::Contains("6-D"));
  CHECK_THROWS_AS(lfnet::nn::parse_conv4d_algorithm("winograd"), lfnet::ConfigError);
}

TEST_CASE("conv4d_flops counts two FLOPs per multiply-add", "[nn][conv4d]") {
  CHECK(lfnet::nn::conv4d_flops(256, 16, 16, 5, 5, 9, 9, 3) == Approx(2.0 * 256 * 2025 * 256 * 81));
}

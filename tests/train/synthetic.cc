#include "synthetic.h"

#include <cmath>

#include "support/small_nets.h"

namespace lfnet::test {

torch::Tensor smooth_patches(int64_t n, const nn::PatchShape& shape, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  auto u = torch::arange(shape.rows, opts) - 0.5 * (shape.rows - 1);
  auto v = torch::arange(shape.cols, opts) - 0.5 * (shape.cols - 1);
  auto y = torch::arange(shape.height, opts);
  auto x = torch::arange(shape.width, opts);
  // Broadcast grids (U, V, h, w).
  auto uu = u.view({-1, 1, 1, 1}), vv = v.view({1, -1, 1, 1});
  auto yy = y.view({1, 1, -1, 1}), xx = x.view({1, 1, 1, -1});
  auto out = torch::empty({n, 1, shape.rows, shape.cols, shape.height, shape.width}, opts);
  for (int64_t i = 0; i < n; ++i) {
    auto r = torch::rand({16}, gen, opts);
    const double disparity = 2 * r[0].item<double>() - 1;
    auto sy = yy + disparity * uu, sx = xx + disparity * vv;
    auto f = torch::full({1}, 0.25 + 0.5 * r[1].item<double>(), opts);
    for (int k = 0; k < 3; ++k) {
      const double fy = 1.2 * (2 * r[2 + 4 * k].item<double>() - 1);
      const double fx = 1.2 * (2 * r[3 + 4 * k].item<double>() - 1);
      const double phase = 6.2832 * r[4 + 4 * k].item<double>();
      const double amp = 0.15 * r[5 + 4 * k].item<double>();
      f = f + amp * torch::sin(fy * sy + fx * sx + phase);
    }
    out[i][0] = f.clamp(0, 1);
  }
  return out.to(torch::kFloat32);
}

torch::Tensor gaussian_phi(int64_t phases, int64_t m, int64_t d, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  return torch::randn({phases, m, d}, gen) / std::sqrt(static_cast<double>(d));
}

torch::Tensor per_pixel_phi(int64_t phases, int64_t n, const nn::PatchShape& shape, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  const int64_t views = shape.rows * shape.cols, pixels = shape.pixels();
  auto weights = torch::rand({phases, n, pixels, views}, gen) * (2.0 / views);
  auto phi = torch::zeros({phases, n * pixels, views * pixels});
  for (int64_t p = 0; p < phases; ++p) {
    for (int64_t k = 0; k < n; ++k) {
      for (int64_t px = 0; px < pixels; ++px) {
        for (int64_t v = 0; v < views; ++v) {
          phi[p][k * pixels + px][v * pixels + px] = weights[p][k][px][v];
        }
      }
    }
  }
  return phi;
}

std::unique_ptr<train::InMemoryBatchSource> make_source(const torch::Tensor& patches,
                                                        const torch::Tensor& phi, uint64_t seed) {
  const int64_t n = patches.size(0), p = phi.size(0);
  auto phase = torch::arange(n, torch::kInt64).remainder(p);
  auto flat = patches.reshape({n, -1});
  auto y = torch::empty({n, phi.size(1)});
  for (int64_t i = 0; i < n; ++i) y[i] = phi[i % p].matmul(flat[i]);
  return std::make_unique<train::InMemoryBatchSource>(y, p > 1 ? phase : torch::Tensor(), patches,
                                                      0.15, seed, 128);
}

nn::NetworkOptions small_net_options(const std::string& branches) {
  nn::NetworkOptions o;
  o.patch = {3, 3, 5, 5};
  o.measurements = 2;
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.branches = lfnet::nn::from_string(branches, p.branches);
    p.ae.hidden = {64, 32, 64, 32, 64};
    p.cnn.channels = 4;
    p.cnn.depth = 3;
  });
  return o;
}

nn::NetworkOptions small_image_options(int64_t side, int64_t channels) {
  nn::NetworkOptions o;
  o.architecture = nn::kLfnetArchitecture;
  o.measurements = 2;
  o.patch = {3, 3, side, side};
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) {
    image.channels = channels;
    image.levels = 2;
    image.blocks = 1;
  });
  return o;
}

nlohmann::json synthetic_phi_spec(const std::string& name, int64_t n, uint64_t seed) {
  return {{"name", name}, {"n", n},       {"rows", 3},
          {"cols", 3},    {"seed", seed}, {"params", nlohmann::json::object()}};
}

}  // namespace lfnet::test

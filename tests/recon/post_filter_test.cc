#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/recon/post_filter.h"

using lfnet::recon::suppress_periodic;

namespace {

// A smooth (C, U, V, H, W) field: a few low-frequency sinusoids per view.
torch::Tensor smooth_field(int64_t h, int64_t w) {
  auto y = torch::arange(h, torch::kFloat64).view({h, 1});
  auto x = torch::arange(w, torch::kFloat64).view({1, w});
  auto views = std::vector<torch::Tensor>();
  for (int v = 0; v < 4; ++v) {
    views.push_back(0.5 + 0.2 * torch::sin(2 * M_PI * (y * (1 + v) / h + x * 2.0 / w)) +
                    0.1 * torch::cos(2 * M_PI * (x * 3.0 / w - y * 1.0 / h + 0.1 * v)));
  }
  return torch::stack(views).view({1, 2, 2, h, w}).to(torch::kFloat32);
}

double rms(const torch::Tensor& t) {
  return std::sqrt(t.to(torch::kFloat64).pow(2).mean().item<double>());
}

}  // namespace

TEST_CASE("the post-filter removes an artefact that repeats with the stride", "[recon]") {
  for (auto [h, w] : {std::pair<int64_t, int64_t>{60, 80}, {63, 71}}) {
    const auto clean = smooth_field(h, w);
    torch::manual_seed(3);
    auto tile = torch::rand({5, 5}) - 0.5;
    tile -= tile.mean();
    const auto pattern =
        0.05 * tile.repeat({(h + 4) / 5, (w + 4) / 5}).slice(0, 0, h).slice(1, 0, w);
    const auto noisy = clean + pattern.view({1, 1, 1, h, w});
    const auto out = suppress_periodic(noisy, 5);
    REQUIRE(out.sizes() == noisy.sizes());
    REQUIRE(torch::isfinite(out).all().item<bool>());
    const double before = rms(noisy - clean), after = rms(out - clean);
    INFO(h << "x" << w << ": " << before << " -> " << after);
    // Exactly periodic when H and W are multiples of 5; spread over neighbouring bins when not.
    CHECK(after < (h % 5 == 0 && w % 5 == 0 ? 0.05 : 0.6) * before);
  }
}

TEST_CASE("the post-filter leaves a field without periodic content nearly alone", "[recon]") {
  const auto clean = smooth_field(60, 80);
  const auto out = suppress_periodic(clean, 5);
  CHECK(rms(out - clean) < 1e-3 * rms(clean));
  // Period 1 or a field too small for two periods is returned as it is.
  CHECK(torch::equal(suppress_periodic(clean, 1), clean));
  const auto tiny = smooth_field(6, 6);
  CHECK(torch::equal(suppress_periodic(tiny, 5), tiny));
}

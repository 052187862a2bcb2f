#include "lfnet/core/metrics.h"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>

#include "support/test_support.h"

using lfnet::LightField;

TEST_CASE("PSNR follows 10 log10(1 / MSE)", "[core][metrics]") {
  auto truth = torch::zeros({1, 2, 2, 4, 4}, torch::kFloat64);
  auto est = torch::full({1, 2, 2, 4, 4}, 0.1, torch::kFloat64);
  CHECK(lfnet::psnr(est, truth) == Approx(20.0).epsilon(1e-9));
  CHECK(std::isinf(lfnet::psnr(truth, truth)));
  // Per view: one view off by 0.01, the others exact.
  auto e = truth.clone();
  e[0][1][0].fill_(0.01);
  auto pv = lfnet::per_view_psnr(LightField(e), LightField(truth));
  CHECK(pv[1][0].item<double>() == Approx(40.0).epsilon(1e-6));
  CHECK(std::isinf(pv[0][0].item<double>()));
}

TEST_CASE("SSIM of identical images is 1 and drops with noise", "[core][metrics]") {
  auto a = torch::rand({1, 32, 32});
  CHECK(lfnet::ssim_image(a, a) == Approx(1.0).epsilon(1e-12));
  auto b = (a + 0.2 * torch::randn_like(a)).clamp(0, 1);
  CHECK(lfnet::ssim_image(a, b) < 0.9);
}

namespace {}  // namespace

TEST_CASE("PSNR and SSIM agree with scikit-image", "[core][metrics][reference]") {
  const std::string py = lfnet::test::python_with("skimage");
  if (py.empty()) {
    LFNET_SKIP("python3-skimage is not installed: no reference PSNR and SSIM");
  }
  torch::manual_seed(7);
  for (int64_t c : {1, 3}) {
    // A smooth-ish truth and a noisy, blurred estimate, with odd sizes.
    auto truth = torch::rand({c, 3, 2, 23, 30});
    auto est = (0.7 * truth + 0.3 * truth.roll(1, 4) + 0.05 * torch::randn_like(truth)).clamp(0, 1);
    lfnet::test::TempDir tmp;
    lfnet::test::write_f64(tmp / "est.f64", est);
    lfnet::test::write_f64(tmp / "truth.f64", truth);
    std::string out;
    const std::string cmd = py + " " + LFNET_SOURCE_DIR + "/tests/support/reference_metrics.py " +
                            (tmp / "est.f64") + " " + (tmp / "truth.f64") + " " +
                            std::to_string(c) + " 3 2 23 30";
    REQUIRE(lfnet::test::run_command(cmd, out) == 0);
    auto ref = nlohmann::json::parse(out);
    LightField e(est), t(truth);
    INFO("channels " << c);
    CHECK(std::abs(lfnet::psnr(e, t) - ref["psnr"].get<double>()) < 1e-4);
    auto pv = lfnet::per_view_psnr(e, t);
    for (int u = 0; u < 3; ++u) {
      for (int v = 0; v < 2; ++v) {
        CHECK(std::abs(pv[u][v].item<double>() - ref["per_view_psnr"][u][v].get<double>()) < 1e-4);
      }
    }
    const double ours = lfnet::ssim(e, t);
    CHECK(std::abs(ours - ref["ssim"].get<double>()) < 1e-4);
    CHECK(ours < 0.99);  // the comparison is not between two perfect scores
  }
}

TEST_CASE("light-field scores go a band of rows at a time, float32 or 16-bit codes",
          "[core][metrics]") {
  torch::manual_seed(4);
  // Views taller than the band of rows the scores take at a time.
  const auto truth = torch::rand({1, 2, 2, 301, 37});
  const auto estimate = (truth + 0.05 * torch::randn({1, 2, 2, 301, 37})).clamp(0, 1);
  const LightField t(truth), e(estimate);
  double whole = 0;
  for (int64_t u = 0; u < 2; ++u) {
    for (int64_t v = 0; v < 2; ++v) whole += lfnet::ssim_image(e.view(u, v), t.view(u, v)) / 4;
  }
  CHECK(lfnet::ssim(e, t) == Approx(whole).epsilon(1e-12));
  CHECK(lfnet::psnr(e, t) == Approx(lfnet::psnr(estimate, truth)).epsilon(1e-12));
  // The same scores of the estimate held in 16-bit codes: within what the codes round.
  const lfnet::LightFieldViews coded(lfnet::encode_codes(estimate));
  CHECK(lfnet::psnr(coded, t) == Approx(lfnet::psnr(e, t)).margin(1e-3));
  CHECK(lfnet::ssim(coded, t) == Approx(lfnet::ssim(e, t)).margin(1e-5));
  CHECK_THROWS_WITH(lfnet::psnr(coded, LightField(truth.slice(3, 0, 300))),
                    Catch::Contains("differ in shape"));
}

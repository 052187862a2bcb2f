// Non-local means and the pinv-nlm baseline.
#include "lfnet/recon/denoise.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/method_registry.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {
torch::Tensor noise(std::vector<int64_t> shape, double sigma, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  return torch::randn(shape, gen) * sigma;
}
double rmse(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).square().mean().sqrt().item<double>();
}
}  // namespace

TEST_CASE("non-local means leaves a noiseless image alone and flattens noise on a flat one",
          "[recon][denoise]") {
  auto x = torch::rand({4, 20, 30});
  CHECK(torch::equal(recon::non_local_means(x, 0.0), x));
  auto flat = torch::full({9, 40, 40}, 0.5) + noise({9, 40, 40}, 0.1, 1);
  auto out = recon::non_local_means(flat, 0.1);
  CHECK(out.sizes() == flat.sizes());
  CHECK((out - 0.5).std().item<double>() < 0.03);
  CHECK(out.mean().item<double>() == Approx(0.5).margin(0.01));
}

TEST_CASE("non-local means keeps an edge that a box filter blurs", "[recon][denoise]") {
  auto clean = torch::zeros({9, 40, 40});
  clean.slice(2, 20, 40).fill_(1.0);
  auto noisy = clean + noise({9, 40, 40}, 0.1, 2);
  auto nlm = recon::non_local_means(noisy, 0.1);
  auto box =
      torch::avg_pool2d(torch::replication_pad2d(noisy.unsqueeze(0), {1, 1, 1, 1}), {3, 3}, {1, 1})
          .squeeze(0);
  CHECK(rmse(nlm, clean) < 0.5 * rmse(noisy, clean));
  CHECK(rmse(nlm, clean) < rmse(box, clean));
  // The columns beside the edge stay sharp.
  CHECK(nlm.select(2, 19).mean().item<double>() < 0.1);
  CHECK(nlm.select(2, 20).mean().item<double>() > 0.9);
}

TEST_CASE("the pseudo-inverse's noise gain matches simulation", "[recon][denoise]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto pinv = optics::pinv_matrix_stack(*phi, 9, 9)[0];  // (U V h w, N h w)
  auto y = noise({20000, pinv.size(1)}, 0.1, 3);
  const double measured = y.matmul(pinv.t()).std().item<double>();
  CHECK(measured == Approx(recon::pinv_noise_sigma(pinv, 0.1)).epsilon(0.03));
}

TEST_CASE("pinv-nlm beats pinv on a noisy sensor image and equals it without noise",
          "[recon][denoise]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(4);
  // Smooth views with a little parallax: a blurred random texture, shifted per view.
  auto base = torch::avg_pool2d(torch::rand({1, 1, 60, 60}, gen), {5, 5}, {1, 1}).squeeze(0)[0];
  auto lf = torch::empty({5, 5, 50, 50});
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) lf[u][v].copy_(base.slice(0, u, u + 50).slice(1, v, v + 50));
  }
  recon::MethodResources r;
  r.phi = phi.get();
  // OpenCV's denoiser, pinv-nlm's default, is not in the numerical core (lfnet/cv registers it):
  // the core alone says so, and runs lfnet's own when told.
  CHECK_THROWS_WITH(recon::make_image_solver("pinv-nlm", r),
                    Catch::Contains("unknown denoiser 'opencv-nlm'") &&
                        Catch::Contains("not by the numerical core"));
  r.options = {{"denoiser", "nlm"}};
  auto nlm = recon::make_image_solver("pinv-nlm", r);
  REQUIRE(nlm);
  recon::ReconstructOptions ro;
  ro.stride = 9;
  auto pinv = recon::make_solver("pinv", r);
  auto clean = optics::simulate_sensor(*phi, lf);
  CHECK(torch::allclose(nlm(clean, 0.0), recon::reconstruct_sensor(*phi, clean, pinv, ro), 1e-5,
                        1e-5));
  optics::SensorOptions effects;
  effects.gaussian = optics::SensorOptions::Gaussian{0.1};
  auto noisy = optics::simulate_sensor(*phi, lf, effects, 5);
  const auto truth = lf.unsqueeze(0);
  CHECK(rmse(nlm(noisy, 0.1), truth) <
        0.7 * rmse(recon::reconstruct_sensor(*phi, noisy, pinv, ro), truth));
  CHECK_THROWS_AS(recon::make_solver("pinv-nlm", r)(torch::zeros({1, 162}), torch::Tensor()),
                  ConfigError);
}

TEST_CASE("lfnet's NLM options are read strictly, with their paths", "[recon][denoise]") {
  const auto& nlm = recon::find_denoiser("nlm");
  const auto complete = nlm.read_options({{"search", 3}}, "opts");
  CHECK(complete["search"] == 3);
  CHECK(complete["patch"] == 1);
  CHECK(complete["h"] == 0.35);
  CHECK_THROWS_WITH(nlm.read_options({{"radius", 3}}, "opts"), Catch::Contains("opts.radius"));
  CHECK_THROWS_WITH(nlm.read_options({{"patch", -1}}, "opts"),
                    Catch::Contains("opts.patch: must be in 0..20"));
  CHECK(recon::registered_denoisers().front() == "nlm");
}

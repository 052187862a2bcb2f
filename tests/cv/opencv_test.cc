// OpenCV's non-local means as the denoiser "opencv-nlm" of pinv-nlm (lfnet/cv/opencv.h).
#include "lfnet/cv/opencv.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"
#include "lfnet/recon/denoise.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/reconstruct.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

double rmse(const torch::Tensor& a, const torch::Tensor& b) {
  return (a.to(torch::kFloat64) - b.to(torch::kFloat64)).square().mean().sqrt().item<double>();
}

// Smooth views with a little parallax: a blurred random texture, shifted per view.
torch::Tensor smooth_light_field(uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  auto base = torch::avg_pool2d(torch::rand({1, 1, 70, 70}, gen), {5, 5}, {1, 1}).squeeze(0)[0];
  auto lf = torch::empty({5, 5, 60, 60});
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) lf[u][v].copy_(base.slice(0, u, u + 60).slice(1, v, v + 60));
  }
  return lf;
}

}  // namespace

TEST_CASE("opencv-nlm removes most of the noise of noisy views and leaves clean ones alone",
          "[cv]") {
  const auto views = smooth_light_field(3).reshape({25, 60, 60});
  CHECK(torch::equal(cv::opencv_nlm(views, 0.0, {}), views));
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(9);
  const auto noisy = views + 0.05 * torch::randn(views.sizes(), gen);
  const auto denoised = cv::opencv_nlm(noisy, 0.05, {});
  CHECK(denoised.sizes() == views.sizes());
  // A fine random texture leaves non-local means few similar patches: a clear gain, not more.
  CHECK(rmse(denoised, views) < 0.85 * rmse(noisy, views));
  // A weaker strength removes less.
  cv::OpenCvNlmOptions weak;
  weak.h = 0.2;
  CHECK(rmse(cv::opencv_nlm(noisy, 0.05, weak), views) > rmse(denoised, views));
  CHECK_THROWS_AS(cv::opencv_nlm(views[0], 0.05, {}), ConfigError);
  CHECK_THROWS_AS(cv::opencv_nlm(noisy, -1, {}), ConfigError);
}

TEST_CASE("once registered, opencv-nlm is pinv-nlm's default denoiser, beating lfnet's own",
          "[cv]") {
  cv::register_opencv();
  cv::register_opencv();  // a second call changes nothing
  const auto names = recon::registered_denoisers();
  CHECK(names == std::vector<std::string>{"nlm", "opencv-nlm"});
  const auto& d = recon::find_denoiser("opencv-nlm");
  CHECK(d.read_options(nlohmann::json::object(), "o") ==
        nlohmann::json({{"h", 1.0}, {"patch", 7}, {"search", 21}}));
  CHECK_THROWS_WITH(d.read_options({{"patch", 6}}, "o"), Catch::Contains("o.patch: must be odd"));

  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto lf = smooth_light_field(4);
  optics::SensorOptions effects;
  effects.gaussian = optics::SensorOptions::Gaussian{0.1};
  const auto noisy = optics::simulate_sensor(*phi, lf, effects, 5);
  recon::MethodResources r;
  r.phi = phi.get();
  const auto by_default = recon::make_image_solver("pinv-nlm", r)(noisy, 0.1);
  r.options = {{"denoiser", "opencv-nlm"}};
  const auto opencv = recon::make_image_solver("pinv-nlm", r)(noisy, 0.1);
  r.options = {{"denoiser", "nlm"}};
  const auto own = recon::make_image_solver("pinv-nlm", r)(noisy, 0.1);
  CHECK(torch::equal(by_default, opencv));
  const auto truth = lf.unsqueeze(0);
  CHECK(rmse(opencv, truth) < rmse(own, truth));
}

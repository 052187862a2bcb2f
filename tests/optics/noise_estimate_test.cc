// The sensor image's noise estimated from the image alone (optics/noise_estimate.h), against the
// noise the simulation added.
#include "lfnet/optics/noise_estimate.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/core/view_noise.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"

using lfnet::optics::estimate_noise_sigma;
using lfnet::optics::SensorOptions;

namespace {

// A 5 x 5 light field of 160 x 200 pixels: smooth shading, a few sinusoids and a bright disk
// with a hard edge, seen with a disparity of one pixel per view.
torch::Tensor scene() {
  const int64_t h = 160, w = 200;
  const auto xx = torch::arange(w + 8, torch::kFloat64).view({1, w + 8}).expand({h, w + 8});
  const auto yy = torch::arange(h, torch::kFloat64).view({h, 1}).expand({h, w + 8});
  auto base = 0.35 + 0.15 * torch::sin(xx / 17.0) * torch::cos(yy / 23.0) +
              0.1 * torch::sin((xx + yy) / 9.0);
  base = base + 0.3 * ((xx - 90).pow(2) + (yy - 70).pow(2) < 40.0 * 40.0).to(torch::kFloat64);
  auto lf = torch::empty({5, 5, h, w}, torch::kFloat64);
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) lf[u][v] = base.slice(1, v + 2, v + 2 + w);
  }
  return lf.to(torch::kFloat32);
}

SensorOptions effects(const char* json) {
  return SensorOptions::from_json(nlohmann::json::parse(json));
}

}  // namespace

TEST_CASE("the noise of a sensor image is estimated from the image within 5 %", "[optics][noise]") {
  const auto lf = scene();
  for (const char* spec : {"asp:2", "mask:2", "asp:15"}) {
    const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse(spec));
    INFO(spec << ", period " << phi->period());
    const auto clean = lfnet::optics::simulate_sensor(*phi, lf);
    CHECK(estimate_noise_sigma(*phi, clean) < 0.01);
    for (double sigma : {0.02, 0.05, 0.1, 0.2}) {
      INFO("sigma " << sigma);
      const auto noisy = lfnet::optics::simulate_sensor(
          *phi, lf, effects(("{\"gaussian\": {\"sigma\": " + std::to_string(sigma) + "}}").c_str()),
          11);
      const double estimate = estimate_noise_sigma(*phi, noisy);
      CHECK(std::abs(estimate - sigma) <= 0.05 * sigma + 0.002);
    }
  }
}

TEST_CASE("the code's own pixel pattern is not taken for noise", "[optics][noise]") {
  // The mask measures each pixel of its period through another code: divided by each pixel's
  // white response the image is smooth; taken as it is, it is not.
  const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("mask:2"));
  REQUIRE(phi->period() > 1);
  const auto clean = lfnet::optics::simulate_sensor(*phi, scene());
  const double code_aware = estimate_noise_sigma(*phi, clean);
  const double blind = estimate_noise_sigma(clean, torch::ones({2, 1, 1}));
  CHECK(code_aware < 0.01);
  CHECK(blind > 3 * code_aware);
}

TEST_CASE("under shot and read noise the estimate is the sigma at the median signal",
          "[optics][noise]") {
  const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  for (const char* json :
       {R"({"photons_at_white": 100, "shot": {"model": "poisson"}, "read": {"electrons": 4}})",
        R"({"photons_at_white": 400, "shot": {"model": "poisson"}, "read": {"electrons": 2}})"}) {
    INFO(json);
    const auto e = effects(json);
    const auto noisy = lfnet::optics::simulate_sensor(*phi, scene(), e, 5);
    const auto clean = lfnet::optics::simulate_sensor(*phi, scene());
    const double want = e.equivalent_sigma(clean.median().item<double>());
    CHECK(std::abs(estimate_noise_sigma(*phi, noisy) - want) <= 0.1 * want);
  }
}

TEST_CASE("white noise is the sensor's; noise correlated over pixels was in the scene",
          "[optics][noise]") {
  using lfnet::optics::white_noise_share;
  const auto lf = scene();
  for (const char* spec : {"asp:2", "mask:2"}) {
    const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse(spec));
    INFO(spec);
    for (double sigma : {0.01, 0.05}) {
      INFO("sensor noise of sigma " << sigma);
      const auto noisy = lfnet::optics::simulate_sensor(
          *phi, lf, effects(("{\"gaussian\": {\"sigma\": " + std::to_string(sigma) + "}}").c_str()),
          7);
      CHECK(white_noise_share(*phi, noisy) > 0.95);
    }
    // Noise of sigma 0.03 in the views, correlated over neighbouring views and pixels as a
    // plenoptic camera's: the sensor image carries it, but not as white noise.
    auto generator = torch::make_generator<at::CPUGeneratorImpl>(5);
    const auto noise = lfnet::view_noise({1, 5, 5, lf.size(2), lf.size(3)}, 1, 1, generator)[0];
    const auto carried = lfnet::optics::simulate_sensor(*phi, lf + 0.03 * noise);
    CHECK(estimate_noise_sigma(*phi, carried) > 0.003);
    CHECK(white_noise_share(*phi, carried) < 0.5);
    // Views whose noise is independent from pixel to pixel give the sensor white noise: the same
    // as the sensor's own, and told apart from it by nothing in the image.
    const auto independent =
        lfnet::view_noise({1, 5, 5, lf.size(2), lf.size(3)}, 0, 0, generator)[0];
    CHECK(white_noise_share(*phi, lfnet::optics::simulate_sensor(*phi, lf + 0.03 * independent)) >
          0.8);
  }
  // Too small for three scales: all of it counts.
  CHECK(white_noise_share(torch::rand({2, 6, 40}), torch::ones({2, 1, 1})) == 1.0);
}

TEST_CASE("a sensor image's exposure is its bright end over the code's white response",
          "[optics][noise]") {
  using lfnet::optics::sensor_exposure;
  for (const char* spec : {"asp:2", "mask:2"}) {
    const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse(spec));
    INFO(spec);
    // A uniform grey scene of 0.3 measures 0.3 of white at every pixel, whatever the code.
    const auto grey = lfnet::optics::simulate_sensor(*phi, torch::full({5, 5, 40, 48}, 0.3));
    CHECK(sensor_exposure(*phi, grey) == Approx(0.3).epsilon(1e-4));
    // The scene: its 99th percentile lies below its brightest pixels and above its mean; a
    // scene dimmed by 0.4 is 0.4 as bright.
    const auto lf = scene();
    const auto sensor = lfnet::optics::simulate_sensor(*phi, lf);
    const double exposure = sensor_exposure(*phi, sensor);
    CHECK(exposure < lf.max().item<double>());
    CHECK(exposure > lf.mean().item<double>());
    CHECK(sensor_exposure(*phi, lfnet::optics::simulate_sensor(*phi, 0.4 * lf)) ==
          Approx(0.4 * exposure).epsilon(1e-4));
    CHECK(sensor_exposure(*phi, sensor, 0.0) < sensor_exposure(*phi, sensor, 0.5));
    CHECK_THROWS_AS(sensor_exposure(*phi, sensor, 1.5), lfnet::ConfigError);
  }
}

TEST_CASE("noise estimation refuses what is no sensor image", "[optics][noise]") {
  const auto white = torch::ones({2, 1, 1});
  CHECK_THROWS_AS(estimate_noise_sigma(torch::zeros({8, 8}), white), lfnet::ConfigError);
  CHECK_THROWS_AS(estimate_noise_sigma(torch::zeros({2, 1, 8}), white), lfnet::ConfigError);
  CHECK_THROWS_AS(estimate_noise_sigma(torch::zeros({3, 8, 8}), white), lfnet::ConfigError);
  CHECK_THROWS_AS(estimate_noise_sigma(torch::zeros({2, 8, 8}), torch::ones({2, 1, 2})),
                  lfnet::ConfigError);
  // A code that measures nothing leaves no pixel.
  CHECK_THROWS_AS(estimate_noise_sigma(torch::zeros({2, 8, 8}), torch::zeros({2, 1, 1})),
                  lfnet::ConfigError);
}

TEST_CASE("shot and read noise are fitted from the image alone", "[optics][noise]") {
  const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  const auto clean = lfnet::optics::simulate_sensor(*phi, scene());
  const double mean = clean.mean().item<double>();
  for (const char* json :
       {R"({"photons_at_white": 100, "shot": {"model": "poisson"}, "read": {"electrons": 4}})",
        R"({"photons_at_white": 400, "shot": {"model": "poisson"}, "read": {"electrons": 2}})",
        R"({"photons_at_white": 25, "shot": {"model": "poisson"}, "read": {"electrons": 3}})"}) {
    INFO(json);
    const auto e = effects(json);
    const auto noisy = lfnet::optics::simulate_sensor(*phi, scene(), e, 5);
    const auto fit = lfnet::optics::estimate_shot_read(*phi, noisy);
    const double shot = 1.0 / e.photons_at_white;
    CHECK(fit.shot == Approx(shot).epsilon(0.25));
    // The sigma at the image's mean signal, what a noise-aware net is told, within 5 %.
    const double want = e.equivalent_sigma(mean);
    CHECK(std::abs(fit.sigma_at(mean) - want) <= 0.05 * want);
  }
  // Gaussian noise alone: no shot noise to speak of, and its sigma.
  for (double sigma : {0.02, 0.1}) {
    const auto noisy = lfnet::optics::simulate_sensor(
        *phi, scene(),
        effects(("{\"gaussian\": {\"sigma\": " + std::to_string(sigma) + "}}").c_str()), 3);
    const auto fit = lfnet::optics::estimate_shot_read(*phi, noisy);
    CHECK(fit.shot * mean < 0.1 * sigma * sigma);
    CHECK(std::abs(fit.sigma_at(mean) - sigma) <= 0.05 * sigma + 0.002);
  }
  CHECK_THROWS_AS(lfnet::optics::estimate_shot_read(*phi, clean.slice(1, 0, 4).slice(2, 0, 4)),
                  lfnet::ConfigError);
}

TEST_CASE("a noise-aware method is told the sigma at the image's mean signal", "[optics][noise]") {
  const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  const auto e = effects(
      R"({"photons_at_white": 25, "shot": {"model": "poisson"}, "read": {"electrons": 3}})");
  const auto clean = lfnet::optics::simulate_sensor(*phi, scene());
  const auto noisy = lfnet::optics::simulate_sensor(*phi, scene(), e, 7);
  const double want = e.equivalent_sigma(clean.mean().item<double>());
  const double told = lfnet::optics::estimate_equivalent_sigma(*phi, noisy);
  CHECK(std::abs(told - want) <= 0.05 * want);
  CHECK(std::abs(told - want) < std::abs(estimate_noise_sigma(*phi, noisy) - want));
  // Too small for the fit: the Gaussian estimate.
  const auto small = noisy.slice(1, 0, 20).slice(2, 0, 20);
  CHECK(lfnet::optics::estimate_equivalent_sigma(*phi, small) == estimate_noise_sigma(*phi, small));
}

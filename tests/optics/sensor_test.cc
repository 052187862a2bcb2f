// Sensor effects: reproducibility and the statistics of each effect's model.
#include "lfnet/optics/sensor.h"

#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/core/runtime.h"
#include "lfnet/optics/counter_rng.h"
#include "support/test_support.h"

using lfnet::optics::apply_sensor_effects;
using lfnet::optics::SensorOptions;

namespace {

constexpr int64_t kSamples = 1000000;

SensorOptions parse(const char* text) {
  return SensorOptions::from_json(nlohmann::json::parse(text));
}

// Mean and standard deviation in float64.
std::pair<double, double> moments(const torch::Tensor& t) {
  auto d = t.to(torch::kFloat64);
  return {d.mean().item<double>(), d.std().item<double>()};
}

}  // namespace

TEST_CASE("the counter RNG gives uniform and normal numbers", "[optics][sensor]") {
  lfnet::optics::CounterRng rng(42, 1);
  double sum = 0, sum2 = 0, nsum = 0, nsum2 = 0, nsum4 = 0;
  for (uint64_t i = 0; i < 200000; ++i) {
    const double u = rng.uniform(i), z = rng.normal(i);
    REQUIRE(u > 0);
    REQUIRE(u < 1);
    sum += u;
    sum2 += u * u;
    nsum += z;
    nsum2 += z * z;
    nsum4 += z * z * z * z;
  }
  const double n = 200000;
  CHECK(sum / n == Approx(0.5).margin(0.003));
  CHECK(sum2 / n - (sum / n) * (sum / n) == Approx(1.0 / 12).epsilon(0.01));
  CHECK(nsum / n == Approx(0).margin(0.01));
  CHECK(nsum2 / n == Approx(1).epsilon(0.01));
  CHECK(nsum4 / n == Approx(3).epsilon(0.03));
  CHECK(rng.bits(5) == lfnet::optics::CounterRng(42, 1).bits(5));
  CHECK(rng.bits(5) != lfnet::optics::CounterRng(42, 2).bits(5));
  CHECK(rng.bits(5) != lfnet::optics::CounterRng(43, 1).bits(5));
}

TEST_CASE("no effect named leaves the measurement bit-identical", "[optics][sensor]") {
  auto y = torch::rand({2, 30, 40});
  SensorOptions none;
  CHECK(none.empty());
  auto out = apply_sensor_effects(y, none, 9);
  CHECK(torch::equal(out, y));
  CHECK(out.data_ptr() == y.data_ptr());
  CHECK(parse("{}").empty());
  CHECK(parse(R"({"photons_at_white": 50})").empty());
}

TEST_CASE("the same seed gives the same sensor image bit for bit", "[optics][sensor]") {
  auto options = parse(R"({"gaussian": {"sigma": 0.05}, "shot": {}, "read": {"electrons": 4},
                           "gain": {"spread": 0.02}, "saturation": {"full_well": 1500},
                           "adc": {"bits": 10}})");
  auto y = torch::rand({3, 64, 80});
  const int before = lfnet::thread_count();
  lfnet::configure_threads(1);
  auto one = apply_sensor_effects(y, options, 11);
  lfnet::configure_threads(2);
  auto two = apply_sensor_effects(y, options, 11);
  lfnet::configure_threads(before);
  CHECK(torch::equal(one, two));
  CHECK(torch::equal(apply_sensor_effects(y, options, 11), one));
  CHECK_FALSE(torch::equal(apply_sensor_effects(y, options, 12), one));
  CHECK(one.scalar_type() == torch::kFloat32);
  CHECK(one.sizes() == y.sizes());
}

TEST_CASE("gaussian noise has the named sigma", "[optics][sensor]") {
  auto y = torch::full({kSamples}, 0.5);
  auto [mean, std] = moments(apply_sensor_effects(y, parse(R"({"gaussian": {"sigma": 0.1}})"), 1));
  CHECK(mean == Approx(0.5).epsilon(0.02));
  CHECK(std == Approx(0.1).epsilon(0.02));
}

TEST_CASE("shot noise is Poisson in electrons, or its Gaussian approximation", "[optics][sensor]") {
  // Large counts (rejection sampler) and small counts (inversion).
  for (double photons : {1000.0, 4.0}) {
    for (const char* model : {"poisson", "gaussian"}) {
      SensorOptions o;
      o.photons_at_white = photons;
      o.shot = SensorOptions::Shot{from_string(model, lfnet::optics::ShotNoiseModel{})};
      auto y = torch::full({kSamples}, 0.8, torch::kFloat64);
      auto out = apply_sensor_effects(y, o, 3);
      auto [mean, std] = moments(out);
      const double lambda = 0.8 * photons;
      INFO(model << " at " << photons << " photons");
      CHECK(mean == Approx(0.8).epsilon(0.02));
      CHECK(std == Approx(std::sqrt(lambda) / photons).epsilon(0.02));
      if (std::string(model) == "poisson") {
        auto electrons = out * photons;
        CHECK(((electrons - electrons.round()).abs().max().item<double>()) < 1e-9);
        // P(0) = exp(-lambda) at small counts.
        if (photons < 10) {
          const double zeros = (electrons == 0).to(torch::kFloat64).mean().item<double>();
          CHECK(zeros == Approx(std::exp(-lambda)).epsilon(0.02));
        }
      }
    }
  }
}

TEST_CASE("read noise is Gaussian in electrons", "[optics][sensor]") {
  auto y = torch::full({kSamples}, 0.3);
  auto out =
      apply_sensor_effects(y, parse(R"({"photons_at_white": 500, "read": {"electrons": 5}})"), 4);
  auto [mean, std] = moments(out);
  CHECK(mean == Approx(0.3).epsilon(0.02));
  CHECK(std == Approx(5.0 / 500).epsilon(0.02));
}

TEST_CASE("the equivalent sigma has the variance of every named noise", "[optics][sensor]") {
  CHECK(parse("{}").equivalent_sigma(0.5) == 0.0);
  CHECK(parse(R"({"gaussian": {"sigma": 0.1}})").equivalent_sigma(0.7) == Approx(0.1));
  // Measured: shot, read and Gaussian noise together at a constant signal.
  const auto o = parse(R"({"photons_at_white": 50, "shot": {"model": "gaussian"},
                           "read": {"electrons": 4}, "gaussian": {"sigma": 0.03}})");
  const double expected = std::sqrt(0.4 / 50 + std::pow(4.0 / 50, 2) + 0.03 * 0.03);
  CHECK(o.equivalent_sigma(0.4) == Approx(expected));
  const double spread = moments(apply_sensor_effects(torch::full({kSamples}, 0.4), o, 6)).second;
  CHECK(spread == Approx(o.equivalent_sigma(0.4)).epsilon(0.02));
  CHECK(o.equivalent_sigma(-1.0) == Approx(std::sqrt(std::pow(4.0 / 50, 2) + 0.03 * 0.03)));
}

TEST_CASE("saturation clips at the full well", "[optics][sensor]") {
  auto y = torch::linspace(0, 3, 301, torch::kFloat64);
  auto out = apply_sensor_effects(y, parse(R"({"photons_at_white": 1000,
                                                "saturation": {"full_well": 1500}})"),
                                  0);
  lfnet::test::require_close(out, y.clamp_max(1.5), 0);
}

TEST_CASE("the ADC quantises to 2^bits levels over its full scale", "[optics][sensor]") {
  auto y = torch::rand({kSamples}, torch::kFloat64) * 2.0;
  auto out = apply_sensor_effects(y, parse(R"({"adc": {"bits": 6, "full_scale": 2.0}})"), 0);
  const double step = 2.0 / 63;
  auto codes = out / step;
  CHECK(((codes - codes.round()).abs().max().item<double>()) < 1e-9);
  auto err = out - y;
  CHECK(err.abs().max().item<double>() <= step / 2 + 1e-12);
  auto [mean, std] = moments(err);
  CHECK(std::abs(mean) < 0.02 * step);
  CHECK(std == Approx(step / std::sqrt(12.0)).epsilon(0.02));
  // Out-of-range values clip to the first and last code.
  auto edges = apply_sensor_effects(torch::tensor({-0.5, 3.0}, torch::kFloat64),
                                    parse(R"({"adc": {"bits": 6, "full_scale": 2.0}})"), 0);
  lfnet::test::require_close(edges, torch::tensor({0.0, 2.0}, torch::kFloat64), 1e-12);
}

TEST_CASE("gain is a fixed per-pixel pattern independent of the capture seed", "[optics][sensor]") {
  auto y = torch::ones({kSamples}, torch::kFloat64);
  auto options = parse(R"({"gain": {"spread": 0.05, "seed": 3}})");
  auto a = apply_sensor_effects(y, options, 1);
  auto [mean, std] = moments(a);
  CHECK(mean == Approx(1.0).epsilon(0.02));
  CHECK(std == Approx(0.05).epsilon(0.02));
  CHECK(torch::equal(apply_sensor_effects(y, options, 2), a));  // another capture, same sensor
  options.gain->seed = 4;
  CHECK_FALSE(torch::equal(apply_sensor_effects(y, options, 1), a));  // another sensor
  // Pixel ids address the pattern: the same pixel gets the same gain wherever it appears.
  auto ids = torch::tensor({7, 7, 8});
  auto g =
      apply_sensor_effects(torch::ones({3}, torch::kFloat64), options, 1, torch::arange(3), ids);
  CHECK(g[0].item<double>() == g[1].item<double>());
  CHECK(g[0].item<double>() != g[2].item<double>());
}

TEST_CASE("sensor options are strict JSON and round-trip", "[optics][sensor]") {
  const char* text = R"({"photons_at_white": 800, "gaussian": {"sigma": 0.1},
                         "shot": {"model": "gaussian"}, "read": {"electrons": 2},
                         "saturation": {"full_well": 900}, "adc": {"bits": 8, "full_scale": 1.5},
                         "gain": {"spread": 0.01, "seed": 5}})";
  auto o = parse(text);
  CHECK(o.to_json() == nlohmann::json::parse(text));
  CHECK(SensorOptions::from_json(o.to_json()).to_json() == o.to_json());
  CHECK_THROWS_WITH(parse(R"({"shot": {"modle": "poisson"}})"), Catch::Contains("$.shot.modle"));
  CHECK_THROWS_WITH(parse(R"({"blur": {}})"), Catch::Contains("$.blur"));
  CHECK_THROWS_WITH(parse(R"({"shot": {"model": "binomial"}})"), Catch::Contains("$.shot.model"));
  CHECK_THROWS_WITH(parse(R"({"adc": {"bits": 40}})"), Catch::Contains("$.adc.bits"));
  CHECK_THROWS_WITH(parse(R"({"gaussian": {"sigma": "big"}})"),
                    Catch::Contains("$.gaussian.sigma"));
  CHECK_THROWS_AS(parse(R"({"gaussian": {"sigma": -1}})"), lfnet::ConfigError);
}

#include "lfnet/optics/sensor.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/optics/counter_rng.h"

namespace lfnet::optics {

namespace {
constexpr EnumName<ShotNoiseModel> kShotNoiseModels[] = {{ShotNoiseModel::kPoisson, "poisson"},
                                                         {ShotNoiseModel::kGaussian, "gaussian"}};
}  // namespace

std::string to_string(ShotNoiseModel value) { return name_of(value, kShotNoiseModels); }
ShotNoiseModel from_string(const std::string& name, ShotNoiseModel) {
  return value_of(name, kShotNoiseModels);
}

bool SensorOptions::empty() const {
  return !gaussian && !shot && !read && !saturation && !adc && !gain;
}

double SensorOptions::equivalent_sigma(double mean_signal) const {
  if (!shot && !read) return gaussian ? gaussian->sigma : 0.0;  // exact, not via its square
  double variance = 0;
  if (gaussian) variance += gaussian->sigma * gaussian->sigma;
  if (shot) variance += std::max(mean_signal, 0.0) / photons_at_white;
  if (read) variance += std::pow(read->electrons / photons_at_white, 2);
  return std::sqrt(variance);
}

void SensorOptions::validate() const {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw ConfigError("sensor effects: " + what);
  };
  check(photons_at_white > 0, "$.photons_at_white must be > 0");
  if (gaussian) check(gaussian->sigma >= 0, "$.gaussian.sigma must be >= 0");
  if (read) check(read->electrons >= 0, "$.read.electrons must be >= 0");
  if (saturation) check(saturation->full_well > 0, "$.saturation.full_well must be > 0");
  if (adc) {
    check(adc->bits >= 1 && adc->bits <= 24, "$.adc.bits must be in 1..24");
    check(adc->full_scale > 0, "$.adc.full_scale must be > 0");
  }
  if (gain) check(gain->spread >= 0, "$.gain.spread must be >= 0");
}

SensorOptions SensorOptions::from_json(const nlohmann::json& j, const std::string& path) {
  JsonReader r(j, path);
  SensorOptions o;
  read_fields(r, o);
  r.finish();
  o.validate();
  return o;
}

nlohmann::json SensorOptions::to_json() const { return fields_to_json(*this); }

namespace {

// Poisson(lambda) from one element's sub-stream: inversion for small lambda, otherwise the
// transformed rejection PTRS of Hoermann (1993), as numpy's generator does.
double poisson(double lambda, const CounterRng& rng) {
  if (lambda <= 0) return 0.0;
  if (lambda < 12.0) {
    const double u = rng.uniform(0);
    double p = std::exp(-lambda), cdf = p;
    int64_t k = 0;
    while (u > cdf && k < 1000) {
      ++k;
      p *= lambda / static_cast<double>(k);
      cdf += p;
    }
    return static_cast<double>(k);
  }
  const double slam = std::sqrt(lambda), loglam = std::log(lambda);
  const double b = 0.931 + 2.53 * slam;
  const double a = -0.059 + 0.02483 * b;
  const double invalpha = 1.1239 + 1.1328 / (b - 3.4);
  const double vr = 0.9277 - 3.6224 / (b - 2);
  for (uint64_t draw = 0;; draw += 2) {
    const double u = rng.uniform(draw) - 0.5;
    const double v = rng.uniform(draw + 1);
    const double us = 0.5 - std::fabs(u);
    const double k = std::floor((2 * a / us + b) * u + lambda + 0.43);
    if (us >= 0.07 && v <= vr) return k;
    if (k < 0 || (us < 0.013 && v > us)) continue;
    if (std::log(v) + std::log(invalpha) - std::log(a / (us * us) + b) <=
        -lambda + k * loglam - std::lgamma(k + 1)) {
      return k;
    }
  }
}

}  // namespace

torch::Tensor apply_sensor_effects(const torch::Tensor& y, const SensorOptions& options,
                                   uint64_t seed, const torch::Tensor& element_ids,
                                   const torch::Tensor& pixel_ids) {
  if (options.empty()) return y;
  options.validate();
  LFNET_CHECK(y.scalar_type() == torch::kFloat32 || y.scalar_type() == torch::kFloat64,
              "sensor effects apply to float32 or float64 measurements");
  const int64_t count = y.numel();
  auto ids = element_ids.defined() ? element_ids : torch::arange(count, torch::kLong);
  auto pids = pixel_ids.defined() ? pixel_ids : ids;
  LFNET_CHECK(ids.numel() == count && pids.numel() == count,
              "sensor effects: element and pixel ids must have one entry per measurement");
  ids = ids.to(torch::kLong).contiguous().reshape({-1});
  pids = pids.to(torch::kLong).contiguous().reshape({-1});
  auto values = y.to(torch::kFloat64).contiguous().reshape({-1}).clone();
  double* v = values.data_ptr<double>();
  const int64_t* id = ids.data_ptr<int64_t>();
  const int64_t* pid = pids.data_ptr<int64_t>();

  const double k = options.photons_at_white;
  const CounterRng gain_rng(options.gain ? options.gain->seed : 0, stream::kGainPattern);
  const CounterRng shot_rng(seed, stream::kShotNoise);
  const CounterRng read_rng(seed, stream::kReadNoise);
  const CounterRng gauss_rng(seed, stream::kGaussianNoise);
  const double levels = options.adc ? std::ldexp(1.0, options.adc->bits) - 1.0 : 0.0;
  at::parallel_for(0, count, 2048, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      double s = v[i];
      const auto e = static_cast<uint64_t>(id[i]);
      if (options.gain)
        s *= 1.0 + options.gain->spread * gain_rng.normal(static_cast<uint64_t>(pid[i]));
      if (options.shot) {
        const double lambda = k * std::max(s, 0.0);
        const double electrons = options.shot->model == ShotNoiseModel::kPoisson
                                     ? poisson(lambda, shot_rng.sub(e))
                                     : lambda + std::sqrt(lambda) * shot_rng.normal(e);
        s = electrons / k;
      }
      if (options.saturation) s = std::min(s, options.saturation->full_well / k);
      if (options.read) s += options.read->electrons / k * read_rng.normal(e);
      if (options.gaussian) s += options.gaussian->sigma * gauss_rng.normal(e);
      if (options.adc) {
        const double fs = options.adc->full_scale;
        s = std::nearbyint(std::clamp(s / fs, 0.0, 1.0) * levels) / levels * fs;
      }
      v[i] = s;
    }
  });
  return values.view(y.sizes()).to(y.scalar_type());
}

}  // namespace lfnet::optics

// Sensor effects on coded measurements: noise, quantisation, saturation, fixed-pattern gain.
// Measurements are relative: a white light field measures 1 on average (see phi.h), so every
// sigma here is relative to a white scene's signal. docs/acquisition.md describes the model.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include "lfnet/core/fields.h"

#include <cstdint>
#include <optional>
#include <string>

namespace lfnet::optics {

// Photon shot noise drawn from the Poisson law or its Gaussian approximation; by name
// "poisson", "gaussian".
enum class ShotNoiseModel { kPoisson, kGaussian };
std::string to_string(ShotNoiseModel value);
ShotNoiseModel from_string(const std::string& name, ShotNoiseModel);

// The effects of SensorOptions, each applied when present. (They live outside SensorOptions,
// which names them by aliases, so that std::optional sees complete types.)

// Additive Gaussian noise in relative units: the paper's "std 0.1 / 0.2".
struct GaussianNoise {
  double sigma = 0.01;  // standard deviation, relative to a white scene's mean signal

  template <typename Fields>
  void fields(Fields& f) {
    f("sigma", sigma, Range::closed(0, 10));
  }
};
// Photon shot noise: electrons ~ Poisson(photons_at_white * y).
struct ShotNoise {
  ShotNoiseModel model = ShotNoiseModel::kPoisson;  // poisson, or gaussian (its approximation)

  template <typename Fields>
  void fields(Fields& f) {
    f("model", model);
  }
};
// Read noise of the pixel's electronics, in electrons.
struct ReadNoise {
  double electrons = 3.0;  // standard deviation in electrons

  template <typename Fields>
  void fields(Fields& f) {
    f("electrons", electrons, Range::closed(0, 1e6));
  }
};
// Full-well saturation: electrons are clipped at the well's capacity.
struct WellSaturation {
  double full_well = 2000.0;  // electrons (twice a white scene's mean at the default scale)

  template <typename Fields>
  void fields(Fields& f) {
    f("full_well", full_well, Range::above(0, 1e12));
  }
};
// Analogue-to-digital conversion: clip to [0, full_scale] and quantise to 2^bits levels.
struct AdcConversion {
  int bits = 12;            // 1 .. 24
  double full_scale = 2.0;  // relative signal at the top code (white's mean is 1)

  template <typename Fields>
  void fields(Fields& f) {
    f("bits", bits);
    f("full_scale", full_scale, Range::above(0, 1e6));
  }
};
// Fixed-pattern photo-response non-uniformity: each sensor pixel's gain ~ N(1, spread).
struct PixelGain {
  double spread = 0.01;  // standard deviation of the per-pixel gain
  uint64_t seed = 0;     // the sensor's pattern: fixed across captures, unlike the noise seed

  template <typename Fields>
  void fields(Fields& f) {
    f("spread", spread, Range::closed(0, 1));
    f("seed", seed);
  }
};

// Which effects a simulation applies; each is applied only when present. Applied in the
// order of a real pixel: gain, shot, saturation, read, gaussian, adc.
struct SensorOptions {
  using Gaussian = GaussianNoise;
  using Shot = ShotNoise;
  using Read = ReadNoise;
  using Saturation = WellSaturation;
  using Adc = AdcConversion;
  using Gain = PixelGain;

  // Electrons a pixel collects when its noiseless measurement is 1 (a white scene's mean):
  // converts relative measurements to electrons for shot, read and saturation.
  double photons_at_white = 1000.0;
  std::optional<Gaussian> gaussian;
  std::optional<Shot> shot;
  std::optional<Read> read;
  std::optional<Saturation> saturation;
  std::optional<Adc> adc;
  std::optional<Gain> gain;

  template <typename Fields>
  void fields(Fields& f) {
    f("photons_at_white", photons_at_white, Range::above(0, 1e12));
    f("gaussian", gaussian);
    f("shot", shot);
    f("read", read);
    f("saturation", saturation);
    f("adc", adc);
    f("gain", gain);
  }
  // True when no effect is named: the measurement is the noiseless forward model.
  bool empty() const;
  // The sigma of Gaussian noise (relative to white) whose variance equals that of the named
  // noises at the relative signal `mean_signal`: gaussian sigma^2, plus the shot noise's
  // mean_signal / photons_at_white, plus the read noise's (electrons / photons_at_white)^2.
  // A noise-aware network reads it as its one noise level (docs/acquisition.md).
  double equivalent_sigma(double mean_signal) const;
  // Throws ConfigError naming the bad field.
  void validate() const;
  // Strict: unknown keys are ConfigErrors naming the JSON path (e.g. "$.shot.modle").
  static SensorOptions from_json(const nlohmann::json& j, const std::string& path = "$");
  nlohmann::json to_json() const;
};

// Applies the named effects to measurements `y` (any shape, float32 or float64) and returns a
// new tensor of the same shape and dtype; with no effect named, returns `y` itself unchanged.
// Random draws are counter-based: element i uses the numbers of (seed, effect, ids[i]), so the
// same seed gives the same result bit for bit, whatever the thread count. `element_ids`
// (int64, same number of elements; default: the flat index) addresses each element's noise;
// `pixel_ids` (default: element_ids) addresses the fixed gain pattern, so the per-patch mode
// can give every patch independent noise but the sensor pixel's own gain.
torch::Tensor apply_sensor_effects(const torch::Tensor& y, const SensorOptions& options,
                                   uint64_t seed, const torch::Tensor& element_ids = {},
                                   const torch::Tensor& pixel_ids = {});

}  // namespace lfnet::optics

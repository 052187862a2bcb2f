#include "lfnet/optics/noise_estimate.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet::optics {

namespace {

// The finest-scale diagonal Haar coefficients of a sensor image divided by its white response,
// each over the noise its four pixels carry after the division (so each is N(0, sigma^2) where
// the scene is smooth), with the local signal each one sees (its pixels' measurements averaged
// as their noise weighs them). Only blocks whose four pixels are usable.
struct HaarCoefficients {
  torch::Tensor normalised;  // (K,) float64
  torch::Tensor signal;      // (K,) float64
};

// The white response at every pixel of a sensor image: the period's tile (N, T, T) repeated.
torch::Tensor response_image(const torch::Tensor& sensor, const torch::Tensor& white) {
  LFNET_CHECK_AS(ConfigError, sensor.dim() == 3, "a sensor image is (N, H, W), not of ",
                 sensor.dim(), " dimensions");
  LFNET_CHECK_AS(ConfigError,
                 white.dim() == 3 && white.size(0) == sensor.size(0) &&
                     white.size(1) == white.size(2) && white.size(1) >= 1,
                 "the white response must be (N, T, T) for a sensor image of ", sensor.size(0),
                 " measurements");
  const int64_t h = sensor.size(1), w = sensor.size(2), t = white.size(1);
  return white.to(torch::kFloat64)
      .repeat({1, (h + t - 1) / t, (w + t - 1) / t})
      .slice(1, 0, h)
      .slice(2, 0, w);
}

// Pixels whose white response is below a fifth of the mean carry too much noise to be used.
double usable_floor(const torch::Tensor& white) {
  return 0.2 * white.to(torch::kFloat64).mean().item<double>();
}

// `sensor` and its white response `response` (both (N, H, W)), each pixel carrying noise of the
// same sigma; pixels whose response is not above `floor` are left out.
HaarCoefficients haar_coefficients(const torch::Tensor& sensor, const torch::Tensor& response_in,
                                   double floor) {
  const int64_t h = sensor.size(1) / 2 * 2, w = sensor.size(2) / 2 * 2;
  LFNET_CHECK_AS(ConfigError, h >= 2 && w >= 2, "a sensor image of ", sensor.size(1), " x ",
                 sensor.size(2), " pixels is too small to estimate its noise");
  const auto response = response_in.slice(1, 0, h).slice(2, 0, w);
  const auto y = sensor.to(torch::kFloat64).slice(1, 0, h).slice(2, 0, w);
  const auto usable = response > floor;
  const auto ratio = y / response.clamp_min(1e-12);
  // Per pixel, the noise's factor after the division; per 2 x 2 block, the diagonal Haar
  // coefficient (a - b - c + d) / 2 and its noise sqrt(sum of the squared factors) / 2.
  const auto factor = 1.0 / response.clamp_min(1e-12);
  auto corner = [](const torch::Tensor& x, int64_t dy, int64_t dx) {
    return x.slice(1, dy, x.size(1), 2).slice(2, dx, x.size(2), 2);
  };
  auto block_sum = [&](const torch::Tensor& x) {
    return corner(x, 0, 0) + corner(x, 0, 1) + corner(x, 1, 0) + corner(x, 1, 1);
  };
  const auto coefficient =
      (corner(ratio, 0, 0) - corner(ratio, 0, 1) - corner(ratio, 1, 0) + corner(ratio, 1, 1)) / 2;
  const auto factor2 = factor.square();
  const auto spread = block_sum(factor2).sqrt() / 2;
  const auto keep =
      corner(usable, 0, 0) & corner(usable, 0, 1) & corner(usable, 1, 0) & corner(usable, 1, 1);
  HaarCoefficients out;
  out.normalised = (coefficient / spread).masked_select(keep);
  out.signal = (block_sum(y * factor2) / block_sum(factor2)).masked_select(keep);
  LFNET_CHECK_AS(ConfigError, out.normalised.numel() > 0,
                 "the code's white response leaves no pixel to estimate the noise from");
  return out;
}

// The median of |z| of a zero-mean Gaussian is 0.6745 sigma.
constexpr double kMadToSigma = 1.0 / 0.6744897501960817;

// White noise reads the same sigma at scales 1 and 2 to within sampling (a few % on a sensor
// image of 100 000 pixels); a sigma that grows by more than this is scene content.
constexpr double kWhiteGrowth = 1.2;

// The white response of a local Phi: (N, U, V, T, T) summed over the views.
torch::Tensor white_response(const Phi& phi) {
  const int64_t t = phi.period();
  return phi.pixel_weights(0, 0, t, t).sum({1, 2});
}

// A sensor image's 2 x 2 blocks summed: (N, H / 2, W / 2).
torch::Tensor bin2(const torch::Tensor& x) {
  const auto even = x.slice(1, 0, x.size(1) / 2 * 2).slice(2, 0, x.size(2) / 2 * 2);
  return even.slice(1, 0, even.size(1), 2).slice(2, 0, even.size(2), 2) +
         even.slice(1, 0, even.size(1), 2).slice(2, 1, even.size(2), 2) +
         even.slice(1, 1, even.size(1), 2).slice(2, 0, even.size(2), 2) +
         even.slice(1, 1, even.size(1), 2).slice(2, 1, even.size(2), 2);
}

}  // namespace

double estimate_noise_sigma(const torch::Tensor& sensor, const torch::Tensor& white) {
  const auto c = haar_coefficients(sensor, response_image(sensor, white), usable_floor(white));
  return c.normalised.abs().median().item<double>() * kMadToSigma;
}

double white_noise_share(const torch::Tensor& sensor, const torch::Tensor& white) {
  auto y = sensor.to(torch::kFloat64);
  auto response = response_image(sensor, white);
  double floor = usable_floor(white);
  if (y.size(1) < 8 || y.size(2) < 8) return 1.0;  // too small for three scales
  // The estimate at scales 1, 2 and 4: a block of 2^j x 2^j pixels summed carries 2^j times
  // the noise of one, so white noise reads the same sigma at every scale.
  double variance[3];
  for (int j = 0; j < 3; ++j) {
    const auto c = haar_coefficients(y, response, floor);
    const double sigma = c.normalised.abs().median().item<double>() * kMadToSigma / (1 << j);
    variance[j] = sigma * sigma;
    y = bin2(y);
    response = bin2(response);
    floor *= 4;
  }
  if (!(variance[0] > 0) || variance[1] <= kWhiteGrowth * kWhiteGrowth * variance[0]) return 1.0;
  // Scene content grows by a factor g per octave (g = d2 / d1, at least 2): its part of the
  // finest scale's variance is d1 / (g - 1).
  const double d1 = variance[1] - variance[0], d2 = variance[2] - variance[1];
  const double growth = std::max(d2 / d1, 2.0);
  const double white_variance = std::max(variance[0] - d1 / (growth - 1), 0.0);
  return std::sqrt(white_variance / variance[0]);
}

double white_noise_share(const Phi& phi, const torch::Tensor& sensor) {
  return white_noise_share(sensor, white_response(phi));
}

double sensor_exposure(const Phi& phi, const torch::Tensor& sensor, double quantile) {
  LFNET_CHECK_AS(ConfigError, quantile >= 0 && quantile <= 1, "a quantile is in [0, 1], not ",
                 quantile);
  const auto white = white_response(phi);
  const auto response = response_image(sensor, white);
  const auto usable = response > usable_floor(white);
  const auto ratio = (sensor.to(torch::kFloat64) / response.clamp_min(1e-12)).masked_select(usable);
  LFNET_CHECK_AS(ConfigError, ratio.numel() > 0,
                 "the code's white response leaves no pixel to measure the exposure of");
  const int64_t k = std::clamp<int64_t>(
      static_cast<int64_t>(std::ceil(quantile * static_cast<double>(ratio.numel()))), 1,
      ratio.numel());
  return std::get<0>(ratio.kthvalue(k)).item<double>();
}

double ShotReadEstimate::sigma_at(double signal) const {
  return std::sqrt(std::max(0.0, shot * std::max(signal, 0.0) + read));
}

ShotReadEstimate estimate_shot_read(const torch::Tensor& sensor, const torch::Tensor& white,
                                    int64_t bins) {
  LFNET_CHECK_AS(ConfigError, bins >= 2, "estimate_shot_read needs at least 2 signal bins");
  const auto c = haar_coefficients(sensor, response_image(sensor, white), usable_floor(white));
  const int64_t k = c.normalised.numel();
  LFNET_CHECK_AS(ConfigError, k >= 16 * bins, "a sensor image of ", sensor.size(1), " x ",
                 sensor.size(2), " pixels is too small to fit signal-dependent noise");
  // Blocks sorted by signal, in bins of equal counts: per bin, the robust variance of its
  // coefficients at its mean signal.
  const auto order = c.signal.argsort();
  const auto z = c.normalised.index_select(0, order).abs();
  const auto s = c.signal.index_select(0, order);
  std::vector<double> level(bins), variance(bins);
  for (int64_t b = 0; b < bins; ++b) {
    const int64_t lo = b * k / bins, hi = (b + 1) * k / bins;
    level[b] = s.slice(0, lo, hi).mean().item<double>();
    const double sigma = z.slice(0, lo, hi).median().item<double>() * kMadToSigma;
    variance[b] = sigma * sigma;
  }
  // Least squares of variance = shot * signal + read over the bins, both >= 0.
  double sl = 0, sv = 0, sll = 0, slv = 0;
  for (int64_t b = 0; b < bins; ++b) {
    sl += level[b];
    sv += variance[b];
    sll += level[b] * level[b];
    slv += level[b] * variance[b];
  }
  const auto n = static_cast<double>(bins);
  const double det = n * sll - sl * sl;
  ShotReadEstimate e;
  e.shot = det > 0 ? (n * slv - sl * sv) / det : 0.0;
  e.read = (sv - e.shot * sl) / n;
  if (e.shot < 0) {
    e.shot = 0;
    e.read = sv / n;
  } else if (e.read < 0) {
    e.read = 0;
    e.shot = sll > 0 ? slv / sll : 0.0;
  }
  return e;
}

ShotReadEstimate estimate_shot_read(const Phi& phi, const torch::Tensor& sensor, int64_t bins) {
  return estimate_shot_read(sensor, white_response(phi), bins);
}

double estimate_noise_sigma(const Phi& phi, const torch::Tensor& sensor) {
  return estimate_noise_sigma(sensor, white_response(phi));
}

double estimate_equivalent_sigma(const Phi& phi, const torch::Tensor& sensor) {
  constexpr int64_t kBins = 12;
  const int64_t blocks = sensor.size(-2) / 2 * (sensor.size(-1) / 2) * sensor.size(0);
  if (sensor.dim() != 3 || blocks < 64 * kBins) return estimate_noise_sigma(phi, sensor);
  return estimate_shot_read(phi, sensor, kBins).sigma_at(sensor.mean().item<double>());
}

}  // namespace lfnet::optics

#include "lfnet/optics/noise_estimate.h"

#include <torch/torch.h>

#include "lfnet/core/error.h"

namespace lfnet::optics {

double estimate_noise_sigma(const torch::Tensor& sensor, const torch::Tensor& white) {
  LFNET_CHECK_AS(ConfigError, sensor.dim() == 3, "a sensor image is (N, H, W), not of ",
                 sensor.dim(), " dimensions");
  LFNET_CHECK_AS(ConfigError,
                 white.dim() == 3 && white.size(0) == sensor.size(0) &&
                     white.size(1) == white.size(2) && white.size(1) >= 1,
                 "the white response must be (N, T, T) for a sensor image of ", sensor.size(0),
                 " measurements");
  const int64_t h = sensor.size(1) / 2 * 2, w = sensor.size(2) / 2 * 2, t = white.size(1);
  LFNET_CHECK_AS(ConfigError, h >= 2 && w >= 2, "a sensor image of ", sensor.size(1), " x ",
                 sensor.size(2), " pixels is too small to estimate its noise");
  // The white response at every pixel: the period's tile repeated over the image.
  const auto tile = white.to(torch::kFloat64);
  const auto response =
      tile.repeat({1, (h + t - 1) / t, (w + t - 1) / t}).slice(1, 0, h).slice(2, 0, w);
  const auto y = sensor.to(torch::kFloat64).slice(1, 0, h).slice(2, 0, w);
  const auto usable = response > 0.2 * tile.mean();
  const auto ratio = y / response.clamp_min(1e-12);
  // Per pixel, the noise's factor after the division; per 2 x 2 block, the diagonal Haar
  // coefficient (a - b - c + d) / 2 and its noise sqrt(sum of the squared factors) / 2.
  const auto factor = 1.0 / response.clamp_min(1e-12);
  auto corner = [](const torch::Tensor& x, int64_t dy, int64_t dx) {
    return x.slice(1, dy, x.size(1), 2).slice(2, dx, x.size(2), 2);
  };
  const auto coefficient =
      (corner(ratio, 0, 0) - corner(ratio, 0, 1) - corner(ratio, 1, 0) + corner(ratio, 1, 1)) / 2;
  const auto spread = (corner(factor, 0, 0).square() + corner(factor, 0, 1).square() +
                       corner(factor, 1, 0).square() + corner(factor, 1, 1).square())
                          .sqrt() /
                      2;
  const auto keep =
      corner(usable, 0, 0) & corner(usable, 0, 1) & corner(usable, 1, 0) & corner(usable, 1, 1);
  const auto normalised = (coefficient / spread).abs().masked_select(keep);
  LFNET_CHECK_AS(ConfigError, normalised.numel() > 0,
                 "the code's white response leaves no pixel to estimate the noise from");
  // The median of |z| of a zero-mean Gaussian is 0.6745 sigma.
  return normalised.median().item<double>() / 0.6744897501960817;
}

double estimate_noise_sigma(const Phi& phi, const torch::Tensor& sensor) {
  const int64_t t = phi.period();
  // (N, U, V, T, T) summed over the views: each pixel phase's measurement of a white field.
  const auto white = phi.pixel_weights(0, 0, t, t).sum({1, 2});
  return estimate_noise_sigma(sensor, white);
}

}  // namespace lfnet::optics

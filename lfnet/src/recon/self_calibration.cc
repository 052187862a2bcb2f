#include "lfnet/recon/self_calibration.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "lfnet/core/error.h"
#include "lfnet/recon/fully_convolutional.h"

namespace lfnet::recon {

namespace {

// The pixel weights (N, U, V, T, T) of one period of `phi` displaced by `error`.
torch::Tensor period_weights(const optics::Phi& phi, const optics::CalibrationError& error) {
  const int64_t t = phi.period();
  return optics::perturbed_pixel_weights(phi, error, 0, 0, t, t, {});
}

// Whether displacing the response along `axis` (0: U, 1: V) changes the Phi's weights at all
// (the ASP pair varies along U only).
bool shift_matters(const optics::Phi& phi, int axis, double shift) {
  optics::CalibrationError error;
  (axis == 0 ? error.angular_shift_u : error.angular_shift_v) = shift;
  const auto nominal = period_weights(phi, {});
  return (period_weights(phi, error) - nominal).abs().max().item<double>() >
         1e-9 * std::max(1.0, nominal.abs().max().item<double>());
}

}  // namespace

NominalPhiOnExit::~NominalPhiOnExit() {
  try {
    tell_camera(net_, phi_, {});
  } catch (...) {  // a destructor must not throw; the nominal Phi was set before
  }
}

void SelfCalibrationOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, std::isfinite(max_shift) && max_shift > 0 && max_shift <= 1,
                 "self-calibration: max_shift must lie in (0, 1] views, got ", max_shift);
  LFNET_CHECK_AS(ConfigError, std::isfinite(tolerance) && tolerance > 0 && tolerance < max_shift,
                 "self-calibration: tolerance must lie in (0, max_shift), got ", tolerance);
  LFNET_CHECK_AS(ConfigError, crop >= 16, "self-calibration: crop must be at least 16, got ", crop);
  LFNET_CHECK_AS(ConfigError, margin >= 0 && 2 * margin < crop,
                 "self-calibration: margin must lie in [0, crop / 2), got ", margin);
}

double angular_roughness(const torch::Tensor& lf, int axis, int64_t margin) {
  LFNET_CHECK(lf.dim() == 5, "angular_roughness: expected (C, U, V, H, W), got ", lf.sizes());
  LFNET_CHECK(axis == 0 || axis == 1, "angular_roughness: axis 0 (U) or 1 (V), got ", axis);
  const int64_t h = lf.size(3), w = lf.size(4);
  LFNET_CHECK(margin >= 0 && 2 * margin < h && 2 * margin < w, "angular_roughness: margin ", margin,
              " leaves no pixel of ", h, "x", w);
  const auto inner = lf.narrow(3, margin, h - 2 * margin).narrow(4, margin, w - 2 * margin);
  const int64_t dim = 1 + axis;
  if (inner.size(dim) < 2) return 0;
  const auto a = inner.narrow(dim, 1, inner.size(dim) - 1).to(torch::kFloat64);
  const auto b = inner.narrow(dim, 0, inner.size(dim) - 1).to(torch::kFloat64);
  return (a - b).abs().mean().item<double>();
}

void tell_camera(nn::LightFieldNet net, const optics::Phi& phi,
                 const optics::CalibrationError& error) {
  LFNET_CHECK_AS(ConfigError, phi.local(),
                 "self-calibration needs a Phi whose measurements are per pixel; ",
                 phi.spec().label(), " is not");
  net->set_phi(period_weights(phi, error).to(torch::kFloat32));
}

SelfCalibration estimate_angular_shift(nn::LightFieldNet net, const optics::Phi& phi,
                                       const torch::Tensor& sensor, double noise_sigma,
                                       const SelfCalibrationOptions& options) {
  options.validate();
  LFNET_CHECK_AS(ConfigError, !net.is_empty() && net->architecture().whole_image(),
                 "self-calibration needs a whole-image network (the lfnet architecture)");
  LFNET_CHECK(sensor.dim() == 3, "self-calibration: expected a sensor image (N, H, W), got ",
              sensor.sizes());
  torch::NoGradGuard no_grad;
  // The centre crop, its origin on a whole period of the code and of a colour filter array (2).
  const int64_t align = 2 * phi.period();
  const int64_t h = sensor.size(1), w = sensor.size(2);
  const int64_t ch = std::min(options.crop, h), cw = std::min(options.crop, w);
  const int64_t y0 = (h - ch) / 2 / align * align, x0 = (w - cw) / 2 / align * align;
  const auto crop = sensor.narrow(1, y0, ch).narrow(2, x0, cw).contiguous();
  const int64_t margin = std::min({options.margin, (ch - 1) / 2, (cw - 1) / 2});

  SelfCalibration found;
  const NominalPhiOnExit restore(net, phi);
  for (int axis = 0; axis < 2; ++axis) {
    if (!shift_matters(phi, axis, options.max_shift)) continue;
    std::map<double, double> seen;  // shift -> roughness
    auto roughness = [&](double shift) {
      const auto at = seen.find(shift);
      if (at != seen.end()) return at->second;
      auto error = found.error;
      (axis == 0 ? error.angular_shift_u : error.angular_shift_v) = shift;
      tell_camera(net, phi, error);
      const auto lf = reconstruct_sensor_tiled(net, crop, std::max(ch, cw), true, noise_sigma);
      ++found.reconstructions;
      return seen[shift] = angular_roughness(lf, axis, margin);
    };
    // A coarse grid, then a golden-section search in the brackets either side of its best.
    const double step = options.max_shift / 2;
    double best = 0;
    for (int k = -2; k <= 2; ++k) {
      if (roughness(k * step) < roughness(best)) best = k * step;
    }
    double lo = std::max(-options.max_shift, best - step);
    double hi = std::min(options.max_shift, best + step);
    const double ratio = (std::sqrt(5.0) - 1) / 2;
    double a = hi - ratio * (hi - lo), b = lo + ratio * (hi - lo);
    double fa = roughness(a), fb = roughness(b);
    while (hi - lo > options.tolerance) {
      if (fa < fb) {
        hi = b;
        b = a;
        fb = fa;
        a = hi - ratio * (hi - lo);
        fa = roughness(a);
      } else {
        lo = a;
        a = b;
        fa = fb;
        b = lo + ratio * (hi - lo);
        fb = roughness(b);
      }
    }
    // The best of every shift tried.
    const auto least = std::min_element(
        seen.begin(), seen.end(), [](const auto& p, const auto& q) { return p.second < q.second; });
    (axis == 0 ? found.error.angular_shift_u : found.error.angular_shift_v) = least->first;
  }
  return found;
}

}  // namespace lfnet::recon

#include "lfnet/optics/calibration.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet::optics {

bool CalibrationError::empty() const {
  return depth == 0 && angular_shift_u == 0 && angular_shift_v == 0 && shift_y == 0 &&
         shift_x == 0 && period == 0 && vignetting == 0;
}

void CalibrationError::validate() const {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw ConfigError(what);
  };
  for (double value : {depth, angular_shift_u, angular_shift_v, shift_y, shift_x, period}) {
    check(std::isfinite(value), "every field of a calibration error must be a finite number");
  }
  check(depth > -1, "depth must be > -1 (the depth times 1 + depth must stay positive)");
  check(period > -0.5 && period < 0.5, "period must lie in (-0.5, 0.5)");
  check(vignetting >= 0 && vignetting < 1, "vignetting must lie in [0, 1)");
}

CalibrationError CalibrationError::from_json(const nlohmann::json& j, const std::string& path) {
  JsonReader r(j, path);
  CalibrationError e;
  read_fields(r, e);
  r.finish();
  try {
    e.validate();
  } catch (const ConfigError& error) {
    throw ConfigError(path + ": " + error.what());
  }
  return e;
}

nlohmann::json CalibrationError::to_json() const { return fields_to_json(*this); }

bool CalibrationRanges::empty() const {
  return depth == 0 && angular_shift == 0 && shift == 0 && period == 0 && vignetting == 0;
}

void CalibrationRanges::validate() const {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw ConfigError("dataset.calibration: " + what);
  };
  check(depth >= 0 && depth < 1, "depth must lie in [0, 1)");
  check(angular_shift >= 0 && std::isfinite(angular_shift), "angular_shift must be >= 0");
  check(shift >= 0 && std::isfinite(shift), "shift must be >= 0");
  check(period >= 0 && period < 0.5, "period must lie in [0, 0.5)");
  check(vignetting >= 0 && vignetting < 1, "vignetting must lie in [0, 1)");
  check(vignetting_sensor >= 1 && std::isfinite(vignetting_sensor),
        "vignetting_sensor must be >= 1");
}

namespace {

// Linear interpolation along `dim` at positions `at` (one per output index), each clamped to
// [0, size - 1] (held at the edges), or wrapped modulo the size when `periodic`.
torch::Tensor interpolate(const torch::Tensor& x, int64_t dim, const std::vector<double>& at,
                          bool periodic) {
  const int64_t size = x.size(dim);
  std::vector<int64_t> lo(at.size()), hi(at.size());
  std::vector<double> frac(at.size());
  for (size_t i = 0; i < at.size(); ++i) {
    double p = at[i];
    if (!periodic) p = std::clamp(p, 0.0, static_cast<double>(size - 1));
    const double f = std::floor(p);
    frac[i] = p - f;
    auto wrap = [&](int64_t k) {
      return periodic ? ((k % size) + size) % size : std::min<int64_t>(k, size - 1);
    };
    lo[i] = wrap(static_cast<int64_t>(f));
    hi[i] = wrap(static_cast<int64_t>(f) + 1);
  }
  std::vector<int64_t> shape(x.dim(), 1);
  shape[dim] = static_cast<int64_t>(at.size());
  auto a = torch::tensor(frac, torch::kFloat64).to(x.scalar_type()).reshape(shape);
  return x.index_select(dim, torch::tensor(lo)) * (1 - a) +
         x.index_select(dim, torch::tensor(hi)) * a;
}

}  // namespace

torch::Tensor perturbed_pixel_weights(const Phi& phi, const CalibrationError& error, int64_t y0,
                                      int64_t x0, int64_t h, int64_t w,
                                      const SensorPlacement& placement, torch::ScalarType dtype) {
  LFNET_CHECK_AS(ConfigError, phi.local(), "a calibration error needs a local Phi; '",
                 phi.spec().label(), "' is not");
  // A camera displaced by half its grid or more no longer sees the scene it was made for.
  const double max_u = 0.5 * static_cast<double>(phi.rows() - 1);
  const double max_v = 0.5 * static_cast<double>(phi.cols() - 1);
  LFNET_CHECK_AS(ConfigError, std::abs(error.angular_shift_u) < max_u, "angular_shift_u ",
                 error.angular_shift_u, " moves the views beyond the ", phi.rows(),
                 "-view grid: it must lie in (-", max_u, ", ", max_u, ") views");
  LFNET_CHECK_AS(ConfigError, std::abs(error.angular_shift_v) < max_v, "angular_shift_v ",
                 error.angular_shift_v, " moves the views beyond the ", phi.cols(),
                 "-view grid: it must lie in (-", max_v, ", ", max_v, ") views");
  const int64_t t = phi.period();
  torch::Tensor weights;
  if (t > 1 && (error.shift_y != 0 || error.shift_x != 0 || error.period != 0)) {
    // Pixel (y, x) reads the code at ((y + shift_y) (1 + period), ...), between tile pixels.
    auto tile = phi.pixel_weights(0, 0, t, t, torch::kFloat64);  // (N, U, V, t, t)
    std::vector<double> ys(h), xs(w);
    for (int64_t y = 0; y < h; ++y) {
      ys[y] = (static_cast<double>(y0 + y) + error.shift_y) * (1 + error.period);
    }
    for (int64_t x = 0; x < w; ++x) {
      xs[x] = (static_cast<double>(x0 + x) + error.shift_x) * (1 + error.period);
    }
    weights = interpolate(interpolate(tile, 3, ys, true), 4, xs, true);
  } else {
    weights = phi.pixel_weights(y0, x0, h, w, torch::kFloat64);
  }
  if (error.angular_shift_u != 0) {
    std::vector<double> us(phi.rows());
    for (int64_t u = 0; u < phi.rows(); ++u) us[u] = static_cast<double>(u) + error.angular_shift_u;
    weights = interpolate(weights, 1, us, false);
  }
  if (error.angular_shift_v != 0) {
    std::vector<double> vs(phi.cols());
    for (int64_t v = 0; v < phi.cols(); ++v) vs[v] = static_cast<double>(v) + error.angular_shift_v;
    weights = interpolate(weights, 2, vs, false);
  }
  if (error.depth != 0) {
    const auto mean = weights.mean({1, 2}, /*keepdim=*/true);
    weights = mean + (weights - mean) * (1 + error.depth);
  }
  if (error.vignetting != 0) {
    LFNET_CHECK(placement.sensor_h > 0 && placement.sensor_w > 0,
                "vignetting needs the sensor's size");
    const double cy = 0.5 * static_cast<double>(placement.sensor_h);
    const double cx = 0.5 * static_cast<double>(placement.sensor_w);
    auto opts = torch::TensorOptions().dtype(torch::kFloat64);
    const int64_t py = placement.y0, px = placement.x0;
    auto dy = (torch::arange(py, py + h, opts) + 0.5 - cy).square().unsqueeze(1);
    auto dx = (torch::arange(px, px + w, opts) + 0.5 - cx).square().unsqueeze(0);
    auto gain = 1 - error.vignetting * (dy + dx) / (cy * cy + cx * cx);
    weights = weights * gain;
  }
  return weights.to(dtype).contiguous();
}

torch::Tensor perturbed_forward(const Phi& phi, const CalibrationError& error,
                                const torch::Tensor& lf) {
  if (error.empty()) return phi.forward(lf);
  LFNET_CHECK_AS(ConfigError,
                 lf.dim() >= 4 && lf.size(-4) == phi.rows() && lf.size(-3) == phi.cols(),
                 "light field of shape ", lf.sizes(), " does not match Phi '", phi.spec().label(),
                 "' (", phi.rows(), " x ", phi.cols(), " views)");
  const int64_t height = lf.size(-2), width = lf.size(-1);
  // Bands of about 16 M weights.
  const int64_t per_row = phi.measurements() * phi.rows() * phi.cols() * width;
  const int64_t band = std::max<int64_t>(1, (int64_t{1} << 24) / std::max<int64_t>(per_row, 1));
  std::vector<torch::Tensor> rows;
  for (int64_t r0 = 0; r0 < height; r0 += band) {
    const int64_t r1 = std::min(height, r0 + band);
    const SensorPlacement at{r0, 0, height, width};
    const auto weights =
        perturbed_pixel_weights(phi, error, r0, 0, r1 - r0, width, at, lf.scalar_type());
    const auto part = lf.slice(-2, r0, r1).unsqueeze(-5);  // (..., 1, U, V, rows, W)
    rows.push_back((part * weights).sum({-4, -3}));        // (..., N, rows, W)
  }
  return torch::cat(rows, -2);
}

torch::Tensor nominal_white(const Phi& phi, int64_t height, int64_t width) {
  LFNET_CHECK_AS(ConfigError, phi.local(), "a flat field needs a local Phi; '", phi.spec().label(),
                 "' is not");
  const int64_t t = phi.period();
  const auto tile = phi.pixel_weights(0, 0, t, t, torch::kFloat64).sum({1, 2});  // (N, t, t)
  const auto rows = torch::arange(height).remainder(t);
  const auto cols = torch::arange(width).remainder(t);
  return tile.index_select(1, rows).index_select(2, cols).to(torch::kFloat32);
}

namespace {
// The largest value, within the image, of the quadratic surface a + b x + c y + d x^2 + e x y +
// f y^2 fitted by least squares to `ratio` (H, W) where `lit`: the brightest point of a smooth
// gain, found without reading any one noisy pixel. Every pixel of a small image, every s-th
// row and column of a large one.
double fitted_peak(const torch::Tensor& ratio, const torch::Tensor& lit) {
  using torch::indexing::None;
  using torch::indexing::Slice;
  const int64_t h = ratio.size(0), w = ratio.size(1);
  const int64_t s = std::max<int64_t>(1, std::max(h, w) / 512);
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  // Coordinates scaled to about [-1, 1], for a well-conditioned fit.
  const double sy = std::max<double>(1, 0.5 * static_cast<double>(h));
  const double sx = std::max<double>(1, 0.5 * static_cast<double>(w));
  auto terms = [&](int64_t step) {
    const auto y = ((torch::arange(0, h, step, opts) - sy) / sy).unsqueeze(1);
    const auto x = ((torch::arange(0, w, step, opts) - sx) / sx).unsqueeze(0);
    const auto ones = torch::ones({y.size(0), x.size(1)}, opts);
    return torch::stack({ones, x * ones, y * ones, x * x * ones, x * y, y * y * ones}, -1);
  };
  const auto keep = lit.index({Slice(None, None, s), Slice(None, None, s)});
  const auto a = terms(s).index({keep});  // (M, 6)
  const auto b = ratio.index({Slice(None, None, s), Slice(None, None, s)}).index({keep});
  if (a.size(0) < 6) return ratio.index({lit}).max().item<double>();
  const auto coef = torch::linalg_solve(a.t().matmul(a), a.t().matmul(b));
  const int64_t fine = std::max<int64_t>(1, std::max(h, w) / 1024);
  return terms(fine).matmul(coef).max().item<double>();
}
}  // namespace

torch::Tensor flat_field_gain(const torch::Tensor& white, const torch::Tensor& nominal) {
  LFNET_CHECK_AS(ConfigError, white.dim() == 3 && white.sizes() == nominal.sizes(),
                 "the white frame is ", white.sizes(), ", the camera's sensor image ",
                 nominal.sizes(), ": a flat field needs a white frame of the same camera");
  const auto measured = white.to(torch::kFloat64).sum(0);
  const auto expected = nominal.to(torch::kFloat64).sum(0);
  const auto lit = expected > 1e-9 * expected.abs().max().item<double>();
  LFNET_CHECK_AS(ConfigError,
                 lit.any().item<bool>() && measured.index({lit}).max().item<double>() > 0,
                 "the white frame has no light: it cannot give a flat field");
  auto ratio = torch::where(lit, measured / expected.clamp_min(1e-300), torch::ones_like(measured));
  const double top = fitted_peak(ratio, lit);
  LFNET_CHECK_AS(ConfigError, std::isfinite(top) && top > 0,
                 "the white frame has no light: it cannot give a flat field");
  // Pixels the nominal camera does not expose keep gain 1.
  return torch::where(lit, ratio / top, torch::ones_like(ratio)).to(torch::kFloat32);
}

torch::Tensor apply_flat_field(const torch::Tensor& sensor, const torch::Tensor& gain) {
  LFNET_CHECK_AS(ConfigError,
                 gain.dim() == 2 && sensor.dim() >= 3 && sensor.size(-2) == gain.size(0) &&
                     sensor.size(-1) == gain.size(1),
                 "the flat field is ", gain.sizes(), ", the sensor image ", sensor.sizes(),
                 ": the white frame must come from a sensor of the same size");
  return sensor / gain.clamp_min(1e-3).to(sensor.scalar_type());
}

}  // namespace lfnet::optics

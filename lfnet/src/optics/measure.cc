#include "lfnet/optics/measure.h"

#include <torch/torch.h>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "models.h"

namespace lfnet::optics {

namespace {
constexpr EnumName<SimulationMode> kSimulationModes[] = {{SimulationMode::kSensor, "sensor"},
                                                         {SimulationMode::kPerPatch, "per_patch"}};
}  // namespace

SimulationMode parse_simulation_mode(const std::string& text) {
  return value_of(text, kSimulationModes);
}

std::string to_string(SimulationMode mode) { return name_of(mode, kSimulationModes); }

torch::Tensor simulate_sensor(const Phi& phi, const torch::Tensor& lf, const SensorOptions& effects,
                              uint64_t seed) {
  return apply_sensor_effects(phi.forward(lf), effects, seed);
}

int64_t patch_phase(const Phi& phi, int64_t y0, int64_t x0) {
  const int64_t t = phi.period();
  return (y0 % t) * t + (x0 % t);
}

torch::Tensor patch_phases(const Phi& phi, const PatchGrid& grid, int64_t row_begin,
                           int64_t row_end, int64_t channels) {
  const int64_t t = phi.period();
  auto ys = torch::tensor(
      std::vector<int64_t>(grid.ys().begin() + row_begin, grid.ys().begin() + row_end));
  auto xs = torch::tensor(grid.xs());
  auto phases = (ys.remainder(t) * t).unsqueeze(1) + xs.remainder(t).unsqueeze(0);
  return phases.reshape({-1}).repeat({channels});
}

torch::Tensor patch_matrix_stack(const Phi& phi, int64_t h, int64_t w, torch::ScalarType dtype) {
  const int64_t t = phi.period();
  std::vector<torch::Tensor> mats;
  for (int64_t py = 0; py < t; ++py) {
    for (int64_t px = 0; px < t; ++px) mats.push_back(phi.patch_matrix(py, px, h, w, dtype));
  }
  return torch::stack(mats);
}

torch::Tensor pixel_weight_stack(const Phi& phi, int64_t h, int64_t w, torch::ScalarType dtype) {
  const int64_t t = phi.period();
  std::vector<torch::Tensor> weights;
  for (int64_t py = 0; py < t; ++py) {
    for (int64_t px = 0; px < t; ++px) weights.push_back(phi.pixel_weights(py, px, h, w, dtype));
  }
  return torch::stack(weights);
}

torch::Tensor pinv_matrix_stack(const Phi& phi, int64_t h, int64_t w, double lambda,
                                torch::ScalarType dtype) {
  const int64_t t = phi.period();
  std::vector<torch::Tensor> mats;
  for (int64_t py = 0; py < t; ++py) {
    for (int64_t px = 0; px < t; ++px) mats.push_back(phi.pinv_matrix(py, px, h, w, lambda, dtype));
  }
  return torch::stack(mats);
}

torch::Tensor pixel_pinv_stack(const Phi& phi, int64_t h, int64_t w, double lambda,
                               torch::ScalarType dtype) {
  LFNET_CHECK(phi.local(), "pixel_pinv_stack: Phi '", phi.spec().label(),
              "' mixes pixels; use pinv_matrix_stack");
  auto weights = pixel_weight_stack(phi, h, w, torch::kFloat64);  // (P, N, U, V, h, w)
  const int64_t p = weights.size(0), n = weights.size(1);
  const int64_t uv = weights.size(2) * weights.size(3), q = h * w;
  // Per pixel, A (N, U V) -> (U V, N), as LocalPhi::pinv_matrix computes it.
  auto per_pixel = weights.reshape({p, n, uv, q}).permute({0, 3, 1, 2});  // (P, h w, N, U V)
  auto pinv = detail::tikhonov_pinv(per_pixel, lambda);                   // (P, h w, U V, N)
  return pinv.permute({0, 3, 2, 1}).to(dtype).contiguous();
}

void check_sensor_consistent(const Phi& phi, const PatchGrid& grid, int64_t row_begin,
                             int64_t row_end) {
  const int64_t b = phi.block();
  LFNET_CHECK_AS(ConfigError, grid.patch_h() % b == 0 && grid.patch_w() % b == 0, "Phi '",
                 phi.spec().label(), "' mixes the pixels of ", b, "x", b, " blocks: patches of ",
                 grid.patch_h(), "x", grid.patch_w(),
                 " are not crops of one sensor image; use per_patch mode or a patch size that "
                 "is a multiple of ",
                 b);
  for (int64_t r = row_begin; r < row_end; ++r) {
    for (int64_t x0 : grid.xs()) {
      const int64_t y0 = grid.ys()[static_cast<size_t>(r)];
      LFNET_CHECK_AS(ConfigError, phi.patch_consistent(y0, x0), "Phi '", phi.spec().label(),
                     "': the patch at (", y0, ", ", x0, ") is not on the ", b,
                     "-pixel block "
                     "grid, so its measurements are not a crop of one sensor image; use "
                     "per_patch mode, or a stride that is a multiple of ",
                     b, " on a light field whose height and width are multiples of ", b);
    }
  }
}

namespace {

// Crops (C * ny * nx, K, h, w) patches at origins (ys - y_offset, xs) from an image
// (C, K, H', W): the patch layout of PatchGrid::extract.
torch::Tensor crop(const torch::Tensor& image, const std::vector<int64_t>& ys, int64_t y_offset,
                   const std::vector<int64_t>& xs, int64_t h, int64_t w) {
  const int64_t c = image.size(0), k = image.size(1);
  const auto ny = static_cast<int64_t>(ys.size()), nx = static_cast<int64_t>(xs.size());
  auto rows = (torch::tensor(ys) - y_offset).unsqueeze(1) + torch::arange(h).unsqueeze(0);
  auto cols = torch::tensor(xs).unsqueeze(1) + torch::arange(w).unsqueeze(0);
  auto sel = image.index_select(2, rows.reshape({-1})).index_select(3, cols.reshape({-1}));
  return sel.view({c, k, ny, h, nx, w}).permute({0, 2, 4, 1, 3, 5}).reshape({c * ny * nx, k, h, w});
}

std::vector<int64_t> band(const PatchGrid& grid, int64_t row_begin, int64_t row_end) {
  return std::vector<int64_t>(grid.ys().begin() + row_begin, grid.ys().begin() + row_end);
}

}  // namespace

torch::Tensor crop_sensor_patches(const Phi& phi, const torch::Tensor& sensor,
                                  const PatchGrid& grid, int64_t row_begin, int64_t row_end) {
  LFNET_CHECK(sensor.dim() == 4 && sensor.size(1) == phi.measurements() &&
                  sensor.size(2) == grid.height() && sensor.size(3) == grid.width(),
              "expected a sensor image (C, ", phi.measurements(), ", ", grid.height(), ", ",
              grid.width(), ") for Phi '", phi.spec().label(), "' and the patch grid");
  LFNET_CHECK(row_begin >= 0 && row_begin <= row_end && row_end <= grid.rows(), "patch rows [",
              row_begin, ", ", row_end, ") outside [0, ", grid.rows(), ")");
  check_sensor_consistent(phi, grid, row_begin, row_end);
  auto patches =
      crop(sensor, band(grid, row_begin, row_end), 0, grid.xs(), grid.patch_h(), grid.patch_w());
  return patches.reshape({patches.size(0), -1}).to(torch::kFloat32);
}

PatchMeasurements measure_patches(const Phi& phi, const torch::Tensor& lf, const PatchGrid& grid,
                                  SimulationMode mode, const SensorOptions& effects, uint64_t seed,
                                  int64_t row_begin, int64_t row_end) {
  if (row_end < 0) row_end = grid.rows();
  LFNET_CHECK(lf.dim() == 5 && lf.size(3) == grid.height() && lf.size(4) == grid.width(),
              "measure_patches expects a light field (C, U, V, ", grid.height(), ", ", grid.width(),
              ") matching the patch grid");
  LFNET_CHECK(row_begin >= 0 && row_begin <= row_end && row_end <= grid.rows(), "patch rows [",
              row_begin, ", ", row_end, ") outside [0, ", grid.rows(), ")");
  const int64_t c = lf.size(0), h = grid.patch_h(), w = grid.patch_w(), n = phi.measurements();
  PatchMeasurements out;
  out.phases = patch_phases(phi, grid, row_begin, row_end, c);
  if (mode == SimulationMode::kSensor) {
    check_sensor_consistent(phi, grid, row_begin, row_end);
    out.values =
        crop_sensor_patches(phi, simulate_sensor(phi, lf, effects, seed), grid, row_begin, row_end);
    return out;
  }
  const auto ys = band(grid, row_begin, row_end);
  if (ys.empty()) {
    out.values = torch::zeros({0, n * h * w});
    return out;
  }
  torch::Tensor clean;  // (C * P, N h w)
  if (phi.local()) {
    // A local model's patch measurements are crops of the forward model: simulate only the
    // band's rows, starting on a period boundary so every pixel keeps its phase.
    const int64_t t = phi.period();
    const int64_t y_start = (ys.front() / t) * t, y_end = ys.back() + h;
    auto sensor = phi.forward(lf.slice(3, y_start, y_end));
    clean = crop(sensor, ys, y_start, grid.xs(), h, w).reshape({-1, n * h * w});
  } else {
    // Non-local models use one block matrix for every patch (period 1).
    auto a = phi.patch_matrix(0, 0, h, w, lf.scalar_type());
    auto patches = grid.extract(lf, row_begin, row_end);
    clean = torch::matmul(patches.reshape({patches.size(0), -1}), a.t());
  }
  clean = clean.to(torch::kFloat32);
  if (effects.empty()) {
    out.values = clean;
    return out;
  }
  // Noise per patch, addressed by (channel, patch index in the whole grid, element); gain by
  // the sensor pixel (channel, n, y, x) as simulate_sensor addresses it.
  const int64_t p_total = grid.size(), nx = grid.cols(), m = n * h * w;
  const int64_t big_h = grid.height(), big_w = grid.width();
  auto p_index =
      (torch::arange(row_begin, row_end).unsqueeze(1) * nx + torch::arange(nx).unsqueeze(0))
          .reshape({-1});  // (P,)
  auto ch = torch::arange(c).view({c, 1, 1});
  auto element = (ch * p_total + p_index.view({1, -1, 1})) * m +
                 torch::arange(m).view({1, 1, m});                                 // (C, P, m)
  auto y_abs = (torch::tensor(ys).view({-1, 1}) + torch::arange(h).view({1, h}));  // (ny, h)
  auto x_abs = (torch::tensor(grid.xs()).view({-1, 1}) + torch::arange(w).view({1, w}));
  const auto ny = static_cast<int64_t>(ys.size());
  // (ny, nx, h, w) flat sensor position, then (C, P, N, h w) pixel ids.
  auto pos =
      (y_abs.view({ny, 1, h, 1}) * big_w + x_abs.view({1, nx, 1, w})).reshape({ny * nx, h * w});
  auto pixel = ((ch.view({c, 1, 1, 1}) * n + torch::arange(n).view({1, 1, n, 1})) * big_h * big_w +
                pos.view({1, ny * nx, 1, h * w}));
  out.values =
      apply_sensor_effects(clean, effects, seed, element.reshape({-1}), pixel.reshape({-1}));
  return out;
}

}  // namespace lfnet::optics

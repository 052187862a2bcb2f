#include "lfnet/recon/reconstruct.h"

#include <algorithm>

#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/core/light_field.h"

namespace lfnet::recon {

void ReconstructOptions::validate() const {
  if (patch_h < 1 || patch_w < 1) throw ConfigError("patch size must be positive");
  const int64_t side = std::min(patch_h, patch_w);
  if (stride < 1 || stride > side) {
    // A stride beyond the patch would leave pixels between patches that no patch covers.
    throw ConfigError("stride must lie in 1.." + std::to_string(side) + " (the " +
                      std::to_string(patch_h) + "x" + std::to_string(patch_w) + " patch), got " +
                      std::to_string(stride));
  }
  if (batch < 1) throw ConfigError("batch must be at least 1, got " + std::to_string(batch));
  if (coded && !clamp) throw ConfigError("a result in 16-bit codes is clamped to [0, 1]");
}

namespace {}  // namespace

torch::Tensor by_phase(const torch::Tensor& x, const torch::Tensor& phase, int64_t out_dim,
                       const std::function<torch::Tensor(const torch::Tensor&, int64_t)>& fn) {
  auto out = torch::empty({x.size(0), out_dim}, x.options());
  auto unique = std::get<0>(torch::_unique(phase));
  for (int64_t i = 0; i < unique.size(0); ++i) {
    const int64_t p = unique[i].item<int64_t>();
    if (unique.size(0) == 1) return fn(x, p);
    auto idx = (phase == p).nonzero().squeeze(1);
    out.index_copy_(0, idx, fn(x.index_select(0, idx), p));
  }
  return out;
}

namespace {

torch::Tensor hann_window(int64_t h, int64_t w) {
  auto wy = torch::sin(M_PI * (torch::arange(h, torch::kFloat64) + 0.5) / h);
  auto wx = torch::sin(M_PI * (torch::arange(w, torch::kFloat64) + 0.5) / w);
  return wy.unsqueeze(1) * wx.unsqueeze(0);
}

}  // namespace

int64_t band_rows(const PatchGrid& grid, const ReconstructOptions& options) {
  return std::max<int64_t>(1, options.batch / std::max<int64_t>(1, grid.cols()));
}

torch::Tensor reconstruct_patches(const optics::Phi& phi, const PatchGrid& grid,
                                  const MeasurementSource& source, const PatchSolver& solver,
                                  const ReconstructOptions& options,
                                  const ProgressCallback& progress) {
  options.validate();
  const int64_t u = phi.rows(), v = phi.cols();
  const int64_t h = grid.patch_h(), w = grid.patch_w();
  Stitcher stitcher(grid, 1, u, v, options.window ? hann_window(h, w) : torch::Tensor(),
                    options.coded);
  const int64_t band = band_rows(grid, options);
  int64_t done = 0;
  for (int64_t r0 = 0; r0 < grid.rows(); r0 += band) {
    const int64_t r1 = std::min(grid.rows(), r0 + band);
    optics::PatchMeasurements meas = source(r0, r1);
    const int64_t n = meas.values.size(0);
    std::vector<torch::Tensor> parts;
    for (int64_t b = 0; b < n; b += options.batch) {
      const int64_t e = std::min(n, b + options.batch);
      parts.push_back(solver(meas.values.slice(0, b, e), meas.phases.slice(0, b, e)));
    }
    auto est = torch::cat(parts, 0).reshape({n, u, v, h, w});
    // One NaN or infinity makes the sum NaN or infinite (as do values too large to sum).
    if (!std::isfinite(est.sum().item<double>())) {
      throw NumericalError(
          "the reconstruction produced NaN, infinite or huge values in patch rows " +
          std::to_string(r0) + ".." + std::to_string(r1 - 1));
    }
    stitcher.add(est, r0, r1);
    done += n;
    if (progress) progress(done, grid.size());
  }
  auto out = stitcher.result();
  return options.clamp && !options.coded ? out.clamp_(0, 1) : out;
}

torch::Tensor reconstruct_sensor(const optics::Phi& phi, const torch::Tensor& sensor,
                                 const PatchSolver& solver, const ReconstructOptions& options,
                                 const ProgressCallback& progress) {
  options.validate();
  LFNET_CHECK_AS(ConfigError, sensor.dim() == 3 && sensor.size(0) == phi.measurements(),
                 "the sensor image has shape ", sensor.sizes(), " but Phi '", phi.spec().name,
                 "' records ", phi.measurements(), " channels per pixel");
  PatchGrid grid(sensor.size(1), sensor.size(2), options.patch_h, options.patch_w, options.stride);
  optics::check_sensor_consistent(phi, grid, 0, grid.rows());
  auto source = [&](int64_t r0, int64_t r1) {
    return optics::PatchMeasurements{
        optics::crop_sensor_patches(phi, sensor.unsqueeze(0), grid, r0, r1),
        optics::patch_phases(phi, grid, r0, r1)};
  };
  return reconstruct_patches(phi, grid, source, solver, options, progress);
}

PatchSolver adjoint_solver(const torch::Tensor& matrices) {
  auto mats = matrices.to(torch::kFloat64);
  // A^T A 1 per phase: the response of the adjoint to a white patch.
  auto white = torch::matmul(mats.transpose(1, 2), mats.sum(2, /*keepdim=*/true)).squeeze(2);
  auto inv = torch::where(white > 1e-12 * white.max(), 1.0 / white, torch::zeros_like(white));
  auto at = (mats.transpose(1, 2) * inv.unsqueeze(2)).to(torch::kFloat32).contiguous();
  return [at](const torch::Tensor& y, const torch::Tensor& phase) {
    return by_phase(y, phase, at.size(1), [&](const torch::Tensor& rows, int64_t p) {
      return torch::matmul(rows, at[p].t());
    });
  };
}

PatchSolver pinv_solver(const torch::Tensor& pinv_matrices) {
  auto r = pinv_matrices.to(torch::kFloat32).contiguous();  // (P, D, m)
  return [r](const torch::Tensor& y, const torch::Tensor& phase) {
    return by_phase(y, phase, r.size(1), [&](const torch::Tensor& rows, int64_t p) {
      return torch::matmul(rows, r[p].t());
    });
  };
}

PatchSolver pixel_pinv_solver(const torch::Tensor& pixel_pinv) {
  LFNET_CHECK(pixel_pinv.dim() == 4, "pixel_pinv_solver: expected (P, N, U V, h w), got ",
              pixel_pinv.sizes());
  auto r = pixel_pinv.to(torch::kFloat32).contiguous();
  const int64_t n = r.size(1), uv = r.size(2), q = r.size(3);
  return [r, n, uv, q](const torch::Tensor& y, const torch::Tensor& phase) {
    return by_phase(y, phase, uv * q, [&](const torch::Tensor& rows, int64_t p) {
      const auto x = rows.reshape({-1, n, 1, q});  // (B, N, 1, h w)
      auto out = x.select(1, 0) * r[p][0];         // (B, U V, h w)
      for (int64_t i = 1; i < n; ++i) out.addcmul_(x.select(1, i), r[p][i]);
      return out.reshape({-1, uv * q});
    });
  };
}

PatchSolver pinv_solver(const optics::Phi& phi, int64_t h, int64_t w) {
  if (phi.local()) return pixel_pinv_solver(optics::pixel_pinv_stack(phi, h, w));
  return pinv_solver(optics::pinv_matrix_stack(phi, h, w));
}

double match_mean(torch::Tensor& measurements, double target_mean) {
  const double mean = measurements.mean().item<double>();
  LFNET_CHECK_AS(NumericalError, std::isfinite(mean) && std::abs(mean) > 1e-12,
                 "cannot match the mean of measurements whose mean is ", mean);
  const double scale = target_mean / mean;
  measurements.mul_(scale);
  return scale;
}

}  // namespace lfnet::recon

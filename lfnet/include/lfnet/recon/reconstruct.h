// Patch-wise reconstruction of a light field from coded measurements, streamed in bands.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <string>

#include "lfnet/core/patches.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"

namespace lfnet::recon {

// Maps a batch of measurement vectors y (B, N h w) and their patch phases (B) int64 — indices
// into the stack of distinct patch matrices (see patch_phase) — to light-field patches
// (B, U V h w), flattened (u, v, y, x).
using PatchSolver =
    std::function<torch::Tensor(const torch::Tensor& y, const torch::Tensor& phase)>;

// Reconstructs a whole sensor image (N, H, W) at once: a grey light field (1, U, V, H, W).
// `noise_sigma` is the sensor's Gaussian noise (relative to white), which noise-aware methods
// read. Methods that see the whole image (the lfnet architecture) give one beside their
// PatchSolver.
using ImageSolver = std::function<torch::Tensor(const torch::Tensor& sensor, double noise_sigma)>;

// Called after every band with (patches done, patches in all).
using ProgressCallback = std::function<void(int64_t done, int64_t total)>;

// Options of patch-wise reconstruction.
struct ReconstructOptions {
  int64_t patch_h = 9;   // spatial patch height h
  int64_t patch_w = 9;   // spatial patch width w
  int64_t stride = 5;    // patch stride; = patch size for non-overlapping patches
  int64_t batch = 1024;  // patches per solver call; with the band, bounds peak memory
  bool window = false;   // weight patch estimates by a separable Hann-like window when stitching
  bool clamp = true;     // clamp the result to [0, 1]
  // Return 16-bit codes (int16; core/light_field.h) instead of float32: half the memory, what a
  // 16-bit file holds. Needs clamp.
  bool coded = false;
  void validate() const;
};

// Reconstructs a grey light field (1, U, V, H, W) from a sensor image (N, H, W), patch by
// patch, in bands of patch rows so memory is bounded by the batch, not the light field.
// Throws ConfigError for patches that are not a crop of one sensor image (random projections
// off their block grid).
torch::Tensor reconstruct_sensor(const optics::Phi& phi, const torch::Tensor& sensor,
                                 const PatchSolver& solver, const ReconstructOptions& options,
                                 const ProgressCallback& progress = {});

// Source of per-patch measurements for a band of grid rows (per_patch mode, or stored
// measurements): values (n, N h w) and phases (n).
using MeasurementSource =
    std::function<optics::PatchMeasurements(int64_t row_begin, int64_t row_end)>;

// Patch rows reconstructed together: about one solver batch, at least one row.
int64_t band_rows(const PatchGrid& grid, const ReconstructOptions& options);

// Reconstructs from per-patch measurements of `grid`, asked for band_rows() rows at a time.
torch::Tensor reconstruct_patches(const optics::Phi& phi, const PatchGrid& grid,
                                  const MeasurementSource& source, const PatchSolver& solver,
                                  const ReconstructOptions& options,
                                  const ProgressCallback& progress = {});

// Applies `fn(rows, phase)` to each group of rows of `x` (B, ...) that share a phase and
// gathers the (rows, out_dim) results in the original order.
torch::Tensor by_phase(const torch::Tensor& x, const torch::Tensor& phase, int64_t out_dim,
                       const std::function<torch::Tensor(const torch::Tensor&, int64_t)>& fn);

// The linear baselines, as solvers over the stack of patch matrices (optics::patch_matrix_stack).
// adjoint: A^T y, divided elementwise by A^T A 1 so a white patch maps to white.
PatchSolver adjoint_solver(const torch::Tensor& matrices);
// pinv: a solver over a stack of pseudo-inverses (optics::pinv_matrix_stack), (P, D, N h w).
PatchSolver pinv_solver(const torch::Tensor& pinv_matrices);
// The same for a local model from its per-pixel pseudo-inverses (optics::pixel_pinv_stack),
// (P, N, U V, h w): N multiply-adds per output value instead of N h w.
PatchSolver pixel_pinv_solver(const torch::Tensor& pixel_pinv);
// pixel_pinv_solver for local models, pinv_solver for the others.
PatchSolver pinv_solver(const optics::Phi& phi, int64_t h, int64_t w);

// Scales real measurements linearly so their mean equals `target_mean` (the paper's step for
// real data); returns the scale applied.
double match_mean(torch::Tensor& measurements, double target_mean);

}  // namespace lfnet::recon

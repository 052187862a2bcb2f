// Patch measurements for training and reconstruction, in both simulation modes
// (docs/acquisition.md):
//   sensor:    one sensor image of the whole light field; each patch's measurements are a
//              crop of it, what a real camera gives;
//   per_patch: each patch multiplied by its own patch matrix, the paper's protocol (for
//              random projections, the block matrix at any origin; noise drawn per patch).
// A patch's matrix is the entry `phase` of the stack of its model's period^2 distinct patch
// matrices, phase = (y0 mod T) T + (x0 mod T) with T = Phi::period().
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <string>

#include "lfnet/core/patches.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"

namespace lfnet::optics {

enum class SimulationMode { kSensor, kPerPatch };

// "sensor" or "per_patch"; anything else is a ConfigError.
SimulationMode parse_simulation_mode(const std::string& text);
std::string to_string(SimulationMode mode);
inline SimulationMode from_string(const std::string& name, SimulationMode) {
  return parse_simulation_mode(name);
}

// The sensor image (..., N, H, W) of a light field (..., U, V, H, W) with the named effects.
// Noise and gain are addressed by the flat index into the sensor image, so a pixel's draws do
// not depend on how the work is split.
torch::Tensor simulate_sensor(const Phi& phi, const torch::Tensor& lf,
                              const SensorOptions& effects = {}, uint64_t seed = 0);

// The phase of a patch at (y0, x0): its index into patch_matrix_stack.
int64_t patch_phase(const Phi& phi, int64_t y0, int64_t x0);

// Phases of the patches of grid rows [row_begin, row_end), repeated for `channels` colour
// channels: (channels * P,) int64 in the layout of PatchGrid::extract.
torch::Tensor patch_phases(const Phi& phi, const PatchGrid& grid, int64_t row_begin,
                           int64_t row_end, int64_t channels = 1);

// The period^2 distinct patch matrices, (period^2, N h w, U V h w). Dense: for a mask of period
// 9 at N = 25 that is 1.3 GB in float32; local models are better served by pixel_weight_stack.
torch::Tensor patch_matrix_stack(const Phi& phi, int64_t h, int64_t w,
                                 torch::ScalarType dtype = torch::kFloat32);

// The same in compact form for local models: (period^2, N, U, V, h, w) per-pixel weights.
torch::Tensor pixel_weight_stack(const Phi& phi, int64_t h, int64_t w,
                                 torch::ScalarType dtype = torch::kFloat32);

// Tikhonov pseudo-inverses of the stack, (period^2, U V h w, N h w) (Phi::pinv_matrix).
torch::Tensor pinv_matrix_stack(const Phi& phi, int64_t h, int64_t w,
                                double lambda = kDefaultPinvLambda,
                                torch::ScalarType dtype = torch::kFloat32);

// The same pseudo-inverses of a local model in compact form, pixel by pixel:
// (period^2, N, U V, h w), entry [p, n, k, q] the weight of measurement n at pixel q in view k
// of the patch of phase p. The patch's pinv_matrix holds exactly these and zeros.
torch::Tensor pixel_pinv_stack(const Phi& phi, int64_t h, int64_t w,
                               double lambda = kDefaultPinvLambda,
                               torch::ScalarType dtype = torch::kFloat32);

// Throws ConfigError naming the first patch of grid rows [row_begin, row_end) whose
// measurements are not a crop of one sensor image (random projections off the block grid).
void check_sensor_consistent(const Phi& phi, const PatchGrid& grid, int64_t row_begin,
                             int64_t row_end);

// The measurement vectors of grid rows [row_begin, row_end) cropped from a sensor image
// (C, N, H, W): (C * P, N h w), channel-major then row-major over origins. Checks consistency.
torch::Tensor crop_sensor_patches(const Phi& phi, const torch::Tensor& sensor,
                                  const PatchGrid& grid, int64_t row_begin, int64_t row_end);

// Measurements of a band of patches and the index of each patch's matrix.
struct PatchMeasurements {
  torch::Tensor values;  // (C * P, N h w) float32
  torch::Tensor phases;  // (C * P,) int64, indices into patch_matrix_stack
};

// Measurements of the patches of grid rows [row_begin, row_end) (row_end < 0: every row) of a
// light field (C, U, V, H, W). Sensor mode simulates the sensor image of the whole light field
// (callers that stream bands should call simulate_sensor once and crop_sensor_patches per
// band). Per-patch mode measures only the band; its noise is drawn per patch (addressed by
// the patch's index in the whole grid, so bands draw the same noise as one call) while the
// fixed gain pattern stays the sensor pixel's own. Noiseless, the two modes agree wherever
// the sensor mode is defined.
PatchMeasurements measure_patches(const Phi& phi, const torch::Tensor& lf, const PatchGrid& grid,
                                  SimulationMode mode, const SensorOptions& effects = {},
                                  uint64_t seed = 0, int64_t row_begin = 0, int64_t row_end = -1);

}  // namespace lfnet::optics

// The built-in Phi models (internal): local models share LocalPhi, random is dense per block.
#pragma once

#include <torch/torch.h>

#include <memory>

#include "lfnet/core/json.h"
#include "lfnet/optics/phi.h"

namespace lfnet::optics::detail {

// A local Phi: weights M_n(u, v, y mod T, x mod T) at every pixel, periodic with period T
// (T = 1 for models that are the same at every pixel).
class LocalPhi : public Phi {
 public:
  // `code`: (N, U, V, T, T) float64, already normalised.
  LocalPhi(PhiSpec spec, const torch::Tensor& code);

  torch::Tensor forward(const torch::Tensor& lf) const override;
  torch::Tensor adjoint(const torch::Tensor& y) const override;
  torch::Tensor patch_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w,
                             torch::ScalarType dtype) const override;
  int64_t period() const override { return code_.size(3); }
  torch::Tensor pixel_weights(int64_t y0, int64_t x0, int64_t h, int64_t w,
                              torch::ScalarType dtype) const override;
  torch::Tensor pinv_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w, double lambda,
                            torch::ScalarType dtype) const override;

 private:
  // (T * T, N, U V) in the dtype asked for.
  torch::Tensor phase_matrices(torch::ScalarType dtype) const;

  torch::Tensor code_;    // (N, U, V, T, T) float64
  torch::Tensor code32_;  // the same in float32, for the common case
};

// Throws ConfigError when a model's code would hold more than 2^27 float64 values (1 GiB):
// specs that ask for that are mistakes, and refusing them beats running out of memory.
void check_code_size(const PhiSpec& spec, int64_t values, const std::string& what);

// Parameters of the asp model (docs/acquisition.md).
struct AspParams {
  double depth = 1.0;                  // m, modulation depth in [0, 1]
  std::string aperture = "full";       // A(u, v): "full" (1 at every view) or "disk"
  double radius = 1.2;                 // disk radius in normalised view angles
  double edge = 0.2;                   // width of the disk's linear soft edge
  std::string layout = "independent";  // table layout: "independent" or "pairs"
  double pair_gamma = 0.0;             // orientation of the complementary pair, degrees
  double pair_alpha = 90.0;            // phase of the pair's first row, degrees: 90 (the
                                       // quadrature pair, odd in the view angle) or 0

  static AspParams read(JsonReader& r);
  nlohmann::json to_json() const;
};

// The per-pixel ASP weights (N, U, V), normalised so a white light field measures 1 on average.
torch::Tensor asp_weights(const PhiSpec& spec, const AspParams& params);

std::unique_ptr<Phi> make_asp(const PhiSpec& spec);
std::unique_ptr<Phi> make_mask(const PhiSpec& spec);
std::unique_ptr<Phi> make_aperture(const PhiSpec& spec);
std::unique_ptr<Phi> make_lenslet(const PhiSpec& spec);
std::unique_ptr<Phi> make_random(const PhiSpec& spec);
// Time-coded models (docs/acquisition.md, "Time-coded cameras"): an aperture that changes per
// sub-frame, per-pixel exposure codes, and the two together.
std::unique_ptr<Phi> make_time_aperture(const PhiSpec& spec);
std::unique_ptr<Phi> make_coded_exposure(const PhiSpec& spec);
std::unique_ptr<Phi> make_exposure_aperture(const PhiSpec& spec);
// A still local camera over an exposure of spec.frames sub-frames: its weights in every
// sub-frame, each a T-th. ConfigError for models that mix pixels.
std::unique_ptr<Phi> still_over_frames(const Phi& still, const PhiSpec& spec);
// A measured local response given value by value (docs/acquisition.md, "Calibrated Phi").
std::unique_ptr<Phi> make_calibrated(const PhiSpec& spec);

// Checks a light field (..., U, V, H, W) against the spec: U, V, float32 or float64.
void check_light_field(const torch::Tensor& lf, const PhiSpec& spec);
// Checks a sensor image (..., N, H, W) against the spec.
void check_sensor(const torch::Tensor& y, const PhiSpec& spec);

// Pseudo-inverses (A^T A + lambda I)^-1 A^T of a batch of matrices (..., m, n) in float64,
// through the SVD: (..., n, m).
torch::Tensor tikhonov_pinv(const torch::Tensor& a, double lambda);

}  // namespace lfnet::optics::detail

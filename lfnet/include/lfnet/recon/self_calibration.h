// Self-calibration (docs/acquisition.md, "Self-calibration"): the angular shift of a camera
// whose response is displaced against its nominal Phi, estimated from one sensor image by a
// whole-image network of the lfnet architecture, which is then told the Phi so displaced.
//
// The net's first stage is the per-pixel pseudo-inverse of the Phi it holds
// (docs/architectures.md, "The lfnet network"); telling it another Phi of the same layout
// changes that stage only. Told the camera's true Phi, the net trained on the nominal one
// reconstructs a displaced camera's sensor image almost as well as the nominal camera's; told
// a wrong one, its views disagree with their neighbours (the light field of the scene seen by
// the wrong Phi is that of a scene whose every point is blended with itself moved by its
// disparity). The estimate is the shift whose reconstruction of a centre crop varies least
// from view to view along the shifted axis: the mean absolute difference of neighbouring
// views (angular_roughness), a natural light field's parallax being small.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <utility>

#include "lfnet/nn/network.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/phi.h"

namespace lfnet::recon {

struct SelfCalibrationOptions {
  double max_shift = 0.5;   // views searched on either side of the nominal response
  double tolerance = 0.02;  // the search ends when its bracket is this narrow, in views
  int64_t crop = 256;       // side of the centre crop reconstructed for each candidate shift
  int64_t margin = 16;      // pixels of the crop's border left out of the criterion
  // Throws ConfigError naming the bad field.
  void validate() const;
};

struct SelfCalibration {
  optics::CalibrationError error;  // angular_shift_u and angular_shift_v; the rest 0
  int64_t reconstructions = 0;     // crops the search reconstructed
};

// The mean absolute difference between neighbouring views of a light field (C, U, V, H, W)
// along U (axis 0) or V (axis 1), its outer `margin` pixels on each side left out.
double angular_roughness(const torch::Tensor& lf, int axis, int64_t margin = 0);

// Tells `net` (lfnet architecture) the camera whose Phi is the local `phi` displaced by
// `error` (its pixel weights over one period; an empty error: the nominal Phi itself).
void tell_camera(nn::LightFieldNet net, const optics::Phi& phi,
                 const optics::CalibrationError& error);

// Tells `net` the nominal `phi` again when it goes out of scope, whether the scope ends normally
// or by an exception: what telling it another camera for a while needs.
class NominalPhiOnExit {
 public:
  NominalPhiOnExit(nn::LightFieldNet net, const optics::Phi& phi)
      : net_(std::move(net)), phi_(phi) {}
  ~NominalPhiOnExit();
  NominalPhiOnExit(const NominalPhiOnExit&) = delete;
  NominalPhiOnExit& operator=(const NominalPhiOnExit&) = delete;

 private:
  nn::LightFieldNet net_;
  const optics::Phi& phi_;
};

// The angular shift (along U, then V; an axis along which the Phi's weights do not change is
// left at 0) of the camera that took `sensor` (N, H, W), estimated with `net`, a whole-image
// net trained for the nominal `phi`: for each candidate the net is told the Phi so displaced
// and reconstructs the centre crop; a coarse grid of 5 shifts over [-max_shift, max_shift],
// then a golden-section search around the best. `noise_sigma` conditions a noise-aware net.
// The net holds the nominal Phi again when it returns (or throws).
SelfCalibration estimate_angular_shift(nn::LightFieldNet net, const optics::Phi& phi,
                                       const torch::Tensor& sensor, double noise_sigma = 0,
                                       const SelfCalibrationOptions& options = {});

}  // namespace lfnet::recon

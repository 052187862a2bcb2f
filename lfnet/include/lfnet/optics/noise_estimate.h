// The noise of a coded sensor image, estimated from the image alone (docs/acquisition.md,
// "Estimating the noise"): what a noise-aware model is told when the user does not know it.
#pragma once

#include <torch/types.h>

#include "lfnet/optics/phi.h"

namespace lfnet::optics {

// The Gaussian noise sigma of a sensor image (N, H, W), relative to a white scene's signal
// (lfnet's Phis measure 1 on average for white, phi.h). `white` (N, T, T) is what each pixel
// phase of the code's period T measures of a white light field. Each measurement is divided by
// its pixels' white response, which leaves a smooth image where the scene is (the code's own
// pixel pattern is no noise), and the noise is Donoho and Johnstone's estimate on it: the
// median absolute finest-scale diagonal Haar wavelet coefficient over 0.6745 (Donoho &
// Johnstone, "Ideal spatial adaptation by wavelet shrinkage", Biometrika 1994), each
// coefficient scaled by the noise its four pixels carry after the division. Pixels whose white
// response is below a fifth of the mean carry too much noise and are left out. Under shot and
// read noise it estimates the sigma at about the image's median signal; scene detail finer than
// a pixel adds a little of its own. A sensor image too small for one coefficient is a
// ConfigError.
double estimate_noise_sigma(const torch::Tensor& sensor, const torch::Tensor& white);

// The same for a local Phi (phi.h, is_local): its white response from pixel_weights.
double estimate_noise_sigma(const Phi& phi, const torch::Tensor& sensor);

}  // namespace lfnet::optics

// Non-local means (Buades, Coll and Morel 2005) for light fields: the classical denoiser of the
// `pinv-nlm` baseline (docs/methods.md). The views are the channels of one image, so the
// similarity of two neighbourhoods is measured over every view at once and all views share
// the weights: parallax does not blur the views apart.
#pragma once

#include <torch/types.h>

#include <cstdint>

namespace lfnet::recon {

struct NlmOptions {
  int64_t search = 5;  // search radius: (2 s + 1)^2 candidate offsets
  int64_t patch = 1;   // patch radius: (2 p + 1)^2 pixels of every channel are compared
  double h = 0.35;     // filtering strength, in units of the noise sigma
};

// Denoises x (C, H, W) whose channels carry independent Gaussian noise of `sigma`: each pixel
// becomes the mean of the pixels of its search window, weighted by
// exp(-max(d^2 - 2 sigma^2, 0) / (h sigma)^2), d^2 the mean squared difference of the two
// neighbourhoods over all channels. Returns x unchanged for sigma = 0. Reflects at the borders.
torch::Tensor non_local_means(const torch::Tensor& x, double sigma, const NlmOptions& options = {});

// The noise sigma of the per-pixel pseudo-inverse's views when the measurements carry
// Gaussian noise of `sigma`: sigma times the root mean square of the rows' norms of the
// pseudo-inverse (UV h w, N h w), a pinv_matrix.
double pinv_noise_sigma(const torch::Tensor& pinv_matrix, double sigma);

}  // namespace lfnet::recon

// Image quality metrics exactly as docs/conventions.md defines them.
#pragma once

#include <torch/types.h>

#include "lfnet/core/light_field.h"

namespace lfnet {

// 10 log10(1 / MSE) over every view, pixel and channel; values in [0, 1]. Infinite when equal.
double psnr(const torch::Tensor& estimate, const torch::Tensor& truth);
// Light fields are read a view at a time, float32 or 16-bit codes.
double psnr(const LightFieldViews& estimate, const LightFieldViews& truth);

// PSNR of every view, a (U, V) float64 tensor.
torch::Tensor per_view_psnr(const LightFieldViews& estimate, const LightFieldViews& truth);

// Options of SSIM; defaults match scikit-image's structural_similarity(gaussian_weights=True,
// sigma=1.5, use_sample_covariance=True, data_range=1).
struct SsimOptions {
  double sigma = 1.5;       // Gaussian window standard deviation
  double truncate = 3.5;    // window radius = int(truncate * sigma + 0.5): 11 x 11 at 1.5
  double data_range = 1.0;  // L in C1 = (K1 L)^2, C2 = (K2 L)^2
  double k1 = 0.01;
  double k2 = 0.03;
  bool sample_covariance = true;  // scale (co)variances by n / (n - 1), n = window pixels
};

// Mean SSIM of two images (C, H, W) or (H, W): mean over channels of the mean SSIM map with
// a border of the window radius cropped, as scikit-image computes it.
double ssim_image(const torch::Tensor& a, const torch::Tensor& b, const SsimOptions& options = {});

// SSIM of a light field: the mean over views of each view's SSIM.
double ssim(const LightFieldViews& estimate, const LightFieldViews& truth,
            const SsimOptions& options = {});

}  // namespace lfnet

// What lfnet takes from OpenCV, outside the numerical core (which links no OpenCV): its
// non-local means as the denoiser "opencv-nlm" of the pinv-nlm baseline (docs/methods.md).
// lfnet's program registers it at start; a program built on the core alone does without.
#pragma once

#include <torch/types.h>

#include <cstdint>

#include "lfnet/core/fields.h"

namespace lfnet::cv {

// cv::fastNlMeansDenoising, one view at a time, on 16-bit views (the L1 norm).
struct OpenCvNlmOptions {
  double h = 1.0;       // filtering strength, in units of the views' noise sigma
  int64_t patch = 7;    // templateWindowSize: the side of the compared neighbourhoods (odd)
  int64_t search = 21;  // searchWindowSize: the side of the search window (odd)

  template <typename Fields>
  void fields(Fields& f) {
    f("h", h, Range::above(0, 100));
    f("patch", patch);
    f("search", search);
  }
  void validate() const;
};

// Denoises views (C, H, W) in [0, 1] (clamped to it) whose pixels carry Gaussian noise of
// `sigma`; sigma = 0 returns them unchanged.
torch::Tensor opencv_nlm(const torch::Tensor& views, double sigma, const OpenCvNlmOptions& options);

// Registers "opencv-nlm" with recon::register_denoiser. Calling it again changes nothing.
void register_opencv();

}  // namespace lfnet::cv

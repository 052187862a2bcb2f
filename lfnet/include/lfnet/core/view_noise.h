// Noise in a light field's views themselves: what a light-field camera's sub-aperture images
// carry. A plenoptic camera's views are resampled from one demosaiced sensor image, so its
// noise is correlated between neighbouring views and neighbouring pixels; independent noise is
// the case of a camera array.
#pragma once

#include <ATen/core/Generator.h>
#include <torch/types.h>

#include <cstdint>

namespace lfnet {

// Noise of unit standard deviation for a light field of `sizes` (C, U, V, H, W): Gaussian,
// averaged over the (2 a + 1)^2 views around each view (a = `angular_radius`, the views the
// grid has) and the (2 s + 1)^2 pixels around each pixel (s = `spatial_radius`), then scaled
// back to unit standard deviation, and the same in every colour (a plenoptic camera demosaics
// its views together). Radii 0: independent per view, pixel and colour.
torch::Tensor view_noise(torch::IntArrayRef sizes, int64_t angular_radius, int64_t spatial_radius,
                         at::Generator generator);

}  // namespace lfnet

// A post-filter for the periodic artefacts of patch-wise reconstruction.
#pragma once

#include <torch/types.h>

#include <cstdint>

namespace lfnet::recon {

// Patch-wise reconstruction leaves faint errors that repeat with the patch stride (every patch
// has its best pixels in the middle and its worst at the border), which show in each view's
// spectrum as peaks on the lattice of frequencies (k H / period, l W / period). This filter
// replaces every lattice bin but DC (both neighbouring integer bins where H / period is not an
// integer) by the mean of its four non-lattice neighbours, per view, and leaves every other
// frequency alone. `lf` is (C, U, V, H, W); returns a new tensor of the same shape and dtype.
// period <= 1, or a view smaller than 2 periods, returns `lf` unchanged.
torch::Tensor suppress_periodic(const torch::Tensor& lf, int64_t period);

}  // namespace lfnet::recon

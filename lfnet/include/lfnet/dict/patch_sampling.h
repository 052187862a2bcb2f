// Random light-field patches for dictionary training (Marwah et al. 2013: random patches of
// the training light fields, low-variance ones dropped).
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include "lfnet/core/fields.h"

#include <cstdint>
#include <string>
#include <vector>

#include "lfnet/core/light_field.h"

namespace lfnet::dict {

// Which patches to draw and which to drop.
struct PatchSamplingOptions {
  int64_t count = 20000;       // patches to return
  int64_t views = 5;           // U = V: the central views x views of every light field
  int64_t patch_size = 9;      // h = w, pixels
  double min_variance = 1e-4;  // drop patches whose variance over all U V h w values is
                               // below this (flat sky, walls: std < 0.01); 0 keeps all
  bool color = false;          // each colour channel a patch of its own (else the luma)
  uint64_t seed = 0;           // positions and light fields drawn
  int64_t max_draws = 50;      // give up after count * max_draws draws

  template <typename Fields>
  void fields(Fields& f) {
    f("count", count, Range::closed(1, 1e8));
    f("views", views, Range::closed(1, 4096));
    f("patch_size", patch_size, Range::closed(1, 256));
    f("min_variance", min_variance, Range::closed(0, 1));
    f("color", color);
    f("seed", seed);
    f("max_draws", max_draws, Range::closed(1, 1e12));
  }
  void validate() const;
  nlohmann::json to_json() const;
  static PatchSamplingOptions from_json(const nlohmann::json& j, const std::string& path = "$");
};

// What sampling did, for the dictionary's training metadata.
struct PatchSamplingStats {
  int64_t drawn = 0;    // patches looked at
  int64_t dropped = 0;  // patches below min_variance
};

// `count` patches (count, views * views * h * w) float32, flattened (u, v, y, x), at uniformly
// random positions over all light fields together (a light field is chosen in proportion to
// its number of patch positions and channels). Throws when a light field is smaller than a
// patch or has fewer views, and when too few patches pass the variance threshold.
torch::Tensor sample_patches(const std::vector<LightField>& light_fields,
                             const PatchSamplingOptions& options,
                             PatchSamplingStats* stats = nullptr);

}  // namespace lfnet::dict

// `lfnet render`: a procedural scene, or a random training scene, into a light-field folder with
// its true disparity map, previews and the resolved spec (docs/scenes.md).
#pragma once

#include <torch/types.h>

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "lfnet/core/light_field.h"

namespace lfnet::pipeline {

struct RenderRequest {
  std::string scene;           // a scene spec (JSON), or
  int64_t random_seed = -1;    // >= 0: the random training scene of this seed
  std::string random_options;  // RandomSceneOptions as a JSON file (random scenes only)
  // Overrides of the random scene's options.
  std::optional<std::pair<int64_t, int64_t>> size;           // H, W
  std::optional<std::pair<int64_t, int64_t>> views;          // rows, columns
  std::optional<std::pair<double, double>> disparity_range;  // px per view step
  bool grey = false;                                         // one luma channel
  std::string out;                                           // the folder to write
  bool force = false;                                        // replace an existing folder
  int bits = 16;                                             // per PNG sample
  int64_t epi_row = -1;  // the EPI's spatial row in preview.png (< 0: the centre)
};

struct RenderSummary {
  std::string name;                  // the scene's name ("scene" when it has none)
  std::string shape;                 // CxUxVxHxW
  std::vector<std::string> effects;  // the scene effects that ran
  double seconds = 0;
  int threads = 0;
  double min_disparity = 0, max_disparity = 0;  // px per view step
};

// Checks the request (a bad one is a ConfigError before any work), renders and writes the
// folder: lf_R_C.png, disparity.pfm, grid and EPI previews, preview.png and scene.json.
RenderSummary render_to_folder(const RenderRequest& request);

// The centre view and the disparity map (viridis: far dark, near yellow) side by side,
// area-downscaled to at most 640 px wide, over a full-resolution crop of the horizontal EPI
// through `epi_row` (the centre row when < 0; 8 rows per view), whose ends are ticked in red on
// the centre view. RGB (3, H, W) in [0, 1].
torch::Tensor render_preview(const LightField& lf, const torch::Tensor& disparity, int64_t epi_row);

}  // namespace lfnet::pipeline

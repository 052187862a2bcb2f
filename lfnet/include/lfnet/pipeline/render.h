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
  // Sub-frames of an exposure (1..64). Above 1 the folder holds frame_0/ .. frame_{T-1}/, each
  // what a still render writes but scene.json, which stays at the top; a random scene whose
  // options set no motion then moves up to kRandomVideoSpeed px per sub-frame.
  int64_t frames = 1;
  // Or a real still light field given synthetic motion over `frames` sub-frames
  // (core/sequence.h, docs/video.md "Synthetic motion"): a whole-image shift of `shift` (dx, dy)
  // px and a sideways walk of `walk` views per sub-frame. Written as frame_t/ folders of views
  // and previews, with sequence.json saying the motion is synthetic.
  std::string lf;
  std::pair<int64_t, int64_t> shift{0, 0};
  int64_t walk = 0;
};

// The random scenes' max_speed (px per sub-frame) for --frames > 1 when the options set no
// motion: moving training scenes by default.
constexpr double kRandomVideoSpeed = 2.0;

struct RenderSummary {
  std::string name;   // the scene's name ("scene" when it has none)
  std::string shape;  // CxUxVxHxW, or TxCxUxVxHxW for several frames
  int64_t frames = 1;
  std::vector<std::string> effects;  // the scene effects that ran
  double seconds = 0;
  int threads = 0;
  double min_disparity = 0, max_disparity = 0;  // px per view step
};

// Checks the request (a bad one is a ConfigError before any work), renders and writes the
// folder: lf_R_C.png, disparity.pfm, grid and EPI previews, preview.png and scene.json (with
// frames > 1: those but scene.json in each frame_t/).
RenderSummary render_to_folder(const RenderRequest& request);

// The centre view and the disparity map (viridis: far dark, near yellow) side by side,
// area-downscaled to at most 640 px wide, over a full-resolution crop of the horizontal EPI
// through `epi_row` (the centre row when < 0; 8 rows per view), whose ends are ticked in red on
// the centre view. RGB (3, H, W) in [0, 1].
torch::Tensor render_preview(const LightField& lf, const torch::Tensor& disparity, int64_t epi_row);

}  // namespace lfnet::pipeline

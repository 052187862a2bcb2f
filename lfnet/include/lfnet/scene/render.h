// Rendering a scene spec into its true light field and the centre view's true disparity map.
#pragma once

#include <torch/types.h>

#include <functional>
#include <string>
#include <vector>

#include "lfnet/core/light_field.h"
#include "lfnet/core/sequence.h"
#include "lfnet/scene/scene_spec.h"

namespace lfnet::scene {

// Loads an image file as (C, H, W) float32 in [0, 1], C = 1 or 3 (or 4: alpha is dropped).
// The scene library has no image I/O of its own; the program passes lfnet::io::read_image.
using ImageLoader = std::function<torch::Tensor(const std::string& path)>;

// Options of render_scene.
struct RenderOptions {
  ImageLoader image_loader;  // needed only by scenes with image textures
  std::string base_dir;      // relative image paths are resolved against it (the scene's folder)
};

// What the renderer produced.
struct RenderResult {
  LightField light_field;   // (C, U, V, H, W) in [0, 1]
  torch::Tensor disparity;  // (H, W) float32: px per view step, centre view
  // What ran, in this order: "occlusion" (more than one layer), then "defocus", "specular",
  // "vignetting" for those the scene names and no others.
  std::vector<std::string> effects_run;
};

// Renders every view: each layer's texture and alpha are generated once on a canvas larger than
// the image by the layer's largest shift, then shifted into every view (pure integer shifts
// for integer shifts, Catmull-Rom cubic interpolation otherwise; a general affine warp for
// slanted layers) and composited back to front with premultiplied alpha. Deterministic: the
// same spec gives bit-identical output for any thread count. Throws ConfigError for image
// textures without a loader.
// Layer motion is ignored: the spec's pose (the middle of an exposure) is rendered.
RenderResult render_scene(const SceneSpec& spec, const RenderOptions& options = {});

// What render_sequence produced.
struct SequenceResult {
  LightFieldSequence light_fields;  // (T, C, U, V, H, W) in [0, 1]
  torch::Tensor disparity;          // (T, H, W) float32: each sub-frame's centre-view disparity
  // As RenderResult's, with "motion" after "occlusion" when a layer moves and T > 1.
  std::vector<std::string> effects_run;
};

// Renders the T = `frames` sub-frames of an exposure: sub-frame t shows every layer moved by
// its motion (MotionSpec) times tau = t - (T - 1) / 2. A moving layer is rasterised once and
// resampled into each sub-frame (integer translations exactly, anything else by 2D Catmull-Rom);
// still layers are rasterised once and those behind every moving one composited once. Without
// motion, or with T = 1, every sub-frame is bit-identical to render_scene. Throws ConfigError
// for T outside [1, kMaxFrames] and for motion that leaves the scene's limits within T
// sub-frames (naming the sub-frame).
SequenceResult render_sequence(const SceneSpec& spec, int64_t frames,
                               const RenderOptions& options = {});

}  // namespace lfnet::scene

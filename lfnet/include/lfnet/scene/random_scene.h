// Random scene specs for training data: varied layers, textures, shapes, disparities and effects.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/scene/scene_spec.h"

namespace lfnet::scene {

// What random_scene draws from. Probabilities are per scene.
struct RandomSceneOptions {
  int64_t height = 256;  // view size in px
  int64_t width = 256;
  int64_t rows = 5;  // angular grid
  int64_t cols = 5;
  bool color = true;            // false: grey scenes
  double min_disparity = -3.0;  // px per view step; layer disparities are drawn
  double max_disparity = 3.0;   // uniformly in this range (nearer layers in front)
  int64_t min_layers = 3;       // layers including the background
  int64_t max_layers = 10;
  double thin_occluder_probability = 0.35;  // a fence, bars or branches in front
  double slanted_probability = 0.3;         // the background is a slanted plane
  double specular_probability = 0.15;       // effects
  double vignetting_probability = 0.15;
  double defocus_probability = 0.1;
  // A man-made frame in front: crossed bars (a window's mullions and transoms, a fence's posts
  // and rails), mostly of one flat colour, half the time in a wall's rectangular opening. A flat
  // bar's edges along one view axis show its parallax only along the other: the crossing bars
  // and the wall are where its depth can be read. 0 (default) leaves scenes as they were.
  double frame_probability = 0.0;
  // Natural-image textures: image files, or folders whose png/jpg/tif files all count (relative
  // paths from the working folder). Each layer takes a random region of a random one of them
  // (zoom 1..4) with this probability; 0 keeps the procedural textures only.
  std::vector<std::string> texture_images;
  double image_probability = 0.0;
  // Procedural textures in vivid palettes: saturated colours of distinct hues and similar
  // brightness, texture in chroma more than in luma. 0 (default) leaves scenes as they were.
  double vivid_probability = 0.0;
  // Motion for light-field video (render_sequence), per sub-frame. With all three maxima 0
  // (default) nothing moves and scenes stay as they were; otherwise each layer moves with
  // motion_probability, its speed, depth speed and (not the background) rotation drawn
  // uniformly up to these, from a stream of its own: the still scene is the same.
  double max_speed = 0.0;            // px per sub-frame, in a random direction
  double max_disparity_speed = 0.0;  // change of disparity per sub-frame, either sign
  double max_rotation = 0.0;         // degrees per sub-frame, either sign
  double motion_probability = 0.5;   // per layer

  template <typename Fields>
  void fields(Fields& f) {
    f("height", height);
    f("width", width);
    f("rows", rows);
    f("cols", cols);
    f("color", color);
    f("min_disparity", min_disparity);
    f("max_disparity", max_disparity);
    f("min_layers", min_layers);
    f("max_layers", max_layers);
    f("thin_occluder_probability", thin_occluder_probability);
    f("slanted_probability", slanted_probability);
    f("specular_probability", specular_probability);
    f("vignetting_probability", vignetting_probability);
    f("defocus_probability", defocus_probability);
    f("frame_probability", frame_probability);
    f("texture_images", texture_images);
    f("image_probability", image_probability);
    f("vivid_probability", vivid_probability);
    f("max_speed", max_speed);
    f("max_disparity_speed", max_disparity_speed);
    f("max_rotation", max_rotation);
    f("motion_probability", motion_probability);
  }
  bool moves() const { return max_speed > 0.0 || max_disparity_speed > 0.0 || max_rotation > 0.0; }
  static RandomSceneOptions from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  // Throws ConfigError naming the bad key under `json_path`.
  void validate(const std::string& json_path = "$") const;
};

// A random scene, a pure function of (seed, options): the same arguments give the same spec
// on every platform. The background layer is full (fronto-parallel or slanted); the layers in
// front of it are natural blobs, rectangles, disks and thin occluders at larger disparities, with
// textures of varied statistics: 1/f^beta fractals with beta in [1.6, 3], smooth noise, stripes,
// checkers, gradients and flat colours in natural palettes of varied contrast.
SceneSpec random_scene(uint64_t seed, const RandomSceneOptions& options = {});

// The image files that `texture_images` names, sorted within each folder. Throws ConfigError
// for a path that is neither an image file nor a folder holding one.
std::vector<std::string> texture_image_files(const std::vector<std::string>& paths);

}  // namespace lfnet::scene

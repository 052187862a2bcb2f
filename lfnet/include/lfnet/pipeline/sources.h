// Light-field sources of a config: folders, scene files and random scenes, loaded as grey
// light fields of the Phi's angular size (docs/architecture.md).
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/core/light_field.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/phi.h"
#include "lfnet/scene/render.h"

namespace lfnet::pipeline {

// Light fields named in a config: real folders, scene specs and random scenes.
struct LightFieldSources {
  std::vector<std::string> light_fields;                     // folders of sub-aperture images
  std::vector<std::string> scenes;                           // scene spec files (configs/scenes)
  int64_t random_scenes = 0;                                 // procedural random scenes
  uint64_t random_seed = 1;                                  // seed of the first random scene
  nlohmann::json random_options = nlohmann::json::object();  // scene::RandomSceneOptions
  std::string views;   // R0:R1,C0:C1 (1-based); "" = central U x V
  std::string layout;  // a file-naming pattern for folders no built-in scheme reads
                       // (io::parse_layout, docs/conventions.md); "" recognises the scheme
  std::string orient;  // angular reorientation of the folders on loading:
                       // flip-u, flip-v, transpose (docs/conventions.md)

  template <typename Fields>
  void fields(Fields& f) {
    f("light_fields", light_fields);
    f("scenes", scenes);
    f("random_scenes", random_scenes, Range::closed(0, 1e6));
    f("random_seed", random_seed);
    f("random_options", random_options);
    f("views", views);
    f("orient", orient);
    f("layout", layout);
  }
  void read(JsonReader& r);
  nlohmann::json to_json() const;
  bool empty() const { return light_fields.empty() && scenes.empty() && random_scenes == 0; }
};

// A named light field (grey unless loaded in colour) with its angular window applied.
struct NamedLightField {
  std::string name;
  LightField lf;
  // Or, loaded with `coded`, the grey light field in 16-bit codes (core/light_field.h), `lf`
  // then undefined.
  torch::Tensor codes;
  // Its views, either way.
  LightFieldViews views() const { return codes.defined() ? LightFieldViews(codes) : lf; }
};

// The flat field (H, W) of a camera coded by `phi`, behind `cfa` if it has one
// (optics::flat_field_gain), from its white frame at `path`: an acquisition folder in sensor
// mode (`lfnet simulate --white HxW --out DIR` makes one), or an image of the camera's N
// measurement channels. Throws ConfigError or IoError naming `option` and the file.
torch::Tensor read_flat_field(const std::string& path, const optics::Phi& phi,
                              const std::optional<optics::ColourFilterArray>& cfa = std::nullopt,
                              const std::string& option = "--flat-field");

// Reads a light-field folder and reorients its angular axes (`orient`, parsed as `what`: an
// option or JSON path); warns once per folder when its horizontal and vertical parallax
// disagree in sign (docs/conventions.md).
LightField read_oriented(const std::string& dir, const std::string& orient, const std::string& what,
                         const std::string& layout = "");

// Loads every source as a grey light field of rows x cols views, with a progress bar. With
// `whole_grids`, folders without a `views` window keep every view (at least rows x cols), for
// a data set that draws its own angular windows.
// With `colour`, light fields keep their colour channels (a grey folder stays grey). With
// `coded`, for commands that only simulate and score, grey folders of 16-bit views are held
// in 16-bit codes (NamedLightField::codes), half the memory.
// With `frames` > 1 (a time-coded Phi, rows = frames U), every folder is read as a sequence
// (docs/video.md): each frame windowed to U x cols, the frames stacked along the rows
// (LightFieldSequence::stacked); a still folder is the same in every frame. A sequence folder
// with `frames` 1 is a ConfigError.
std::vector<NamedLightField> load_sources(const LightFieldSources& sources, int64_t rows,
                                          int64_t cols, bool whole_grids = false,
                                          bool colour = false, bool coded = false,
                                          int64_t frames = 1);

// Render options for a scene file: image textures are read with io::read_image, relative to
// the scene file's folder ("" for none).
scene::RenderOptions scene_render_options(const std::string& scene_file);

// Checks, before any work, that every light-field folder of `sources` holds a complete grid of
// views (io::scan_folder; the files are not decoded) and every scene file exists. Errors name
// the folder or file and `where` (a JSON path such as "$.evaluation.data").
void check_sources(const LightFieldSources& sources, const std::string& where);

// lfnet info: what a light-field folder holds (its naming scheme, grid, view size, shape, value
// range, load time, orientation and parallax), as printable lines; `axis_reversed` when one
// angular axis looks reversed against the other.
struct LightFieldFolderInfo {
  std::string text;
  bool axis_reversed = false;
};
LightFieldFolderInfo describe_light_field_folder(const std::string& dir, const std::string& orient,
                                                 const std::string& layout);

}  // namespace lfnet::pipeline

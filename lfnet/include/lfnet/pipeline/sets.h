// Light-field sets with a role: the validation set every choice is made on and the test set every
// claim is reported on (docs/protocol.md). A set is a JSON file (configs/sets/) of entries, each a
// light field made from a real folder, a scene spec or a random scene, cut and degraded on
// purpose into a hard case: a crop, a downscale (finer texture, smaller disparity), a wider
// view spacing (larger disparity), a darker exposure, noise in the views themselves.
// `lfnet sets make` writes each entry as a light-field folder with a `set.json` that says which
// set and role it belongs to; `lfnet evaluate` copies that into its record, so `lfnet report`
// can tell a choice made on the test set.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/core/light_field.h"
#include "lfnet/scene/random_scene.h"

namespace lfnet::pipeline {

// The hard classes a set entry may stand for (docs/protocol.md).
const std::vector<std::string>& hard_classes();

// One light field of a set, and how it is made. Exactly one of `lf`, `scene` and `random`.
struct SetEntry {
  std::string name;                  // its folder's name; unique over every set
  std::string description;           // what it is, in a sentence
  std::vector<std::string> classes;  // hard classes it stands for (hard_classes())
  std::string lf;                    // a real light-field folder
  std::string orient;                // its angular reorientation (docs/conventions.md)
  std::string scene;                 // or a scene spec (docs/scenes.md)
  int64_t random = -1;               // or the random scene of this seed (>= 0)
  std::optional<scene::RandomSceneOptions> random_options;  // its options
  int64_t views = 5;          // the U x V grid written (square), centred on the source's grid
  int64_t angular_step = 1;   // view spacing: 2 takes every second view (twice the disparity)
  std::vector<int64_t> crop;  // [y, x, height, width] in the source's pixels; empty: whole
  int64_t downscale = 1;      // f x f area average after the crop: f times finer, disparity / f
  double gamma = 1.0;         // v -> gain * v^gamma (a darker, flatter exposure: gain < 1)
  double gain = 1.0;
  // Gaussian noise of this sigma (relative to white) in every view, drawn independently per view,
  // pixel and colour, clipped to [0, 1]: the truth of a light-field camera whose sub-aperture
  // images carry its own noise.
  double view_noise = 0.0;
  // Its correlation (core/view_noise.h): averaged over the views within this many steps and the
  // pixels within this many pixels, as in a plenoptic camera's views; 0: independent.
  int64_t view_noise_angular = 0;
  int64_t view_noise_spatial = 0;
  uint64_t seed = 0;  // the view noise's draw
  bool grey = false;  // written as one luma channel

  template <typename Fields>
  void fields(Fields& f) {
    f("name", name);
    f("description", description);
    f("classes", classes);
    f("lf", lf);
    f("orient", orient);
    f("scene", scene);
    f("random", random);
    f("random_options", random_options);
    f("views", views);
    f("angular_step", angular_step);
    f("crop", crop);
    f("downscale", downscale);
    f("gamma", gamma);
    f("gain", gain);
    f("view_noise", view_noise);
    f("view_noise_angular", view_noise_angular);
    f("view_noise_spatial", view_noise_spatial);
    f("seed", seed);
    f("grey", grey);
  }
  // Throws ConfigError naming the key under `path`.
  void validate(const std::string& path) const;
  // The source it is made from: the folder, the scene file or "random SEED".
  std::string source() const;
};

struct LightFieldSet {
  std::string name;  // "validation", "test"
  std::string role;  // "validation" or "test"
  std::string about;
  std::vector<SetEntry> light_fields;  // "light_fields": a list of entries, read by read_set

  template <typename Fields>
  void fields(Fields& f) {
    f("name", name);
    f("role", role);
    f("about", about);
  }
};

// Reads and checks a set file: its keys, its role, every entry, and names unique within it.
LightFieldSet read_set(const std::string& path);

// The light field of an entry (C, U, V, H, W) in [0, 1]: read or rendered, windowed, cropped,
// downscaled, exposed and made noisy as the entry says. Relative paths are taken from the
// working folder.
LightField make_set_entry(const SetEntry& entry);

// Writes every entry of `set` (or only those named in `only`) to OUT/NAME/: 16-bit PNG views,
// previews and set.json (set_record()). OUT must be new or empty, or `force` replaces the
// entries' folders (and only those).
void write_set(const LightFieldSet& set, const std::string& set_path, const std::string& out,
               const std::vector<std::string>& only, bool force);

// What a set entry's folder says of itself: {"set", "role", "name", "classes", "source", "file"}.
nlohmann::json set_record(const LightFieldSet& set, const SetEntry& entry,
                          const std::string& set_path);

// The set.json of a light-field folder written by write_set, or null when it has none. A
// malformed one is an IoError naming it.
nlohmann::json folder_set_record(const std::string& dir);

// Refuses (ConfigError naming `where`) any folder of `folders` that a set made: no config
// trains on a validation or test light field (docs/protocol.md).
void check_not_held_out(const std::vector<std::string>& folders, const std::string& where);

// Where a record's light field sits in the protocol: its "set" object's role ("validation",
// "test"), or "" for a light field of no set.
std::string record_role(const nlohmann::json& record);

}  // namespace lfnet::pipeline

#include "lfnet/pipeline/sets.h"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/view_noise.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/scene/scene.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

const std::vector<std::string>& hard_classes() {
  static const std::vector<std::string> classes = {
      "fine-texture",      "small-disparity", "large-disparity", "occlusion-edges",
      "dark-low-contrast", "noisy-views",     "colour-texture",  "plain"};
  return classes;
}

std::string SetEntry::source() const {
  if (!lf.empty()) return lf;
  if (!scene.empty()) return scene;
  return "random " + std::to_string(random);
}

void SetEntry::validate(const std::string& path) const {
  LFNET_CHECK_AS(ConfigError, !name.empty(), path, ".name: required");
  LFNET_CHECK_AS(ConfigError,
                 name.find('/') == std::string::npos && name.find('\\') == std::string::npos &&
                     name != "." && name != "..",
                 path, ".name '", name, "': a folder name, without separators");
  const int sources = (lf.empty() ? 0 : 1) + (scene.empty() ? 0 : 1) + (random >= 0 ? 1 : 0);
  LFNET_CHECK_AS(ConfigError, sources == 1, path,
                 ": give exactly one of lf (a folder), scene (a spec) and random (a seed)");
  LFNET_CHECK_AS(ConfigError, !random_options || random >= 0, path,
                 ".random_options: applies to a random scene only");
  LFNET_CHECK_AS(ConfigError, orient.empty() || !lf.empty(), path,
                 ".orient: applies to a light-field folder only");
  LFNET_CHECK_AS(ConfigError, !classes.empty(), path,
                 ".classes: name at least one hard class (or \"plain\")");
  for (size_t i = 0; i < classes.size(); ++i) {
    const auto& known = hard_classes();
    if (std::find(known.begin(), known.end(), classes[i]) == known.end()) {
      std::string list;
      for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
      throw ConfigError(path + ".classes[" + std::to_string(i) + "]: unknown class '" + classes[i] +
                        "' (known: " + list + ")");
    }
  }
  LFNET_CHECK_AS(ConfigError, views >= 1 && views <= 16, path, ".views: must lie in 1..16");
  LFNET_CHECK_AS(ConfigError, angular_step >= 1 && angular_step <= 8, path,
                 ".angular_step: must lie in 1..8");
  LFNET_CHECK_AS(ConfigError, crop.empty() || crop.size() == 4, path,
                 ".crop: [y, x, height, width], or empty");
  if (crop.size() == 4) {
    LFNET_CHECK_AS(ConfigError, crop[0] >= 0 && crop[1] >= 0 && crop[2] >= 1 && crop[3] >= 1, path,
                   ".crop: y and x >= 0, height and width >= 1");
  }
  LFNET_CHECK_AS(ConfigError, downscale >= 1 && downscale <= 16, path,
                 ".downscale: must lie in 1..16");
  LFNET_CHECK_AS(ConfigError, std::isfinite(gamma) && gamma > 0 && gamma <= 10, path,
                 ".gamma: must lie in (0, 10]");
  LFNET_CHECK_AS(ConfigError, std::isfinite(gain) && gain > 0 && gain <= 10, path,
                 ".gain: must lie in (0, 10]");
  LFNET_CHECK_AS(ConfigError, std::isfinite(view_noise) && view_noise >= 0 && view_noise <= 1, path,
                 ".view_noise: must lie in [0, 1]");
  LFNET_CHECK_AS(ConfigError, view_noise_angular >= 0 && view_noise_angular <= 4, path,
                 ".view_noise_angular: must lie in 0..4");
  LFNET_CHECK_AS(ConfigError, view_noise_spatial >= 0 && view_noise_spatial <= 8, path,
                 ".view_noise_spatial: must lie in 0..8");
  if (random_options) random_options->validate(path + ".random_options");
}

LightFieldSet read_set(const std::string& path) {
  const auto doc = read_json_file(path);
  LFNET_CHECK_AS(ConfigError, doc.is_object(), path, ": a set file is a JSON object");
  LightFieldSet set;
  JsonReader reader(doc, path + ":$");
  read_fields(reader, set);
  nlohmann::json entries = nlohmann::json::array();
  reader.require("light_fields", entries);
  reader.finish();
  LFNET_CHECK_AS(ConfigError, entries.is_array(), path, ":$.light_fields: a list of entries");
  for (size_t i = 0; i < entries.size(); ++i) {
    const std::string at = path + ":$.light_fields[" + std::to_string(i) + "]";
    LFNET_CHECK_AS(ConfigError, entries[i].is_object(), at, ": an entry is a JSON object");
    JsonReader entry_reader(entries[i], at);
    SetEntry entry;
    read_fields(entry_reader, entry);
    entry_reader.finish();
    set.light_fields.push_back(std::move(entry));
  }
  LFNET_CHECK_AS(ConfigError, set.role == "validation" || set.role == "test", path,
                 ":$.role: 'validation' or 'test', got '", set.role, "'");
  LFNET_CHECK_AS(ConfigError, !set.name.empty(), path, ":$.name: required");
  LFNET_CHECK_AS(ConfigError, !set.light_fields.empty(), path, ":$.light_fields: the set is empty");
  std::set<std::string> names;
  for (size_t i = 0; i < set.light_fields.size(); ++i) {
    const std::string at = path + ":$.light_fields[" + std::to_string(i) + "]";
    set.light_fields[i].validate(at);
    LFNET_CHECK_AS(ConfigError, names.insert(set.light_fields[i].name).second, at, ".name '",
                   set.light_fields[i].name, "' appears twice");
  }
  return set;
}

namespace {

// The entry's source, rendered or read, with every view it has.
LightField read_source(const SetEntry& e, int64_t span) {
  if (!e.lf.empty()) return read_oriented(e.lf, e.orient, "orient");
  scene::SceneSpec spec;
  std::string base;
  if (!e.scene.empty()) {
    try {
      spec = scene::load_scene(e.scene);
    } catch (const ConfigError& err) {
      throw ConfigError(e.scene + ": " + err.what());
    }
    base = e.scene;
  } else {
    auto options = e.random_options.value_or(scene::RandomSceneOptions{});
    options.rows = std::max(options.rows, span);
    options.cols = std::max(options.cols, span);
    spec = scene::random_scene(static_cast<uint64_t>(e.random), options);
  }
  spec.rows = std::max(spec.rows, span);
  spec.cols = std::max(spec.cols, span);
  return scene::render_scene(spec, scene_render_options(base)).light_field;
}

}  // namespace

LightField make_set_entry(const SetEntry& e) {
  const int64_t span = e.angular_step * (e.views - 1) + 1;
  LightField lf = read_source(e, span);
  LFNET_CHECK_AS(ConfigError, lf.rows() >= span && lf.cols() >= span, e.name, ": ", e.source(),
                 " has ", lf.rows(), "x", lf.cols(), " views; ", e.views, "x", e.views, " at step ",
                 e.angular_step, " need ", span, "x", span);
  const int64_t u0 = central_start(lf.rows(), span), v0 = central_start(lf.cols(), span);
  auto data =
      lf.data().slice(1, u0, u0 + span, e.angular_step).slice(2, v0, v0 + span, e.angular_step);
  if (e.crop.size() == 4) {
    const int64_t y = e.crop[0], x = e.crop[1], h = e.crop[2], w = e.crop[3];
    LFNET_CHECK_AS(ConfigError, y + h <= lf.height() && x + w <= lf.width(), e.name, ": crop [", y,
                   ", ", x, ", ", h, ", ", w, "] leaves the ", lf.height(), "x", lf.width(),
                   " views of ", e.source());
    data = data.slice(3, y, y + h).slice(4, x, x + w);
  }
  if (e.downscale > 1) {
    const int64_t f = e.downscale;
    LFNET_CHECK_AS(ConfigError, data.size(3) >= 2 * f && data.size(4) >= 2 * f, e.name,
                   ": views of ", data.size(3), "x", data.size(4),
                   " are too small to downscale by ", f);
    const auto c = data.size(0), u = data.size(1), v = data.size(2);
    data = torch::avg_pool2d(data.reshape({c * u * v, 1, data.size(3), data.size(4)}), f)
               .reshape({c, u, v, data.size(3) / f, data.size(4) / f});
  }
  data = data.contiguous().clamp(0.0, 1.0);
  if (e.gamma != 1.0) data = data.pow(e.gamma);
  if (e.gain != 1.0) data = (data * e.gain).clamp(0.0, 1.0);
  if (e.view_noise > 0) {
    const auto noise = view_noise(data.sizes(), e.view_noise_angular, e.view_noise_spatial,
                                  at::detail::createCPUGenerator(e.seed));
    data = (data + e.view_noise * noise).clamp(0.0, 1.0);
  }
  LightField out(data.to(torch::kFloat32).contiguous());
  return e.grey ? out.grey() : out;
}

nlohmann::json set_record(const LightFieldSet& set, const SetEntry& entry,
                          const std::string& set_path) {
  return {{"set", set.name},
          {"role", set.role},
          {"name", entry.name},
          {"classes", entry.classes},
          {"source", entry.source()},
          {"file", set_path},
          {"entry", fields_to_json(entry)}};
}

void write_set(const LightFieldSet& set, const std::string& set_path, const std::string& out,
               const std::vector<std::string>& only, bool force) {
  std::vector<const SetEntry*> chosen;
  for (const auto& name : only) {
    const bool known = std::any_of(set.light_fields.begin(), set.light_fields.end(),
                                   [&](const SetEntry& e) { return e.name == name; });
    LFNET_CHECK_AS(ConfigError, known, "--only ", name, ": no such light field in ", set_path);
  }
  for (const auto& e : set.light_fields) {
    if (only.empty() || std::find(only.begin(), only.end(), e.name) != only.end()) {
      chosen.push_back(&e);
    }
  }
  OutputFolderPolicy policy;
  policy.force = force;
  policy.inputs = {set_path};
  for (const auto* e : chosen) {
    if (!e->lf.empty()) policy.inputs.push_back(e->lf);
    if (!e->scene.empty()) policy.inputs.push_back(e->scene);
  }
  // Every refusal before any work.
  for (const auto* e : chosen) check_output_folder((fs::path(out) / e->name).string(), policy);
  ProgressBar bar("making " + set.name + " light fields", static_cast<int64_t>(chosen.size()));
  for (const auto* e : chosen) {
    LightField lf;
    // The set file and the entry named once, whichever step failed.
    auto where = [&](const std::string& what) {
      return set_path + ": " + (what.rfind(e->name + ": ", 0) == 0 ? what : e->name + ": " + what);
    };
    try {
      lf = make_set_entry(*e);
    } catch (const ConfigError& err) {
      throw ConfigError(where(err.what()));
    } catch (const IoError& err) {
      throw IoError(where(err.what()));
    }
    const auto record = set_record(set, *e, set_path);
    write_folder((fs::path(out) / e->name).string(), policy, [&](const std::string& dir) {
      io::write_light_field(lf, dir, {"png", 16});
      io::write_previews(lf, dir);
      auto r = record;
      r["shape"] = lf.shape_string();
      write_json_file((fs::path(dir) / "set.json").string(), r);
    });
    spdlog::info("{}: {} ({})", e->name, lf.shape_string(), e->source());
    bar.advance();
  }
}

nlohmann::json folder_set_record(const std::string& dir) {
  const auto path = fs::path(dir) / "set.json";
  std::error_code ec;
  if (dir.empty() || !fs::is_regular_file(path, ec)) return nullptr;
  nlohmann::json doc;
  try {
    doc = read_json_file(path.string());
  } catch (const Error& e) {
    throw IoError(path.string() + ": " + e.what());
  }
  LFNET_CHECK_AS(IoError, doc.is_object() && doc.value("role", "") != "" && doc.contains("name"),
                 path.string(), ": not a set entry's record (no role or name)");
  return doc;
}

void check_not_held_out(const std::vector<std::string>& folders, const std::string& where) {
  for (size_t i = 0; i < folders.size(); ++i) {
    const auto set = folder_set_record(folders[i]);
    if (set.is_null()) continue;
    throw ConfigError(where + ".light_fields[" + std::to_string(i) + "]: " + folders[i] +
                      " is the " + set.value("role", "") + " set's light field " +
                      set.value("name", "") +
                      ": no config trains on the validation or test sets (docs/protocol.md)");
  }
}

std::string record_role(const nlohmann::json& record) {
  if (!record.contains("set") || !record["set"].is_object()) return "";
  return record["set"].value("role", "");
}

}  // namespace lfnet::pipeline

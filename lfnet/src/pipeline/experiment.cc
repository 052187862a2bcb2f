#include "lfnet/pipeline/experiment.h"

#include <cmath>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/stages.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

void EvaluationConfig::read(JsonReader& r) {
  if (r.has("data")) {
    auto d = r.child("data");
    data.read(d);
  }
  r.get("methods", methods);
  for (size_t i = 0; i < methods.size(); ++i) {
    try {
      recon::find_method(methods[i]);
    } catch (const ConfigError& e) {
      throw ConfigError(r.path_of("methods") + "[" + std::to_string(i) + "]: " + e.what());
    }
  }
  r.get("method_options", method_options);
  check_method_options(method_options, methods, r.path_of("method_options"));
  FieldReader fields{r};
  fields("strides", strides, Range::closed(1, 64));
  fields("modes", modes);
  fields("noise", noise, Range::closed(0, 10));
  r.get("model_stage", model_stage);
  r.finish();
}

nlohmann::json EvaluationConfig::to_json() const {
  nlohmann::json out = {
      {"data", data.to_json()}, {"methods", methods}, {"method_options", method_options},
      {"strides", strides},     {"noise", noise},     {"model_stage", model_stage}};
  FieldWriter{out}("modes", modes);
  return out;
}

void apply_override(nlohmann::json& config, const std::string& text) {
  const size_t eq = text.find('=');
  LFNET_CHECK_AS(ConfigError, eq != std::string::npos && eq > 0, "--set ", text,
                 ": expected KEY.PATH=VALUE, e.g. training.epochs=1");
  const std::string key = text.substr(0, eq), value_text = text.substr(eq + 1);
  nlohmann::json value;
  try {
    value = nlohmann::json::parse(value_text);
  } catch (const nlohmann::json::exception&) {
    value = value_text;  // a bare word is a string
  }
  nlohmann::json* node = &config;
  size_t start = 0;
  while (true) {
    const size_t dot = key.find('.', start);
    const std::string part =
        key.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    LFNET_CHECK_AS(ConfigError, !part.empty(), "--set ", text, ": empty key in '", key, "'");
    LFNET_CHECK_AS(ConfigError, node->is_object(), "--set ", text, ": $.",
                   key.substr(0, start ? start - 1 : 0), " is not an object");
    if (dot == std::string::npos) {
      (*node)[part] = value;
      return;
    }
    if (!node->contains(part)) (*node)[part] = nlohmann::json::object();
    node = &(*node)[part];
    start = dot + 1;
  }
}

ExperimentConfig ExperimentConfig::load_run(const std::string& run_dir) {
  const std::string path = (fs::path(run_dir) / "config.json").string();
  LFNET_CHECK_AS(IoError, fs::is_regular_file(path), run_dir,
                 " is not a run folder: it has no config.json");
  auto j = read_json_file(path);
  LFNET_CHECK_AS(ConfigError, j.is_object(), path, ": a config is a JSON object");
  const std::string scale = j.value("scale", "");
  j.erase("scale");
  auto config = from_json(j, path);
  config.scale = scale;
  return config;
}

namespace {

// A config file with its bases merged in ($.extends) and `scale` applied: the base's own
// resolution at that scale, then this file's keys (objects merged key by key, lists and values
// replaced), then this file's patch for the scale. `scale` empty: the file's default_scale,
// else its base's. `found`: whether some file of the chain has the scale.
struct ResolvedConfig {
  nlohmann::json j;
  std::string scale;
  bool found = false;
  std::vector<std::string> files;  // the file, then each base it extends
};

ResolvedConfig resolve_config(const std::string& path, const std::string& scale,
                              std::vector<std::string>& chain) {
  const std::string by = chain.empty() ? "" : " ($.extends of " + chain.back() + ")";
  LFNET_CHECK_AS(ConfigError, !fs::is_directory(path), "config ", path, by,
                 " is a folder, not a config file");
  LFNET_CHECK_AS(ConfigError, fs::is_regular_file(path), "config ", path, by, " does not exist");
  const std::string canonical = fs::weakly_canonical(path).string();
  for (const auto& seen : chain) {
    LFNET_CHECK_AS(ConfigError, seen != canonical, path, ": $.extends makes a cycle");
  }
  LFNET_CHECK_AS(ConfigError, chain.size() < 16, path, ": $.extends goes 16 files deep");
  nlohmann::json j;
  try {
    j = read_json_file(path);
  } catch (const Error& e) {
    if (chain.empty()) throw;
    throw ConfigError("$.extends of " + chain.back() + ": " + e.what());
  }
  chain.push_back(canonical);
  LFNET_CHECK_AS(ConfigError, j.is_object(), path, ": a config is a JSON object");
  ResolvedConfig out;
  out.scale = scale;
  out.files.push_back(path);
  if (out.scale.empty() && j.contains("default_scale")) {
    LFNET_CHECK_AS(ConfigError, j["default_scale"].is_string(), path,
                   ": $.default_scale: expected the name of a scale, got ",
                   j["default_scale"].dump());
    out.scale = j["default_scale"].get<std::string>();
  }
  nlohmann::json scales = nlohmann::json::object();
  if (j.contains("scales")) {
    LFNET_CHECK_AS(ConfigError, j["scales"].is_object(), path,
                   ": $.scales: expected an object of named config patches");
    // Every scale is merged into the config when chosen, so each must be an object.
    for (const auto& [name, patch] : j["scales"].items()) {
      LFNET_CHECK_AS(ConfigError, patch.is_object(), path, ": $.scales.", name,
                     ": expected an object (a patch merged into the config)");
    }
    scales = j["scales"];
  }
  if (j.contains("extends")) {
    LFNET_CHECK_AS(ConfigError,
                   j["extends"].is_string() && !j["extends"].get<std::string>().empty(), path,
                   ": $.extends: expected the path of a config (relative to this one), got ",
                   j["extends"].dump());
    const auto base_path = fs::path(path).parent_path() / j["extends"].get<std::string>();
    auto base = resolve_config(base_path.lexically_normal().string(), out.scale, chain);
    out.scale = base.scale;
    out.found = base.found;
    out.j = std::move(base.j);
    out.files.insert(out.files.end(), base.files.begin(), base.files.end());
  }
  j.erase("extends");
  j.erase("scales");
  j.erase("default_scale");
  out.j.merge_patch(j);
  if (!out.scale.empty() && scales.contains(out.scale)) {
    out.j.merge_patch(scales[out.scale]);
    out.found = true;
  }
  chain.pop_back();
  return out;
}

}  // namespace

ExperimentConfig::Merged ExperimentConfig::merge(const std::string& path, const std::string& scale,
                                                 const std::vector<std::string>& overrides) {
  std::vector<std::string> chain;
  auto resolved = resolve_config(path, scale, chain);
  LFNET_CHECK_AS(ConfigError, resolved.scale.empty() || resolved.found, path,
                 ": $.scales has no scale '", resolved.scale, "'");
  for (const auto& o : overrides) apply_override(resolved.j, o);
  return {std::move(resolved.j), resolved.scale, std::move(resolved.files)};
}

ExperimentConfig ExperimentConfig::load(const std::string& path, const std::string& scale,
                                        const std::vector<std::string>& overrides) {
  auto merged = merge(path, scale, overrides);
  auto config = from_json(merged.j, overrides.empty() ? path : path + " (with --set)");
  config.scale = merged.scale;
  config.files = std::move(merged.files);
  // A new run starts from $.init: it must be there (a resumed run may no longer need it). A
  // config's paths are taken from the working folder, $.extends alone from the config's: a path
  // that exists beside the config only is named.
  const auto where = [&](const std::string& file) {
    const auto beside = fs::path(path).parent_path() / file;
    return fs::path(file).is_relative() && fs::is_regular_file(beside)
               ? " (it is taken from the working folder, not the config's: give " +
                     beside.string() + ")"
               : "";
  };
  LFNET_CHECK_AS(ConfigError, config.init.empty() || fs::is_regular_file(config.init), path,
                 ": $.init: ", config.init, " is not a file", where(config.init),
                 ": give a checkpoint to start from");
  LFNET_CHECK_AS(ConfigError, config.code.from.empty() || fs::is_regular_file(config.code.from),
                 path, ": $.code.from: ", config.code.from, " is not a file",
                 where(config.code.from),
                 ": give a model that learned a code of this family and shape");
  return config;
}

void DistillConfig::read(JsonReader& r) {
  read_fields(r, *this);
  r.finish();
  if (!(weight >= 0 && weight <= 1))
    throw ConfigError(r.path_of("weight") + ": must lie in [0, 1]");
}

nlohmann::json DistillConfig::to_json() const { return fields_to_json(*this); }

void CodeConfig::read(JsonReader& r) {
  enabled = true;
  r.get("from", from);
  read_fields(r, phi);
  read_fields(r, training);
  r.finish();
  try {
    phi.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(r.path() + ": " + e.what());
  }
  LFNET_CHECK_AS(ConfigError, !training.binarise || phi.family != "asp", r.path_of("binarise"),
                 ": an ASP's response is a cosine and has no binary form (mask and aperture do)");
}

nlohmann::json CodeConfig::to_json() const {
  auto out = fields_to_json(phi);
  out.update(fields_to_json(training));
  if (!from.empty()) out["from"] = from;
  return out;
}

namespace {

// $.stages: names, or objects with a name and training options, each checked before any work.
void read_stages(JsonReader& r, ExperimentConfig& c) {
  nlohmann::json stages = nlohmann::json::array({"joint"});
  r.get("stages", stages);
  LFNET_CHECK_AS(ConfigError, stages.is_array() && !stages.empty(),
                 "$.stages: a non-empty list of stages (ae, cnn, joint, joint_scratch)");
  for (size_t i = 0; i < stages.size(); ++i) {
    const std::string path = "$.stages[" + std::to_string(i) + "]";
    StageConfig s;
    if (stages[i].is_string()) {
      s.name = stages[i].get<std::string>();
    } else {
      JsonReader sr(stages[i], path);
      sr.require("name", s.name);
      sr.get("training", s.training);
      sr.finish();
      LFNET_CHECK_AS(ConfigError, s.training.is_object(), path,
                     ".training: expected an object of training options");
    }
    LFNET_CHECK_AS(ConfigError,
                   s.name == "ae" || s.name == "cnn" || s.name == "joint" ||
                       s.name == "joint_scratch" || s.name == "dict",
                   path, ": unknown stage '", s.name,
                   "' (known: ae, cnn, joint, joint_scratch, dict)");
    LFNET_CHECK_AS(ConfigError, s.name != "dict" || s.training.empty(), path,
                   ": the dict stage takes its options from $.dictionary, not 'training'");
    c.stages.push_back(s);
    // Values (not only keys and types) are checked before any work starts.
    try {
      if (is_network_stage(s.name)) c.stage_options(s).validate();
    } catch (const ConfigError& e) {
      throw ConfigError("$.training (stage " + s.name + "): " + e.what());
    }
  }
}

// $.dictionary: the sampling, K-SVD and sparse-coding options of the dict stage.
void read_dictionary(JsonReader& r, ExperimentConfig& c) {
  if (r.has("dictionary")) {
    auto d = r.child("dictionary");
    nlohmann::json sampling = nlohmann::json::object(), ksvd = nlohmann::json::object(),
                   coding = nlohmann::json::object();
    d.get("sampling", sampling);
    d.get("ksvd", ksvd);
    d.get("coding", coding);
    d.finish();
    c.dictionary_coding = dict::SparseCodingOptions::from_json(coding, "$.dictionary.coding");
    c.dictionary_sampling =
        dict::PatchSamplingOptions::from_json(sampling, "$.dictionary.sampling");
    c.dictionary_ksvd = dict::KsvdOptions::from_json(ksvd, "$.dictionary.ksvd");
  }
}

// The net's measurements and patch follow from the Phi and the dataset's patches: a value given
// in $.network is honoured when it agrees, and refused when it does not.
void derive_network_shape(ExperimentConfig& c, const nlohmann::json& j, const std::string& source) {
  const auto given = c.network;
  c.network.measurements = c.phi.n;
  c.network.patch.rows = c.phi.coded_rows();  // T U for a time-coded camera (docs/video.md)
  c.network.frames = c.phi.frames;
  c.network.patch.cols = c.phi.cols;
  c.network.patch.height = c.dataset.patch_h;
  c.network.patch.width = c.dataset.patch_w;
  const nlohmann::json network_json = j.contains("network") ? j["network"] : nlohmann::json();
  auto refuse_if_differs = [&](const std::string& key, int64_t given_value, int64_t value,
                               const std::string& from) {
    const bool set = key.rfind("patch.", 0) == 0 ? network_json.contains("patch") &&
                                                       network_json["patch"].contains(key.substr(6))
                                                 : network_json.contains(key);
    if (set && given_value != value) {
      throw ConfigError(source + ": $.network." + key + " is " + std::to_string(given_value) +
                        " but " + from + " makes it " + std::to_string(value) + ": set " + from +
                        " instead, or leave $.network." + key + " out");
    }
  };
  refuse_if_differs("measurements", given.measurements, c.network.measurements,
                    "the Phi's N ($.phi)");
  refuse_if_differs("patch.rows", given.patch.rows, c.network.patch.rows,
                    "the Phi's views ($.phi)");
  refuse_if_differs("patch.cols", given.patch.cols, c.network.patch.cols,
                    "the Phi's views ($.phi)");
  refuse_if_differs("patch.height", given.patch.height, c.network.patch.height,
                    "$.dataset.patch_h");
  refuse_if_differs("patch.width", given.patch.width, c.network.patch.width, "$.dataset.patch_w");
}

}  // namespace

ExperimentConfig ExperimentConfig::from_json(const nlohmann::json& j, const std::string& source) {
  ExperimentConfig c;
  c.raw = j;
  try {
    JsonReader r(j, "$");
    r.get("name", c.name);
    // The name makes the default run folder out/<name>, which --force replaces: one path
    // component, never "", "." or "..".
    LFNET_CHECK_AS(
        ConfigError,
        !c.name.empty() && c.name != "." && c.name != ".." &&
            c.name.find('/') == std::string::npos && c.name.find('\\') == std::string::npos,
        "$.name: a run's name is one folder name (no '/', not empty, '.' or '..'), got '", c.name,
        "'");
    r.get("init", c.init);
    nlohmann::json phi;
    r.require("phi", phi);
    // A string is NAME[:N] or a file: a calibrated-Phi folder, a spec, a model.
    c.phi = phi.is_string() ? phi_from_argument(phi.get<std::string>(), "$.phi")
                            : optics::PhiSpec::from_json(phi, "$.phi");
    {
      auto d = r.child("data");
      c.train_data.read(d);
    }
    if (r.has("dataset")) {
      auto d = r.child("dataset");
      c.dataset = data::DatasetOptions::from_json(d);
    }
    nlohmann::json network = nlohmann::json::object();
    r.get("network", network);
    c.network = nn::NetworkOptions::from_json(network, "$.network");
    r.get("training", c.training);
    if (r.has("distill")) {
      auto d = r.child("distill");
      c.distill.read(d);
    }
    if (r.has("code")) {
      auto k = r.child("code");
      c.code.read(k);
    }
    // Parse once so errors in the common options surface before any work.
    (void)train::TrainerOptions::from_json(c.training, "$.training");
    read_stages(r, c);
    read_dictionary(r, c);
    if (r.has("evaluation")) {
      auto e = r.child("evaluation");
      c.evaluation.read(e);
    }
    r.finish();
  } catch (const ConfigError& e) {
    throw ConfigError(source + ": " + e.what());
  }
  // The resolved spec (every parameter filled in) is what models and results record.
  c.phi = optics::make_phi(c.phi)->spec();
  if (c.code.enabled) {
    // The code's start, with $.phi's N and views, is the Phi the data and the net begin with.
    try {
      const nn::LearnedPhi start(c.code.phi, c.phi.n, c.phi.rows, c.phi.cols);
      c.phi = optics::make_phi(start->spec())->spec();
    } catch (const ConfigError& e) {
      throw ConfigError(source + ": $.code: " + e.what());
    }
  }
  derive_network_shape(c, j, source);
  if (!c.network.cfa.empty()) {
    // A colour net trains on its own colour crops, measured by the code of $.phi.
    LFNET_CHECK_AS(ConfigError, !c.code.enabled, source,
                   ": $.network.cfa: a colour net learns no code ($.code) yet");
  }
  return c;
}

namespace {
// The trainer's stage of a network stage: joint_scratch trains as joint does, from random weights.
train::Stage trainer_stage(const StageConfig& stage) {
  return train::from_string(stage.name == "joint_scratch" ? "joint" : stage.name, train::Stage{});
}
}  // namespace

train::TrainerOptions ExperimentConfig::stage_options(const StageConfig& stage) const {
  nlohmann::json merged = training;
  if (stage.training.is_object()) merged.merge_patch(stage.training);
  merged["stage"] = train::to_string(trainer_stage(stage));
  return train::TrainerOptions::from_json(merged, "$.stages[" + stage.name + "].training");
}

nn::NetworkOptions ExperimentConfig::stage_network(const StageConfig& stage) const {
  nn::NetworkOptions o = network;
  o.set_branches(train::branches_of_stage(trainer_stage(stage)));
  o.validate();
  return o;
}

}  // namespace lfnet::pipeline

#include "lfnet/pipeline/models.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/zip_check.h"
#include "lfnet/io/phi_io.h"
#include "lfnet/nn/learned_phi.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/methods.h"
#include "lfnet/train/checkpoint.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

torch::Tensor phi_tensor(const optics::Phi& phi, const nn::NetworkOptions& options) {
  if (options.arch().phi_input() == nn::PhiInput::kPatchMatrices) {
    return optics::patch_matrix_stack(phi, options.patch.height, options.patch.width);
  }
  LFNET_CHECK_AS(ConfigError, phi.local(), "the ", options.architecture,
                 " architecture needs a Phi whose measurements are per pixel; ", phi.spec().label(),
                 " is not");
  const int64_t t = phi.period();
  return phi.pixel_weights(0, 0, t, t);
}

ModelFileKind model_file_kind(const std::string& path) {
  // Only a regular file: a folder would fail with the stream library's words, and reading a
  // FIFO or a device could block forever.
  std::error_code ec;
  const auto status = fs::status(path, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot read ", path, ": ", ec.message());
  LFNET_CHECK_AS(IoError, !fs::is_directory(status), path,
                 " is a folder, not a model file: give the checkpoint or exported file in it");
  LFNET_CHECK_AS(IoError, fs::is_regular_file(status), path,
                 " is not a regular file (a FIFO, socket or device): give a model file");
  std::ifstream in(path, std::ios::binary);
  LFNET_CHECK_AS(IoError, in.good(), "cannot read ", path, ": ", std::strerror(errno));
  char head[8] = {0};
  in.read(head, 8);
  if (in.gcount() == 8 && std::memcmp(head, "LFNETCKP", 8) == 0) return ModelFileKind::kCheckpoint;
  if (in.gcount() >= 1 && head[0] == '{' && fs::file_size(path, ec) < (1 << 20) && !ec) {
    // A small JSON file: a noise switch if it says so.
    nlohmann::json j = nlohmann::json::parse(std::ifstream(path), nullptr, false);
    // Cut off or hand-edited: say so, as a JSON file (a noise switch), not as a checkpoint.
    LFNET_CHECK_AS(ConfigError, !j.is_discarded(), path,
                   " is not valid JSON (truncated or malformed); a model given as JSON is a noise "
                   "switch (docs/models.md)");
    if (j.is_object() && j.value("format", "") == kNoiseSwitchFormat) {
      return ModelFileKind::kNoiseSwitch;
    }
    return ModelFileKind::kOther;
  }
  if (in.gcount() < 4 || std::memcmp(head, "PK\x03\x04", 4) != 0) return ModelFileKind::kOther;
  // Dictionaries and exported models are both zip archives: a damaged one is neither, and a
  // dictionary loads as one.
  check_zip_integrity(path, path);
  try {
    (void)dict::load_dictionary(path);
    return ModelFileKind::kDictionary;
  } catch (const Error&) {
    return ModelFileKind::kExported;
  }
}

std::vector<std::string> model_input_files(const std::string& path) {
  std::vector<std::string> files{path};
  if (path.empty()) return files;
  try {
    if (model_file_kind(path) != ModelFileKind::kNoiseSwitch) return files;
    const auto j = read_json_file(path);
    const auto folder = fs::path(path).parent_path();
    for (const char* key : {"quiet", "noisy"}) {
      if (!j.contains(key) || !j[key].is_string()) continue;
      const fs::path member = j[key].get<std::string>();
      files.push_back((member.is_absolute() ? member : folder / member).string());
    }
  } catch (const Error&) {
  }
  return files;
}

namespace {

// A noise switch: its two checkpoints, checked to fit together.
ModelFile load_noise_switch(const std::string& path, bool network) {
  std::string quiet, noisy;
  double sigma = 0, exposure = 0;
  int64_t version = 0;
  try {
    const auto j = read_json_file(path);
    JsonReader r(j, path + ":$");
    std::string format, about;
    r.require("format", format);
    r.require("version", version);
    r.get("about", about);
    r.require("quiet", quiet);
    r.require("noisy", noisy);
    r.require("switch_sigma", sigma);
    r.get("exposure_target", exposure);
    r.finish();
    LFNET_CHECK_AS(ConfigError, version == 1, r.path_of("version"),
                   ": this lfnet reads version 1, got ", version);
    LFNET_CHECK_AS(ConfigError, sigma > 0 && std::isfinite(sigma), r.path_of("switch_sigma"),
                   ": must be a finite sigma > 0, got ", sigma);
    LFNET_CHECK_AS(ConfigError, exposure >= 0 && exposure <= 1, r.path_of("exposure_target"),
                   ": must be an exposure in [0, 1] (0: none), got ", exposure);
  } catch (const ConfigError& e) {
    throw ConfigError(std::string("noise switch ") + e.what());
  }
  // Its checkpoints' paths are relative to the file.
  const auto folder = fs::path(path).parent_path();
  auto member = [&](const std::string& name) {
    const auto p = fs::path(name).is_absolute() ? fs::path(name) : folder / name;
    LFNET_CHECK_AS(ConfigError, model_file_kind(p.string()) == ModelFileKind::kCheckpoint, path,
                   ": ", name, " is not an lfnet checkpoint (a noise switch joins two)");
    auto m = load_model(p.string(), network);
    LFNET_CHECK_AS(ConfigError, m.network.arch().whole_image(), path, ": ", name,
                   " is not of a whole-image architecture such as lfnet");
    LFNET_CHECK_AS(ConfigError, m.network.arch().reads_noise(m.network), path, ": ", name,
                   " has no noise input: it cannot be told the sigma the switch reads");
    return m;
  };
  auto model = member(quiet);
  const auto above = member(noisy);
  LFNET_CHECK_AS(ConfigError, above.phi == model.phi, path, ": ", quiet, " and ", noisy,
                 " were trained for different Phis");
  LFNET_CHECK_AS(ConfigError, above.network.cfa == model.network.cfa, path, ": ", quiet, " (",
                 model.network.cfa.empty() ? "grey" : model.network.cfa, ") and ", noisy, " (",
                 above.network.cfa.empty() ? "grey" : above.network.cfa,
                 ") reconstruct different colours: a switch joins two models of one sensor");
  model.quiet_path = model.path;  // resolved against the switch's folder
  model.path = path;
  model.noisy_path = above.path;
  model.noisy = above.net;
  model.switch_sigma = sigma;
  model.exposure_target = exposure;
  return model;
}

}  // namespace

ModelFile load_model(const std::string& path, bool network) {
  ModelFile model;
  model.path = path;
  const auto kind = model_file_kind(path);
  if (kind == ModelFileKind::kNoiseSwitch) return load_noise_switch(path, network);
  LFNET_CHECK_AS(ConfigError, kind != ModelFileKind::kDictionary, "--model ", path,
                 " is a dictionary (for --method dict): give it as --dictionary");
  model.scripted = kind == ModelFileKind::kExported;
  if (model.scripted) {
    model.script = std::make_shared<nn::ScriptedNetwork>(nn::load_script(path));
    model.phi = model.script->meta.phi;
    model.config = model.script->meta.config;
    model.network = model.script->network;
    return model;
  }
  const auto ckpt = train::load_checkpoint(path);
  model.phi = ckpt.phi;
  model.config = ckpt.config;
  try {
    model.network = nn::NetworkOptions::from_file_json(ckpt.network, "$.network");
  } catch (const ConfigError& e) {
    throw CheckpointError(path + " has invalid network options: " + e.what());
  }
  if (network) model.net = train::build_net(ckpt, path);
  return model;
}

void ModelFile::check_cfa(const std::string& cfa) const {
  const auto& own = network.cfa;
  if (own == cfa) return;
  LFNET_CHECK_AS(ConfigError, !own.empty(), "model ", path,
                 " reconstructs grey sensor images; behind a colour filter array use pinv, "
                 "adjoint, no-parallax or a colour model (docs/reconstruction.md)");
  LFNET_CHECK_AS(ConfigError, !cfa.empty(), "model ", path,
                 " reconstructs colour sensor images behind a Bayer ", own, " filter: give --cfa ",
                 own);
  throw ConfigError("model " + path + " reconstructs colour sensor images behind a Bayer " + own +
                    " filter, not " + cfa);
}

void ModelFile::check_phi(const nlohmann::json& phi_spec) const {
  if (script) return nn::check_script_phi(*script, phi_spec);
  train::Checkpoint ckpt;
  ckpt.phi = phi;
  train::check_phi(ckpt, phi_spec, path);
}

nlohmann::json ModelFile::noise_switch_record() const {
  if (!noise_switch()) return nullptr;
  nlohmann::json j = {{"quiet", quiet_path}, {"noisy", noisy_path}, {"switch_sigma", switch_sigma}};
  if (exposure_target > 0) j["exposure_target"] = exposure_target;
  return j;
}

double ModelFile::measurement_mean() const {
  return config.contains("measurement_mean") ? config["measurement_mean"].get<double>() : 0.0;
}

ModelFile& ModelCache::model(const std::string& path) {
  auto it = models_.find(path);
  if (it == models_.end()) {
    it = models_.emplace(path, load_model(path, /*network=*/true)).first;
    ++loads_;
  }
  return it->second;
}

const dict::Dictionary& ModelCache::dictionary(const std::string& path) {
  auto it = dictionaries_.find(path);
  if (it == dictionaries_.end()) {
    const auto kind = model_file_kind(path);
    LFNET_CHECK_AS(
        ConfigError, kind != ModelFileKind::kCheckpoint && kind != ModelFileKind::kExported,
        "--dictionary ", path, " is ",
        kind == ModelFileKind::kCheckpoint ? "a network checkpoint" : "an exported network",
        ": give it as --model (with --method net, ae or cnn)");
    it = dictionaries_.emplace(path, dict::load_dictionary(path)).first;
    ++loads_;
  }
  return it->second;
}

void check_demosaic_argument(optics::Demosaic demosaic, bool cfa, bool network,
                             const std::string& method) {
  if (demosaic == optics::Demosaic::kBilinear) return;
  LFNET_CHECK_AS(ConfigError, cfa, "--demosaic ", optics::to_string(demosaic),
                 " needs a colour filter array (--cfa)");
  LFNET_CHECK_AS(ConfigError, !network, "--demosaic: method '", method,
                 "' reconstructs the colours itself (a colour net demosaics inside, by its "
                 "network.demosaic)");
}

std::optional<optics::ColourFilterArray> cfa_of_arguments(const std::string& cfa,
                                                          const std::string& phi) {
  const auto spec = !phi.empty() && phi_argument_is_file(phi) ? phi_from_argument(phi).to_json()
                                                              : nlohmann::json();
  return optics::resolve_cfa(cfa, spec);
}

bool phi_argument_is_file(const std::string& text) {
  std::error_code ec;
  return fs::path(text).extension() == ".json" || fs::exists(text, ec);
}

namespace {
nlohmann::json learned_code_at(const std::string& phi_argument, int hops);
}

nlohmann::json learned_code_of(const std::string& phi_argument) {
  return learned_code_at(phi_argument, 0);
}

namespace {

// learned_code_of, `hops` models away from the one asked about (a chain of models trained on
// one learned code is followed a few links, never round a cycle).
nlohmann::json learned_code_at(const std::string& phi_argument, int hops) {
  std::error_code ec;
  if (!fs::is_regular_file(phi_argument, ec) ||
      model_file_kind(phi_argument) != ModelFileKind::kCheckpoint) {
    return nullptr;
  }
  const auto ck = train::load_checkpoint(phi_argument);
  if (!ck.config.contains("code") || !ck.config["code"].is_object()) {
    // Trained on a code another model learned: this model carries the code's parameters
    // (written when it was trained), or else that model holds them.
    if (ck.training.code.contains("physical")) return ck.training.code["physical"];
    const auto from = ck.config.value("phi", nlohmann::json());
    if (hops < 4 && from.is_string() && from.get<std::string>() != phi_argument &&
        fs::is_regular_file(from.get<std::string>(), ec) &&
        fs::path(from.get<std::string>()).extension() == ".ckpt") {
      // Only if that model's camera is this one's, weight for weight.
      if (train::load_checkpoint(from.get<std::string>()).phi != ck.phi) return nullptr;
      auto code = learned_code_at(from.get<std::string>(), hops + 1);
      if (!code.is_null()) code["learned_by"] = from;
      return code;
    }
    return nullptr;
  }
  nn::LearnedPhiOptions options;
  {
    JsonReader r(ck.config["code"], phi_argument + ":$.config.code");
    read_fields(r, options);  // its training keys (lr, ...) are not the code's
  }
  const auto spec = optics::PhiSpec::from_json(ck.phi, phi_argument + ":$.phi");
  nn::LearnedPhi code(options, spec.n, spec.rows, spec.cols);
  train::load_code_state(code, ck.model, phi_argument, /*strict=*/true);
  auto out = code->physical();
  out["options"] = fields_to_json(options);
  out["phi_source"] = spec.params.value("source", "");
  return out;
}

}  // namespace

optics::PhiSpec phi_from_argument(const std::string& text, const std::string& option) {
  // A folder can only be a calibrated Phi: reading it says what is wrong with it.
  std::error_code ec;
  if (fs::is_directory(text, ec) || io::is_calibrated_phi(text)) {
    return io::read_calibrated_phi(text);
  }
  if (fs::path(text).extension() == ".json") {
    // A Phi spec, or a noise switch (a model, read below).
    const auto j = read_json_file(text);
    if (!j.is_object() || j.value("format", "") != kNoiseSwitchFormat) {
      return optics::PhiSpec::from_json(j, text + ":$");
    }
  }
  if (!fs::is_regular_file(text, ec)) {
    // A path (a folder or an extension in it) names a file that is not there, not a bad NAME.
    const fs::path p(text);
    LFNET_CHECK_AS(ConfigError, !p.has_parent_path() && !p.has_extension(), option, " ", text,
                   ": no such file (a Phi is NAME[:N], a Phi spec .json, a calibrated-Phi folder "
                   "or a model)");
    return optics::PhiSpec::parse(text);
  }
  ModelFile model;
  try {
    model = load_model(text, /*network=*/false);
  } catch (const Error& e) {
    throw ConfigError(option + " " + text +
                      ": neither NAME[:N], a Phi spec (.json) nor a model: " + e.what());
  }
  return optics::PhiSpec::from_json(model.phi, text + ":$.phi");
}

}  // namespace lfnet::pipeline

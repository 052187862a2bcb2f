// Trained model files (lfnet checkpoints, exported TorchScript files, dictionaries), loaded
// once and kept for many reconstructions.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/dict/dictionary.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/reconstruct.h"

namespace lfnet::pipeline {

// A trained model given as --model: an lfnet checkpoint or a file `lfnet export` wrote
// (told apart by content).
struct ModelFile {
  std::string path;
  bool scripted = false;  // an exported TorchScript file
  nlohmann::json phi;     // the Phi spec it was trained for
  nlohmann::json config;  // the resolved config of its training run
  nn::NetworkOptions network;
  nn::LightFieldNet net{nullptr};               // checkpoints (when the network was asked for)
  std::shared_ptr<nn::ScriptedNetwork> script;  // exported files
  // A noise switch (kNoiseSwitch, docs/models.md "One model for any noise"): two checkpoints of
  // the lfnet architecture for one Phi. `net` (the file `path` names first, its phi, config and
  // network are the model's) reconstructs sensor images whose noise sigma, told or estimated, is
  // below `switch_sigma`; `noisy` (from `noisy_path`) the others.
  nn::LightFieldNet noisy{nullptr};
  std::string quiet_path, noisy_path;
  double switch_sigma = 0;
  // A noise switch's exposure_target (recon::MethodResources::exposure_target; 0: none).
  double exposure_target = 0;
  bool noise_switch() const { return !noisy_path.empty(); }
  // What a record says of a noise switch: {"quiet", "noisy", "switch_sigma"}; null otherwise.
  nlohmann::json noise_switch_record() const;

  // Throws CheckpointError unless the model was trained for `phi_spec` (equal JSON).
  void check_phi(const nlohmann::json& phi_spec) const;
  // Throws ConfigError unless the model reconstructs sensor images behind the Bayer pattern
  // `cfa` (a colour net, network.cfa), or grey ones when `cfa` is empty.
  void check_cfa(const std::string& cfa) const;
  // The training measurement mean its config records, or 0.
  double measurement_mean() const;
};

// The Phi tensor a net of `options` takes (LightFieldNet::set_phi): the stack of patch
// matrices for the paper's architecture, the pixel weights of one period for lfnet's (a
// ConfigError for a Phi that is not local).
torch::Tensor phi_tensor(const optics::Phi& phi, const nn::NetworkOptions& options);

// What a model file is, by its content.
enum class ModelFileKind { kCheckpoint, kExported, kDictionary, kNoiseSwitch, kOther };

// The JSON file of a noise switch: its "format".
constexpr const char* kNoiseSwitchFormat = "lfnet-noise-switch";
ModelFileKind model_file_kind(const std::string& path);

// The files a model argument reads, for the inputs an output policy protects: the file itself
// and, for a noise switch, its two member checkpoints. Never throws: a path that cannot be read
// as a switch is itself alone (loading it says what is wrong).
std::vector<std::string> model_input_files(const std::string& path);

// Loads --model; `network`: build the checkpoint's network too (exported files always are).
// A dictionary given as a model is a ConfigError that says to give it as --dictionary.
ModelFile load_model(const std::string& path, bool network);

// Models and dictionaries loaded once for many reconstructions (lfnet batch, the evaluations
// of lfnet experiment), by path.
class ModelCache {
 public:
  ModelFile& model(const std::string& path);
  const dict::Dictionary& dictionary(const std::string& path);
  int64_t loads() const { return loads_; }  // files read so far

 private:
  std::map<std::string, ModelFile> models_;
  std::map<std::string, dict::Dictionary> dictionaries_;
  int64_t loads_ = 0;
};

// A Phi named on the command line: NAME[:N] (e.g. asp:2), a JSON file holding a spec, a
// calibrated-Phi folder (or its phi.json: a measured response, docs/acquisition.md), or a
// model file (an lfnet checkpoint or an exported model), whose Phi it takes: `--phi
// models/asp-n2.ckpt` simulates exactly the camera the model was trained for.
optics::PhiSpec phi_from_argument(const std::string& text, const std::string& option = "--phi");

// The colour filter array of a command: `--cfa` (`cfa`, empty for none) or the one a
// calibrated-Phi folder given as `--phi` names (docs/acquisition.md, "Calibrated Phi"); both
// must agree when both are given.
std::optional<optics::ColourFilterArray> cfa_of_arguments(const std::string& cfa,
                                                          const std::string& phi);

// --demosaic (`demosaic`) checked against the command: it demosaics the views of a method that
// reconstructs the mosaicked light field behind a colour filter array (`cfa`), so it needs one,
// and a network method (`network`, such as a colour net, which demosaics inside itself)
// refuses any but the default. ConfigErrors naming the option.
void check_demosaic_argument(optics::Demosaic demosaic, bool cfa, bool network,
                             const std::string& method);

// True when `text` names a file or folder (a spec, a calibrated Phi, a model) rather than
// NAME[:N].
bool phi_argument_is_file(const std::string& text);

// The learned code of a checkpoint trained with $.code (docs/training.md, "Learned codes") in
// its physical units, nn::LearnedPhiImpl::physical(): the transmittances of a mask or aperture,
// or each ASP pixel's grating (beta, gamma, alpha, depth), what a fabricated camera needs; with
// the code's options as "options". A model trained on a code another model learned (its config's
// $.phi names that checkpoint) gives that model's code. Null for anything else (a Phi name, a
// file without a code, a code whose learning model is not at hand).
nlohmann::json learned_code_of(const std::string& phi_argument);

}  // namespace lfnet::pipeline

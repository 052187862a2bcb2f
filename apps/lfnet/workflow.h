// Experiments: a JSON config that names the Phi, the data, the network, the training stages
// and the evaluations; shared by `lfnet train`, `lfnet experiment` and `lfnet evaluate`.
#pragma once

#include <nlohmann/json.hpp>

#include <unistd.h>

#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/light_field.h"
#include "lfnet/data/patch_dataset.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/dict/patch_sampling.h"
#include "lfnet/dist/communicator.h"
#include "lfnet/eval/evaluate.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/reconstruct.h"
#include "lfnet/train/trainer.h"

namespace lfnet::app {

// Light fields named in a config: real folders, scene specs and random scenes.
struct LightFieldSources {
  std::vector<std::string> light_fields;  // folders of sub-aperture images
  std::vector<std::string> scenes;        // scene spec files (configs/scenes)
  int64_t random_scenes = 0;              // procedural random scenes
  uint64_t random_seed = 1;               // seed of the first random scene
  nlohmann::json random_options = nlohmann::json::object();  // scene::RandomSceneOptions
  std::string views;                      // R0:R1,C0:C1 (1-based); "" = central U x V
  std::string orient;                     // angular reorientation of the folders on loading:
                                          // flip-u, flip-v, transpose (docs/conventions.md)

  void read(JsonReader& r);
  nlohmann::json to_json() const;
  bool empty() const { return light_fields.empty() && scenes.empty() && random_scenes == 0; }
};

// A named grey light field with its angular window applied.
struct NamedLightField {
  std::string name;
  LightField lf;
};

// Reads a light-field folder and reorients its angular axes (`orient`, parsed as `what`: an
// option or JSON path); warns once per folder when its horizontal and vertical parallax
// disagree in sign (docs/conventions.md).
LightField read_oriented(const std::string& dir, const std::string& orient,
                         const std::string& what);

// Loads every source as a grey light field of rows x cols views, with a progress bar. With
// `whole_grids`, folders without a `views` window keep every view (at least rows x cols), for
// a data set that draws its own angular windows.
std::vector<NamedLightField> load_sources(const LightFieldSources& sources, int64_t rows,
                                          int64_t cols, bool whole_grids = false);

// One training stage of an experiment.
struct StageConfig {
  std::string name;          // ae, cnn, joint, joint_scratch or dict (a K-SVD dictionary)
  nlohmann::json training = nlohmann::json::object();  // overrides of the common training options
};

// What to evaluate after training.
struct EvaluationConfig {
  LightFieldSources data;                       // held-out light fields
  std::vector<std::string> methods = {"net", "no-parallax"};
  std::vector<int64_t> strides = {5};
  std::vector<std::string> modes = {"sensor"};
  std::vector<double> noise = {0.0};
  std::string model_stage;  // stage whose model net/ae/cnn use ("" = the last)

  void read(JsonReader& r);
  nlohmann::json to_json() const;
};

// The resolved experiment config.
struct ExperimentConfig {
  std::string name = "experiment";
  std::string scale;  // the scale applied (its overrides are merged in)
  optics::PhiSpec phi;
  LightFieldSources train_data;
  data::DatasetOptions dataset;
  nn::NetworkOptions network;
  nlohmann::json training = nlohmann::json::object();  // common train::TrainerOptions
  std::vector<StageConfig> stages;
  // The dict stage: training patches and K-SVD ($.dictionary.sampling, $.dictionary.ksvd).
  dict::PatchSamplingOptions dictionary_sampling;
  dict::KsvdOptions dictionary_ksvd;
  EvaluationConfig evaluation;
  nlohmann::json raw;  // the config after merging the scale, as written to config.json

  // Reads a config file; `scale` picks one of its "scales" (merge patches) or, when empty,
  // its "default_scale".
  static ExperimentConfig load(const std::string& path, const std::string& scale = "");
  static ExperimentConfig from_json(const nlohmann::json& j, const std::string& source);

  // The trainer options of one stage: common options, then the stage's overrides.
  train::TrainerOptions stage_options(const StageConfig& stage) const;
  // The network options of a stage (branches ae, cnn or net).
  nn::NetworkOptions stage_network(const StageConfig& stage) const;
};

// Creates DIR (and DIR/models). An existing non-empty DIR is an error unless `force`.
void prepare_run_dir(const std::string& dir, bool force);

// Trains one stage; returns the path of its best checkpoint, copied to DIR/models/<stage>.ckpt.
// `init` (optional) starts from a checkpoint (finetuning, Phi switching); `resume` continues.
// With a communicator of several ranks (docs/distributed.md) only rank 0 reads checkpoints,
// logs and writes; the others receive its state when training starts.
std::string train_stage(const ExperimentConfig& config, const StageConfig& stage,
                        data::PatchDataset& dataset, const std::string& run_dir,
                        const std::string& init, const std::string& resume,
                        const std::string& command_line,
                        std::shared_ptr<dist::Communicator> comm = nullptr);

// Learns the dict stage's dictionary from the config's training light fields (K-SVD, with a
// progress line per iteration) and writes DIR/models/dict.ckpt; returns its path.
std::string train_dictionary_stage(const ExperimentConfig& config, const std::string& run_dir,
                                   const std::string& command_line);

// True for the stages that train a network (all but dict).
inline bool is_network_stage(const std::string& name) { return name != "dict"; }

// The dataset of a config.
std::unique_ptr<data::PatchDataset> make_dataset(const ExperimentConfig& config,
                                                 const optics::Phi& phi);

// Writes into a temporary sibling of `out`, then renames it into place, so `out` is never
// half-written. An existing non-empty `out` is an error unless `force`.
template <typename Writer>
void write_folder(const std::string& out, bool force, Writer&& write) {
  namespace fs = std::filesystem;
  fs::path target = fs::absolute(out).lexically_normal();
  if (target.filename().empty()) target = target.parent_path();
  std::error_code ec;
  const bool exists = fs::exists(target, ec);
  if (exists) {
    LFNET_CHECK_AS(ConfigError, fs::is_directory(target), "--out ", out,
                   " exists and is not a folder");
    LFNET_CHECK_AS(ConfigError, force || fs::is_empty(target), "--out ", out,
                   " exists and is not empty: choose another folder or pass --force to "
                   "replace it");
  }
  fs::create_directories(target.parent_path(), ec);
  const std::string tag = std::to_string(::getpid());
  const fs::path tmp = target.parent_path() / ("." + target.filename().string() + ".tmp" + tag);
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot create the output folder ", out, ": ", ec.message());
  try {
    write(tmp.string());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  fs::path old;
  if (exists) {
    old = target.parent_path() / ("." + target.filename().string() + ".old" + tag);
    fs::rename(target, old, ec);
    LFNET_CHECK_AS(IoError, !ec, "cannot replace ", out, ": ", ec.message());
  }
  fs::rename(tmp, target, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot move the result into ", out, ": ", ec.message());
  if (exists) fs::remove_all(old, ec);
}

// Appends one JSON record as a line to `path`.
void append_jsonl(const std::string& path, const nlohmann::json& record);

}  // namespace lfnet::app

namespace lfnet::app {

// A trained model given as --model: an lfnet checkpoint or a file `lfnet export` wrote
// (told apart by content).
struct ModelFile {
  std::string path;
  bool scripted = false;                        // an exported TorchScript file
  nlohmann::json phi;                           // the Phi spec it was trained for
  nlohmann::json config;                        // the resolved config of its training run
  nn::NetworkOptions network;
  nn::LightFieldNet net{nullptr};               // checkpoints (when the network was asked for)
  std::shared_ptr<nn::ScriptedNetwork> script;  // exported files

  // Throws CheckpointError unless the model was trained for `phi_spec` (equal JSON).
  void check_phi(const nlohmann::json& phi_spec) const;
  // The model's solver for method net, ae or cnn.
  recon::PatchSolver solver(const std::string& method) const;
  // The training measurement mean its config records, or 0.
  double measurement_mean() const;
};

// Loads --model; `network`: build the checkpoint's network too (exported files always are).
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

// What a method needs besides the measurements.
struct MethodContext {
  const optics::Phi* phi = nullptr;
  nn::LightFieldNet net{nullptr};  // for net, ae, cnn
  std::shared_ptr<nn::ScriptedNetwork> script;  // or an exported net (used when set)
  std::string dictionary;          // for dict: a dictionary file
  ModelCache* cache = nullptr;     // where to read it (and keep it) for many calls; none: read it each call
  std::string dict_method = "omp";  // for dict: omp or admm
};

// What `lfnet reconstruct` does for one acquisition.
struct ReconstructRequest {
  // An acquisition folder (sensor.json with sensor.tif or measurements.f32), or a camera's own
  // sensor image: one file of N channels per colour channel, comma-separated, with `phi`.
  std::string sensor;
  std::string phi;  // Phi spec for plain images: NAME[:N] or a JSON file ("" = the model's)
  std::string method = "net";
  std::string model;       // checkpoint for net, ae, cnn
  std::string dictionary;  // dictionary file for dict
  std::string dict_method = "omp";
  recon::ReconstructOptions options;  // stride (sensor mode), batch, window
  bool match_mean = false;            // scale the measurements to the training mean
  bool post_filter = false;           // suppress artefacts with the stride's period
  std::string device = "cpu";         // cpu or cuda[:K], for checkpoints' networks
  std::string cnn_mode = "patches";   // patches, or full (the CNN branch once, in tiles)
  int64_t tile = 128;                 // tile of cnn_mode full
  std::string precision = "float32";  // float32 or bfloat16 for the CNN branch
};

// A reconstruction and its record (method, model, sensor, stride, seconds, phi, mode, shape).
struct Reconstruction {
  LightField lf;
  nlohmann::json record;
};

// Reconstructs one acquisition. `progress` (optional) gets (patches done, patches in all);
// with a `cache`, the model or dictionary is read once and reused by later calls.
Reconstruction reconstruct_acquisition(const ReconstructRequest& request,
                                       const recon::ProgressCallback& progress = {},
                                       ModelCache* cache = nullptr);

// Writes a reconstruction as a light-field folder with previews and reconstruction.json.
void write_reconstruction(const Reconstruction& r, const std::string& out, bool force);

// The evaluation options of the command line: simulation mode, Gaussian noise sigma (0: none),
// noise seed, patch stride, solver batch, window stitching, and the model's patch size when
// there is a model (else the default 9 x 9).
eval::EvalOptions make_eval_options(const std::string& mode, double noise, uint64_t seed,
                                    int64_t stride, int64_t batch, bool window,
                                    const std::optional<nn::PatchShape>& patch);

// Evaluates `method` on one grey light field; the record names the light field and method.
// `show_progress` draws a progress bar over the patches.
nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, eval::EvalOptions options,
                               torch::Tensor* estimate = nullptr, bool show_progress = true);

}  // namespace lfnet::app

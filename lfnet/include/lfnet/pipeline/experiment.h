// Experiments: a JSON config that names the Phi, the data, the network, the training stages
// and the evaluations; scales merge named patches into it (docs/experiments.md).
#pragma once

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/data/patch_dataset.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/dict/patch_sampling.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/nn/learned_phi.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/train/trainer.h"

namespace lfnet::pipeline {

// One training stage of an experiment.
struct StageConfig {
  std::string name;  // ae, cnn, joint, joint_scratch or dict (a K-SVD dictionary)
  nlohmann::json training = nlohmann::json::object();  // overrides of the common training options
};

// What to evaluate after training.
struct EvaluationConfig {
  LightFieldSources data;  // held-out light fields
  std::vector<std::string> methods = {"net", "no-parallax"};
  // The methods' options, keyed by method name (as --method-options; docs/methods.md).
  nlohmann::json method_options = nlohmann::json::object();
  std::vector<int64_t> strides = {5};
  std::vector<optics::SimulationMode> modes = {optics::SimulationMode::kSensor};
  std::vector<double> noise = {0.0};
  std::string model_stage;  // stage whose model net/ae/cnn use ("" = the last)

  void read(JsonReader& r);
  nlohmann::json to_json() const;
};

// Distillation ($.distill, docs/training.md "Distillation"): every training crop's target is
// blended with a teacher's self-ensemble of the crop (recon::reconstruct_crops_mirrored), so
// a net learns in one pass what the teacher gives in several. Off while `teacher` is "".
struct DistillConfig {
  std::string teacher;  // an lfnet checkpoint of the lfnet architecture, for the config's Phi
  int64_t passes = 0;   // the teacher's mirror images (0: every one, as --self-ensemble)
  double weight = 1.0;  // the teacher's share of each target, in [0, 1]
  nn::Precision precision = nn::Precision::kFloat32;  // the teacher's U-Net arithmetic

  template <typename Fields>
  void fields(Fields& f) {
    f("teacher", teacher);
    f("passes", passes, Range::closed(0, 64));
    f("weight", weight);
    f("precision", precision);
  }
  bool enabled() const { return !teacher.empty(); }
  void read(JsonReader& r);
  nlohmann::json to_json() const;
};

// A code trained with the network ($.code, docs/training.md "Learned codes"): one object with
// the keys of nn::LearnedPhiOptions (family, period, max_depth, init, seed, init_spread) and of
// train::CodeTrainingOptions (lr, freeze_epochs, binarise). $.phi then gives only the code's N
// and views; the config's Phi becomes the code's start (a `calibrated` spec), and each model
// the run writes records the code it was trained with. `from` names a model that learned a code
// of the same family and shape: the code starts from that one instead (after $.init, whose own
// code it replaces), so a code learned with one network can go on with another.
struct CodeConfig {
  bool enabled = false;  // $.code is present
  std::string from;      // $.code.from: a checkpoint whose learned code starts this one
  nn::LearnedPhiOptions phi;
  train::CodeTrainingOptions training;

  void read(JsonReader& r);
  nlohmann::json to_json() const;
};

// Sets one value of a JSON config from `KEY.PATH=VALUE` (--set): VALUE is read as JSON (a
// number, true, a list, a quoted string...) and otherwise taken as a string; objects on the
// path are created. A malformed override is a ConfigError naming it.
void apply_override(nlohmann::json& config, const std::string& override_text);

// The resolved experiment config.
struct ExperimentConfig {
  std::string name = "experiment";
  std::string scale;  // the scale applied (its overrides are merged in)
  // $.init: the checkpoint the first stage starts from (warm start, widening, deepening,
  // switching the Phi: as `lfnet train --init`, which overrides it); "" starts from scratch.
  std::string init;
  optics::PhiSpec phi;
  LightFieldSources train_data;
  data::DatasetOptions dataset;
  nn::NetworkOptions network;
  nlohmann::json training = nlohmann::json::object();  // common train::TrainerOptions
  DistillConfig distill;                               // $.distill: off unless it names a teacher
  CodeConfig code;                                     // $.code: off unless present
  std::vector<StageConfig> stages;
  // The dict stage: training patches and K-SVD ($.dictionary.sampling, $.dictionary.ksvd).
  dict::PatchSamplingOptions dictionary_sampling;
  dict::KsvdOptions dictionary_ksvd;
  // How the dictionary codes patches by default ($.dictionary.coding), kept in its file.
  dict::SparseCodingOptions dictionary_coding;
  EvaluationConfig evaluation;
  nlohmann::json raw;  // the config after merging the scale, as written to config.json
  // The config file and each base it extends ($.extends), as load() read them; none for a run's
  // config.json (load_run).
  std::vector<std::string> files;

  // Reads a config file; `scale` picks one of its "scales" (merge patches) or, when empty,
  // its "default_scale". A config may extend another ($.extends: a path relative to it): the
  // base resolved at the same scale, then this file's keys, then this file's patch for the
  // scale (docs/experiments.md "Recipes"). `overrides` (KEY.PATH=VALUE, see apply_override)
  // apply last. A new run starts from the files it names ($.init, $.code.from): they must
  // exist.
  static ExperimentConfig load(const std::string& path, const std::string& scale = "",
                               const std::vector<std::string>& overrides = {});
  // The config file as load() reads it, merged ($.extends, the scale, `overrides`) but not
  // parsed: a config before the models it starts from, measures with or distils are made
  // (train --show-config, the recipes' scripts/models.py). `scale` is the one chosen.
  struct Merged {
    nlohmann::json j;
    std::string scale;
    std::vector<std::string> files;
  };
  static Merged merge(const std::string& path, const std::string& scale = "",
                      const std::vector<std::string>& overrides = {});
  // Reads the config.json of a run folder (the config as it was trained, scale merged).
  static ExperimentConfig load_run(const std::string& run_dir);
  static ExperimentConfig from_json(const nlohmann::json& j, const std::string& source);

  // The trainer options of one stage: common options, then the stage's overrides.
  train::TrainerOptions stage_options(const StageConfig& stage) const;
  // The network options of a stage (branches ae, cnn or net).
  nn::NetworkOptions stage_network(const StageConfig& stage) const;
};

}  // namespace lfnet::pipeline

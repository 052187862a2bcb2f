#include "lfnet/pipeline/run.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/runtime.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/sets.h"
#include "lfnet/pipeline/stages.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/train/checkpoint.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// Puts back a run that an interrupted --force had replaced (core/output.h,
// remove_stale_temporaries) before anything reads the folder.
void recover_run_folder(const std::string& dir) {
  if (dir.empty()) return;
  fs::path path = fs::absolute(dir).lexically_normal();
  if (path.filename().empty()) path = path.parent_path();
  if (remove_stale_temporaries(path)) {
    spdlog::warn(
        "{}: put back the run that an interrupted --force had replaced (the new run "
        "stopped before its first checkpoint)",
        dir);
  }
}

}  // namespace

void check_config_inputs(const ExperimentConfig& config) {
  check_sources(config.train_data, "$.data");
  check_not_held_out(config.train_data.light_fields, "$.data");
  check_sources(config.evaluation.data, "$.evaluation.data");
}

bool resumes_folder(const TrainRequest& request) {
  return !request.resume.empty() && fs::is_directory(request.resume);
}

ExperimentConfig resolve_request(const TrainRequest& r) {
  LFNET_CHECK_AS(ConfigError, r.resume.empty() || r.init.empty(),
                 "give --resume or --init, not both");
  LFNET_CHECK_AS(ConfigError, r.resume.empty() || fs::exists(r.resume), "--resume ", r.resume,
                 " does not exist: give a run folder or a stage's last.ckpt");
  LFNET_CHECK_AS(ConfigError, !(r.force && !r.resume.empty()),
                 "--force starts a run afresh and --resume continues one: give one of them");
  LFNET_CHECK_AS(ConfigError, r.init.empty() || fs::is_regular_file(r.init), "--init ", r.init,
                 " is not a file: give a checkpoint");
  ExperimentConfig config;
  if (resumes_folder(r)) {
    LFNET_CHECK_AS(ConfigError, r.config.empty(), "--resume ", r.resume,
                   " continues the run with the config it recorded (its config.json); give no "
                   "config file (",
                   r.config, "), or start a new run from it without --resume");
    LFNET_CHECK_AS(ConfigError, r.scale.empty() && r.set.empty(),
                   "--scale and --set apply to "
                   "a new run; a resumed run keeps the config in ",
                   r.resume, "/config.json");
    config = ExperimentConfig::load_run(r.resume);
    LFNET_CHECK_AS(ConfigError, r.out.empty() || fs::equivalent(r.out, r.resume), "--out ", r.out,
                   " differs from the run folder --resume ", r.resume, " continues");
  } else {
    LFNET_CHECK_AS(ConfigError, !r.config.empty() || r.resume.empty(), "--resume ", r.resume,
                   " is a checkpoint: it continues one stage of a run, so give the run's config "
                   "and --stage NAME too (or give the run folder to continue every stage)");
    LFNET_CHECK_AS(ConfigError, !r.config.empty(), "give a config file (or --resume RUN_FOLDER)");
    config = ExperimentConfig::load(r.config, r.scale, r.set);
  }
  if (!r.device.empty()) {
    parse_device(r.device);  // a clear error before any data is prepared
    config.training["device"] = r.device;
    config.raw["training"]["device"] = r.device;
  }
  // What the first stage starts from must be an lfnet checkpoint: said now, not after the data
  // is loaded.
  const std::string init = !r.init.empty() ? r.init : resumes_folder(r) ? "" : config.init;
  if (!init.empty()) {
    const auto kind = model_file_kind(init);
    LFNET_CHECK_AS(ConfigError, kind == ModelFileKind::kCheckpoint,
                   r.init.empty() ? "$.init " : "--init ", init, " is ",
                   kind == ModelFileKind::kExported     ? "an exported TorchScript file"
                   : kind == ModelFileKind::kDictionary ? "a dictionary"
                                                        : "not an lfnet checkpoint",
                   ": give a checkpoint (.ckpt) to start from");
  }
  bool found = r.stage.empty();
  for (const auto& s : config.stages) found |= s.name == r.stage;
  LFNET_CHECK_AS(ConfigError, found, r.config, " has no stage '", r.stage, "'");
  LFNET_CHECK_AS(ConfigError, r.resume.empty() || resumes_folder(r) || !r.stage.empty(),
                 "--resume CHECKPOINT continues one stage: name it with --stage (or give the "
                 "run folder to continue every stage)");
  LFNET_CHECK_AS(ConfigError, !config.train_data.empty(), r.config,
                 ": the config names no training data ($.data)");
  return config;
}

std::string run_folder(const TrainRequest& r, const ExperimentConfig& config) {
  if (resumes_folder(r)) return r.resume;
  return r.out.empty() ? "out/" + config.name : r.out;
}

namespace {

// lfnet train as a controller: check() resolves the config and its inputs and the run folder
// before any work; run() makes the folder, the training data (when a network stage is left)
// and trains each stage in turn, skipping those a resumed folder has done.
class Training {
 public:
  Training(const TrainRequest& request, std::shared_ptr<dist::Communicator> comm)
      : request_(request),
        comm_(comm ? std::move(comm) : std::make_shared<dist::LocalCommunicator>()),
        lead_(comm_->rank() == 0),
        continue_folder_(resumes_folder(request)),
        // Resuming one stage from its checkpoint writes into the folder that holds it.
        continue_in_place_(continue_folder_ || !request.resume.empty()) {}

  void check() {
    // Rank 0 owns the folder (another host's process ids mean nothing here).
    if (lead_ && continue_folder_) recover_run_folder(request_.resume);
    config_ = resolve_request(request_);
    check_config_inputs(config_);
    out_ = run_folder(request_, config_);
    if (lead_) recover_run_folder(out_);
    // An interrupted run in the way: say how to continue it, not only how to discard it (rank
    // 0 owns the folder; the launcher stops the others).
    LFNET_CHECK_AS(ConfigError,
                   !lead_ || continue_in_place_ || request_.force ||
                       !fs::is_regular_file(fs::path(out_) / "config.json"),
                   "--out ", out_,
                   " exists and is not empty: it holds a run (its config.json); continue it with "
                   "--resume ",
                   out_, " (no config file), or pass --force to start it afresh");
    for (const auto& s : config_.stages) {
      if (request_.stage.empty() || s.name == request_.stage) stages_.push_back(s);
    }
    resolved_ = config_.raw;
    resolved_["scale"] = config_.scale;
    resolved_["phi"] = config_.phi.to_json();  // the camera itself, not a path to it
  }

  TrainResult run() {
    if (lead_) make_folder();
    const auto phi = optics::make_phi(config_.phi);
    spdlog::info("{}: Phi {}, {} stage(s), output in {}{}", config_.name, config_.phi.label(),
                 stages_.size(), out_,
                 comm_->world_size() > 1
                     ? " (" + std::to_string(comm_->world_size()) + " data-parallel ranks)"
                     : "");
    if (lead_ && !continue_folder_) {
      write_json_file((fs::path(out_) / "config.json").string(), resolved_);
    }
    make_dataset_if_needed(*phi);
    std::string last;
    for (size_t i = 0; i < stages_.size(); ++i) last = train(i);
    saved();
    comm_->barrier();  // leave together: rank 0 hosts the rendezvous
    config_.raw = resolved_;
    return {config_, out_, last};
  }

 private:
  // Every file the run reads: the config and its bases, what it starts from, its data, its
  // teacher, and the model whose learned code it trains on or starts from.
  void make_folder() {
    OutputFolderPolicy policy;
    policy.force = request_.force;
    policy.inputs = config_.files;
    policy.inputs.insert(policy.inputs.end(), {request_.init, config_.init});
    const auto phi_file = config_.raw.value("phi", nlohmann::json());
    std::error_code ec;
    if (phi_file.is_string() && fs::exists(phi_file.get<std::string>(), ec)) {
      policy.inputs.push_back(phi_file.get<std::string>());
    }
    for (const auto& lf : config_.train_data.light_fields) policy.inputs.push_back(lf);
    if (config_.distill.enabled()) policy.inputs.push_back(config_.distill.teacher);
    if (config_.code.enabled) policy.inputs.push_back(config_.code.from);
    folder_ = std::make_unique<RunFolder>(out_, policy, continue_in_place_);
    fs::create_directories(fs::path(out_) / "models");
  }

  std::string model_of(const StageConfig& s) const {
    return (fs::path(out_) / "models" / (s.name + ".ckpt")).string();
  }
  std::string last_of(const StageConfig& s) const {
    return (fs::path(out_) / "models" / s.name / "last.ckpt").string();
  }
  bool done(const StageConfig& s) const { return continue_folder_ && fs::exists(model_of(s)); }

  // The patch dataset (simulated measurements) is built only when a network is trained; a
  // teacher that cannot teach fails before it is made.
  void make_dataset_if_needed(const optics::Phi& phi) {
    const bool networks = std::any_of(stages_.begin(), stages_.end(), [&](const StageConfig& s) {
      return is_network_stage(s.name) && !done(s);
    });
    if (!networks) return;
    if (config_.distill.enabled()) (void)load_teacher(config_);
    dataset_ = make_dataset(config_, phi);
    spdlog::info("{} training light fields; measurement mean {:.4f}", dataset_->light_fields(),
                 dataset_->measurement_mean());
  }

  void saved() {
    if (folder_) folder_->commit();
  }

  // Stage i: done before, the dictionary, or a network; returns its model file.
  std::string train(size_t i) {
    const auto& stage = stages_[i];
    if (done(stage)) {
      spdlog::info("stage {}: done ({})", stage.name, model_of(stage));
      return model_of(stage);
    }
    if (!is_network_stage(stage.name)) {
      LFNET_CHECK_AS(ConfigError,
                     (request_.resume.empty() || continue_folder_) && request_.init.empty(),
                     "--resume and --init apply to network stages, not to '", stage.name, "'");
      LFNET_CHECK_AS(ConfigError, comm_->world_size() == 1, "the '", stage.name,
                     "' stage does not train data-parallel: train it in one process (--stage ",
                     stage.name, ")");
      auto model = train_dictionary_stage(config_, out_, request_.command_line);
      saved();
      return model;
    }
    std::string resume = continue_folder_ ? "" : request_.resume;
    if (continue_folder_ && fs::exists(last_of(stage))) {
      resume = last_of(stage);
      spdlog::info("stage {}: resuming from {}", stage.name, resume);
    }
    // --init (else the config's $.init) applies to the first stage; later stages follow the
    // usual chain.
    const std::string init = request_.init.empty() ? config_.init : request_.init;
    auto model = train_stage(config_, stage, *dataset_, out_, i == 0 ? init : "", resume,
                             request_.command_line, comm_, [this] { saved(); });
    spdlog::info("stage {} done: {}", stage.name, model);
    return model;
  }

  const TrainRequest& request_;
  std::shared_ptr<dist::Communicator> comm_;
  const bool lead_;
  const bool continue_folder_, continue_in_place_;
  ExperimentConfig config_;
  std::string out_;
  std::vector<StageConfig> stages_;
  nlohmann::json resolved_;            // the config as the run records it
  std::unique_ptr<RunFolder> folder_;  // the other ranks write nothing
  std::unique_ptr<data::PatchDataset> dataset_;
};

}  // namespace

TrainResult train_experiment(const TrainRequest& request,
                             std::shared_ptr<dist::Communicator> comm) {
  Training training(request, std::move(comm));
  training.check();
  return training.run();
}

void evaluate_experiment(const ExperimentConfig& config, const std::string& out) {
  const auto& ev = config.evaluation;
  if (ev.data.empty()) {
    spdlog::warn("the config names no evaluation data ($.evaluation.data): nothing evaluated");
    return;
  }
  // net, ae and cnn use the last network stage's model (or model_stage); dict uses the dict
  // stage's dictionary.
  std::string model;
  for (const auto& s : config.stages) {
    if (is_network_stage(s.name)) model = (fs::path(out) / "models" / (s.name + ".ckpt")).string();
  }
  if (!ev.model_stage.empty()) {
    model = (fs::path(out) / "models" / (ev.model_stage + ".ckpt")).string();
  }
  // A learned code's camera is the one its model was trained with.
  auto spec = config.phi;
  std::optional<train::Checkpoint> checkpoint;
  if (!model.empty()) checkpoint = train::load_checkpoint(model);
  if (checkpoint && config.code.enabled) spec = optics::PhiSpec::from_json(checkpoint->phi);
  const auto phi = optics::make_phi(spec);
  MethodContext context;
  context.phi = phi.get();
  if (checkpoint) context.net = train::build_net(*checkpoint, model);
  const fs::path dictionary = fs::path(out) / "models" / "dict.ckpt";
  if (fs::exists(dictionary)) context.dictionary = dictionary.string();
  ModelCache cache;  // the dictionary is read once for every light field, stride, mode and noise
  context.cache = &cache;
  context.method_options = ev.method_options;
  const std::string results = (fs::path(out) / "results.jsonl").string();
  if (fs::exists(results)) {
    spdlog::info("evaluations: done ({})", results);
    return;
  }
  // A colour net is evaluated behind its colour filter array, on colour light fields.
  const bool colour = !config.network.cfa.empty();
  const auto truths =
      load_sources(ev.data, phi->rows(), phi->cols(), false, colour, false, phi->frames());
  std::string lines;  // results.jsonl appears whole, once every evaluation is done
  for (const auto& truth : truths) {
    for (const auto& method : ev.methods) {
      for (int64_t stride : ev.strides) {
        for (const auto& mode : ev.modes) {
          for (double noise : ev.noise) {
            // The net's patch grid: none for a whole-image architecture.
            const auto patch = config.network.patch_grid();
            const eval::EvalOptions defaults;
            auto o =
                make_eval_options(mode, noise, defaults.seed, stride, defaults.reconstruct.batch,
                                  defaults.reconstruct.window, patch);
            if (colour) o.cfa = optics::ColourFilterArray::bayer(config.network.cfa);
            auto record = evaluate_method(truth, method, context, o);
            record["experiment"] = config.name;
            record["scale"] = config.scale;
            const auto needs = recon::find_method(method).needs();
            record["model"] = needs == recon::MethodNeeds::kNetwork      ? model
                              : needs == recon::MethodNeeds::kDictionary ? context.dictionary
                                                                         : "";
            lines += record.dump() + "\n";
            // A whole-image network has no stride.
            const bool whole = record.value("whole_image", false);
            spdlog::info(
                "{:<12} {:<14} {} {:<9} noise {:.2f}: PSNR {:.2f} dB, SSIM {:.4f}, {:.2f} s",
                method, truth.name, whole ? "whole image" : "stride " + std::to_string(stride),
                optics::to_string(mode), noise,
                record["psnr_db"].is_null() ? INFINITY : record["psnr_db"].get<double>(),
                record["ssim"].get<double>(), record["seconds"].get<double>());
          }
        }
      }
    }
  }
  write_text_file(results, lines);
  spdlog::info("results in {}", results);
}

}  // namespace lfnet::pipeline

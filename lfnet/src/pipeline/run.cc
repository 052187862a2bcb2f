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

TrainResult train_experiment(const TrainRequest& request,
                             std::shared_ptr<dist::Communicator> comm) {
  if (!comm) comm = std::make_shared<dist::LocalCommunicator>();
  const bool lead = comm->rank() == 0;
  // Rank 0 owns the folder (another host's process ids mean nothing here).
  if (lead && resumes_folder(request)) recover_run_folder(request.resume);
  ExperimentConfig config = resolve_request(request);
  check_config_inputs(config);
  const std::string out = run_folder(request, config);
  if (lead) recover_run_folder(out);
  const bool continue_folder = resumes_folder(request);
  // Resuming one stage from its checkpoint writes into the folder that holds it.
  const bool continue_in_place = continue_folder || !request.resume.empty();
  // An interrupted run in the way: say how to continue it, not only how to discard it (rank 0
  // owns the folder; the launcher stops the others).
  LFNET_CHECK_AS(ConfigError,
                 !lead || continue_in_place || request.force ||
                     !fs::is_regular_file(fs::path(out) / "config.json"),
                 "--out ", out,
                 " exists and is not empty: it holds a run (its config.json); continue it with "
                 "--resume ",
                 out, " (no config file), or pass --force to start it afresh");
  std::vector<StageConfig> stages;
  for (const auto& s : config.stages) {
    if (request.stage.empty() || s.name == request.stage) stages.push_back(s);
  }
  nlohmann::json resolved = config.raw;
  resolved["scale"] = config.scale;
  resolved["phi"] = config.phi.to_json();  // the camera itself, not a path to it
  std::unique_ptr<RunFolder> folder;       // the other ranks write nothing
  if (lead) {
    OutputFolderPolicy policy;
    policy.force = request.force;
    // Every file the run reads: the config and its bases, what it starts from, its data, its
    // teacher, and the model whose learned code it trains on or starts from.
    policy.inputs = config.files;
    policy.inputs.insert(policy.inputs.end(), {request.init, config.init});
    const auto phi_file = config.raw.value("phi", nlohmann::json());
    std::error_code ec;
    if (phi_file.is_string() && fs::exists(phi_file.get<std::string>(), ec)) {
      policy.inputs.push_back(phi_file.get<std::string>());
    }
    for (const auto& lf : config.train_data.light_fields) policy.inputs.push_back(lf);
    if (config.distill.enabled()) policy.inputs.push_back(config.distill.teacher);
    if (config.code.enabled) policy.inputs.push_back(config.code.from);
    folder = std::make_unique<RunFolder>(out, policy, continue_in_place);
    fs::create_directories(fs::path(out) / "models");
  }
  const auto phi = optics::make_phi(config.phi);
  spdlog::info("{}: Phi {}, {} stage(s), output in {}{}", config.name, config.phi.label(),
               stages.size(), out,
               comm->world_size() > 1
                   ? " (" + std::to_string(comm->world_size()) + " data-parallel ranks)"
                   : "");
  auto model_of = [&](const StageConfig& s) {
    return (fs::path(out) / "models" / (s.name + ".ckpt")).string();
  };
  auto last_of = [&](const StageConfig& s) {
    return (fs::path(out) / "models" / s.name / "last.ckpt").string();
  };
  // The patch dataset (simulated measurements) is built only when a network is trained.
  std::unique_ptr<data::PatchDataset> dataset;
  const bool networks = std::any_of(stages.begin(), stages.end(), [&](const StageConfig& s) {
    return is_network_stage(s.name) && !(continue_folder && fs::exists(model_of(s)));
  });
  if (lead && !continue_folder) write_json_file((fs::path(out) / "config.json").string(), resolved);
  // A teacher that cannot teach fails before the training data are made.
  if (networks && config.distill.enabled()) (void)load_teacher(config);
  if (networks) dataset = make_dataset(config, *phi);
  if (dataset) {
    spdlog::info("{} training light fields; measurement mean {:.4f}", dataset->light_fields(),
                 dataset->measurement_mean());
  }
  auto saved = [&] {
    if (folder) folder->commit();
  };
  std::string last;
  for (size_t i = 0; i < stages.size(); ++i) {
    const auto& stage = stages[i];
    if (continue_folder && fs::exists(model_of(stage))) {
      spdlog::info("stage {}: done ({})", stage.name, model_of(stage));
      last = model_of(stage);
      continue;
    }
    if (!is_network_stage(stage.name)) {
      LFNET_CHECK_AS(ConfigError,
                     (request.resume.empty() || continue_folder) && request.init.empty(),
                     "--resume and --init apply to network stages, not to '", stage.name, "'");
      LFNET_CHECK_AS(ConfigError, comm->world_size() == 1, "the '", stage.name,
                     "' stage does not train data-parallel: train it in one process (--stage ",
                     stage.name, ")");
      last = train_dictionary_stage(config, out, request.command_line);
      saved();
      continue;
    }
    std::string resume = continue_folder ? "" : request.resume;
    if (continue_folder && fs::exists(last_of(stage))) {
      resume = last_of(stage);
      spdlog::info("stage {}: resuming from {}", stage.name, resume);
    }
    // --init (else the config's $.init) applies to the first stage; later stages follow the
    // usual chain.
    const std::string init = request.init.empty() ? config.init : request.init;
    last = train_stage(config, stage, *dataset, out, i == 0 ? init : "", resume,
                       request.command_line, comm, saved);
    spdlog::info("stage {} done: {}", stage.name, last);
  }
  saved();
  comm->barrier();  // leave together: rank 0 hosts the rendezvous
  config.raw = resolved;
  return {config, out, last};
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
  const auto truths = load_sources(ev.data, phi->rows(), phi->cols(), false, colour);
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

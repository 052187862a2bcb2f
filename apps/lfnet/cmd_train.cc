// lfnet train / lfnet experiment: train the stages of a config, then (experiment) evaluate.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "command.h"
#include "dist_flags.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/runtime.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/methods.h"
#include "lfnet/train/checkpoint.h"
#include "workflow.h"

namespace fs = std::filesystem;

namespace lfnet::app {

namespace {

struct TrainArgs {
  std::string config;
  std::string out;
  std::string scale;
  std::string resume;
  std::string init;
  std::string stage;  // train only this stage
  std::string device;  // overrides the config's training.device ("" keeps it)
  bool force = false;
  dist::DistOptions dist;  // train: data-parallel ranks (docs/distributed.md)
  bool check = false;  // read and check the config, then stop
};

std::string command_line_of(const TrainArgs& a, const std::string& verb) {
  std::string s = "lfnet " + verb + " " + a.config;
  if (!a.out.empty()) s += " --out " + a.out;
  if (!a.scale.empty()) s += " --scale " + a.scale;
  if (!a.resume.empty()) s += " --resume " + a.resume;
  if (!a.init.empty()) s += " --init " + a.init;
  if (!a.stage.empty()) s += " --stage " + a.stage;
  if (a.dist.world_size > 1) s += " --world-size " + std::to_string(a.dist.world_size);
  if (!a.device.empty()) s += " --device " + a.device;
  return s;
}

// Trains the selected stages; returns the config and the checkpoint of the last stage.
std::pair<ExperimentConfig, std::string> run_training(const TrainArgs& args,
                                                      const std::string& verb) {
  // Join the job first, so that a rank that cannot reach the others fails before loading data.
  auto comm = join_job(args.dist);
  const bool lead = comm->rank() == 0;
  ExperimentConfig config = ExperimentConfig::load(args.config, args.scale);
  if (!args.device.empty()) {
    parse_device(args.device);  // a clear error before any data is prepared
    config.training["device"] = args.device;
  }
  const std::string out = args.out.empty() ? "out/" + config.name : args.out;
  if (args.check) {
    for (const auto& s : config.stages) {
      if (is_network_stage(s.name)) (void)config.stage_network(s), (void)config.stage_options(s);
    }
    std::string names;
    for (const auto& s : config.stages) names += (names.empty() ? "" : ", ") + s.name;
    std::printf("%s: %s, scale '%s', Phi %s, stages %s; the config is valid\n",
                args.config.c_str(), config.name.c_str(), config.scale.c_str(),
                config.phi.label().c_str(), names.c_str());
    return {config, ""};
  }
  LFNET_CHECK_AS(ConfigError, args.resume.empty() || args.init.empty(),
                 "give --resume or --init, not both");
  std::vector<StageConfig> stages;
  for (const auto& s : config.stages) {
    if (args.stage.empty() || s.name == args.stage) stages.push_back(s);
  }
  LFNET_CHECK_AS(ConfigError, !stages.empty(), args.config, " has no stage '", args.stage, "'");
  LFNET_CHECK_AS(ConfigError, args.resume.empty() || stages.size() == 1,
                 "--resume continues one stage: name it with --stage");
  LFNET_CHECK_AS(ConfigError, !config.train_data.empty(), args.config,
                 ": the config names no training data ($.data)");
  // Resuming writes into the run folder it continues; anything else needs a fresh one.
  std::error_code ec;
  const bool fresh = !fs::exists(out, ec);
  nlohmann::json resolved = config.raw;
  resolved["scale"] = config.scale;
  if (lead) prepare_run_dir(out, args.force || !args.resume.empty());  // the other ranks write nothing
  const auto phi = optics::make_phi(config.phi);
  spdlog::info("{}: Phi {}, {} stage(s), output in {}{}", config.name, config.phi.label(),
               stages.size(), out,
               comm->world_size() > 1
                   ? " (" + std::to_string(comm->world_size()) + " data-parallel ranks)"
                   : "");
  // The patch dataset (simulated measurements) is built only when a network is trained.
  std::unique_ptr<data::PatchDataset> dataset;
  const bool networks = std::any_of(stages.begin(), stages.end(),
                                    [](const StageConfig& s) { return is_network_stage(s.name); });
  try {
    if (lead) write_json_file((fs::path(out) / "config.json").string(), resolved);
    if (networks) dataset = make_dataset(config, *phi);
  } catch (...) {
    // Nothing was trained: a run folder this command created goes again, so the same command
    // can be repeated once the data is fixed.
    if (fresh && lead) fs::remove_all(out, ec);
    throw;
  }
  if (dataset) {
    spdlog::info("{} training light fields; measurement mean {:.4f}", dataset->light_fields(),
                 dataset->measurement_mean());
  }
  std::string last;
  for (size_t i = 0; i < stages.size(); ++i) {
    if (!is_network_stage(stages[i].name)) {
      LFNET_CHECK_AS(ConfigError, args.resume.empty() && args.init.empty(),
                     "--resume and --init apply to network stages, not to '", stages[i].name, "'");
      LFNET_CHECK_AS(ConfigError, comm->world_size() == 1, "the '", stages[i].name,
                     "' stage does not train data-parallel: train it in one process (--stage ",
                     stages[i].name, ")");
      last = train_dictionary_stage(config, out, command_line_of(args, verb));
      continue;
    }
    // --init applies to the first stage trained; later stages follow the usual chain.
    last = train_stage(config, stages[i], *dataset, out, i == 0 ? args.init : "", args.resume,
                       command_line_of(args, verb), comm);
    spdlog::info("stage {} done: {}", stages[i].name, last);
  }
  comm->barrier();  // leave together: rank 0 hosts the rendezvous
  config.raw = resolved;
  return {config, last};
}

void add_train_args(CLI::App* cmd, TrainArgs& a) {
  cmd->add_option("config", a.config, "experiment config (JSON), e.g. configs/quickstart.json")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", a.out, "run folder (default out/<config name>)");
  cmd->add_option("--scale", a.scale, "config scale: quick or paper (default: the config's)");
  cmd->add_flag("--force", a.force, "write into an existing non-empty run folder");
  cmd->add_flag("--check", a.check, "only read and check the config (every stage), then stop");
  cmd->add_option("--device", a.device, "cpu or cuda[:K]: where to train (default: the config's training.device, cpu)");
}

}  // namespace

void add_train_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand("train", "Train the stages of a config (ae, cnn, joint, dict)");
  auto args = std::make_shared<TrainArgs>();
  add_train_args(cmd, *args);
  cmd->add_option("--resume", args->resume, "continue an interrupted stage from its last.ckpt");
  cmd->add_option("--init", args->init,
                  "start from a checkpoint: finetuning, or Phi switching when its Phi differs");
  cmd->add_option("--stage", args->stage, "train only this stage of the config");
  add_dist_flags(cmd, args->dist);
  cmd->callback([args] { run_training(*args, "train"); });
}

void add_experiment_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "experiment", "Train a config's stages, then run its evaluations into results.jsonl");
  auto args = std::make_shared<TrainArgs>();
  add_train_args(cmd, *args);
  cmd->add_option("--init", args->init, "start the first stage from a checkpoint");
  cmd->callback([args] {
    auto config = run_training(*args, "experiment").first;
    if (args->check) return;
    const std::string out = args->out.empty() ? "out/" + config.name : args->out;
    const auto& ev = config.evaluation;
    if (ev.data.empty()) {
      spdlog::warn("the config names no evaluation data ($.evaluation.data): nothing evaluated");
      return;
    }
    const auto phi = optics::make_phi(config.phi);
    MethodContext context;
    context.phi = phi.get();
    // net, ae and cnn use the last network stage's model (or model_stage); dict uses the
    // dict stage's dictionary.
    std::string model;
    for (const auto& s : config.stages) {
      if (is_network_stage(s.name)) model = (fs::path(out) / "models" / (s.name + ".ckpt")).string();
    }
    if (!ev.model_stage.empty()) model = (fs::path(out) / "models" / (ev.model_stage + ".ckpt")).string();
    if (!model.empty()) context.net = train::build_net(train::load_checkpoint(model), model);
    const fs::path dictionary = fs::path(out) / "models" / "dict.ckpt";
    if (fs::exists(dictionary)) context.dictionary = dictionary.string();
    ModelCache cache;  // the dictionary is read once for every light field, stride, mode and noise
    context.cache = &cache;
    const auto truths = load_sources(ev.data, phi->rows(), phi->cols());
    const std::string results = (fs::path(out) / "results.jsonl").string();
    for (const auto& truth : truths) {
      for (const auto& method : ev.methods) {
        for (int64_t stride : ev.strides) {
          for (const auto& mode : ev.modes) {
            for (double noise : ev.noise) {
              nn::PatchShape patch;
              patch.height = config.dataset.patch_h;
              patch.width = config.dataset.patch_w;
              const eval::EvalOptions defaults;
              const auto o = make_eval_options(mode, noise, defaults.seed, stride, defaults.reconstruct.batch,
                                               defaults.reconstruct.window, patch);
              auto record = evaluate_method(truth, method, context, o);
              record["experiment"] = config.name;
              record["scale"] = config.scale;
              record["model"] = recon::needs_network(method) ? model
                                : method == "dict"               ? context.dictionary
                                                                 : "";
              append_jsonl(results, record);
              spdlog::info("{:<12} {:<14} stride {} {:<9} noise {:.2f}: PSNR {:.2f} dB, SSIM {:.4f}, {:.2f} s",
                           method, truth.name, stride, mode, noise,
                           record["psnr_db"].is_null() ? INFINITY : record["psnr_db"].get<double>(),
                           record["ssim"].get<double>(), record["seconds"].get<double>());
            }
          }
        }
      }
    }
    spdlog::info("results in {}", results);
  });
}

}  // namespace lfnet::app

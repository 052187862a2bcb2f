// lfnet train / lfnet experiment: train the stages of a config, then (experiment) evaluate.
#include <cstdio>

#include "command.h"
#include "dist_flags.h"
#include "flags.h"
#include "lfnet/pipeline/run.h"
#include "lfnet/pipeline/stages.h"

namespace lfnet::app {

namespace {

struct TrainArgs {
  pipeline::TrainRequest request;
  pipeline::DistOptions dist;  // train: data-parallel ranks (docs/distributed.md)
  bool check = false;          // read and check the config, then stop
  bool show = false;           // print the resolved config as JSON, then stop
};

std::string command_line_of(const TrainArgs& a, const std::string& verb) {
  const auto& r = a.request;
  std::string s = "lfnet " + verb;
  if (!r.config.empty()) s += " " + r.config;
  if (!r.out.empty()) s += " --out " + r.out;
  if (!r.scale.empty()) s += " --scale " + r.scale;
  for (const auto& o : r.set) s += " --set " + o;
  if (!r.resume.empty()) s += " --resume " + r.resume;
  if (!r.init.empty()) s += " --init " + r.init;
  if (!r.stage.empty()) s += " --stage " + r.stage;
  if (a.dist.world_size > 1) s += " --world-size " + std::to_string(a.dist.world_size);
  if (!r.device.empty()) s += " --device " + r.device;
  return s;
}

// Prints what the config holds and that it is valid.
void check_config(const TrainArgs& a) {
  if (a.show) {
    // The config as the run would record it: bases, scale and --set merged in. A config's
    // inputs ($.init, ...) need not be made yet.
    const auto& r = a.request;
    nlohmann::json resolved;
    if (!r.config.empty() && r.resume.empty() && r.init.empty()) {
      const auto merged = pipeline::ExperimentConfig::merge(r.config, r.scale, r.set);
      resolved = merged.j;
      resolved["scale"] = merged.scale;
    } else {
      const auto config = pipeline::resolve_request(r);
      resolved = config.raw;
      resolved["scale"] = config.scale;
    }
    std::printf("%s\n", resolved.dump(2).c_str());
    return;
  }
  const auto config = pipeline::resolve_request(a.request);
  pipeline::check_config_inputs(config);
  std::string names;
  for (const auto& s : config.stages) {
    if (pipeline::is_network_stage(s.name))
      (void)config.stage_network(s), (void)config.stage_options(s);
    names += (names.empty() ? "" : ", ") + s.name;
  }
  std::string from;
  if (!a.request.init.empty() || !config.init.empty()) {
    from = ", starting from " + (a.request.init.empty() ? config.init : a.request.init);
  }
  if (config.distill.enabled()) from += ", distilled from " + config.distill.teacher;
  std::printf(
      "%s: %s, scale '%s', Phi %s, stages %s%s; the config is valid\n",
      (a.request.config.empty() ? a.request.resume + "/config.json" : a.request.config).c_str(),
      config.name.c_str(), config.scale.c_str(), config.phi.label().c_str(), names.c_str(),
      from.c_str());
}

void add_train_args(CLI::App* cmd, TrainArgs& a) {
  auto& r = a.request;
  input_path(
      cmd->add_option("config", r.config, "experiment config (JSON), e.g. configs/quickstart.json"))
      ->check(CLI::ExistingFile);
  output_folder(cmd->add_option("--out", r.out, "run folder (default out/<config name>)"));
  cmd->add_option("--scale", r.scale, "config scale: quick or paper (default: the config's)");
  cmd->add_option("--set", r.set,
                  "KEY.PATH=VALUE: override one config value (JSON-typed, repeatable), e.g. "
                  "--set training.epochs=1");
  run_folder(
      cmd->add_option("--resume", r.resume,
                      "continue an interrupted run: its run folder (every stage), or a stage's "
                      "last.ckpt with --stage"));
  add_force_flag(cmd, r.force);  // a run folder: the run starts afresh
  cmd->add_flag("--check", a.check, "only read and check the config (every stage), then stop");
  cmd->add_flag("--show-config", a.show,
                "print the resolved config (its bases, the scale and --set merged in) as JSON, "
                "then stop");
  add_device_option(cmd, r.device);
  input_path(
      cmd->add_option("--init", r.init,
                      "start the first stage from a checkpoint: finetuning, or Phi switching when "
                      "its Phi differs (overrides the config's $.init); a zoo model's name stands "
                      "for its file"))
      ->transform(zoo_model_file);
}

}  // namespace

void add_train_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand("train", "Train the stages of a config (ae, cnn, joint, dict)");
  auto args = std::make_shared<TrainArgs>();
  add_train_args(cmd, *args);
  cmd->add_option("--stage", args->request.stage, "train only this stage of the config");
  add_dist_flags(cmd, args->dist);
  cmd->callback([args] {
    if (args->check || args->show) return check_config(*args);
    auto comm = pipeline::join_job(args->dist);  // a rank that cannot reach the others fails first
    args->request.command_line = command_line_of(*args, "train");
    pipeline::train_experiment(args->request, comm);
  });
}

void add_experiment_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "experiment", "Train a config's stages, then run its evaluations into results.jsonl");
  auto args = std::make_shared<TrainArgs>();
  add_train_args(cmd, *args);
  cmd->callback([args] {
    if (args->check || args->show) return check_config(*args);
    args->request.command_line = command_line_of(*args, "experiment");
    const auto run = pipeline::train_experiment(args->request);
    pipeline::evaluate_experiment(run.config, run.out);
  });
}

}  // namespace lfnet::app

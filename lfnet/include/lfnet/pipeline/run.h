// Running an experiment: train its stages into a run folder (fresh, afresh with force, or
// continued from where an interrupted run stopped), then evaluate it (docs/experiments.md).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "lfnet/dist/communicator.h"
#include "lfnet/pipeline/experiment.h"

namespace lfnet::pipeline {

// What `lfnet train` and `lfnet experiment` were asked to do.
struct TrainRequest {
  std::string config;            // config file ("" when resuming a run folder: its config)
  std::string scale;             // "" = the config's default_scale
  std::vector<std::string> set;  // KEY.PATH=VALUE overrides (apply_override)
  std::string out;               // run folder ("" = out/<config name>)
  std::string resume;            // a stage's last.ckpt (with stage), or a run folder
  std::string init;              // first stage starts from this checkpoint
  std::string stage;             // train only this stage ("" = all)
  std::string device;            // overrides training.device ("" keeps it)
  bool force = false;            // replace an existing run folder (start afresh)
  std::string command_line;      // recorded in checkpoints
};

// The config a request trains (the run folder's own config when it resumes a folder), with
// every check that needs no data: stage names, option values, --resume/--init combinations.
ExperimentConfig resolve_request(const TrainRequest& request);

// The run folder a request writes.
std::string run_folder(const TrainRequest& request, const ExperimentConfig& config);

// True when `resume` names a run folder (rather than a checkpoint file).
bool resumes_folder(const TrainRequest& request);

// Checks every input a run of `config` will read, before any work: the training and evaluation
// light-field folders (complete grids) and scene files (pipeline::check_sources).
void check_config_inputs(const ExperimentConfig& config);

struct TrainResult {
  ExperimentConfig config;
  std::string out;   // the run folder
  std::string last;  // the last stage's model
};

// Trains the requested stages. Resuming a run folder skips the stages whose model exists and
// continues a stage from its last.ckpt. A run that fails before its first checkpoint leaves
// nothing behind (an existing folder replaced with force comes back). With several ranks only
// rank 0 writes (docs/distributed.md).
TrainResult train_experiment(const TrainRequest& request,
                             std::shared_ptr<dist::Communicator> comm = nullptr);

// Runs the config's evaluations on the run's models, appending to OUT/results.jsonl.
void evaluate_experiment(const ExperimentConfig& config, const std::string& out);

}  // namespace lfnet::pipeline

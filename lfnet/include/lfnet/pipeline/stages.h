// Training the stages of an experiment into a run folder: networks (ae, cnn, joint) and the
// K-SVD dictionary, with the stage-chaining policy (joint starts from ae and cnn).
#pragma once

#include <nlohmann/json.hpp>

#include <functional>
#include <memory>
#include <string>

#include "lfnet/data/patch_dataset.h"
#include "lfnet/dist/communicator.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/experiment.h"

namespace lfnet::pipeline {

// Trains one stage; returns the path of its best checkpoint, copied to DIR/models/<stage>.ckpt.
// `init` (optional) starts from a checkpoint (finetuning, Phi switching); `resume` continues.
// With a communicator of several ranks (docs/distributed.md) only rank 0 reads checkpoints,
// logs and writes; the others receive its state when training starts. `on_saved` (optional)
// is called after every epoch's checkpoint.
std::string train_stage(const ExperimentConfig& config, const StageConfig& stage,
                        data::PatchDataset& dataset, const std::string& run_dir,
                        const std::string& init, const std::string& resume,
                        const std::string& command_line,
                        std::shared_ptr<dist::Communicator> comm = nullptr,
                        const std::function<void()>& on_saved = {});

// Learns the dict stage's dictionary from the config's training light fields (K-SVD, with a
// progress line per iteration) and writes DIR/models/dict.ckpt; returns its path.
std::string train_dictionary_stage(const ExperimentConfig& config, const std::string& run_dir,
                                   const std::string& command_line);

// True for the stages that train a network (all but dict).
inline bool is_network_stage(const std::string& name) { return name != "dict"; }

// The teacher of $.distill (DistillConfig), on `device`, in its precision: a ConfigError unless
// it is an lfnet checkpoint of the lfnet architecture for the config's Phi.
nn::LightFieldNet load_teacher(const ExperimentConfig& config, const std::string& device = "cpu");

// The dataset of a config.
std::unique_ptr<data::PatchDataset> make_dataset(const ExperimentConfig& config,
                                                 const optics::Phi& phi);

// Appends one JSON record as a line to `path`.
void append_jsonl(const std::string& path, const nlohmann::json& record);

}  // namespace lfnet::pipeline

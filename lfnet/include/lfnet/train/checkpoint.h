// Checkpoints (STYLE item 6): one self-checking file with everything needed to rebuild, use,
// resume or finetune a network: format version, resolved config, network options, Phi spec,
// command line, model state by registered names, Adam state and training state.
//
// File layout (little-endian), see docs/training.md:
//   "LFNETCKP" | u32 format version | u64 header length | header JSON | tensor payload |
//   u64 payload length | u64 FNV-1a checksum of everything before it | "LFNETEND"
// Tensors are raw float32/float64/int64/int32/uint8 arrays; mostly-zero ones (the Phi stack of
// a per-pixel Phi has 1 / (h w) non-zeros) are stored as flat indices and values.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "lfnet/nn/learned_phi.h"
#include "lfnet/nn/network.h"

namespace lfnet::train {

// Bumped whenever the layout or the meaning of a stored field changes.
constexpr uint32_t kCheckpointFormatVersion = 1;

using TensorMap = std::map<std::string, torch::Tensor>;

// The names a learned code's parameters and Adam moments have in a checkpoint (Trainer::set_code):
// "code." then the code module's own names. Nets leave them out (check_architecture).
constexpr const char* kCodePrefix = "code.";

// Where training stands; saved with every checkpoint.
struct TrainingState {
  std::string stage;                                              // ae, cnn or joint
  int64_t epoch = 0;                                              // epochs completed
  int64_t step = 0;                                               // optimizer steps taken
  double best_metric = -std::numeric_limits<double>::infinity();  // best validation PSNR, dB
  int64_t best_epoch = 0;  // the epoch that reached best_metric (0: none yet)
  nlohmann::json history = nlohmann::json::array();  // one EpochRecord (JSON) per epoch
  nlohmann::json origin = nlohmann::json::object();  // what the weights were initialised from
  // A learned code's events (Trainer::set_code): {"binarised": {"epoch", "continuous_psnr_db",
  // "binary_psnr_db"}} once the code was rounded to 0 or 1.
  nlohmann::json code = nlohmann::json::object();
  torch::Tensor rng_state;  // LibTorch's default CPU generator (uint8), may be undefined

  nlohmann::json to_json() const;  // everything but rng_state
  static TrainingState from_json(const nlohmann::json& j);
};

// The contents of one checkpoint file.
struct Checkpoint {
  uint32_t format_version = kCheckpointFormatVersion;
  nlohmann::json config = nlohmann::json::object();   // the resolved config of the run
  nlohmann::json network = nlohmann::json::object();  // nn::NetworkOptions::to_json()
  nlohmann::json phi = nlohmann::json::object();      // the Phi spec the net was trained for
  std::string command_line;
  TensorMap model;      // registered names -> parameters and buffers
  TensorMap optimizer;  // "<parameter>/exp_avg", "<parameter>/exp_avg_sq", "<parameter>/step"
  nlohmann::json optimizer_options = nlohmann::json::object();  // {"type": "adam", ...}
  TrainingState training;
};

// Writes atomically: a temporary file in the same folder, fsync, rename, fsync of the folder.
// An existing file at `path` stays intact until the new one is complete. IoError on failure.
void save_checkpoint(const Checkpoint& checkpoint, const std::string& path);

// Reads and verifies a checkpoint. A missing file is an IoError; a foreign, truncated or
// corrupted file or another format version is a CheckpointError that says which.
Checkpoint load_checkpoint(const std::string& path);

// Parameters and buffers of a module by registered name: detached contiguous CPU copies.
TensorMap module_state(const torch::nn::Module& module);

// Throws CheckpointError when `state` does not fit `net` name for name and shape (the Phi
// buffers phi, adjoint_scale and base may have another number of phases). `what` names the
// checkpoint in the message.
void check_architecture(const nn::LightFieldNet& net, const TensorMap& state,
                        const std::string& what);

// Copies `state` into `net` after check_architecture: the Phi buffers through set_phi, then
// every tensor bit for bit.
void load_net_state(nn::LightFieldNet& net, const TensorMap& state, const std::string& what);

// Copies a learned code's parameters from a checkpoint's model state (their names under
// kCodePrefix) into `code`; returns the names copied (with the prefix). A parameter the state
// lacks, or holds in another shape, is a CheckpointError naming `what` when `strict`, and is
// left as it is otherwise.
std::vector<std::string> load_code_state(nn::LearnedPhi& code, const TensorMap& state,
                                         const std::string& what, bool strict);

// The network a checkpoint holds, rebuilt from its network options and loaded.
nn::LightFieldNet build_net(const Checkpoint& checkpoint, const std::string& what = "checkpoint");

// Throws CheckpointError unless the checkpoint was trained for `phi_spec` (equal JSON).
void check_phi(const Checkpoint& checkpoint, const nlohmann::json& phi_spec,
               const std::string& what = "checkpoint");

}  // namespace lfnet::train

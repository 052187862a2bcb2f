// The training loop (docs/training.md, STYLE item 7): Adam with a learning-rate schedule,
// validation PSNR every epoch, last/best checkpoints, exact resume, finetuning with Phi
// switching, and detection of non-finite numbers. Logging plugs in through hooks.
#pragma once

#include <torch/optim/adam.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/dist/communicator.h"
#include "lfnet/nn/learned_phi.h"
#include "lfnet/nn/loss.h"
#include "lfnet/nn/network.h"
#include "lfnet/train/batch_source.h"
#include "lfnet/train/checkpoint.h"

namespace lfnet::train {

// The closed sets of the trainer's options, read and written by name (core/enum_names.h).
enum class Stage { kAe, kCnn, kJoint };                 // "ae", "cnn", "joint"
enum class ScheduleKind { kConstant, kStep, kCosine };  // "constant", "step", "cosine"
enum class OnNonFinite { kStop, kSkip };                // "stop", "skip"
std::string to_string(Stage value);
std::string to_string(ScheduleKind value);
std::string to_string(OnNonFinite value);
Stage from_string(const std::string& name, Stage);
ScheduleKind from_string(const std::string& name, ScheduleKind);
OnNonFinite from_string(const std::string& name, OnNonFinite);
// The branches a stage trains: ae, cnn, or both (net) for joint.
nn::Branches branches_of_stage(Stage stage);

// The learning-rate schedule: a factor on TrainerOptions::lr per step.
struct LrScheduleOptions {
  ScheduleKind name = ScheduleKind::kCosine;  // constant, step or cosine (evaluated every step)
  int64_t step_epochs = 20;                   // step: multiply by gamma every step_epochs epochs
  double gamma = 0.1;                         // step: the factor
  double min_factor = 0.01;                   // cosine: the last learning rate as a fraction of lr
  int64_t warmup_epochs = 0;  // linear warm-up from lr / steps over this many epochs

  template <typename Fields>
  void fields(Fields& f) {
    f("name", name);
    f("step_epochs", step_epochs, Range::closed(1, 1e6));
    f("gamma", gamma, Range::above(0, 10));
    f("min_factor", min_factor);
    f("warmup_epochs", warmup_epochs, Range::closed(0, 1e6));
  }
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate() const;  // ConfigError naming the field
};

// Everything the Trainer does, with strict JSON (TrainerOptions::from_json).
struct TrainerOptions {
  Stage stage = Stage::kJoint;  // ae, cnn or joint: must match the net's branches (ae, cnn, net)
  int64_t epochs = 60;          // total epochs (the paper: about 60)
  int64_t batch_size = 64;      // patches per step
  // Adam. The paper used 1e-5 in Caffe; 1e-3 with the cosine decay converges within a CPU
  // budget of a few epochs (docs/training.md).
  double lr = 1e-3;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-8;
  double weight_decay = 0.0;  // L2 penalty added to the gradient (torch's Adam)
  LrScheduleOptions schedule;
  nn::LossOptions loss;         // weighted_l2 by default (the paper's)
  double clip_grad_norm = 0.0;  // clip the global gradient norm to this (0: off)
  // What a non-finite loss or gradient does: "stop" throws NumericalError; "skip" drops the
  // batch, at most max_skipped_batches per epoch. Diverged weights always stop.
  OnNonFinite on_nonfinite = OnNonFinite::kStop;
  int64_t max_skipped_batches = 10;
  // last.ckpt (everything, for resume) is written after every epoch, best.ckpt (the model of
  // the best validation PSNR, without Adam moments) whenever it improves; "" writes none.
  std::string out_dir;
  bool progress = true;  // a progress bar with ETA and loss on stderr
  // Where the net trains: "cpu" or "cuda[:K]" (lfnet::parse_device). Batches are moved there;
  // checkpoints always hold CPU tensors, so a run resumes on either.
  std::string device = "cpu";
  // The arithmetic the model is trained for: bfloat16 rounds its reduced-precision layers as a
  // --precision bfloat16 run does, in the forward pass of training and validation, with float32
  // weights (nn::emulate_precision; docs/performance.md, "Training for bfloat16").
  nn::Precision precision = nn::Precision::kFloat32;

  template <typename Fields>
  void fields(Fields& f) {
    f("stage", stage);
    f("epochs", epochs, Range::closed(1, 1e6));
    f("batch_size", batch_size, Range::closed(1, 1e6));
    // Up to 1e12: rates far too large are how divergence handling is exercised.
    f("lr", lr, Range::above(0, 1e12));
    f("beta1", beta1);
    f("beta2", beta2);
    f("eps", eps, Range::above(0, 1));
    f("weight_decay", weight_decay, Range::closed(0, 1));
    f("schedule", schedule);
    f("loss", loss);
    f("clip_grad_norm", clip_grad_norm, Range::closed(0, 1e6));
    f("on_nonfinite", on_nonfinite);
    f("max_skipped_batches", max_skipped_batches, Range::closed(0, 1e9));
    f("out_dir", out_dir);
    f("progress", progress);
    f("device", device);
    f("precision", precision);
  }
  static TrainerOptions from_json(const nlohmann::json& j, const std::string& path = "$");
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate() const;  // ConfigError naming the field
};

// Training a code with the net (Trainer::set_code, docs/training.md "Learned codes"): the code's
// own Adam, its learning rate following the net's schedule, and what happens at the end.
struct CodeTrainingOptions {
  double lr = 0.01;           // the code's Adam learning rate (times the schedule's factor)
  int64_t freeze_epochs = 0;  // the last epochs hold the code fixed, so the net settles on it
  // mask and aperture: the code held fixed is rounded to 0 or 1 (binarised_weights), the code
  // a binary mask prints; needs freeze_epochs >= 1. Its cost is measured when it happens.
  bool binarise = false;
  // With binarise: the epochs before the freeze in which the code learns through its rounding
  // (LearnedPhiImpl::straight_through_weights): the net sees the binary code, the code's
  // transmittances get its gradient.
  int64_t straight_through_epochs = 0;

  template <typename Fields>
  void fields(Fields& f) {
    f("lr", lr, Range::above(0, 10));
    f("freeze_epochs", freeze_epochs, Range::closed(0, 1e6));
    f("binarise", binarise);
    f("straight_through_epochs", straight_through_epochs, Range::closed(0, 1e6));
  }
  void validate(int64_t epochs) const;  // ConfigError naming the field
};

// The learning rate at batch `batch` of epoch `epoch` (0-based) of `batches` per epoch. A pure
// function of its arguments, so resumed runs follow the same schedule.
double learning_rate(const TrainerOptions& options, int64_t epoch, int64_t batch, int64_t batches);

// One completed epoch, given to the on_epoch hook and kept in the checkpoint's history.
struct EpochRecord {
  int64_t epoch = 0;         // 1-based
  int64_t step = 0;          // optimizer steps so far
  double lr = 0;             // learning rate at the epoch's last step
  double train_loss = 0;     // mean loss over the epoch's trained batches
  double val_loss = 0;       // loss over the validation set
  double val_psnr_db = 0;    // PSNR of the validation patches, predictions clipped to [0, 1]
  double seconds = 0;        // wall time of the epoch, validation included
  double patches_per_s = 0;  // training throughput (forward, backward and step)
  // Of the epoch's training time, the seconds spent in the steps' collectives (the gradients'
  // and the loss's all-reduce, waiting for the slowest rank included); 0 on one process.
  double communication_s = 0;
  int64_t skipped_batches = 0;  // batches dropped for non-finite numbers
  bool best = false;            // a new best validation PSNR (written to best.ckpt)

  nlohmann::json to_json() const;
  static EpochRecord from_json(const nlohmann::json& j);
};

// One optimizer step, for the on_step hook.
struct StepRecord {
  int64_t epoch = 0;  // 1-based
  int64_t batch = 0;  // 0-based within the epoch
  int64_t step = 0;   // optimizer steps so far
  double loss = 0;
  double lr = 0;
};

// Validation loss and PSNR.
struct Evaluation {
  double loss = 0;
  double psnr_db = 0;
  int64_t patches = 0;
};

class Trainer;

// What fit() does around the optimizer steps, each part replaceable. An empty function keeps
// the default, named beside it; the defaults are what TrainerOptions describes.
struct TrainerHooks {
  // The learning rate of batch `batch` (0-based) of epoch `epoch` (0-based) of `batches`.
  // Default: learning_rate(options, ...). It must be a pure function of its arguments so that a
  // resumed run follows the same schedule.
  std::function<double(int64_t epoch, int64_t batch, int64_t batches)> schedule;
  // The validation of each epoch, whose PSNR picks the best epoch. Default:
  // Trainer::evaluate(source), the source's validation batches. It runs on every rank and must
  // return the same numbers on each.
  std::function<Evaluation(Trainer&, BatchSource&)> validate;
  // Saving after each epoch (only rank 0 calls it), after the record is complete and the
  // training state holds the epoch. Default: Trainer::save_checkpoints, last.ckpt always and
  // best.ckpt when the record is a new best, in options.out_dir ("" writes nothing).
  std::function<void(Trainer&, const EpochRecord&)> save;
  std::function<void(const EpochRecord&)> on_epoch;  // after each epoch's checkpoints
  std::function<void(const StepRecord&)> on_step;    // after each optimizer step
  std::function<bool()> stop_requested;              // checked after each epoch
};

// What the run is, stored in every checkpoint it writes.
struct RunInfo {
  nlohmann::json config = nlohmann::json::object();  // the resolved config of the run
  nlohmann::json phi = nlohmann::json::object();     // the Phi spec of the measurements
  std::string command_line;
};

// What initialising from a checkpoint did, parameter by parameter.
struct InitReport {
  std::vector<std::string> copied;         // taken as they were
  std::vector<std::string> mapped;         // carried over to the new Phi (ae.fc1.weight)
  std::vector<std::string> widened;        // a narrower U-Net's layer in a wider one's
  std::vector<std::string> deepened;       // set so a deeper U-Net's new levels add nothing
  std::vector<std::string> reinitialised;  // left at their fresh initialisation
  nlohmann::json to_json() const;
};

// train --init's start of `net` from a checkpoint's tensors `model` (its network and Phi in
// `from`) for the parameters whose names start with `prefix`: each is taken the way the net's
// architecture says (nn::NetworkArchitecture::warm_start), then finish_warm_start adjusts what
// it started. Throws CheckpointError naming `what` for a tensor of another shape. The caller
// checks that something was taken.
InitReport warm_start_net(nn::LightFieldNetImpl& net, const TensorMap& model,
                          const nn::WarmStartSource& from, const std::string& prefix,
                          const std::string& what);

// Trains one LightFieldNet for one stage; owns its Adam optimizer and training state.
class Trainer {
 public:
  // `net` must already hold the Phi of the measurements (set_phi).
  Trainer(nn::LightFieldNet net, TrainerOptions options, RunInfo run);

  // Trains `code` with the net (lfnet architecture, one process): every batch is measured again
  // by the code's current weights inside the graph (train/joint_phi.h), the code takes its own
  // Adam steps, and the last options.freeze_epochs epochs hold it fixed. Checkpoints then record
  // the code: its parameters and Adam moments under kCodePrefix, and as their Phi the code's
  // `calibrated` spec, for which the net's Phi buffers are set. Call before resume or
  // init_from.
  void set_code(nn::LearnedPhi code, CodeTrainingOptions options);
  nn::LearnedPhi code() const { return code_; }
  // The code's weights (N, U, V, T, T) as the net uses them now: fixed (perhaps binarised) in
  // the freeze epochs, else the code's current weights. Undefined without a code.
  torch::Tensor code_weights() const;
  // The `calibrated` Phi of code_weights(): what checkpoints record as the model's Phi.
  optics::PhiSpec code_phi_spec() const;

  // Continues an interrupted run from `path` (usually last.ckpt): weights, Adam moments,
  // schedule position, RNG and history. The architecture, Phi and stage must match (with a
  // learned code, the code's options instead of the Phi); anything else is a CheckpointError.
  void resume(const std::string& path);

  // Finetuning: starts from the weights of any checkpoint (another stage, another Phi) with a
  // fresh optimizer and history. Only parameters whose names start with `prefix` are taken
  // ("ae." or "cnn." to take one branch). The net keeps its own Phi; when the checkpoint's Phi
  // differs, ae.fc1.weight (which reads measurements) is mapped to the new Phi when both Phis
  // have one phase, and re-initialised otherwise (docs/training.md). A narrower lfnet U-Net of
  // the same depth is embedded in a wider one (nn::embed_narrow_parameter), so the wider net
  // starts from what the narrow one computed; a shallower one starts a deeper one the same way
  // (ImageNetImpl::start_new_levels). Other shape mismatches are a CheckpointError.
  InitReport init_from(const std::string& path, const std::string& prefix = "");

  // The code's start from a model that learned a code of the same family and shape (after
  // init_from, whose own code it replaces), with a fresh Adam for the code. Returns the code's
  // parameters taken; anything missing or of another shape is a CheckpointError. Needs set_code.
  std::vector<std::string> init_code_from(const std::string& path);

  // The joint stage's start: the autoencoder from one checkpoint, the CNN from another.
  InitReport init_branches(const std::string& ae_path, const std::string& cnn_path);

  // Trains until options.epochs epochs are complete (or stop_requested). Returns the records
  // of the epochs it ran. Throws NumericalError on non-finite numbers (per on_nonfinite); the
  // last checkpoint written stays intact.
  std::vector<EpochRecord> fit(BatchSource& source, const TrainerHooks& hooks = {});

  // Loss and PSNR on the source's validation batches (shared out among the ranks, then
  // summed: every rank receives the whole set's numbers).
  Evaluation evaluate(BatchSource& source);

  // Data-parallel training (docs/distributed.md). options.batch_size stays the global batch:
  // fit() asks the source for this rank's part of each batch (BatchSource::set_shard), sums
  // the gradients of all ranks and divides by the global batch, so W ranks take the steps one
  // process would take. When fit() starts, rank 0's weights, Adam moments and training
  // position are sent to every rank, so only rank 0 needs to resume or initialise. Only rank 0
  // writes checkpoints and shows progress; the hooks run on every rank with global numbers.
  void set_communicator(std::shared_ptr<dist::Communicator> communicator);

  // The complete current state as a checkpoint.
  Checkpoint checkpoint() const;

  // The default save hook: last.ckpt in options.out_dir, and best.ckpt (the model without
  // Adam moments) when `record` is a new best. Does nothing when out_dir is "".
  void save_checkpoints(const EpochRecord& record);

  // The last checkpoint this run wrote ("" when none), named by non-finite-number errors.
  // A save hook that writes checkpoints elsewhere reports them here.
  const std::string& last_written() const { return last_written_; }
  void set_last_written(std::string path) { last_written_ = std::move(path); }

  const TrainingState& state() const { return state_; }
  nn::LightFieldNet net() const { return net_; }
  const TrainerOptions& options() const { return options_; }

 private:
  // What one optimizer step did: the batch's mean loss over every rank, the patches it held
  // over every rank, and what was not finite ("" when all was).
  struct StepOutcome {
    double loss = 0;
    double patches = 0;
    std::string problem;
  };
  // Forward, backward (with the all-reduce of the gradients when distributed) and the
  // gradient norm or clipping; the optimizer step is left to the caller.
  StepOutcome compute_gradients(const Batch& batch, bool distributed);
  // True when any rank asks to stop (all ranks stop together).
  bool agree_to_stop(bool stop);
  void check_batch(const Batch& batch, const std::string& where) const;
  void apply_lr(double lr);
  [[noreturn]] void fail_nonfinite(const std::string& what, const Batch& batch, int64_t epoch,
                                   int64_t index, double lr) const;
  bool weights_finite() const;
  // With a code: whether epoch `epoch` (0-based) holds it fixed, or learns it straight through
  // its rounding.
  bool code_frozen(int64_t epoch) const;
  bool code_straight_through(int64_t epoch) const;
  // With a code: fixes it when epoch `epoch` is a freeze epoch (binarising it, measured on
  // `source`'s validation, when asked), and sets the net's Phi to the weights in use.
  void prepare_code(int64_t epoch, BatchSource& source);
  void sync_code_phi();
  // The code's parameters from a checkpoint's `model` (all of them when `strict`, else those it
  // holds in this code's shapes), a fresh Adam for the code, and the net's Phi set to it: the
  // start of init_from and init_code_from. Returns the names taken.
  std::vector<std::string> start_code_from(const TensorMap& model, const std::string& what,
                                           bool strict);
  // Makes every rank hold rank 0's weights, buffers, Adam state and training position.
  void synchronise();
  // Sums the gradients over the ranks and divides by `patches` (the global batch).
  void average_gradients(double patches);

  nn::LightFieldNet net_;
  TrainerOptions options_;
  c10::Device device_{c10::kCPU};
  RunInfo run_;
  std::unique_ptr<torch::optim::Adam> optimizer_;
  nn::ReconstructionLoss loss_;
  TrainingState state_;
  std::string last_written_;  // the last checkpoint this run wrote, for error messages
  std::shared_ptr<dist::Communicator> comm_;  // LocalCommunicator unless set_communicator
  double communication_s_ = 0;                // the current epoch's EpochRecord::communication_s
  nn::LearnedPhi code_{nullptr};              // a code trained with the net (set_code)
  CodeTrainingOptions code_options_;
  std::unique_ptr<torch::optim::Adam> code_optimizer_;
  torch::Tensor fixed_code_;       // the code's weights in the freeze epochs (undefined before)
  bool straight_through_ = false;  // this epoch learns the code through its rounding
};

// "<dir>/last.ckpt" and "<dir>/best.ckpt".
std::string last_checkpoint_path(const std::string& dir);
std::string best_checkpoint_path(const std::string& dir);

// Adam moments by parameter name ("<name>/exp_avg", "<name>/exp_avg_sq", "<name>/step"), and
// back. Loading checks names and shapes (CheckpointError).
TensorMap adam_state(const torch::optim::Adam& adam, const torch::nn::Module& module);
void load_adam_state(torch::optim::Adam& adam, const torch::nn::Module& module,
                     const TensorMap& state, const std::string& what);

}  // namespace lfnet::train

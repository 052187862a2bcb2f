// Where training data comes from: the interface the Trainer reads batches through, and an
// in-memory implementation over precomputed tensors.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <vector>

namespace lfnet::train {

// A batch of measured patches and their truth.
struct Batch {
  torch::Tensor y;       // (B, N h w) float32 measurement vectors, flattened (n, y, x)
  torch::Tensor phase;   // (B) int64 indices into the Phi's patch-matrix stack; may be
                         // undefined when the Phi has one phase
  torch::Tensor target;  // (B, 1, U, V, h, w) float32 true patches, values in [0, 1]
  torch::Tensor noise;   // (B) float32 sigma of the Gaussian noise on each patch's measurements
                         // (relative to white, as optics::SensorOptions); undefined: none known

  int64_t size() const { return y.defined() ? y.size(0) : 0; }
};

// A source of training and validation batches. The Trainer calls start_epoch(e, b) before
// each epoch, then next_train() train_batches_per_epoch() times, then reads validation().
// Resumed training is exact only if the source is deterministic per epoch: the batches of
// epoch e must follow from the source's seed and e alone, not from what came before.
class BatchSource {
 public:
  virtual ~BatchSource() = default;

  // Prepares epoch `epoch` (0-based) of batches of `batch_size` patches (the last may be
  // smaller).
  virtual void start_epoch(int64_t epoch, int64_t batch_size) = 0;
  // Training batches in the epoch that start_epoch prepared.
  virtual int64_t train_batches_per_epoch() const = 0;
  // The next training batch of the current epoch.
  virtual Batch next_train() = 0;
  // The validation set, the same every epoch (never trained on).
  virtual const std::vector<Batch>& validation() = 0;

  // Data-parallel training (docs/distributed.md): from now on next_train() returns only
  // rank `rank`'s part of each batch, dist::shard_range of the batch's patches, so the parts
  // of all `world` ranks together are exactly the batch a single process gets. Sources that
  // cannot shard throw ConfigError for world > 1 (this default).
  virtual void set_shard(int64_t rank, int64_t world);
};

// Patches held in memory: a fixed train/validation split (by a seeded permutation) and a new
// seeded shuffle of the training part every epoch.
class InMemoryBatchSource : public BatchSource {
 public:
  // y (n, N h w), phase (n) int64 or undefined, target (n, 1, U, V, h, w). A fraction
  // `validation_fraction` of the patches (the paper's 15 %) is held out for validation.
  InMemoryBatchSource(torch::Tensor y, torch::Tensor phase, torch::Tensor target,
                      double validation_fraction = 0.15, uint64_t seed = 0,
                      int64_t validation_batch_size = 256);

  void start_epoch(int64_t epoch, int64_t batch_size) override;
  int64_t train_batches_per_epoch() const override;
  Batch next_train() override;
  const std::vector<Batch>& validation() override { return validation_; }
  void set_shard(int64_t rank, int64_t world) override;

  int64_t train_size() const { return train_index_.size(0); }
  int64_t validation_size() const;

 private:
  Batch gather(const torch::Tensor& index) const;

  torch::Tensor y_, phase_, target_;
  torch::Tensor train_index_, order_;
  std::vector<Batch> validation_;
  uint64_t seed_;
  int64_t batch_size_ = 1, cursor_ = 0;
  int64_t shard_rank_ = 0, shard_world_ = 1;
};

// Distillation (docs/training.md, "Distillation"): the training batches of `inner` with their
// targets blended with a teacher's estimates, weight * teacher(batch) + (1 - weight) * target,
// the teacher's clamped to [0, 1]. `teacher` maps a batch to (B, 1, U, V, h, w) estimates of
// its targets. Validation batches are the inner source's, true targets and all, so the
// validation PSNR still measures the student against the truth. Deterministic when the inner
// source and the teacher are, so resumed training stays exact.
class TeacherBatchSource : public BatchSource {
 public:
  using Teacher = std::function<torch::Tensor(const Batch&)>;
  // `weight` in [0, 1] (ConfigError otherwise); `inner` must outlive this source.
  TeacherBatchSource(BatchSource& inner, Teacher teacher, double weight);

  void start_epoch(int64_t epoch, int64_t batch_size) override;
  int64_t train_batches_per_epoch() const override;
  Batch next_train() override;
  const std::vector<Batch>& validation() override { return inner_.validation(); }
  void set_shard(int64_t rank, int64_t world) override { inner_.set_shard(rank, world); }

 private:
  BatchSource& inner_;
  Teacher teacher_;
  double weight_;
};

}  // namespace lfnet::train

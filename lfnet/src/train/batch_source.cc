#include "lfnet/train/batch_source.h"

#include <torch/torch.h>

#include <cmath>
#include <utility>

#include "lfnet/core/error.h"
#include "lfnet/dist/communicator.h"

namespace lfnet::train {

void BatchSource::set_shard(int64_t rank, int64_t world) {
  LFNET_CHECK_AS(ConfigError, world == 1 && rank == 0,
                 "this batch source cannot be split across ranks (world size ", world, ")");
}

InMemoryBatchSource::InMemoryBatchSource(torch::Tensor y, torch::Tensor phase, torch::Tensor target,
                                         double validation_fraction, uint64_t seed,
                                         int64_t validation_batch_size)
    : y_(std::move(y)), phase_(std::move(phase)), target_(std::move(target)), seed_(seed) {
  LFNET_CHECK(
      y_.dim() == 2 && target_.dim() == 6 && target_.size(0) == y_.size(0) && target_.size(1) == 1,
      "InMemoryBatchSource: expected y (n, N h w) and target (n, 1, U, V, h, w), got ", y_.sizes(),
      " and ", target_.sizes());
  LFNET_CHECK(!phase_.defined() || (phase_.dim() == 1 && phase_.size(0) == y_.size(0) &&
                                    phase_.scalar_type() == torch::kInt64),
              "InMemoryBatchSource: phase must be (n) int64");
  LFNET_CHECK(validation_fraction >= 0 && validation_fraction < 1,
              "InMemoryBatchSource: validation_fraction must lie in [0, 1)");
  LFNET_CHECK(validation_batch_size > 0, "InMemoryBatchSource: bad validation batch size");
  const int64_t n = y_.size(0);
  const auto n_val = static_cast<int64_t>(std::llround(validation_fraction * n));
  LFNET_CHECK(n - n_val >= 1, "InMemoryBatchSource: no training patches left of ", n);
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  auto perm = torch::randperm(n, gen, torch::kInt64);
  train_index_ = perm.narrow(0, n_val, n - n_val);
  order_ = train_index_;
  auto val_index = std::get<0>(perm.narrow(0, 0, n_val).sort());  // validation in data order
  for (int64_t i = 0; i < n_val; i += validation_batch_size) {
    validation_.push_back(
        gather(val_index.narrow(0, i, std::min(validation_batch_size, n_val - i))));
  }
}

int64_t InMemoryBatchSource::validation_size() const {
  int64_t n = 0;
  for (const auto& b : validation_) n += b.size();
  return n;
}

Batch InMemoryBatchSource::gather(const torch::Tensor& index) const {
  Batch b;
  b.y = y_.index_select(0, index);
  if (phase_.defined()) b.phase = phase_.index_select(0, index);
  b.target = target_.index_select(0, index);
  return b;
}

void InMemoryBatchSource::start_epoch(int64_t epoch, int64_t batch_size) {
  LFNET_CHECK(batch_size > 0, "InMemoryBatchSource: batch size must be positive");
  batch_size_ = batch_size;
  cursor_ = 0;
  // The epoch's order depends on (seed, epoch) alone, so a resumed run sees the same batches.
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed_ * 1000003ull + 7919ull * epoch + 1);
  order_ = train_index_.index_select(0, torch::randperm(train_index_.size(0), gen, torch::kInt64));
}

int64_t InMemoryBatchSource::train_batches_per_epoch() const {
  return (train_index_.size(0) + batch_size_ - 1) / batch_size_;
}

Batch InMemoryBatchSource::next_train() {
  const int64_t n = order_.size(0);
  if (cursor_ >= n) cursor_ = 0;  // past the epoch's end: start over rather than fail
  const int64_t take = std::min(batch_size_, n - cursor_);
  const auto [begin, end] = dist::shard_range(take, shard_rank_, shard_world_);
  auto b = gather(order_.narrow(0, cursor_ + begin, end - begin));
  cursor_ += take;
  return b;
}

void InMemoryBatchSource::set_shard(int64_t rank, int64_t world) {
  LFNET_CHECK_AS(ConfigError, world >= 1 && rank >= 0 && rank < world, "bad shard: rank ", rank,
                 " of ", world);
  shard_rank_ = rank;
  shard_world_ = world;
}

TeacherBatchSource::TeacherBatchSource(BatchSource& inner, Teacher teacher, double weight)
    : inner_(inner), teacher_(std::move(teacher)), weight_(weight) {
  LFNET_CHECK_AS(ConfigError, teacher_ != nullptr, "distillation needs a teacher");
  LFNET_CHECK_AS(ConfigError, weight >= 0 && weight <= 1,
                 "the teacher's weight must lie in [0, 1], got ", weight);
}

void TeacherBatchSource::start_epoch(int64_t epoch, int64_t batch_size) {
  inner_.start_epoch(epoch, batch_size);
}

int64_t TeacherBatchSource::train_batches_per_epoch() const {
  return inner_.train_batches_per_epoch();
}

Batch TeacherBatchSource::next_train() {
  Batch b = inner_.next_train();
  if (b.size() == 0 || weight_ == 0) return b;
  torch::Tensor taught;
  {
    torch::NoGradGuard no_grad;
    taught = teacher_(b).to(b.target.device(), b.target.scalar_type()).clamp_(0.0, 1.0);
  }
  LFNET_CHECK(taught.sizes() == b.target.sizes(), "the teacher's estimates have shape ",
              taught.sizes(), ", the targets ", b.target.sizes());
  b.target = weight_ == 1 ? taught : taught.mul_(weight_).add_(b.target, 1.0 - weight_);
  return b;
}

}  // namespace lfnet::train

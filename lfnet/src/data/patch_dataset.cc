#include "lfnet/data/patch_dataset.h"

#include <algorithm>
#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/dist/communicator.h"
#include "lfnet/optics/measure.h"

namespace lfnet::data {

DatasetOptions DatasetOptions::from_json(JsonReader& r) {
  DatasetOptions o;
  r.get("patch_h", o.patch_h);
  r.get("patch_w", o.patch_w);
  r.get("train_patches", o.train_patches);
  r.get("validation_patches", o.validation_patches);
  r.get("validation_fraction", o.validation_fraction);
  r.get("augment", o.augment);
  r.get("min_std", o.min_std);
  r.get("seed", o.seed);
  if (r.has("effects")) {
    nlohmann::json effects;
    r.get("effects", effects);
    o.effects = optics::SensorOptions::from_json(effects, r.path_of("effects"));
  }
  r.finish();
  try {
    o.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(r.path() + ": " + e.what());
  }
  return o;
}

nlohmann::json DatasetOptions::to_json() const {
  return {{"patch_h", patch_h},
          {"patch_w", patch_w},
          {"train_patches", train_patches},
          {"validation_patches", validation_patches},
          {"validation_fraction", validation_fraction},
          {"augment", augment},
          {"min_std", min_std},
          {"seed", seed},
          {"effects", effects.to_json()}};
}

void DatasetOptions::validate() const {
  if (patch_h < 1 || patch_w < 1) throw ConfigError("patch size must be positive");
  if (train_patches < 1) throw ConfigError("train_patches must be at least 1");
  if (validation_patches < 1) throw ConfigError("validation_patches must be at least 1");
  if (!(validation_fraction > 0 && validation_fraction < 1)) {
    throw ConfigError("validation_fraction must lie in (0, 1)");
  }
  if (min_std < 0) throw ConfigError("min_std must be non-negative");
}

namespace {
// Augmentation codes: bit 0 flips (U, H), bit 1 flips (V, W), bit 2 transposes (U<->V, H<->W).
torch::Tensor augment_patch(torch::Tensor p, int code) {
  // p: (U, V, h, w)
  if (code & 1) p = p.flip({0, 2});
  if (code & 2) p = p.flip({1, 3});
  if (code & 4) p = p.permute({1, 0, 3, 2});
  return p;
}
}  // namespace

PatchDataset::PatchDataset(std::vector<LightField> light_fields, const optics::Phi& phi,
                           DatasetOptions options, int64_t validation_batch_size)
    : lfs_(std::move(light_fields)), phi_(phi), options_(std::move(options)) {
  options_.validate();
  LFNET_CHECK_AS(ConfigError, !lfs_.empty(), "the training data holds no light field");
  LFNET_CHECK_AS(ConfigError, validation_batch_size >= 1, "validation batch size must be >= 1");
  for (size_t i = 0; i < lfs_.size(); ++i) {
    auto& lf = lfs_[i];
    lf = lf.grey();
    LFNET_CHECK_AS(ConfigError, lf.rows() == phi.rows() && lf.cols() == phi.cols(),
                   "training light field ", i, " has ", lf.rows(), "x", lf.cols(),
                   " views but Phi codes ", phi.rows(), "x", phi.cols());
    const int64_t split = static_cast<int64_t>(
        std::floor(static_cast<double>(lf.height()) * (1.0 - options_.validation_fraction)));
    LFNET_CHECK_AS(ConfigError,
                   split >= options_.patch_h && lf.height() - split >= options_.patch_h &&
                       lf.width() >= options_.patch_w,
                   "training light field ", i, " (", lf.shape_string(),
                   ") is too small for a train/validation split with ", options_.patch_h, "x",
                   options_.patch_w, " patches");
    split_row_.push_back(split);
    train_weight_.push_back(static_cast<double>((split - options_.patch_h + 1) *
                                                (lf.width() - options_.patch_w + 1)));
  }
  if (phi_.local()) {
    weights_ = optics::pixel_weight_stack(phi_, options_.patch_h, options_.patch_w);
  } else {
    matrix_ = phi_.patch_matrix(0, 0, options_.patch_h, options_.patch_w);
  }
  // The validation set: drawn once from the held-out rows, never augmented.
  std::mt19937_64 rng(options_.seed ^ 0x9e3779b97f4a7c15ULL);
  for (int64_t done = 0; done < options_.validation_patches; done += validation_batch_size) {
    const int64_t n = std::min(validation_batch_size, options_.validation_patches - done);
    validation_.push_back(make_batch(draw(true, n, rng), options_.seed + 0x7a11d + done));
  }
  // Mean of simulated measurements over a fixed training sample.
  std::mt19937_64 probe_rng(options_.seed + 17);
  measurement_mean_ =
      make_batch(draw(false, std::min<int64_t>(2048, options_.train_patches), probe_rng), 0)
          .y.mean()
          .item<double>();
}

PatchDataset::Draw PatchDataset::draw(bool validation, int64_t count, std::mt19937_64& rng) const {
  std::discrete_distribution<int64_t> pick(train_weight_.begin(), train_weight_.end());
  const bool square = options_.patch_h == options_.patch_w && phi_.rows() == phi_.cols();
  std::uniform_int_distribution<int> codes(0, square ? 7 : 3);
  Draw d;
  for (int64_t i = 0; i < count; ++i) {
    const int64_t k = pick(rng);
    const auto& lf = lfs_[k];
    const int64_t lo = validation ? split_row_[k] : 0;
    const int64_t hi =
        validation ? lf.height() - options_.patch_h : split_row_[k] - options_.patch_h;
    std::uniform_int_distribution<int64_t> ys(lo, hi), xs(0, lf.width() - options_.patch_w);
    int64_t py = ys(rng), px = xs(rng);
    // Flat patches teach little; redraw a few times when a minimum contrast is asked for.
    for (int tries = 0; !validation && options_.min_std > 0 && tries < 8; ++tries) {
      auto patch =
          lf.data()[0].slice(2, py, py + options_.patch_h).slice(3, px, px + options_.patch_w);
      if (patch.std().item<double>() >= options_.min_std) break;
      py = ys(rng);
      px = xs(rng);
    }
    d.lf.push_back(k);
    d.y0.push_back(py);
    d.x0.push_back(px);
    d.aug.push_back(!validation && options_.augment ? codes(rng) : 0);
  }
  return d;
}

train::Batch PatchDataset::make_batch(const Draw& d, uint64_t noise_seed) const {
  const int64_t b = static_cast<int64_t>(d.lf.size());
  const int64_t h = options_.patch_h, w = options_.patch_w;
  std::vector<torch::Tensor> patches;
  std::vector<int64_t> phases;
  patches.reserve(b);
  for (int64_t i = 0; i < b; ++i) {
    auto p = lfs_[d.lf[i]].data()[0].slice(2, d.y0[i], d.y0[i] + h).slice(3, d.x0[i], d.x0[i] + w);
    patches.push_back(augment_patch(p, d.aug[i]));
    phases.push_back(phi_.local() ? optics::patch_phase(phi_, d.y0[i], d.x0[i]) : 0);
  }
  auto target = torch::stack(patches, 0).contiguous();  // (B, U, V, h, w)
  auto phase = torch::tensor(phases, torch::kInt64);
  torch::Tensor y;
  if (phi_.local()) {
    // Each sensor pixel sums its own rays: y[b, n, y, x] = sum_uv W[phase_b, n, u, v, y, x] L[b, u, v, y, x].
    auto weights = weights_.index_select(0, phase);  // (B, N, U, V, h, w)
    y = (weights * target.unsqueeze(1)).sum({2, 3}).reshape({b, -1});
  } else {
    y = torch::matmul(target.reshape({b, -1}), matrix_.t());
  }
  if (!options_.effects.empty()) y = optics::apply_sensor_effects(y, options_.effects, noise_seed);
  return {y.contiguous(), phase, target.unsqueeze(1)};
}

PatchDataset::~PatchDataset() {
  if (prefetch_.valid()) prefetch_.wait();
}

void PatchDataset::start_epoch(int64_t epoch, int64_t batch_size) {
  LFNET_CHECK_AS(ConfigError, batch_size >= 1, "batch size must be >= 1");
  if (prefetch_.valid()) prefetch_.get();  // a batch of the previous epoch, not used
  epoch_ = epoch;
  batch_size_ = batch_size;
  served_ = 0;
  rng_.seed(options_.seed * 1000003ULL + static_cast<uint64_t>(epoch) + 1);
}

int64_t PatchDataset::train_batches_per_epoch() const {
  return (options_.train_patches + batch_size_ - 1) / batch_size_;
}

train::Batch PatchDataset::next_train() {
  train::Batch batch = prefetch_.valid() ? prefetch_.get() : prepare_next();
  if (served_ < options_.train_patches) {
    prefetch_ = std::async(std::launch::async, [this] { return prepare_next(); });
  }
  return batch;
}

train::Batch PatchDataset::prepare_next() {
  const int64_t n = std::min(batch_size_, options_.train_patches - served_);
  LFNET_CHECK(n > 0, "the epoch's training batches are used up");
  const uint64_t noise_seed = options_.seed * 0x100000001b3ULL +
                              static_cast<uint64_t>(epoch_) * 1000003ULL +
                              static_cast<uint64_t>(served_);
  served_ += n;
  Draw d = draw(false, n, rng_);
  if (shard_world_ == 1) return make_batch(d, noise_seed);
  const auto [begin, end] = dist::shard_range(n, shard_rank_, shard_world_);
  if (!options_.effects.empty()) {
    // The noise of one patch depends on the whole batch's draw: simulate it all, keep a part.
    auto full = make_batch(d, noise_seed);
    return {full.y.slice(0, begin, end).contiguous(), full.phase.slice(0, begin, end),
            full.target.slice(0, begin, end).contiguous()};
  }
  if (begin == end) {
    // A last batch smaller than the world leaves this rank nothing: an empty batch.
    Draw one{{d.lf[0]}, {d.y0[0]}, {d.x0[0]}, {d.aug[0]}};
    auto b = make_batch(one, noise_seed);
    return {b.y.slice(0, 0, 0), b.phase.slice(0, 0, 0), b.target.slice(0, 0, 0)};
  }
  Draw part;
  part.lf.assign(d.lf.begin() + begin, d.lf.begin() + end);
  part.y0.assign(d.y0.begin() + begin, d.y0.begin() + end);
  part.x0.assign(d.x0.begin() + begin, d.x0.begin() + end);
  part.aug.assign(d.aug.begin() + begin, d.aug.begin() + end);
  return make_batch(part, noise_seed);
}

void PatchDataset::set_shard(int64_t rank, int64_t world) {
  LFNET_CHECK_AS(ConfigError, world >= 1 && rank >= 0 && rank < world, "bad shard: rank ", rank,
                 " of ", world);
  if (prefetch_.valid()) prefetch_.get();  // prepared for the old shard
  shard_rank_ = rank;
  shard_world_ = world;
}

}  // namespace lfnet::data

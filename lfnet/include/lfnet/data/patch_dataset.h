// Training patches: random (U, V, h, w) patches of light fields, simulated on the fly.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/core/light_field.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"
#include "lfnet/train/batch_source.h"

namespace lfnet::data {

// Which angular windows training patches come from; by name "central", "any".
enum class AngularWindows { kCentral, kAny };
std::string to_string(AngularWindows value);
AngularWindows from_string(const std::string& name, AngularWindows);

// Options of the patch data set.
struct DatasetOptions {
  int64_t patch_h = 9;                // spatial patch height
  int64_t patch_w = 9;                // spatial patch width
  int64_t train_patches = 50000;      // patches drawn per training epoch (paper: 50,000)
  int64_t validation_patches = 4000;  // fixed validation patches, drawn once
  double validation_fraction = 0.15;  // share of every light field's rows kept for validation
  bool augment = true;                // flips and transposes that keep angular axes consistent
  double min_std = 0.0;               // drop training patches flatter than this (0: keep all)
  // Which U x V windows of a wider light field training patches come from: "central" (the
  // central window at each step) or "any" (every window that fits). `angular_steps` are the
  // view spacings: 2 takes every second view, which doubles the baseline and the disparity.
  // Validation always uses the central window at step 1.
  AngularWindows angular_windows = AngularWindows::kCentral;
  std::vector<int64_t> angular_steps = {1};
  // Photometric jitter of training patches, drawn per patch (0: off): the patch is raised to
  // a gamma exp(+-gamma), its contrast about its mean scaled by exp(+-contrast), its level
  // shifted by +-brightness, then clipped to [0, 1]; all uniform in those ranges.
  double jitter_gamma = 0.0;
  double jitter_contrast = 0.0;
  double jitter_brightness = 0.0;
  // Noise-aware training: each patch (training and validation) draws a sigma uniformly in
  // [lo, hi] and its measurements get Gaussian noise of that sigma (relative to white, on top
  // of `effects`); the batch carries the sigmas (train::Batch::noise). Empty: off.
  std::vector<double> noise_range;
  // With noise_range, the share of patches whose noise is a real pixel's instead: photon shot
  // noise (its Gaussian approximation) at photons_at_white drawn log-uniformly in
  // `shot_photons_range`, plus read noise of electrons drawn uniformly in
  // `read_electrons_range`. The sigma the net reads is then the Gaussian sigma of the same
  // variance at the patch's mean measurement (optics::SensorOptions::equivalent_sigma), as at
  // reconstruction. 0: Gaussian noise only.
  double shot_read_fraction = 0.0;
  std::vector<double> shot_photons_range = {20, 2000};
  std::vector<double> read_electrons_range = {0, 10};
  // With noise_range, the share of patches measured without noise (sigma 0), so that a
  // noise-aware net keeps its noiseless accuracy. 0: none beyond the range's own draws.
  double clean_fraction = 0.0;
  // Calibration-robust training: each patch (training and validation) is measured by a camera
  // whose Phi has its own small error drawn from these ranges (optics/calibration.h); the net
  // is told the nominal Phi. Empty (all 0): every patch is measured by the nominal Phi.
  optics::CalibrationRanges calibration;
  // Noise in the truth: this share of training patches has Gaussian noise of a sigma drawn
  // uniformly in `view_noise_range` added to every view (independently per view, pixel and
  // colour, clipped to [0, 1]) before it is measured, and the net is scored against the noisy
  // views: a light-field camera whose sub-aperture images carry its own noise. Empty: off.
  std::vector<double> view_noise_range;
  double view_noise_fraction = 1.0;
  // The share of those noisy patches whose noise is correlated as a plenoptic camera's
  // (core/view_noise.h): averaged over the views within `view_noise_angular` steps and the
  // pixels within `view_noise_spatial` pixels. 0: all independent.
  double view_noise_correlated_fraction = 0.0;
  int64_t view_noise_angular = 1;
  int64_t view_noise_spatial = 1;
  // Each training light field also at these downscales (f x f area average, where the copy
  // still splits into training and validation rows of whole patches): f times finer texture at
  // 1/f the disparity. {1}: as loaded.
  std::vector<int64_t> downscales = {1};
  // Dim exposures: this share of training crops is multiplied by a gain drawn log-uniformly in
  // `dark_gain_range`, after the photometric jitter and before any view noise, so the noise
  // stands higher against the signal (a dark, flat scene). 0: off.
  double dark_fraction = 0.0;
  std::vector<double> dark_gain_range = {0.2, 0.6};
  // Chroma of colour training crops: each crop's colours about their per-pixel grey are scaled
  // by exp(+-jitter_saturation) (uniform; clipped to [0, 1]), and with `permute_channels` its
  // R, G, B are put in one of the six orders at random, so hues the data lacks are seen too.
  // After the dim exposures' draws; 0 and false: off, crops as they were.
  double jitter_saturation = 0.0;
  bool permute_channels = false;
  uint64_t seed = 1;              // patch draws, augmentation and noise
  optics::SensorOptions effects;  // sensor effects on the measurements (none by default)
  // A colour net's Bayer pattern (network.cfa, not a dataset key): the patches keep their three
  // colours (a grey light field counts as grey in all three), and every pixel measures its N
  // coded values in its own colour. Empty: grey patches.
  std::string cfa;

  // Whether training draws windows other than the central one at step 1, so that light
  // fields should come with their whole angular grid.
  bool needs_whole_grids() const {
    return angular_windows != AngularWindows::kCentral || angular_steps != std::vector<int64_t>{1};
  }

  template <typename Fields>
  void fields(Fields& f) {
    f("patch_h", patch_h, Range::closed(1, 4096));
    f("patch_w", patch_w, Range::closed(1, 4096));
    f("train_patches", train_patches);
    f("validation_patches", validation_patches);
    f("validation_fraction", validation_fraction);
    f("augment", augment);
    f("min_std", min_std, Range::closed(0, 1));
    f("angular_windows", angular_windows);
    f("angular_steps", angular_steps);
    f("jitter_gamma", jitter_gamma);
    f("jitter_contrast", jitter_contrast);
    f("jitter_brightness", jitter_brightness);
    f("noise_range", noise_range);
    f("shot_read_fraction", shot_read_fraction);
    f("shot_photons_range", shot_photons_range);
    f("read_electrons_range", read_electrons_range);
    f("clean_fraction", clean_fraction);
    f("calibration", calibration);
    f("view_noise_range", view_noise_range);
    f("view_noise_fraction", view_noise_fraction);
    f("view_noise_correlated_fraction", view_noise_correlated_fraction);
    f("view_noise_angular", view_noise_angular);
    f("view_noise_spatial", view_noise_spatial);
    f("downscales", downscales);
    f("dark_fraction", dark_fraction, Range::closed(0, 1));
    f("dark_gain_range", dark_gain_range);
    f("jitter_saturation", jitter_saturation);
    f("permute_channels", permute_channels);
    f("seed", seed);
    f("effects", effects);
  }
  static DatasetOptions from_json(JsonReader& r);
  nlohmann::json to_json() const;
  void validate() const;
};

// Random patches of grey light fields (colour ones behind a CFA: DatasetOptions::cfa) with an 85:15
// split that shares no pixel: the bottom `validation_fraction` of every light field's rows is kept
// for validation, and training patches never reach into it. Measurements are simulated per patch
// with the patch matrix of the patch's origin, which for every local Phi equals cropping a
// simulated sensor image (noise aside: here every patch draws its own). Deterministic: the batches
// of an epoch follow from (seed, epoch) alone, so resumed training is exact.
class PatchDataset : public train::BatchSource {
 public:
  PatchDataset(std::vector<LightField> light_fields, const optics::Phi& phi, DatasetOptions options,
               int64_t validation_batch_size = 256);
  ~PatchDataset() override;

  void start_epoch(int64_t epoch, int64_t batch_size) override;
  int64_t train_batches_per_epoch() const override;
  train::Batch next_train() override;
  const std::vector<train::Batch>& validation() override { return validation_; }
  // Every rank draws the whole batch (the generator advances alike) but simulates only its
  // part; with sensor effects it simulates the whole batch, whose noise is one draw.
  void set_shard(int64_t rank, int64_t world) override;

  // Mean of simulated training measurements: real measurements are scaled to it.
  double measurement_mean() const { return measurement_mean_; }
  int64_t light_fields() const { return static_cast<int64_t>(lfs_.size()); }

 private:
  struct Draw {
    std::vector<int64_t> lf, y0, x0;
    std::vector<int> aug;
    std::vector<int64_t> window;  // index into windows_[lf]
    std::vector<float> gamma, contrast, brightness;
    std::vector<float> sigma;  // per patch with noise_range, else empty
    // Per patch with shot_read_fraction: photons at white (0: Gaussian noise) and read
    // electrons; else empty.
    std::vector<float> photons, read_electrons;
    // Per patch with calibration ranges: its camera's error and its place on that camera's
    // sensor; else empty.
    std::vector<optics::CalibrationError> calibration;
    std::vector<optics::SensorPlacement> placement;
    std::vector<float> view_sigma;       // per patch with view_noise_range (0: clean), else empty
    std::vector<float> view_correlated;  // per patch with view_noise_range: 1 correlated noise
    std::vector<float> gain;             // per patch with dark_fraction (1: as is), else empty
    std::vector<float> saturation;       // per patch with jitter_saturation (1: as is), else empty
    std::vector<int> channel_order;      // per patch with permute_channels: 0..5 (0: R, G, B)
    Draw slice(int64_t begin, int64_t end) const;
  };
  // An angular window: views u0, u0 + step, ... (U of them), and likewise v.
  struct Window {
    int64_t u0 = 0, v0 = 0, step = 1;
  };
  Draw draw(bool validation, int64_t count, std::mt19937_64& rng) const;
  train::Batch make_batch(const Draw& d, uint64_t noise_seed) const;
  // Draws and simulates the epoch's next batch (the rng advances in batch order).
  train::Batch prepare_next();

  std::vector<LightField> lfs_;
  const optics::Phi& phi_;
  DatasetOptions options_;
  torch::Tensor weights_;                     // local Phi: (P, N, U, V, h, w) per-pixel weights
  torch::Tensor matrix_;                      // block Phi: (N h w, U V h w)
  torch::Tensor cfa_;                         // with options.cfa: the response tile (3, P, P)
  int64_t period_ = 1;                        // the phases' period: the code's and the CFA's
  std::vector<std::vector<Window>> windows_;  // per light field; [0]: central, step 1
  std::vector<int64_t> split_row_;            // first validation row of every light field
  std::vector<double> train_weight_;
  std::mt19937_64 rng_;
  int64_t epoch_ = 0, batch_size_ = 64, served_ = 0;
  int64_t shard_rank_ = 0, shard_world_ = 1;
  std::vector<train::Batch> validation_;
  double measurement_mean_ = 0;
  // The batch after the one being trained on, prepared on another thread while the network
  // trains; batches come out in the same order either way, so results do not change.
  std::future<train::Batch> prefetch_;
};

}  // namespace lfnet::data

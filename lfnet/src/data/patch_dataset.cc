#include "lfnet/data/patch_dataset.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/core/view_noise.h"
#include "lfnet/dist/communicator.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/measure.h"

namespace lfnet::data {

namespace {
constexpr EnumName<AngularWindows> kAngularWindows[] = {{AngularWindows::kCentral, "central"},
                                                        {AngularWindows::kAny, "any"}};
}  // namespace

std::string to_string(AngularWindows value) { return name_of(value, kAngularWindows); }
AngularWindows from_string(const std::string& name, AngularWindows) {
  return value_of(name, kAngularWindows);
}

DatasetOptions DatasetOptions::from_json(JsonReader& r) {
  DatasetOptions o;
  read_fields(r, o);
  r.finish();
  try {
    o.effects.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(r.path_of("effects") + ": " + e.what());
  }
  try {
    o.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(r.path() + ": " + e.what());
  }
  return o;
}

nlohmann::json DatasetOptions::to_json() const { return fields_to_json(*this); }

void DatasetOptions::validate() const {
  if (patch_h < 1 || patch_w < 1) throw ConfigError("patch size must be positive");
  // An epoch is drawn and simulated patch by patch: beyond these counts a run would take
  // days per epoch on any machine, so they are refused rather than left to hang.
  constexpr int64_t kMaxTrainPatches = 100'000'000, kMaxValidationPatches = 10'000'000;
  if (train_patches < 1 || train_patches > kMaxTrainPatches) {
    throw ConfigError("dataset.train_patches must be from 1 to 100,000,000 per epoch, got " +
                      std::to_string(train_patches));
  }
  if (validation_patches < 1 || validation_patches > kMaxValidationPatches) {
    throw ConfigError("dataset.validation_patches must be from 1 to 10,000,000, got " +
                      std::to_string(validation_patches));
  }
  if (!(validation_fraction > 0 && validation_fraction < 1)) {
    throw ConfigError("validation_fraction must lie in (0, 1)");
  }
  if (min_std < 0) throw ConfigError("min_std must be non-negative");
  if (!noise_range.empty() &&
      (noise_range.size() != 2 || !(noise_range[0] >= 0 && noise_range[1] >= noise_range[0] &&
                                    std::isfinite(noise_range[1])))) {
    throw ConfigError("noise_range must be [lo, hi] with 0 <= lo <= hi, or empty");
  }
  if (!(shot_read_fraction >= 0 && shot_read_fraction <= 1)) {
    throw ConfigError("shot_read_fraction must lie in [0, 1]");
  }
  if (shot_read_fraction > 0 && noise_range.empty()) {
    throw ConfigError("shot_read_fraction needs a noise_range: a noise-aware net reads a sigma");
  }
  if (shot_photons_range.size() != 2 ||
      !(shot_photons_range[0] > 0 && shot_photons_range[1] >= shot_photons_range[0] &&
        std::isfinite(shot_photons_range[1]))) {
    throw ConfigError("shot_photons_range must be [lo, hi] with 0 < lo <= hi");
  }
  if (read_electrons_range.size() != 2 ||
      !(read_electrons_range[0] >= 0 && read_electrons_range[1] >= read_electrons_range[0] &&
        std::isfinite(read_electrons_range[1]))) {
    throw ConfigError("read_electrons_range must be [lo, hi] with 0 <= lo <= hi");
  }
  if (!(clean_fraction >= 0 && clean_fraction <= 1)) {
    throw ConfigError("clean_fraction must lie in [0, 1]");
  }
  if (clean_fraction > 0 && noise_range.empty()) {
    throw ConfigError("clean_fraction needs a noise_range: it is the share of noiseless patches");
  }
  calibration.validate();
  if (!view_noise_range.empty() &&
      (view_noise_range.size() != 2 ||
       !(view_noise_range[0] >= 0 && view_noise_range[1] >= view_noise_range[0] &&
         view_noise_range[1] <= 1))) {
    throw ConfigError("view_noise_range must be [lo, hi] with 0 <= lo <= hi <= 1, or empty");
  }
  if (!(view_noise_fraction >= 0 && view_noise_fraction <= 1)) {
    throw ConfigError("view_noise_fraction must lie in [0, 1]");
  }
  if (!(view_noise_correlated_fraction >= 0 && view_noise_correlated_fraction <= 1)) {
    throw ConfigError("view_noise_correlated_fraction must lie in [0, 1]");
  }
  if (view_noise_angular < 0 || view_noise_angular > 4 || view_noise_spatial < 0 ||
      view_noise_spatial > 8) {
    throw ConfigError("view_noise_angular must lie in 0..4 and view_noise_spatial in 0..8");
  }
  if (downscales.empty()) throw ConfigError("downscales must list at least one factor (1: as is)");
  for (int64_t f : downscales) {
    if (f < 1 || f > 8) throw ConfigError("downscales must lie in 1..8");
  }
  if (angular_steps.empty()) throw ConfigError("angular_steps must list at least one step");
  for (int64_t step : angular_steps) {
    if (step < 1 || step > 8) throw ConfigError("angular_steps must lie in 1..8");
  }
  if (dark_gain_range.size() != 2 || !(dark_gain_range[0] > 0) ||
      !(dark_gain_range[0] <= dark_gain_range[1]) || !(dark_gain_range[1] <= 1)) {
    throw ConfigError("dark_gain_range must be [lo, hi] with 0 < lo <= hi <= 1");
  }
  for (double j : {jitter_gamma, jitter_contrast, jitter_brightness}) {
    if (!(std::isfinite(j) && j >= 0 && j <= 1)) {
      throw ConfigError("jitter_gamma, jitter_contrast and jitter_brightness must lie in [0, 1]");
    }
  }
  if (!(std::isfinite(jitter_saturation) && jitter_saturation >= 0 && jitter_saturation <= 2)) {
    throw ConfigError("jitter_saturation must lie in [0, 2]");
  }
}

namespace {
// Augmentation codes: bit 0 flips (U, H), bit 1 flips (V, W), bit 2 transposes (U<->V, H<->W).
torch::Tensor augment_patch(torch::Tensor p, int code) {
  // p: (C, U, V, h, w)
  if (code & 1) p = p.flip({1, 3});
  if (code & 2) p = p.flip({2, 4});
  if (code & 4) p = p.permute({0, 2, 1, 4, 3});
  return p;
}
}  // namespace

PatchDataset::PatchDataset(std::vector<LightField> light_fields, const optics::Phi& phi,
                           DatasetOptions options, int64_t validation_batch_size)
    : lfs_(std::move(light_fields)), phi_(phi), options_(std::move(options)) {
  options_.validate();
  LFNET_CHECK_AS(ConfigError, !lfs_.empty(), "the training data holds no light field");
  LFNET_CHECK_AS(ConfigError, validation_batch_size >= 1, "validation batch size must be >= 1");
  const int64_t nu = phi.rows(), nv = phi.cols();
  // The downscaled copies after every light field as loaded, so that indices of the light
  // fields as loaded stay as they were.
  const size_t loaded = lfs_.size();
  for (int64_t f : options_.downscales) {
    if (f == 1) continue;
    for (size_t i = 0; i < loaded; ++i) {
      const torch::Tensor x = lfs_[i].data();
      // Only where the copy still splits into training and validation rows of whole patches.
      const int64_t h = x.size(3) / f, w = x.size(4) / f;
      const auto split = static_cast<int64_t>(
          std::floor(static_cast<double>(h) * (1.0 - options_.validation_fraction)));
      if (split < options_.patch_h || h - split < options_.patch_h || w < options_.patch_w)
        continue;
      const auto c = x.size(0), u = x.size(1), v = x.size(2);
      LightField small(torch::avg_pool2d(x.reshape({c * u * v, 1, x.size(3), x.size(4)}), f)
                           .reshape({c, u, v, x.size(3) / f, x.size(4) / f})
                           .contiguous());
      lfs_.push_back(std::move(small));
    }
  }
  for (size_t i = 0; i < lfs_.size(); ++i) {
    auto& lf = lfs_[i];
    if (options_.cfa.empty()) {
      lf = lf.grey();
    } else if (lf.channels() == 1) {
      lf = LightField(lf.data().expand({3, -1, -1, -1, -1}));  // grey in every colour
    }
    LFNET_CHECK_AS(ConfigError, lf.rows() >= nu && lf.cols() >= nv, "training light field ", i,
                   " has ", lf.rows(), "x", lf.cols(), " views but Phi codes ", nu, "x", nv);
    // Its windows: [0] the central one at step 1 (validation's), then training's: each
    // configured step that fits the grid, centrally or everywhere. None fits: the central.
    std::vector<Window> windows = {{central_start(lf.rows(), nu), central_start(lf.cols(), nv), 1}};
    for (int64_t step : options_.angular_steps) {
      const int64_t su = step * (nu - 1) + 1, sv = step * (nv - 1) + 1;
      if (su > lf.rows() || sv > lf.cols()) continue;
      if (options_.angular_windows == AngularWindows::kCentral) {
        windows.push_back({central_start(lf.rows(), su), central_start(lf.cols(), sv), step});
        continue;
      }
      for (int64_t u0 = 0; u0 + su <= lf.rows(); ++u0) {
        for (int64_t v0 = 0; v0 + sv <= lf.cols(); ++v0) windows.push_back({u0, v0, step});
      }
    }
    if (windows.size() == 1) windows.push_back(windows.front());
    windows_.push_back(std::move(windows));
    const int64_t split = static_cast<int64_t>(
        std::floor(static_cast<double>(lf.height()) * (1.0 - options_.validation_fraction)));
    LFNET_CHECK_AS(ConfigError,
                   split >= options_.patch_h && lf.height() - split >= options_.patch_h &&
                       lf.width() >= options_.patch_w,
                   "training light field ", i, " (", lf.shape_string(),
                   ") is too small for a train/validation split with ", options_.patch_h, "x",
                   options_.patch_w, " patches");
    split_row_.push_back(split);
    train_weight_.push_back(
        static_cast<double>((split - options_.patch_h + 1) * (lf.width() - options_.patch_w + 1)));
  }
  LFNET_CHECK_AS(ConfigError, options_.calibration.empty() || phi_.local(),
                 "dataset.calibration needs a local Phi; '", phi_.spec().label(), "' is not");
  if (!options_.cfa.empty()) {
    LFNET_CHECK_AS(ConfigError, phi_.local(), "a colour filter array needs a local Phi; '",
                   phi_.spec().label(), "' is not");
    cfa_ = optics::ColourFilterArray::bayer(options_.cfa).response();
  }
  if (phi_.local()) {
    weights_ = optics::pixel_weight_stack(phi_, options_.patch_h, options_.patch_w);
    const int64_t t = phi_.period();
    period_ = cfa_.defined() ? std::lcm(t, cfa_.size(1)) : t;
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
  const auto probe = draw(false, std::min<int64_t>(2048, options_.train_patches), probe_rng);
  const auto probes = static_cast<int64_t>(probe.lf.size());
  double sum = 0;
  for (int64_t i = 0; i < probes; i += 128) {  // in parts: large crops take memory
    sum += make_batch(probe.slice(i, std::min(probes, i + 128)), 0).y.sum().item<double>();
  }
  measurement_mean_ =
      sum / static_cast<double>(probes * phi_.measurements() * options_.patch_h * options_.patch_w);
}

PatchDataset::Draw PatchDataset::Draw::slice(int64_t begin, int64_t end) const {
  auto part = [&](const auto& v) {
    using V = std::decay_t<decltype(v)>;
    return v.empty() ? V() : V(v.begin() + begin, v.begin() + end);  // sigma, photons may be empty
  };
  return {part(lf),
          part(y0),
          part(x0),
          part(aug),
          part(window),
          part(gamma),
          part(contrast),
          part(brightness),
          part(sigma),
          part(photons),
          part(read_electrons),
          part(calibration),
          part(placement),
          part(view_sigma),
          part(view_correlated),
          part(gain),
          part(saturation),
          part(channel_order)};
}

PatchDataset::Draw PatchDataset::draw(bool validation, int64_t count, std::mt19937_64& rng) const {
  std::discrete_distribution<int64_t> pick(train_weight_.begin(), train_weight_.end());
  const bool square = options_.patch_h == options_.patch_w && phi_.rows() == phi_.cols();
  std::uniform_int_distribution<int> codes(0, square ? 7 : 3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const bool jitter = !validation && (options_.jitter_gamma > 0 || options_.jitter_contrast > 0 ||
                                      options_.jitter_brightness > 0);
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
    // Draws beyond the original ones only where an option asks for them, so that configs
    // without these options draw exactly the patches they always drew.
    const auto& windows = windows_[k];
    int64_t w = validation ? 0 : 1;
    if (!validation && windows.size() > 2) {
      const auto last = static_cast<int64_t>(windows.size()) - 1;
      w = std::uniform_int_distribution<int64_t>(1, last)(rng);
    }
    d.window.push_back(w);
    double g = 1, c = 1, b = 0;
    if (jitter) {
      g = std::exp(options_.jitter_gamma * unit(rng));
      c = std::exp(options_.jitter_contrast * unit(rng));
      b = options_.jitter_brightness * unit(rng);
    }
    d.gamma.push_back(static_cast<float>(g));
    d.contrast.push_back(static_cast<float>(c));
    d.brightness.push_back(static_cast<float>(b));
  }
  // After the patches' own draws, so that a noise range leaves which patches are drawn alone.
  if (!options_.noise_range.empty()) {
    const double lo = options_.noise_range[0], hi = options_.noise_range[1];
    for (int64_t i = 0; i < count; ++i) {
      d.sigma.push_back(static_cast<float>(lo + (hi - lo) * 0.5 * (unit(rng) + 1.0)));
    }
    if (options_.shot_read_fraction > 0) {
      const double log_lo = std::log(options_.shot_photons_range[0]);
      const double log_hi = std::log(options_.shot_photons_range[1]);
      const double e_lo = options_.read_electrons_range[0], e_hi = options_.read_electrons_range[1];
      for (int64_t i = 0; i < count; ++i) {
        const bool shot = 0.5 * (unit(rng) + 1.0) < options_.shot_read_fraction;
        const double photons = std::exp(log_lo + (log_hi - log_lo) * 0.5 * (unit(rng) + 1.0));
        const double electrons = e_lo + (e_hi - e_lo) * 0.5 * (unit(rng) + 1.0);
        d.photons.push_back(shot ? static_cast<float>(photons) : 0.0f);
        d.read_electrons.push_back(static_cast<float>(electrons));
      }
    }
    if (options_.clean_fraction > 0) {
      for (int64_t i = 0; i < count; ++i) {
        if (0.5 * (unit(rng) + 1.0) >= options_.clean_fraction) continue;
        d.sigma[i] = 0.0f;
        if (!d.photons.empty()) d.photons[i] = 0.0f;  // Gaussian of sigma 0: no noise at all
      }
    }
  }
  // Last, so that configs without calibration ranges draw what they always drew.
  const auto& cal = options_.calibration;
  if (!cal.empty()) {
    const auto h = options_.patch_h, w = options_.patch_w;
    const auto sensor_h = static_cast<int64_t>(std::ceil(cal.vignetting_sensor * h));
    const auto sensor_w = static_cast<int64_t>(std::ceil(cal.vignetting_sensor * w));
    for (int64_t i = 0; i < count; ++i) {
      optics::CalibrationError e;
      e.depth = cal.depth * unit(rng);
      e.angular_shift_u = cal.angular_shift * unit(rng);
      e.angular_shift_v = cal.angular_shift * unit(rng);
      e.shift_y = cal.shift * unit(rng);
      e.shift_x = cal.shift * unit(rng);
      e.period = cal.period * unit(rng);
      e.vignetting = cal.vignetting * 0.5 * (unit(rng) + 1.0);
      const auto y0 = std::uniform_int_distribution<int64_t>(0, sensor_h - h)(rng);
      const auto x0 = std::uniform_int_distribution<int64_t>(0, sensor_w - w)(rng);
      d.calibration.push_back(e);
      d.placement.push_back({y0, x0, sensor_h, sensor_w});
    }
  }
  // Noise in the truth, after every other draw; training patches only.
  if (!validation && !options_.view_noise_range.empty()) {
    const double lo = options_.view_noise_range[0], hi = options_.view_noise_range[1];
    for (int64_t i = 0; i < count; ++i) {
      const bool noisy = 0.5 * (unit(rng) + 1.0) < options_.view_noise_fraction;
      const double sigma = lo + (hi - lo) * 0.5 * (unit(rng) + 1.0);
      const bool correlated = 0.5 * (unit(rng) + 1.0) < options_.view_noise_correlated_fraction;
      d.view_sigma.push_back(noisy ? static_cast<float>(sigma) : 0.0f);
      d.view_correlated.push_back(correlated ? 1.0f : 0.0f);
    }
  }
  // Dim exposures last of all, so that configs without them draw what they always drew.
  if (!validation && options_.dark_fraction > 0) {
    const double log_lo = std::log(options_.dark_gain_range[0]);
    const double log_hi = std::log(options_.dark_gain_range[1]);
    for (int64_t i = 0; i < count; ++i) {
      const bool dark = 0.5 * (unit(rng) + 1.0) < options_.dark_fraction;
      const double gain = std::exp(log_lo + (log_hi - log_lo) * 0.5 * (unit(rng) + 1.0));
      d.gain.push_back(dark ? static_cast<float>(gain) : 1.0f);
    }
  }
  // Chroma after everything else, so that configs without it draw what they always drew.
  if (!validation && options_.jitter_saturation > 0) {
    for (int64_t i = 0; i < count; ++i) {
      d.saturation.push_back(static_cast<float>(std::exp(options_.jitter_saturation * unit(rng))));
    }
  }
  if (!validation && options_.permute_channels) {
    std::uniform_int_distribution<int> orders(0, 5);
    for (int64_t i = 0; i < count; ++i) d.channel_order.push_back(orders(rng));
  }
  return d;
}

train::Batch PatchDataset::make_batch(const Draw& d, uint64_t noise_seed) const {
  const int64_t b = static_cast<int64_t>(d.lf.size());
  const int64_t h = options_.patch_h, w = options_.patch_w;
  std::vector<torch::Tensor> patches, responses;
  std::vector<int64_t> phases, code_phases;
  patches.reserve(b);
  const int64_t nu = phi_.rows(), nv = phi_.cols();
  for (int64_t i = 0; i < b; ++i) {
    const Window& win = windows_[d.lf[i]][d.window[i]];
    auto p = lfs_[d.lf[i]]
                 .data()
                 .slice(1, win.u0, win.u0 + win.step * (nu - 1) + 1, win.step)
                 .slice(2, win.v0, win.v0 + win.step * (nv - 1) + 1, win.step)
                 .slice(3, d.y0[i], d.y0[i] + h)
                 .slice(4, d.x0[i], d.x0[i] + w);
    if (d.gamma[i] != 1.0f || d.contrast[i] != 1.0f || d.brightness[i] != 0.0f) {
      p = p.pow(d.gamma[i]);
      const auto mean = p.mean();
      p = ((p - mean) * d.contrast[i] + mean + d.brightness[i]).clamp(0.0, 1.0);
    }
    if (!d.saturation.empty() && d.saturation[i] != 1.0f && p.size(0) == 3) {
      const auto grey = p.mean(0, true);
      p = (grey + (p - grey) * d.saturation[i]).clamp(0.0, 1.0);
    }
    if (!d.channel_order.empty() && d.channel_order[i] != 0 && p.size(0) == 3) {
      static const int64_t kOrders[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2},
                                            {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
      const auto* o = kOrders[d.channel_order[i]];
      p = p.index_select(0, torch::tensor({o[0], o[1], o[2]}, torch::kInt64));
    }
    if (!d.gain.empty() && d.gain[i] != 1.0f) p = p * d.gain[i];
    if (!d.view_sigma.empty() && d.view_sigma[i] > 0) {
      auto gen = torch::make_generator<at::CPUGeneratorImpl>(
          noise_seed ^ (0x766965776eULL + static_cast<uint64_t>(i)));
      const bool correlated = d.view_correlated[i] > 0;
      const auto noise = view_noise(p.sizes(), correlated ? options_.view_noise_angular : 0,
                                    correlated ? options_.view_noise_spatial : 0, gen);
      p = (p + noise * d.view_sigma[i]).clamp(0.0, 1.0);
    }
    patches.push_back(augment_patch(p, d.aug[i]));
    code_phases.push_back(phi_.local() ? optics::patch_phase(phi_, d.y0[i], d.x0[i]) : 0);
    // The net's phase: over the period of the code and the CFA together.
    phases.push_back(cfa_.defined() ? (d.y0[i] % period_) * period_ + d.x0[i] % period_
                                    : code_phases.back());
    if (cfa_.defined()) {
      const int64_t p = cfa_.size(1);
      responses.push_back(cfa_.roll({-(d.y0[i] % p), -(d.x0[i] % p)}, {1, 2})
                              .repeat({1, (h + p - 1) / p, (w + p - 1) / p})
                              .slice(1, 0, h)
                              .slice(2, 0, w));
    }
  }
  auto target = torch::stack(patches, 0).contiguous();  // (B, C, U, V, h, w)
  auto phase = torch::tensor(phases, torch::kInt64);
  torch::Tensor y;
  if (phi_.local()) {
    // Each sensor pixel sums its own rays: y[b, n, y, x] = sum_uv W[phase_b, n, u, v, y, x] L[b, u,
    // v, y, x].
    torch::Tensor weights;
    if (d.calibration.empty()) {
      weights = weights_.index_select(0, torch::tensor(code_phases, torch::kInt64));
    } else {
      // Each patch's own camera: the code at the patch's origin, the vignetting at its place.
      std::vector<torch::Tensor> own;
      own.reserve(b);
      for (int64_t i = 0; i < b; ++i) {
        own.push_back(optics::perturbed_pixel_weights(phi_, d.calibration[i], d.y0[i], d.x0[i], h,
                                                      w, d.placement[i]));
      }
      weights = torch::stack(own);
    }
    // Behind a CFA each pixel records its own colour of what the code measures (optics::
    // mosaic); the code being linear, that is the code applied to the rays' colour mix at
    // that pixel.
    const auto rays =
        cfa_.defined() ? (target * torch::stack(responses).unsqueeze(2).unsqueeze(3)).sum(1, true)
                       : target;  // (B, 1, U, V, h, w), broadcast over N
    y = (weights * rays).sum({2, 3}).reshape({b, -1});
  } else {
    y = torch::matmul(target.reshape({b, -1}), matrix_.t());
  }
  if (!options_.effects.empty()) y = optics::apply_sensor_effects(y, options_.effects, noise_seed);
  torch::Tensor noise;
  if (!d.sigma.empty()) {
    noise = torch::tensor(d.sigma, torch::kFloat32);
    auto gen = torch::make_generator<at::CPUGeneratorImpl>(noise_seed ^ 0x6e6f697365ULL);
    auto spread = noise.unsqueeze(1).expand_as(y);
    if (!d.photons.empty()) {
      // Shot and read noise: each measurement's own sigma, and the patch's equivalent sigma
      // for the net.
      auto photons = torch::tensor(d.photons, torch::kFloat32);
      const auto shot = photons > 0;
      photons = photons.clamp_min(1e-3);
      const auto read = (torch::tensor(d.read_electrons, torch::kFloat32) / photons).square();
      const auto signal = y.clamp_min(0.0);
      const auto pixel = (signal / photons.unsqueeze(1) + read.unsqueeze(1)).sqrt();
      spread = torch::where(shot.unsqueeze(1), pixel, spread);
      noise = torch::where(shot, (signal.mean(1) / photons + read).sqrt(), noise);
    }
    y = y + torch::randn(y.sizes(), gen, y.options()) * spread;
  }
  return {y.contiguous(), phase, target, noise};
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
  auto part = [](const train::Batch& b, int64_t from, int64_t to) {
    return train::Batch{b.y.slice(0, from, to).contiguous(), b.phase.slice(0, from, to),
                        b.target.slice(0, from, to).contiguous(),
                        b.noise.defined() ? b.noise.slice(0, from, to) : b.noise};
  };
  if (!options_.effects.empty() || !options_.noise_range.empty()) {
    // The noise of one patch depends on the whole batch's draw: simulate it all, keep a part.
    return part(make_batch(d, noise_seed), begin, end);
  }
  if (begin == end) {
    // A last batch smaller than the world leaves this rank nothing: an empty batch.
    return part(make_batch(d.slice(0, 1), noise_seed), 0, 0);
  }
  return make_batch(d.slice(begin, end), noise_seed);
}

void PatchDataset::set_shard(int64_t rank, int64_t world) {
  LFNET_CHECK_AS(ConfigError, world >= 1 && rank >= 0 && rank < world, "bad shard: rank ", rank,
                 " of ", world);
  if (prefetch_.valid()) prefetch_.get();  // prepared for the old shard
  shard_rank_ = rank;
  shard_world_ = world;
}

}  // namespace lfnet::data

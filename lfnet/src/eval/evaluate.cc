#include "lfnet/eval/evaluate.h"

#include <cmath>
#include <optional>

#include "lfnet/core/error.h"
#include "lfnet/core/file_backed.h"
#include "lfnet/core/json.h"
#include "lfnet/core/metrics.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/optics/noise_estimate.h"

namespace lfnet::eval {

namespace {
nlohmann::json base_record(const optics::Phi& phi, const std::string& method, const EvalOptions& o,
                           int64_t patches, double seconds) {
  return {{"method", method},
          {"stride", o.reconstruct.stride},
          {"patch", {o.reconstruct.patch_h, o.reconstruct.patch_w}},
          {"phi", phi.spec().to_json()},
          {"measurements", phi.measurements()},
          {"noise_sigma", o.effects.gaussian ? o.effects.gaussian->sigma : 0.0},
          {"effects", o.effects.to_json()},
          {"mode", optics::to_string(o.mode)},
          {"patches", patches},
          {"seconds", seconds},
          {"threads", thread_count()},
          {"device", "cpu"}};
}
// Every patch of `grid` measured on its own (per_patch mode), in bands of `band` grid rows:
// memory is N h w floats per patch.
std::vector<optics::PatchMeasurements> measure_bands(const LightField& truth,
                                                     const optics::Phi& phi, const PatchGrid& grid,
                                                     const EvalOptions& options, int64_t band) {
  std::vector<optics::PatchMeasurements> bands;
  for (int64_t r0 = 0; r0 < grid.rows(); r0 += band) {
    bands.push_back(optics::measure_patches(phi, truth.data(), grid,
                                            optics::SimulationMode::kPerPatch, options.effects,
                                            options.seed, r0, std::min(grid.rows(), r0 + band)));
  }
  return bands;
}

// The mean of every measurement of `bands`.
double mean_of(const std::vector<optics::PatchMeasurements>& bands) {
  double sum = 0, count = 0;
  for (const auto& b : bands) {
    sum += b.values.sum().item<double>();
    count += static_cast<double>(b.values.numel());
  }
  return count > 0 ? sum / count : 0.0;
}

// The sensor image of a grey light field held in 16-bit codes, simulated in bands of rows that
// start on the code's period, so that no float32 copy of the whole light field is made. A local
// Phi measures each pixel from its own rays: the bands give the whole image's sensor exactly.
torch::Tensor coded_forward(const optics::Phi& phi, const LightFieldViews& truth) {
  LFNET_CHECK(phi.local() && truth.coded() && truth.channels() == 1,
              "coded_forward: a local Phi and grey views in 16-bit codes");
  const int64_t h = truth.height(), w = truth.width(), period = phi.period();
  // About 2^22 values a band.
  const int64_t per_row = truth.rows() * truth.cols() * w;
  const int64_t band =
      std::max<int64_t>(1, (int64_t{1} << 22) / std::max<int64_t>(per_row * period, 1)) * period;
  auto sensor = torch::empty({phi.measurements(), h, w});
  const auto codes = truth.raw()[0];  // (U, V, H, W)
  for (int64_t y0 = 0; y0 < h; y0 += band) {
    const int64_t y1 = std::min(h, y0 + band);
    sensor.slice(1, y0, y1).copy_(phi.forward(decode_codes(codes.slice(2, y0, y1))));
  }
  return sensor;
}

// Shot and read noise are named in records by the Gaussian sigma of the same variance at the
// measurements' mean `signal` (docs/acquisition.md), which is what a noise-aware net reads.
void add_equivalent_sigma(nlohmann::json& record, const EvalOptions& o, double signal) {
  if (o.effects.shot || o.effects.read)
    record["equivalent_sigma"] = o.effects.equivalent_sigma(signal);
}
}  // namespace

// PSNR may be +inf for a perfect view; JSON has no inf, so such values are written as null.
nlohmann::json score(const LightFieldViews& estimate, const LightFieldViews& truth) {
  auto pv = per_view_psnr(estimate, truth);
  nlohmann::json table = nlohmann::json::array();
  for (int64_t u = 0; u < pv.size(0); ++u) {
    nlohmann::json row = nlohmann::json::array();
    for (int64_t v = 0; v < pv.size(1); ++v) row.push_back(finite_or_null(pv[u][v].item<double>()));
    table.push_back(row);
  }
  return {{"psnr_db", finite_or_null(psnr(estimate, truth))},
          {"ssim", ssim(estimate, truth)},
          {"per_view_psnr_db", table}};
}

nlohmann::json per_frame_psnr(const nlohmann::json& per_view_psnr_db, int64_t frames) {
  const auto rows = static_cast<int64_t>(per_view_psnr_db.size());
  LFNET_CHECK(frames >= 1 && rows % frames == 0, "cannot split ", rows, " view rows into ", frames,
              " frames");
  const int64_t per_frame = rows / frames;
  nlohmann::json out = nlohmann::json::array();
  for (int64_t t = 0; t < frames; ++t) {
    double mse = 0;
    int64_t views = 0;
    for (int64_t u = t * per_frame; u < (t + 1) * per_frame; ++u) {
      for (const auto& psnr_db : per_view_psnr_db.at(static_cast<size_t>(u))) {
        if (!psnr_db.is_null()) mse += std::pow(10.0, -psnr_db.get<double>() / 10.0);
        ++views;
      }
    }
    out.push_back(finite_or_null(-10.0 * std::log10(mse / static_cast<double>(views))));
  }
  return out;
}

namespace {

// Colour and luma scores of a colour reconstruction.
nlohmann::json colour_score(const LightField& estimate, const LightField& truth) {
  auto out = score(estimate, truth);
  out["luma_psnr_db"] = finite_or_null(psnr(estimate.grey(), truth.grey()));
  return out;
}

// evaluate() behind a colour filter array: the three colours' sensor images mosaicked into one
// (then the sensor effects), and either a colour net reconstructs the colour light field from
// it (`image`), or the mosaicked light field is reconstructed and its views demosaiced.
EvalResult evaluate_cfa(const LightField& truth, const optics::Phi& phi, const std::string& method,
                        const recon::PatchSolver& solver, const EvalOptions& options,
                        const recon::ProgressCallback& progress, const recon::ImageSolver& image) {
  const auto& cfa = *options.cfa;
  LFNET_CHECK_AS(ConfigError, truth.channels() == 3,
                 "a colour filter array needs a colour light field, got ", truth.channels(),
                 " channel(s)");
  LFNET_CHECK_AS(ConfigError, options.mode == optics::SimulationMode::kSensor,
                 "a colour filter array is simulated in sensor mode only");
  // A whole-image method other than a (colour) net, such as pinv-nlm, reconstructs grey images:
  // refused before the work, not after it.
  LFNET_CHECK_AS(ConfigError, image ? method == "net" : static_cast<bool>(solver), "method '",
                 method,
                 "' reconstructs grey sensor images; behind a colour filter array use pinv, "
                 "adjoint, no-parallax or a colour model");
  const auto& ro = options.reconstruct;
  ro.validate();
  const auto colour = optics::perturbed_forward(phi, options.camera_error, truth.data());
  auto sensor =
      optics::apply_sensor_effects(optics::mosaic(colour, cfa)[0], options.effects, options.seed);
  if (options.flat_field.defined()) sensor = optics::apply_flat_field(sensor, options.flat_field);
  const double signal = sensor.mean().item<double>();
  Stopwatch clock;  // the reconstruction and the demosaicing, not the simulation
  torch::Tensor estimate;
  if (image) {
    estimate = image(sensor, options.effects.equivalent_sigma(signal));  // (3, U, V, H, W)
    const int64_t pixels = truth.height() * truth.width();
    if (progress) progress(pixels, pixels);
  } else {
    const auto mosaicked = recon::reconstruct_sensor(phi, sensor, solver, ro, progress);
    estimate = optics::demosaic(mosaicked[0], cfa, options.demosaic);  // (3, U, V, H, W)
  }
  LFNET_CHECK(estimate.dim() == 5 && estimate.size(0) == 3, "method '", method, "' returned ",
              estimate.sizes(), " behind a colour filter array, not (3, U, V, H, W)");
  if (ro.clamp) estimate.clamp_(0.0, 1.0);
  const double seconds = clock.seconds();
  const PatchGrid grid(truth.height(), truth.width(), ro.patch_h, ro.patch_w, ro.stride);
  auto record = base_record(phi, method, options, image ? 0 : grid.size(), seconds);
  if (image) record["whole_image"] = true;
  add_equivalent_sigma(record, options, signal);
  record["cfa"] = cfa.to_json();
  if (!image) record["demosaic"] = optics::to_string(options.demosaic);
  if (!options.camera_error.empty()) record["camera_error"] = options.camera_error.to_json();
  if (options.flat_field.defined()) record["flat_field"] = true;
  record.update(colour_score(LightField(estimate), truth));
  return {estimate, record};
}

}  // namespace

EvalResult evaluate(const LightFieldViews& truth, const optics::Phi& phi, const std::string& method,
                    const recon::PatchSolver& solver, const EvalOptions& options,
                    const recon::ProgressCallback& progress, const recon::ImageSolver& image) {
  if (options.cfa) {
    return evaluate_cfa(truth.decode(), phi, method, solver, options, progress, image);
  }
  LFNET_CHECK_AS(ConfigError, truth.channels() == 1, "evaluation takes a grey light field");
  const auto& ro = options.reconstruct;
  ro.validate();
  PatchGrid grid(truth.height(), truth.width(), ro.patch_h, ro.patch_w, ro.stride);
  torch::Tensor estimate;
  std::optional<double> estimated;  // the noise sigma estimated from the sensor image
  double signal = 0;                // the measurements' mean
  Stopwatch clock;
  LFNET_CHECK_AS(ConfigError,
                 options.camera_error.empty() || options.mode == optics::SimulationMode::kSensor,
                 "a camera error is simulated in sensor mode only");
  LFNET_CHECK_AS(ConfigError,
                 !options.flat_field.defined() || options.mode == optics::SimulationMode::kSensor,
                 "a flat field corrects a sensor image: sensor mode only");
  if (options.mode == optics::SimulationMode::kSensor) {
    // The camera's own Phi (the nominal one without a camera error), then its effects. Views
    // in 16-bit codes are coded a band at a time where the Phi allows.
    const bool banded = truth.coded() && phi.local() && options.camera_error.empty();
    auto sensor = optics::apply_sensor_effects(
        banded ? coded_forward(phi, truth)
               : optics::perturbed_forward(phi, options.camera_error, truth.decode().data()[0]),
        options.effects, options.seed);
    // The camera's flat field, measured beforehand, undoes its gain across the sensor.
    if (options.flat_field.defined()) sensor = optics::apply_flat_field(sensor, options.flat_field);
    signal = sensor.mean().item<double>();
    // A file-backed truth (core/file_backed.h) leaves memory while the method runs, and comes
    // back from the file when it is scored.
    page_out(truth.raw());
    release_free_memory();  // the simulation's working memory, before the reconstruction's
    clock.reset();          // time the reconstruction, not the simulation
    if (image) {
      // Shot and read noise reach a noise-aware method as the Gaussian sigma of the same
      // variance at the sensor image's mean signal.
      if (options.estimate_noise) estimated = optics::estimate_equivalent_sigma(phi, sensor);
      estimate = image(sensor, estimated.value_or(options.effects.equivalent_sigma(signal)));
      // A whole image has no patches: its progress counts its pixels.
      const int64_t pixels = truth.height() * truth.width();
      if (progress) progress(pixels, pixels);
    } else {
      estimate = recon::reconstruct_sensor(phi, sensor, solver, ro, progress);
    }
  } else {
    // Simulate every band up front so only the reconstruction is timed.
    const int64_t band = recon::band_rows(grid, ro);
    const auto bands = measure_bands(truth.decode(), phi, grid, options, band);
    signal = mean_of(bands);
    auto source = [&](int64_t r0, int64_t) { return bands[r0 / band]; };
    clock.reset();
    estimate = recon::reconstruct_patches(phi, grid, source, solver, ro, progress);
  }
  const double seconds = clock.seconds();
  release_free_memory();                // the reconstruction's working memory, before the scores'
  const LightFieldViews est(estimate);  // float32, or 16-bit codes (options.reconstruct.coded)
  // A whole-image solver (the lfnet architecture) uses no patches: the record says so, and
  // keeps the stride it was asked for only as a setting.
  const bool whole_image = image && options.mode == optics::SimulationMode::kSensor;
  auto record = base_record(phi, method, options, whole_image ? 0 : grid.size(), seconds);
  if (whole_image) record["whole_image"] = true;
  add_equivalent_sigma(record, options, signal);
  if (estimated) record["noise_sigma_estimated"] = *estimated;
  if (!options.camera_error.empty()) record["camera_error"] = options.camera_error.to_json();
  if (options.flat_field.defined()) record["flat_field"] = true;
  record.update(score(est, truth));
  return {estimate, record};
}

EvalResult evaluate_no_parallax(const LightField& truth, const optics::Phi& phi,
                                const EvalOptions& options) {
  Stopwatch clock;
  auto est = truth.angular_mean();
  const double seconds = clock.seconds();
  auto record = base_record(phi, "no-parallax", options, 0, seconds);
  if (options.cfa) {
    // The truth's own colours: a conventional colour camera, demosaicing aside.
    record["cfa"] = options.cfa->to_json();
    record.update(colour_score(est, truth));
    return {est.data(), record};
  }
  if (options.effects.shot || options.effects.read) {
    // The measurements' mean as the other methods see it, so that their records agree.
    double signal = 0;
    if (options.mode == optics::SimulationMode::kSensor) {
      signal = optics::simulate_sensor(phi, truth.data()[0], options.effects, options.seed)
                   .mean()
                   .item<double>();
    } else {
      const auto& ro = options.reconstruct;
      const PatchGrid grid(truth.height(), truth.width(), ro.patch_h, ro.patch_w, ro.stride);
      signal = mean_of(measure_bands(truth, phi, grid, options, recon::band_rows(grid, ro)));
    }
    add_equivalent_sigma(record, options, signal);
  }
  record.update(score(est, truth));
  return {est.data(), record};
}

}  // namespace lfnet::eval

// Time-coded cameras: codes that change within one exposure of T sub-frames, and still cameras
// filming one (docs/acquisition.md, "Time-coded cameras").
#include <cmath>
#include <nlohmann/json.hpp>
#include <numeric>

#include "lfnet/core/error.h"
#include "lfnet/optics/counter_rng.h"
#include "models.h"

namespace lfnet::optics::detail {

namespace {

// Each sub-frame's aperture a_n(t, u, v): (N, T, U, V), uniform in (0, 1) or binary with at
// least one open view per sub-frame (a closed aperture would record nothing of that sub-frame).
torch::Tensor aperture_codes(const PhiSpec& spec, const std::string& kind) {
  const int64_t frames = spec.frames, uv = spec.rows * spec.cols;
  const CounterRng rng(spec.seed, stream::kTimeApertureCode);
  auto a = torch::empty({spec.n, frames, uv}, torch::kFloat64);
  auto acc = a.accessor<double, 3>();
  for (int64_t n = 0; n < spec.n; ++n) {
    for (int64_t t = 0; t < frames; ++t) {
      const uint64_t base = static_cast<uint64_t>((n * frames + t) * uv);
      int64_t any = 0, best = 0;
      for (int64_t k = 0; k < uv; ++k) {
        const double draw = rng.uniform(base + static_cast<uint64_t>(k));
        acc[n][t][k] = kind == "uniform" ? draw : (draw < 0.5 ? 1.0 : 0.0);
        any += acc[n][t][k] > 0 ? 1 : 0;
        if (draw < rng.uniform(base + static_cast<uint64_t>(best))) best = k;
      }
      if (any == 0) acc[n][t][best] = 1.0;
    }
  }
  return a.view({spec.n, frames, spec.rows, spec.cols});
}

struct ExposureParams {
  int64_t period = 4;  // P: the exposure code's tile is P x P pixels
  double open = 0.5;   // fraction of the T sub-frames each pixel integrates
  bool shared = true;  // one shutter per pixel: its N measurements integrate the same sub-frames
};

// Each pixel's exposure e_n(t, y, x) over a P x P tile: (N, T, P, P) in {0, 1}. Every pixel of
// every measurement integrates max(1, round(open T)) of the T sub-frames, drawn by a seeded
// shuffle, so each pixel sees part of the exposure and no sub-frame is favoured; with `shared`
// a pixel's N measurements take measurement 0's.
torch::Tensor exposure_codes(const PhiSpec& spec, const ExposureParams& p) {
  const int64_t period = p.period;
  const double open = p.open;
  const int64_t frames = spec.frames, cells = period * period;
  const int64_t on = std::max<int64_t>(1, std::llround(open * static_cast<double>(frames)));
  const CounterRng rng(spec.seed, stream::kExposureCode);
  auto e = torch::zeros({spec.n, frames, period, period}, torch::kFloat64);
  auto acc = e.accessor<double, 4>();
  std::vector<int64_t> order(static_cast<size_t>(frames));
  for (int64_t n = 0; n < (p.shared ? 1 : spec.n); ++n) {
    for (int64_t cell = 0; cell < cells; ++cell) {
      std::iota(order.begin(), order.end(), 0);
      const uint64_t base = static_cast<uint64_t>((n * cells + cell) * frames);
      for (int64_t i = frames - 1; i > 0; --i) {
        const auto j = static_cast<int64_t>(rng.bits(base + static_cast<uint64_t>(i)) %
                                            static_cast<uint64_t>(i + 1));
        std::swap(order[static_cast<size_t>(i)], order[static_cast<size_t>(j)]);
      }
      for (int64_t k = 0; k < on; ++k)
        acc[n][order[static_cast<size_t>(k)]][cell / period][cell % period] = 1.0;
    }
  }
  if (p.shared) e.copy_(e[0].unsqueeze(0).expand_as(e).clone());
  return e;
}

ExposureParams read_exposure(JsonReader& r) {
  ExposureParams p;
  r.get("period", p.period);
  r.get("open", p.open);
  r.get("shared", p.shared);
  LFNET_CHECK_AS(ConfigError, p.period >= 1 && p.period <= 64, r.path_of("period"),
                 ": the exposure tile period P must be in 1..64, got ", p.period);
  LFNET_CHECK_AS(ConfigError, p.open > 0 && p.open <= 1, r.path_of("open"),
                 ": the open fraction of sub-frames must be in (0, 1], got ", p.open);
  return p;
}

std::string read_aperture_kind(JsonReader& r) {
  std::string kind = "binary";  // a_n(t, u, v): "binary" {0, 1} (a mask that flips) or "uniform"
  r.get("code", kind);
  LFNET_CHECK_AS(ConfigError, kind == "uniform" || kind == "binary", r.path_of("code"),
                 ": expected \"uniform\" or \"binary\", got \"", kind, "\"");
  return kind;
}

// (N, T, U, V, P, P) -> the local code (N, T U, V, P, P), normalised for a white sequence.
std::unique_ptr<Phi> local_time_phi(const PhiSpec& resolved, const torch::Tensor& code) {
  const auto& s = code.sizes();
  auto stacked = code.reshape({s[0], s[1] * s[2], s[3], s[4], s[5]});
  return std::make_unique<LocalPhi>(resolved, normalise_white(stacked));
}

}  // namespace

std::unique_ptr<Phi> make_time_aperture(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  const auto kind = read_aperture_kind(r);
  r.finish();
  PhiSpec resolved = spec;
  resolved.params = {{"code", kind}};
  auto a = aperture_codes(spec, kind);  // (N, T, U, V)
  return local_time_phi(resolved, a.view({spec.n, spec.frames, spec.rows, spec.cols, 1, 1}));
}

std::unique_ptr<Phi> make_coded_exposure(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  const auto p = read_exposure(r);
  std::string base;  // a still local model whose pixels are exposure-coded ("": open pixels)
  nlohmann::json base_params = nlohmann::json::object();
  r.get("base", base);
  r.get("base_params", base_params);
  r.finish();
  PhiSpec resolved = spec;
  resolved.params = {{"period", p.period}, {"open", p.open}, {"shared", p.shared}};
  // The base camera's weights (N, 1, U, V, B, B), B its period (1: open pixels).
  torch::Tensor weights = torch::ones({spec.n, 1, spec.rows, spec.cols, 1, 1}, torch::kFloat64);
  if (!base.empty()) {
    LFNET_CHECK_AS(ConfigError, !phi_is_time_coded(base) || base == "calibrated", r.path_of("base"),
                   ": the base is a still camera, not '", base, "'");
    PhiSpec still = spec;
    still.name = base;
    still.frames = 1;
    still.params = base_params;
    const auto camera = make_phi(still);
    LFNET_CHECK_AS(ConfigError, camera->local(), r.path_of("base"), ": '", base,
                   "' mixes pixels; an exposure code needs a local camera");
    const int64_t b = camera->period();
    weights = camera->pixel_weights(0, 0, b, b, torch::kFloat64).unsqueeze(1);
    resolved.params["base"] = base;
    resolved.params["base_params"] = camera->spec().params;
  }
  // Both codes on their common period.
  const int64_t period = std::lcm(p.period, weights.size(-1));
  check_code_size(spec, spec.n * spec.coded_rows() * spec.cols * period * period,
                  "an exposure code");
  auto e = exposure_codes(spec, p)
               .view({spec.n, spec.frames, 1, 1, p.period, p.period})
               .repeat({1, 1, 1, 1, period / p.period, period / p.period});
  const int64_t b = weights.size(-1);
  auto w = weights.repeat({1, 1, 1, 1, period / b, period / b});
  return local_time_phi(resolved, e * w);
}

std::unique_ptr<Phi> make_exposure_aperture(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  const auto kind = read_aperture_kind(r);
  const auto p = read_exposure(r);
  r.finish();
  check_code_size(spec, spec.n * spec.coded_rows() * spec.cols * p.period * p.period,
                  "an exposure and aperture code");
  PhiSpec resolved = spec;
  resolved.params = {{"code", kind}, {"period", p.period}, {"open", p.open}, {"shared", p.shared}};
  auto a = aperture_codes(spec, kind).view({spec.n, spec.frames, spec.rows, spec.cols, 1, 1});
  auto e = exposure_codes(spec, p).view({spec.n, spec.frames, 1, 1, p.period, p.period});
  return local_time_phi(resolved, a * e);
}

}  // namespace lfnet::optics::detail

namespace lfnet::optics {

bool same_response(const Phi& a, const Phi& b) {
  if (!a.local() || !b.local() || a.rows() != b.rows() || a.cols() != b.cols() ||
      a.measurements() != b.measurements()) {
    return false;
  }
  const int64_t p = std::lcm(a.period(), b.period());
  const auto wa = a.pixel_weights(0, 0, p, p, torch::kFloat64);
  const auto wb = b.pixel_weights(0, 0, p, p, torch::kFloat64);
  const double top = std::max(wa.abs().max().item<double>(), wb.abs().max().item<double>());
  return (wa - wb).abs().max().item<double>() <= 1e-9 * top;
}

std::unique_ptr<Phi> still_equivalent(const Phi& phi) {
  auto spec = phi.spec();
  if (phi.frames() == 1) return make_phi(spec);
  // A still model over sub-frames holds the same weights in each: its sum is the model.
  spec.frames = 1;
  if (!phi_is_time_coded(spec.name)) return make_phi(spec);
  LFNET_CHECK_AS(ConfigError, phi.local(), "Phi '", phi.spec().label(),
                 "' mixes pixels: it has no still equivalent");
  const int64_t p = phi.period(), t = phi.frames();
  auto w = phi.pixel_weights(0, 0, p, p, torch::kFloat64);  // (N, T U, V, P, P)
  auto sum = w.view({w.size(0), t, w.size(1) / t, w.size(2), p, p}).sum(1).contiguous();
  PhiSpec still;
  still.name = "calibrated";
  still.n = spec.n;
  still.rows = spec.rows;
  still.cols = spec.cols;
  still.params = {{"period", p},
                  {"weights", std::vector<double>(sum.data_ptr<double>(),
                                                  sum.data_ptr<double>() + sum.numel())},
                  {"normalise", false},
                  {"source", "still equivalent of " + phi.spec().label()}};
  return make_phi(still);
}

}  // namespace lfnet::optics

namespace lfnet::optics::detail {

std::unique_ptr<Phi> still_over_frames(const Phi& still, const PhiSpec& spec) {
  LFNET_CHECK_AS(ConfigError, still.local(), "Phi '", still.spec().label(),
                 "' mixes pixels and has no time-coded form: use a local model with @T");
  const int64_t p = still.period();
  auto w = still.pixel_weights(0, 0, p, p, torch::kFloat64);  // (N, U, V, P, P)
  // The same weights in every sub-frame, each a T-th: a white sequence still measures 1.
  auto code = w.unsqueeze(1).expand({w.size(0), spec.frames, w.size(1), w.size(2), p, p}) /
              static_cast<double>(spec.frames);
  PhiSpec resolved = still.spec();
  resolved.frames = spec.frames;
  const auto& s = code.sizes();
  return std::make_unique<LocalPhi>(resolved, code.reshape({s[0], s[1] * s[2], s[3], p, p}));
}

}  // namespace lfnet::optics::detail

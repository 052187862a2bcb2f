// The local models besides asp: a coded mask in the camera body, a coded aperture, lenslets.
#include <cmath>
#include <numeric>

#include "lfnet/core/error.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/counter_rng.h"
#include "models.h"

namespace lfnet::optics::detail {

std::unique_ptr<Phi> make_mask(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  int64_t period = 9;  // T: the code tile is T x T pixels, so Phi repeats every T pixels
  int64_t shift = 1;   // s: pixels the mask's shadow moves per view step
  double open = 0.5;   // fraction of open cells of each tile
  r.get("period", period);
  r.get("shift", shift);
  r.get("open", open);
  r.finish();
  LFNET_CHECK_AS(ConfigError, period >= 1 && period <= 64, r.path_of("period"),
                 ": the tile period T must be in 1..64, got ", period);
  LFNET_CHECK_AS(ConfigError, open > 0 && open <= 1, r.path_of("open"),
                 ": the open fraction must be in (0, 1], got ", open);
  const int64_t t = period, cells = t * t;
  check_code_size(spec, spec.n * spec.rows * spec.cols * cells, "a mask code");
  const auto open_cells = std::max<int64_t>(1, std::llround(open * static_cast<double>(cells)));

  // Each exposure's tile: exactly `open_cells` open cells, placed by a seeded Fisher-Yates shuffle.
  const CounterRng rng(spec.seed, stream::kMaskCode);
  auto tiles = torch::zeros({spec.n, t, t}, torch::kFloat64);
  auto tile_acc = tiles.accessor<double, 3>();
  for (int64_t n = 0; n < spec.n; ++n) {
    std::vector<int64_t> order(static_cast<size_t>(cells));
    std::iota(order.begin(), order.end(), 0);
    for (int64_t i = cells - 1; i > 0; --i) {
      const auto j = static_cast<int64_t>(rng.bits(static_cast<uint64_t>(n * cells + i)) %
                                          static_cast<uint64_t>(i + 1));
      std::swap(order[static_cast<size_t>(i)], order[static_cast<size_t>(j)]);
    }
    for (int64_t k = 0; k < open_cells; ++k) {
      const int64_t cell = order[static_cast<size_t>(k)];
      tile_acc[n][cell / t][cell % t] = 1.0;
    }
  }
  // M_n(u, v, y, x) = c_n((y + s (u - uc)) mod T, (x + s (v - vc)) mod T), uc, vc the
  // central view (rounded down for even grids).
  const int64_t uc = (spec.rows - 1) / 2, vc = (spec.cols - 1) / 2;
  auto code = torch::empty({spec.n, spec.rows, spec.cols, t, t}, torch::kFloat64);
  auto acc = code.accessor<double, 5>();
  auto wrap = [t](int64_t i) { return ((i % t) + t) % t; };
  for (int64_t n = 0; n < spec.n; ++n) {
    for (int64_t u = 0; u < spec.rows; ++u) {
      for (int64_t v = 0; v < spec.cols; ++v) {
        for (int64_t y = 0; y < t; ++y) {
          for (int64_t x = 0; x < t; ++x) {
            acc[n][u][v][y][x] =
                tile_acc[n][wrap(y + shift * (u - uc))][wrap(x + shift * (v - vc))];
          }
        }
      }
    }
  }
  PhiSpec resolved = spec;
  resolved.params = {{"period", period}, {"shift", shift}, {"open", open}};
  return std::make_unique<LocalPhi>(resolved, normalise_white(code));
}

std::unique_ptr<Phi> make_aperture(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  std::string code_kind = "uniform";  // a_n(u, v): "uniform" in [0, 1) or "binary" {0, 1}
  r.get("code", code_kind);
  r.finish();
  LFNET_CHECK_AS(ConfigError, code_kind == "uniform" || code_kind == "binary", r.path_of("code"),
                 ": expected \"uniform\" or \"binary\", got \"", code_kind, "\"");
  const int64_t uv = spec.rows * spec.cols;
  const CounterRng rng(spec.seed, stream::kApertureCode);
  auto a = torch::empty({spec.n, uv}, torch::kFloat64);
  auto acc = a.accessor<double, 2>();
  for (int64_t n = 0; n < spec.n; ++n) {
    int64_t nearest_open = 0;
    double any = 0;
    for (int64_t k = 0; k < uv; ++k) {
      const double draw = rng.uniform(static_cast<uint64_t>(n * uv + k));
      acc[n][k] = code_kind == "uniform" ? draw : (draw < 0.5 ? 1.0 : 0.0);
      any += acc[n][k];
      if (draw < rng.uniform(static_cast<uint64_t>(n * uv + nearest_open))) nearest_open = k;
    }
    // A shot through a fully closed binary aperture records nothing: open one view.
    if (any == 0) acc[n][nearest_open] = 1.0;
  }
  PhiSpec resolved = spec;
  resolved.params = {{"code", code_kind}};
  auto code = normalise_white(a.view({spec.n, spec.rows, spec.cols, 1, 1}));
  return std::make_unique<LocalPhi>(resolved, code);
}

std::unique_ptr<Phi> make_lenslet(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  r.finish();
  // Pixel (y, x) of a U x V super-pixel sees view (y mod U, x mod V) in channel 0; channel n
  // sees the view n steps further in row-major order, so N = U V records every view.
  const int64_t uv = spec.rows * spec.cols;
  const int64_t t = std::lcm(spec.rows, spec.cols);
  check_code_size(spec, spec.n * spec.rows * spec.cols * t * t, "a lenslet code");
  auto code = torch::zeros({spec.n, spec.rows, spec.cols, t, t}, torch::kFloat64);
  auto acc = code.accessor<double, 5>();
  for (int64_t n = 0; n < spec.n; ++n) {
    for (int64_t y = 0; y < t; ++y) {
      for (int64_t x = 0; x < t; ++x) {
        const int64_t k = ((y % spec.rows) * spec.cols + (x % spec.cols) + n) % uv;
        acc[n][k / spec.cols][k % spec.cols][y][x] = 1.0;
      }
    }
  }
  PhiSpec resolved = spec;
  resolved.params = nlohmann::json::object();
  return std::make_unique<LocalPhi>(resolved, normalise_white(code));
}

std::unique_ptr<Phi> make_calibrated(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  int64_t period = 1;           // T: the response repeats every T pixels
  std::vector<double> weights;  // M_n(u, v, y, x), N * U * V * T * T values in that order
  bool normalise = true;        // scale so a white light field measures 1 on average
  std::string source;           // where the measurement came from (informational)
  nlohmann::json cfa;           // the camera's colour filter array (optics/cfa.h), if it has one
  r.get("period", period);
  r.require("weights", weights);
  r.get("normalise", normalise);
  r.get("source", source);
  r.get("cfa", cfa);
  r.finish();
  if (!cfa.is_null()) cfa = ColourFilterArray::from_json(cfa, r.path_of("cfa")).to_json();
  LFNET_CHECK_AS(ConfigError, period >= 1 && period <= 64, r.path_of("period"),
                 ": the period T must be in 1..64, got ", period);
  const int64_t expected = spec.n * spec.coded_rows() * spec.cols * period * period;
  check_code_size(spec, expected, "a calibrated code");
  LFNET_CHECK_AS(ConfigError, static_cast<int64_t>(weights.size()) == expected,
                 r.path_of("weights"), ": expected N x U x V x T x T = ", spec.n, " x ",
                 spec.coded_rows(), " x ", spec.cols, " x ", period, " x ", period, " = ", expected,
                 " values, got ", weights.size());
  for (size_t i = 0; i < weights.size(); ++i) {
    LFNET_CHECK_AS(ConfigError, std::isfinite(weights[i]) && weights[i] >= 0, r.path_of("weights"),
                   "[", i, "]: a measured response must be finite and non-negative, got ",
                   weights[i]);
  }
  auto code =
      torch::from_blob(weights.data(), {spec.n, spec.coded_rows(), spec.cols, period, period},
                       torch::kFloat64)
          .clone();
  PhiSpec resolved = spec;
  resolved.params = {{"period", period}, {"weights", weights}, {"normalise", normalise}};
  if (!source.empty()) resolved.params["source"] = source;
  if (!cfa.is_null()) resolved.params["cfa"] = cfa;
  return std::make_unique<LocalPhi>(resolved, normalise ? normalise_white(code) : code);
}

}  // namespace lfnet::optics::detail

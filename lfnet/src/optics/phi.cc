// PhiSpec, the model registry, and what every Phi shares.
#include "lfnet/optics/phi.h"

#include <torch/linalg.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <regex>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/sequence.h"
#include "models.h"

namespace lfnet::optics {

nlohmann::json PhiSpec::to_json() const {
  nlohmann::json j = {{"name", name}, {"n", n},       {"rows", rows},
                      {"cols", cols}, {"seed", seed}, {"params", params}};
  // Still cameras keep the JSON (and the hashes of specs) they always had.
  if (frames != 1) j["frames"] = frames;
  return j;
}

PhiSpec PhiSpec::from_json(const nlohmann::json& j, const std::string& path) {
  JsonReader r(j, path);
  PhiSpec spec;
  r.require("name", spec.name);
  r.get("n", spec.n);
  r.get("rows", spec.rows);
  r.get("cols", spec.cols);
  r.get("frames", spec.frames);
  if (j.contains("seed") && j.at("seed").is_number_integer() &&
      !j.at("seed").is_number_unsigned() && j.at("seed").get<int64_t>() < 0) {
    throw ConfigError(r.path_of("seed") + ": the seed must be a non-negative integer, got " +
                      j.at("seed").dump());
  }
  r.get("seed", spec.seed);
  if (r.has("params")) {
    r.get("params", spec.params);
    LFNET_CHECK_AS(ConfigError, spec.params.is_object(), r.path_of("params"),
                   ": expected a JSON object of model parameters");
  }
  r.finish();
  LFNET_CHECK_AS(
      ConfigError,
      spec.rows >= 1 && spec.cols >= 1 && spec.rows <= kMaxViews && spec.cols <= kMaxViews, path,
      ": rows and cols must be in 1..", kMaxViews, ", got ", spec.rows, "x", spec.cols);
  LFNET_CHECK_AS(ConfigError, spec.frames >= 1 && spec.frames <= kMaxFrames, r.path_of("frames"),
                 ": the sub-frames T must be in 1..", kMaxFrames, ", got ", spec.frames);
  LFNET_CHECK_AS(ConfigError, spec.n >= 1 && spec.n <= spec.coded_rows() * spec.cols,
                 r.path_of("n"), ": N must be in 1..", spec.coded_rows() * spec.cols,
                 spec.frames > 1 ? " (T U V)" : " (U V)", " for ", spec.rows, "x", spec.cols,
                 " views", spec.frames > 1 ? " of " + std::to_string(spec.frames) + " frames" : "",
                 ", got ", spec.n);
  return spec;
}

PhiSpec PhiSpec::parse(const std::string& text) {
  static const std::regex kPattern(
      R"(^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?::\s*(\d+))?\s*(?:@\s*(\d+))?\s*$)");
  std::smatch m;
  LFNET_CHECK_AS(ConfigError, std::regex_match(text, m, kPattern), "Phi '", text,
                 "' is not of the form NAME[:N][@T], e.g. asp:2 or exposure_aperture:1@4 (or give "
                 "a PHI.json file)");
  PhiSpec spec;
  spec.name = m[1];
  if (m[2].matched) {
    // More digits than an int64 holds is no N either.
    LFNET_CHECK_AS(ConfigError, m[2].length() <= 9, "Phi '", text, "': N must be in 1..U V");
    spec.n = std::stoll(m[2]);
    LFNET_CHECK_AS(ConfigError, spec.n >= 1, "Phi '", text, "': N must be >= 1");
  }
  if (m[3].matched) {
    LFNET_CHECK_AS(ConfigError, m[3].length() <= 9, "Phi '", text, "': T must be in 1..",
                   kMaxFrames);
    spec.frames = std::stoll(m[3]);
    LFNET_CHECK_AS(ConfigError, spec.frames >= 1 && spec.frames <= kMaxFrames, "Phi '", text,
                   "': T must be in 1..", kMaxFrames);
  }
  return spec;
}

std::string PhiSpec::label() const {
  auto text = name + ":" + std::to_string(n);
  return frames == 1 ? text : text + "@" + std::to_string(frames);
}

bool PhiSpec::operator==(const PhiSpec& other) const {
  return name == other.name && n == other.n && rows == other.rows && cols == other.cols &&
         frames == other.frames && seed == other.seed && params == other.params;
}

torch::Tensor Phi::pixel_weights(int64_t, int64_t, int64_t, int64_t, torch::ScalarType) const {
  throw ConfigError("Phi '" + spec_.name +
                    "' is not local (its measurements mix pixels): it has no per-pixel weights");
}

torch::Tensor Phi::pinv_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w, double lambda,
                               torch::ScalarType dtype) const {
  return detail::tikhonov_pinv(patch_matrix(y0, x0, h, w, torch::kFloat64), lambda).to(dtype);
}

namespace {

struct Registry {
  std::mutex mutex;
  std::map<std::string, PhiFactory> factories;
  // Models that build time-coded codes themselves; the others are still cameras, built at
  // T = 1 and held for every sub-frame of a spec with frames > 1.
  std::set<std::string> time_coded;
};

Registry& registry() {
  static Registry instance;
  return instance;
}

void add_factory(const std::string& name, PhiFactory factory, bool time_coded = false) {
  auto& reg = registry();
  std::lock_guard<std::mutex> lock(reg.mutex);
  reg.factories[name] = std::move(factory);
  if (time_coded) {
    reg.time_coded.insert(name);
  } else {
    reg.time_coded.erase(name);
  }
}

// The built-ins are registered before anything else, so a model registered by name later
// replaces a built-in of that name and is never replaced by it.
void ensure_builtins() {
  static std::once_flag once;
  std::call_once(once, [] {
    add_factory("asp", detail::make_asp);
    add_factory("mask", detail::make_mask);
    add_factory("aperture", detail::make_aperture);
    add_factory("random", detail::make_random);
    add_factory("lenslet", detail::make_lenslet);
    add_factory("calibrated", detail::make_calibrated, /*time_coded=*/true);
    add_factory("time_aperture", detail::make_time_aperture, /*time_coded=*/true);
    add_factory("coded_exposure", detail::make_coded_exposure, /*time_coded=*/true);
    add_factory("exposure_aperture", detail::make_exposure_aperture, /*time_coded=*/true);
  });
}

}  // namespace

void register_phi(const std::string& name, PhiFactory factory, bool time_coded) {
  ensure_builtins();
  add_factory(name, std::move(factory), time_coded);
}

bool phi_is_time_coded(const std::string& name) {
  ensure_builtins();
  auto& reg = registry();
  std::lock_guard<std::mutex> lock(reg.mutex);
  return reg.time_coded.count(name) > 0;
}

std::vector<std::string> phi_names() {
  ensure_builtins();
  auto& reg = registry();
  std::lock_guard<std::mutex> lock(reg.mutex);
  std::vector<std::string> names;
  for (const auto& [name, factory] : reg.factories) names.push_back(name);
  return names;
}

torch::Tensor normalise_white(const torch::Tensor& code) {
  const auto white = code.sum({1, 2}).mean();
  LFNET_CHECK_AS(NumericalError, white.item<double>() > 0,
                 "a Phi code measures nothing of a white light field");
  return code / white;
}

std::unique_ptr<Phi> make_phi(const PhiSpec& spec) {
  ensure_builtins();
  PhiFactory factory;
  bool time_coded = false;
  {
    auto& reg = registry();
    std::lock_guard<std::mutex> lock(reg.mutex);
    auto it = reg.factories.find(spec.name);
    if (it != reg.factories.end()) factory = it->second;
    time_coded = reg.time_coded.count(spec.name) > 0;
  }
  if (!factory) {
    std::string known;
    for (const auto& name : phi_names()) known += (known.empty() ? "" : ", ") + name;
    throw ConfigError("unknown Phi model '" + spec.name + "' (known: " + known + ")");
  }
  LFNET_CHECK_AS(
      ConfigError,
      spec.rows >= 1 && spec.cols >= 1 && spec.rows <= kMaxViews && spec.cols <= kMaxViews, "Phi '",
      spec.label(), "': the angular grid must be 1x1 to ", kMaxViews, "x", kMaxViews, ", got ",
      spec.rows, "x", spec.cols);
  LFNET_CHECK_AS(ConfigError, spec.frames >= 1 && spec.frames <= kMaxFrames, "Phi '", spec.label(),
                 "': the sub-frames T must be in 1..", kMaxFrames);
  LFNET_CHECK_AS(ConfigError, spec.n >= 1 && spec.n <= spec.coded_rows() * spec.cols, "Phi '",
                 spec.label(), "': N must be in 1..", spec.coded_rows() * spec.cols, " for ",
                 spec.rows, "x", spec.cols, " views", spec.frames > 1 ? " of T frames" : "");
  LFNET_CHECK_AS(ConfigError, spec.params.is_object(), "Phi '", spec.label(),
                 "': params must be a JSON object");
  if (spec.frames == 1 || time_coded) return factory(spec);
  PhiSpec still = spec;
  still.frames = 1;
  return detail::still_over_frames(*factory(still), spec);
}

PhiConditioning conditioning(const Phi& phi) {
  PhiConditioning c;
  torch::Tensor pieces;  // (pieces, rows, cols)
  if (phi.local()) {
    const int64_t t = phi.period();
    auto w = phi.pixel_weights(0, 0, t, t, torch::kFloat64);  // (N, U, V, T, T)
    pieces =
        w.permute({3, 4, 0, 1, 2}).reshape({t * t, phi.measurements(), phi.rows() * phi.cols()});
    c.piece = "pixel";
  } else {
    const int64_t b = phi.block();
    pieces = phi.patch_matrix(0, 0, b, b, torch::kFloat64).unsqueeze(0);
    c.piece = "block";
  }
  c.piece_rows = pieces.size(1);
  c.piece_cols = pieces.size(2);
  c.singular_values = torch::linalg::svdvals(pieces, c10::nullopt);
  auto smax = c.singular_values.select(1, 0);
  auto smin = c.singular_values.select(1, c.singular_values.size(1) - 1);
  c.condition = torch::where(smin > 1e-10 * smax, smax / smin,
                             torch::full_like(smax, std::numeric_limits<double>::infinity()));
  c.rank = (c.singular_values > 1e-10 * smax.unsqueeze(1)).sum(1);
  return c;
}

}  // namespace lfnet::optics

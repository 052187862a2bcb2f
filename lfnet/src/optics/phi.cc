// PhiSpec, the model registry, and what every Phi shares.
#include "lfnet/optics/phi.h"

#include <torch/linalg.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <regex>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "models.h"

namespace lfnet::optics {

nlohmann::json PhiSpec::to_json() const {
  return {{"name", name}, {"n", n},       {"rows", rows},
          {"cols", cols}, {"seed", seed}, {"params", params}};
}

PhiSpec PhiSpec::from_json(const nlohmann::json& j, const std::string& path) {
  JsonReader r(j, path);
  PhiSpec spec;
  r.require("name", spec.name);
  r.get("n", spec.n);
  r.get("rows", spec.rows);
  r.get("cols", spec.cols);
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
  LFNET_CHECK_AS(ConfigError, spec.n >= 1 && spec.n <= spec.rows * spec.cols, r.path_of("n"),
                 ": N must be in 1..", spec.rows * spec.cols, " (U V) for ", spec.rows, "x",
                 spec.cols, " views, got ", spec.n);
  return spec;
}

PhiSpec PhiSpec::parse(const std::string& text) {
  static const std::regex kPattern(R"(^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?::\s*(\d+))?\s*$)");
  std::smatch m;
  LFNET_CHECK_AS(ConfigError, std::regex_match(text, m, kPattern), "Phi '", text,
                 "' is not of the form NAME[:N], e.g. asp:2 (or give a PHI.json file)");
  PhiSpec spec;
  spec.name = m[1];
  if (m[2].matched) {
    // More digits than an int64 holds is no N either.
    LFNET_CHECK_AS(ConfigError, m[2].length() <= 9, "Phi '", text, "': N must be in 1..U V");
    spec.n = std::stoll(m[2]);
    LFNET_CHECK_AS(ConfigError, spec.n >= 1, "Phi '", text, "': N must be >= 1");
  }
  return spec;
}

std::string PhiSpec::label() const { return name + ":" + std::to_string(n); }

bool PhiSpec::operator==(const PhiSpec& other) const {
  return name == other.name && n == other.n && rows == other.rows && cols == other.cols &&
         seed == other.seed && params == other.params;
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
};

Registry& registry() {
  static Registry instance;
  return instance;
}

void add_factory(const std::string& name, PhiFactory factory) {
  auto& reg = registry();
  std::lock_guard<std::mutex> lock(reg.mutex);
  reg.factories[name] = std::move(factory);
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
    add_factory("calibrated", detail::make_calibrated);
  });
}

}  // namespace

void register_phi(const std::string& name, PhiFactory factory) {
  ensure_builtins();
  add_factory(name, std::move(factory));
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
  {
    auto& reg = registry();
    std::lock_guard<std::mutex> lock(reg.mutex);
    auto it = reg.factories.find(spec.name);
    if (it != reg.factories.end()) factory = it->second;
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
  LFNET_CHECK_AS(ConfigError, spec.n >= 1 && spec.n <= spec.rows * spec.cols, "Phi '", spec.label(),
                 "': N must be in 1..", spec.rows * spec.cols, " for ", spec.rows, "x", spec.cols,
                 " views");
  LFNET_CHECK_AS(ConfigError, spec.params.is_object(), "Phi '", spec.label(),
                 "': params must be a JSON object");
  return factory(spec);
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

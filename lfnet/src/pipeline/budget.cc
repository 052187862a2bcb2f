#include "lfnet/pipeline/budget.h"

#include <spdlog/spdlog.h>
#include <torch/version.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <thread>

#include <unistd.h>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/machine.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/version.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/nn/image_net.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/catalog.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/simulate.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

std::string calibration_path() {
  if (const char* env = std::getenv("LFNET_CALIBRATION"); env != nullptr && *env != '\0') {
    return env;
  }
  fs::path base;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0') {
    base = xdg;
  } else if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    base = fs::path(home) / ".cache";
  } else {
    base = fs::temp_directory_path();
  }
  return (base / "lfnet" / "calibration.json").string();
}

nlohmann::json machine_fingerprint() {
  return {
      {"cpu", cpu_info("model name")},
      {"logical_cpus", static_cast<int64_t>(std::thread::hardware_concurrency())},
      {"lfnet_version", kVersion},
      {"torch_version", TORCH_VERSION},
      // Timings made under another automatic tile (nn::auto_image_tile) are stale.
      {"auto_tile",
       {nn::kAutoTileWhole, nn::kAutoTileCrop, nn::kAutoTileWholeColour, nn::kAutoTileCropColour}}};
}

nlohmann::json TimingSetting::to_json() const {
  return {{"device", device}, {"threads", threads}, {"precision", nn::to_string(precision)}};
}

TimingSetting run_setting(const std::string& model, const std::string& device,
                          std::optional<nn::Precision> precision) {
  if (model.empty()) return {device, thread_count(), nn::Precision::kFloat32};
  return {device, thread_count(),
          precision ? *precision : choose_precision(std::vector<std::string>{model}, device)};
}

namespace {

bool same_setting(const TimingSetting& a, const TimingSetting& b) {
  return a.device == b.device && a.threads == b.threads && a.precision == b.precision;
}

}  // namespace

void CalibrationEntry::fit() {
  auto& e = *this;
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const auto& [pixels, seconds] : e.timings) {
    const auto x = static_cast<double>(pixels);
    n += 1;
    sx += x;
    sy += seconds;
    sxx += x * x;
    sxy += x * seconds;
  }
  const double det = n * sxx - sx * sx;
  e.per_pixel = det > 0 ? (n * sxy - sx * sy) / det : (sx > 0 ? sy / sx : 0);
  e.fixed = n > 0 ? (sy - e.per_pixel * sx) / n : 0;
  // Timings noisier than the size's effect: the larger one alone, proportional to pixels.
  if (e.per_pixel <= 0 || e.fixed < 0) {
    const auto& big = *std::max_element(e.timings.begin(), e.timings.end());
    e.fixed = 0;
    e.per_pixel = big.second / static_cast<double>(std::max<int64_t>(big.first, 1));
  }
}

nlohmann::json CalibrationEntry::to_json() const {
  nlohmann::json t = nlohmann::json::array();
  for (const auto& [pixels, seconds] : timings)
    t.push_back({{"pixels", pixels}, {"seconds", seconds}});
  return {{"model", model},
          {"camera", camera},
          {"colour", colour},
          {"file_bytes", file_bytes},
          {"setting", setting.to_json()},
          {"fixed_seconds", fixed},
          {"seconds_per_megapixel", per_pixel * 1e6},
          {"timings", t}};
}

CalibrationEntry CalibrationEntry::from_json(const nlohmann::json& j) {
  CalibrationEntry e;
  e.model = j.at("model").get<std::string>();
  e.camera = j.at("camera").get<std::string>();
  e.colour = j.at("colour").get<std::string>();
  e.file_bytes = j.at("file_bytes").get<int64_t>();
  const auto& s = j.at("setting");
  e.setting = {s.at("device").get<std::string>(), s.at("threads").get<int>(),
               nn::parse_precision(s.at("precision").get<std::string>())};
  e.fixed = j.at("fixed_seconds").get<double>();
  e.per_pixel = j.at("seconds_per_megapixel").get<double>() / 1e6;
  for (const auto& t : j.at("timings")) {
    e.timings.emplace_back(t.at("pixels").get<int64_t>(), t.at("seconds").get<double>());
  }
  return e;
}

namespace {

bool same_key(const CalibrationEntry& e, const std::string& model, const std::string& camera,
              const std::string& colour, const TimingSetting& setting) {
  return e.model == model && e.camera == camera && e.colour == colour &&
         same_setting(e.setting, setting);
}

}  // namespace

const CalibrationEntry* Calibration::find(const std::string& model, const std::string& camera,
                                          const std::string& colour,
                                          const TimingSetting& setting) const {
  for (const auto& e : entries) {
    if (same_key(e, model, camera, colour, setting)) return &e;
  }
  return nullptr;
}

void Calibration::put(const CalibrationEntry& entry) {
  for (auto& e : entries) {
    if (same_key(e, entry.model, entry.camera, entry.colour, entry.setting)) {
      e = entry;
      return;
    }
  }
  entries.push_back(entry);
}

Calibration read_calibration(const std::string& path) {
  Calibration c;
  c.machine = machine_fingerprint();
  std::error_code ec;
  if (!fs::exists(path, ec)) return c;
  try {
    const auto doc = read_json_file(path);
    if (doc.at("machine") != c.machine) {
      spdlog::info("the calibration {} is of another machine or lfnet version: timing again", path);
      return c;
    }
    for (const auto& e : doc.at("entries")) c.entries.push_back(CalibrationEntry::from_json(e));
  } catch (const std::exception& e) {
    spdlog::warn("the calibration {} is unreadable ({}): timing again", path, e.what());
    c.entries.clear();
  }
  return c;
}

void write_calibration(const std::string& path, const Calibration& calibration) {
  nlohmann::json entries = nlohmann::json::array();
  for (const auto& e : calibration.entries) entries.push_back(e.to_json());
  const auto dir = fs::path(path).parent_path();
  std::error_code ec;
  if (!dir.empty()) fs::create_directories(dir, ec);
  write_json_file(path, {{"about",
                          "lfnet's per-machine timings of zoo models for --budget "
                          "(docs/models.md); lfnet bench --calibrate rewrites it"},
                         {"machine", calibration.machine},
                         {"entries", entries}});
}

namespace {

int64_t file_bytes(const std::string& path) {
  std::error_code ec;
  const auto n = fs::file_size(path, ec);
  return ec ? 0 : static_cast<int64_t>(n);
}

// The card's camera as a Phi spec ("asp:2"); nullopt for a learned code or "any".
std::optional<optics::PhiSpec> card_camera(const nlohmann::json& card) {
  const auto camera = card.value("camera", "");
  if (camera.empty() || camera.find(' ') != std::string::npos) return std::nullopt;
  try {
    return phi_from_argument(camera);
  } catch (const Error&) {
    return std::nullopt;
  }
}

bool is_network_file(const std::string& path) {
  const auto kind = model_file_kind(path);
  return kind == ModelFileKind::kCheckpoint || kind == ModelFileKind::kNoiseSwitch ||
         kind == ModelFileKind::kExported;
}

double mean_of(const nlohmann::json& margins) {
  double sum = 0;
  for (const auto& [name, v] : margins.items()) sum += v.get<double>();
  return margins.empty() ? 0 : sum / static_cast<double>(margins.size());
}

// A card's accuracy on `basis`: "validation", or "benchmark".
std::optional<double> card_accuracy(const nlohmann::json& card, const std::string& basis) {
  if (!card.contains("measured")) return std::nullopt;
  const auto& m = card["measured"];
  if (basis == "validation") {
    if (m.contains("validation") && m["validation"].contains("mean_margin_over_pinv_db")) {
      return m["validation"]["mean_margin_over_pinv_db"].get<double>();
    }
    return std::nullopt;
  }
  if (m.contains("benchmark") && m["benchmark"].contains("margins_over_pinv_db")) {
    return mean_of(m["benchmark"]["margins_over_pinv_db"]);
  }
  return std::nullopt;
}

// A sensor folder of a random scene at height x width for a camera and colour.
void write_calibration_scene(const optics::PhiSpec& spec, const std::string& colour, int64_t height,
                             int64_t width, uint64_t seed, const std::string& dir) {
  scene::RandomSceneOptions so;
  so.height = height;
  so.width = width;
  so.color = colour != "grey";
  auto lf = scene::render_scene(scene::random_scene(seed, so)).light_field;
  if (!so.color) lf = lf.grey();
  const auto phi = optics::make_phi(spec);
  SimulateRequest r;
  r.lf = lf;
  r.phi = phi.get();
  if (so.color) r.cfa = optics::resolve_cfa(colour, spec.to_json());
  fs::create_directories(dir);
  write_acquisition(r, dir);
}

double time_reconstruction(const std::string& sensor, const std::string& method,
                           const std::string& model, const TimingSetting& setting,
                           ModelCache& cache) {
  ReconstructRequest q;
  q.sensor = sensor;
  q.method = method;
  q.model = model;
  q.device = setting.device;
  q.precision = setting.precision;
  q.coded = true;
  return reconstruct_acquisition(q, {}, &cache).record.at("seconds").get<double>();
}

struct CalibrationJob {
  std::string model, path, camera, colour;  // path "" for pinv
  optics::PhiSpec spec;
};

std::vector<CalibrationJob> calibration_jobs(const Zoo& zoo,
                                             const std::vector<std::string>& names) {
  std::vector<CalibrationJob> jobs;
  std::set<std::pair<std::string, std::string>> cameras;
  // A name, or the card's file (a command line's zoo names arrive resolved to files).
  auto names_card = [&](const std::string& name, const ZooCard& m) {
    std::error_code ec;
    return name == m.name || fs::equivalent(name, zoo.path(m), ec);
  };
  for (const auto& m : zoo.models) {
    const auto path = zoo.path(m);
    if (!names.empty() && std::none_of(names.begin(), names.end(),
                                       [&](const std::string& n) { return names_card(n, m); })) {
      continue;
    }
    const auto spec = card_camera(m.card);
    if (!spec || !is_network_file(path)) {
      LFNET_CHECK_AS(ConfigError, names.empty(), "the zoo model ", m.name,
                     " cannot be calibrated: a budget chooses only networks of a named camera");
      continue;
    }
    const auto colour = m.card.value("colour", "grey");
    jobs.push_back({m.name, path, spec->label(), colour, *spec});
    if (cameras.insert({spec->label(), colour}).second) {
      jobs.push_back({"pinv", "", spec->label(), colour, *spec});
    }
  }
  for (const auto& name : names) {
    const bool found = std::any_of(zoo.models.begin(), zoo.models.end(),
                                   [&](const ZooCard& m) { return names_card(name, m); });
    LFNET_CHECK_AS(ConfigError, found, "--calibrate times zoo models; ", name,
                   " is none of them (lfnet models)");
  }
  return jobs;
}

}  // namespace

std::vector<CalibrationEntry> calibrate_machine(
    const CalibrateOptions& o, const std::function<void(const std::string&)>& print) {
  const auto path = o.path.empty() ? calibration_path() : o.path;
  auto calibration = read_calibration(path);
  const auto zoo = read_zoo();
  const auto jobs = calibration_jobs(zoo, o.models);
  std::vector<CalibrationEntry> timed;
  if (jobs.empty()) return timed;
  const auto scratch =
      fs::temp_directory_path() / ("lfnet-calibrate-" + std::to_string(::getpid()));
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{scratch};
  const std::vector<std::pair<int64_t, int64_t>> sizes = {{(o.height + 1) / 2, (o.width + 1) / 2},
                                                          {o.height, o.width}};
  ModelCache cache;
  std::map<std::string, std::string> scenes;  // camera|colour|size -> sensor folder
  auto scene_for = [&](const CalibrationJob& j, int64_t h, int64_t w) {
    const auto key = j.camera + "|" + j.colour + "|" + std::to_string(h);
    if (!scenes.count(key)) {
      const auto dir = (scratch / ("scene-" + std::to_string(scenes.size()))).string();
      write_calibration_scene(j.spec, j.colour, h, w, o.seed, dir);
      scenes[key] = dir;
    }
    return scenes[key];
  };
  int width = 30;  // the model column fits the longest name, as in `lfnet models`
  for (const auto& j : jobs) width = std::max(width, static_cast<int>(j.model.size()));
  bool warm = false;
  for (const auto& j : jobs) {
    CalibrationEntry e;
    e.model = j.model;
    e.camera = j.camera;
    e.colour = j.colour;
    e.file_bytes = file_bytes(j.path);
    e.setting = run_setting(j.path, o.device, o.precision);
    const auto& setting = e.setting;
    const auto method = j.path.empty() ? "pinv" : "net";
    // One untimed run first: the process's first reconstruction pays its thread pools and
    // allocator, and a model's first its loading.
    if (!warm || !j.path.empty()) {
      time_reconstruction(scene_for(j, sizes[0].first, sizes[0].second), method, j.path, setting,
                          cache);
      warm = true;
    }
    for (const auto& [h, w] : sizes) {
      e.timings.emplace_back(
          h * w, time_reconstruction(scene_for(j, h, w), method, j.path, setting, cache));
    }
    e.fit();
    calibration.put(e);
    timed.push_back(e);
    char line[256];
    std::snprintf(line, sizeof line, "%-*s %-10s %-6s %6.2f s at %lldx%lld, %6.2f s at %lldx%lld",
                  width, e.model.c_str(), e.camera.c_str(), e.colour.c_str(), e.timings[0].second,
                  static_cast<long long>(sizes[0].first), static_cast<long long>(sizes[0].second),
                  e.timings[1].second, static_cast<long long>(o.height),
                  static_cast<long long>(o.width));
    if (print) print(line);
  }
  write_calibration(path, calibration);
  return timed;
}

std::vector<BudgetCandidate> budget_candidates(const Zoo& zoo, const std::string& camera,
                                               const std::string& colour) {
  std::vector<const ZooCard*> cards;
  for (const auto& m : zoo.models) {
    const auto spec = card_camera(m.card);
    if (spec && spec->label() == camera && m.card.value("colour", "grey") == colour &&
        is_network_file(zoo.path(m))) {
      cards.push_back(&m);
    }
  }
  std::vector<BudgetCandidate> out;
  for (const std::string basis : {"validation", "benchmark"}) {
    for (const auto* m : cards) {
      if (const auto a = card_accuracy(m->card, basis)) {
        const auto section =
            basis == "validation" ? basis : m->card["measured"]["benchmark"].value("section", "");
        out.push_back({m->name, zoo.path(*m), *a, section});
      }
    }
    if (!out.empty()) break;
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const auto& a, const auto& b) { return a.accuracy > b.accuracy; });
  return out;
}

std::vector<std::string> ladder_models(const std::string& camera) {
  std::vector<std::string> paths;
  for (const auto& c : budget_candidates(read_zoo(), camera, "grey")) {
    if (model_file_kind(c.path) == ModelFileKind::kCheckpoint) paths.push_back(c.path);
  }
  LFNET_CHECK_AS(ConfigError, !paths.empty(), "--ladder: the zoo has no measured checkpoint for ",
                 camera, " (grey)");
  return paths;
}

nlohmann::json BudgetChoice::record() const {
  return {{"seconds", budget},
          {"model", model},
          {"predicted_seconds", predicted_seconds},
          {"camera", camera},
          {"colour", colour},
          {"pixels", pixels},
          {"setting", setting.to_json()},
          {"candidates", candidates},
          {"calibration", calibration_path()}};
}

std::string BudgetChoice::summary() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "--budget %.2f s: %s, the most accurate zoo model for %s (%s) that fits here "
                "(%.2f s predicted)",
                budget, model.c_str(), camera.c_str(), colour.c_str(), predicted_seconds);
  return buf;
}

BudgetChoice choose_within_budget(double budget, const std::string& camera,
                                  const std::string& colour, int64_t pixels,
                                  const std::string& device,
                                  std::optional<nn::Precision> precision) {
  LFNET_CHECK_AS(ConfigError, budget > 0, "--budget must be a positive number of seconds");
  const auto zoo = read_zoo();
  const auto candidates = budget_candidates(zoo, camera, colour);
  LFNET_CHECK_AS(ConfigError, !candidates.empty(), "--budget: the zoo (", zoo.dir,
                 ") has no measured model for ", camera, " (", colour, ")");
  const auto path = calibration_path();
  auto calibration = read_calibration(path);
  std::vector<std::string> missing;
  const auto pinv_setting = run_setting("", device, precision);
  for (const auto& c : candidates) {
    const auto* e =
        calibration.find(c.name, camera, colour, run_setting(c.path, device, precision));
    if (e == nullptr || e->file_bytes != file_bytes(c.path)) missing.push_back(c.name);
  }
  if (missing.empty() && calibration.find("pinv", camera, colour, pinv_setting) == nullptr) {
    missing.push_back(candidates.front().name);  // its camera's pinv comes with it
  }
  if (!missing.empty()) {
    spdlog::info("--budget: timing {} model(s) on this machine once, into {}", missing.size(),
                 path);
    CalibrateOptions o;
    o.models = missing;
    o.device = device;
    o.precision = precision;
    o.path = path;
    calibrate_machine(o, [](const std::string& line) { spdlog::info("calibrated {}", line); });
    calibration = read_calibration(path);
  }
  BudgetChoice choice;
  choice.budget = budget;
  choice.camera = camera;
  choice.colour = colour;
  choice.pixels = pixels;
  for (const auto& c : candidates) {
    const auto setting = run_setting(c.path, device, precision);
    const auto* e = calibration.find(c.name, camera, colour, setting);
    LFNET_CHECK_AS(Error, e != nullptr, "--budget: ", c.name, " was not timed");
    const double predicted = e->predict(pixels);
    choice.candidates.push_back({{"model", c.name},
                                 {"accuracy_db", c.accuracy},
                                 {"accuracy_on", c.basis},
                                 {"predicted_seconds", predicted}});
    if (choice.model.empty() && predicted <= budget) {
      choice.model = c.name;
      choice.path = c.path;
      choice.predicted_seconds = predicted;
      choice.setting = setting;
    }
  }
  if (choice.model.empty()) {
    const auto fastest = std::min_element(choice.candidates.begin(), choice.candidates.end(),
                                          [](const auto& a, const auto& b) {
                                            return a["predicted_seconds"].template get<double>() <
                                                   b["predicted_seconds"].template get<double>();
                                          });
    const auto* pinv = calibration.find("pinv", camera, colour, pinv_setting);
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "--budget %.2f s: no zoo model for %s (%s) fits; the fastest, %s, needs %.2f s "
                  "here; --method pinv needs %.2f s",
                  budget, camera.c_str(), colour.c_str(),
                  (*fastest)["model"].get<std::string>().c_str(),
                  (*fastest)["predicted_seconds"].get<double>(),
                  pinv != nullptr ? pinv->predict(pixels) : 0.0);
    throw ConfigError(buf);
  }
  return choice;
}

SensorFacts sensor_facts(const std::string& sensor, const std::string& phi,
                         const std::string& cfa) {
  SensorFacts f;
  const auto camera = sensor_camera(sensor, phi, cfa);
  f.camera = camera.camera;
  f.colour = camera.colour;
  std::error_code ec;
  if (fs::is_directory(sensor, ec)) {
    const auto meta = read_json_file((fs::path(sensor) / "sensor.json").string());
    const auto& lf = meta.at("light_field");
    f.height = lf.at("height").get<int64_t>();
    f.width = lf.at("width").get<int64_t>();
  } else {
    const auto first = sensor.substr(0, sensor.find(','));
    const auto image = io::read_image_channels(first);
    f.height = image.size(1);
    f.width = image.size(2);
  }
  LFNET_CHECK_AS(ConfigError, !f.camera.empty(), "--budget: the camera of ", sensor,
                 " is unknown (give --phi)");
  return f;
}

void check_budget_request(const BudgetConflicts& given) {
  LFNET_CHECK_AS(ConfigError, !given.model,
                 "--budget chooses the zoo model: give --budget or --model, not both");
  LFNET_CHECK_AS(ConfigError, !given.method,
                 "--budget runs a network of the zoo (net): leave out --method");
  LFNET_CHECK_AS(ConfigError, !given.self_ensemble,
                 "--budget predicts one pass of a model: leave out --self-ensemble");
  LFNET_CHECK_AS(ConfigError, !given.self_calibrate,
                 "--budget predicts a reconstruction without self-calibration: leave out "
                 "--self-calibrate");
  LFNET_CHECK_AS(ConfigError, !given.per_patch,
                 "--budget times reconstructions of sensor images: leave out --mode per_patch");
}

BudgetChoice budget_for_sensor(double budget, const std::string& sensor, const std::string& phi,
                               const std::string& cfa, const std::string& device,
                               std::optional<nn::Precision> precision) {
  const auto f = sensor_facts(sensor, phi, cfa);
  auto choice =
      choose_within_budget(budget, f.camera, f.colour, f.height * f.width, device, precision);
  spdlog::info("{}", choice.summary());
  return choice;
}

BudgetChoice budget_for_light_field(double budget, int64_t pixels, const std::string& phi,
                                    const std::string& cfa, const std::string& device,
                                    std::optional<nn::Precision> precision) {
  LFNET_CHECK_AS(ConfigError, !phi.empty(), "--budget needs the camera: give --phi");
  const auto camera = sensor_camera("", phi, cfa);
  LFNET_CHECK_AS(ConfigError, !camera.camera.empty(), "--budget: the camera of --phi ", phi,
                 " cannot be read");
  auto choice =
      choose_within_budget(budget, camera.camera, camera.colour, pixels, device, precision);
  spdlog::info("{}", choice.summary());
  return choice;
}

void record_budget(const BudgetChoice& choice, nlohmann::json& record) {
  record["budget"] = choice.record();
  const double actual = record.value("seconds", 0.0);
  record["budget"]["actual_seconds"] = actual;
  spdlog::info("--budget {:.2f} s: {} took {:.2f} s ({:.2f} s predicted)", choice.budget,
               choice.model, actual, choice.predicted_seconds);
}

int64_t light_field_pixels(const std::string& lf, const std::string& layout,
                           const std::string& scene) {
  if (!scene.empty()) {
    const auto spec = scene::load_scene(scene);
    return spec.height * spec.width;
  }
  const auto folder = io::scan_folder(lf, layout);
  LFNET_CHECK_AS(IoError, !folder.views.empty(), lf, " holds no views");
  const auto view = io::read_image(folder.views.front().path);
  return view.size(-2) * view.size(-1);
}

}  // namespace lfnet::pipeline

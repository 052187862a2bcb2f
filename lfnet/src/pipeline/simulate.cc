#include "lfnet/pipeline/simulate.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/light_field.h"
#include "lfnet/core/output.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/sequence.h"
#include "lfnet/core/text.h"
#include "lfnet/core/version.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/optics/asp.h"
#include "lfnet/pipeline/figures.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// Sensor mode: the sensor image(s), (C, N, H, W) by the camera's own Phi, into `dir`.
void write_sensor_acquisition(const SimulateRequest& r, const std::string& dir,
                              nlohmann::json& meta) {
  const auto& lf = r.lf;
  const auto& phi = *r.phi;
  const int64_t n = phi.measurements();
  Stopwatch clock;
  // The nominal Phi without a camera error.
  auto sensor = optics::perturbed_forward(phi, r.camera_error, lf.data());
  if (r.cfa) sensor = optics::mosaic(sensor, *r.cfa);  // (1, N, H, W): one colour sensor
  sensor = optics::apply_sensor_effects(sensor, r.effects, r.seed);
  meta["seconds"] = clock.seconds();
  // Shot and read noise included: what a noise-aware net reads (optics/sensor.h).
  meta["noise_sigma"] = r.effects.equivalent_sigma(sensor.mean().item<double>());
  io::write_sensor_images(dir, sensor);
  meta["sensor"] = {{"files", io::sensor_file_names(sensor.size(0))},
                    {"channels_per_file", n},
                    {"dtype", "float32"},
                    {"shape", {sensor.size(0), n, lf.height(), lf.width()}}};
  spdlog::info("simulated a {}x{}x{} sensor image with {} in {:.3f} s", n, lf.height(), lf.width(),
               phi.spec().label(), clock.seconds());
}

// Patch modes: the measurements of every patch of the grid, written in bands of rows.
void write_patch_acquisition(const SimulateRequest& r, const std::string& dir,
                             nlohmann::json& meta) {
  const auto& lf = r.lf;
  const auto& phi = *r.phi;
  const int64_t n = phi.measurements();
  Stopwatch clock;
  const PatchGrid grid(lf.height(), lf.width(), r.patch, r.patch, r.stride);
  const int64_t m = n * r.patch * r.patch, c = lf.channels();
  io::MeasurementWriter writer((fs::path(dir) / io::kMeasurementsName).string(), c, grid.size(), m);
  const int64_t band = std::max<int64_t>(1, 4096 / std::max<int64_t>(1, grid.cols()));
  ProgressBar bar("simulate", grid.rows(), "rows");
  for (int64_t row = 0; row < grid.rows(); row += band) {
    const int64_t row_end = std::min(grid.rows(), row + band);
    auto values =
        optics::measure_patches(phi, lf.data(), grid, r.mode, r.effects, r.seed, row, row_end)
            .values;
    writer.write(values.view({c, -1, m}), row * grid.cols());
    bar.advance(row_end - row);
  }
  bar.finish();
  writer.close();
  meta["seconds"] = clock.seconds();
  meta["measurements"] = {{"file", io::kMeasurementsName},
                          {"dtype", "float32"},
                          {"byte_order", "little"},
                          {"shape", {c, grid.size(), m}}};
  meta["grid"] = {{"patch", r.patch},      {"stride", r.stride},  {"height", grid.height()},
                  {"width", grid.width()}, {"rows", grid.rows()}, {"cols", grid.cols()}};
  spdlog::info("simulated {} patches of {} measurements with {} ({}) in {:.3f} s", c * grid.size(),
               m, phi.spec().label(), optics::to_string(r.mode), clock.seconds());
}

}  // namespace

nlohmann::json write_acquisition(const SimulateRequest& r, const std::string& dir) {
  LFNET_CHECK(r.phi != nullptr, "write_acquisition needs a Phi");
  LFNET_CHECK_AS(ConfigError, r.patch >= 1 && r.stride >= 1, "the patch and stride must be >= 1");
  const auto& lf = r.lf;
  const auto& phi = *r.phi;
  nlohmann::json meta = {
      {"format", io::kAcquisitionFormat},
      {"format_version", io::kAcquisitionFormatVersion},
      {"lfnet_version", kVersion},
      {"mode", optics::to_string(r.mode)},
      {"phi", phi.spec().to_json()},
      {"effects", r.effects.to_json()},
      {"noise_sigma", r.effects.gaussian ? r.effects.gaussian->sigma : 0.0},
      {"seed", r.seed},
      {"light_field",
       {{"channels", lf.channels()},
        {"rows", lf.rows()},
        {"cols", lf.cols()},
        {"height", lf.height()},
        {"width", lf.width()}}},
      {"views", r.views},
      {"color", lf.channels() == 3},
      {"source", r.source},
  };
  LFNET_CHECK_AS(ConfigError, r.camera_error.empty() || r.mode == optics::SimulationMode::kSensor,
                 "a camera error is simulated in sensor mode only");
  if (!r.camera_error.empty()) meta["camera_error"] = r.camera_error.to_json();
  LFNET_CHECK_AS(ConfigError, !r.cfa || r.mode == optics::SimulationMode::kSensor,
                 "a colour filter array is simulated in sensor mode only");
  LFNET_CHECK_AS(ConfigError, !r.cfa || lf.channels() == 3,
                 "a colour filter array needs a colour light field (--color), got ", lf.channels(),
                 " channel(s)");
  if (r.cfa) meta["cfa"] = r.cfa->to_json();
  if (r.mode == optics::SimulationMode::kSensor) {
    write_sensor_acquisition(r, dir, meta);
  } else {
    write_patch_acquisition(r, dir, meta);
  }
  write_json_file((fs::path(dir) / io::kSidecarName).string(), meta);
  return meta;
}

namespace {
// `lf`'s window (--views, else the central 5 x 5), grey unless --color, recorded in `in`.
LightField window_input(LightField lf, const SimulateSource& args, SimulateInput& in) {
  AngularRange ru, rv;
  if (args.views.empty()) {
    const int64_t n = 5;
    LFNET_CHECK_AS(ConfigError, lf.rows() >= n && lf.cols() >= n, "the light field in ", args.lf,
                   " has ", lf.rows(), "x", lf.cols(), " views, fewer than the default central ", n,
                   "x", n, ": choose views with --views R0:R1,C0:C1");
    ru = {central_start(lf.rows(), n), central_start(lf.rows(), n) + n};
    rv = {central_start(lf.cols(), n), central_start(lf.cols(), n) + n};
  } else {
    std::tie(ru, rv) = parse_views(args.views);
  }
  in.views = {{"rows", {ru.begin + 1, ru.end}},
              {"cols", {rv.begin + 1, rv.end}},
              {"source_grid", {lf.rows(), lf.cols()}}};
  lf = lf.window(ru, rv);
  if (!args.color) {
    lf = lf.grey();
  } else if (lf.channels() == 1) {
    spdlog::warn("--color given but {} is grey: simulating one channel", args.lf);
  }
  return lf;
}

// The still light field of `args`: a folder, a rendered scene or a white frame, windowed.
SimulateInput load_still_input(const SimulateSource& args) {
  SimulateInput in;
  LightField lf;
  if (!args.white.empty()) {
    // A white frame: every view of every pixel 1, on the window's grid (a flat field's input,
    // docs/acquisition.md).
    int64_t h = 0, w = 0;
    char x = 0, extra = 0;
    std::istringstream text(args.white);
    LFNET_CHECK_AS(ConfigError,
                   (text >> h >> x >> w) && x == 'x' && !(text >> extra) && h >= 1 && w >= 1 &&
                       h <= 100000 && w <= 100000,
                   "--white takes the sensor's size HxW, e.g. 593x840, not '", args.white, "'");
    const auto [rows, cols] = window_size(args.views);
    // The white views and the sensor image simulated from them, in float32.
    check_fits_in_memory(4.0 * (args.color ? 3 : 1) * static_cast<double>(rows * cols + 2) *
                             static_cast<double>(h) * static_cast<double>(w),
                         "--white " + args.white);
    lf = LightField(torch::ones({args.color ? 3 : 1, rows, cols, h, w}));
    in.source = {{"kind", "white"}, {"size", {h, w}}};
    in.views = {{"rows", {1, rows}}, {"cols", {1, cols}}, {"source_grid", {rows, cols}}};
    in.lf = lf;
    return in;
  }
  if (!args.scene.empty()) {
    scene::SceneSpec spec;
    try {
      spec = scene::load_scene(args.scene);
    } catch (const ConfigError& e) {
      throw ConfigError(args.scene + ": " + e.what());
    }
    lf = scene::render_scene(spec, scene_render_options(args.scene)).light_field;
    in.scene_effects = spec.sensor;
    in.source = {{"kind", "scene"}, {"path", fs::absolute(args.scene).string()}};
  } else {
    lf = read_oriented(args.lf, args.orient, "--orient", args.layout);
    in.source = {{"kind", "light_field"}, {"path", fs::absolute(args.lf).string()}};
    if (!args.orient.empty()) in.source["orient"] = args.orient;
    if (!args.layout.empty()) in.source["layout"] = args.layout;
  }
  in.lf = window_input(lf, args, in);
  return in;
}

// A scene's sub-frames, each windowed, as a stacked light field (docs/video.md).
SimulateInput load_scene_sequence(const SimulateSource& args, int64_t frames) {
  scene::SceneSpec spec;
  try {
    spec = scene::load_scene(args.scene);
  } catch (const ConfigError& e) {
    throw ConfigError(args.scene + ": " + e.what());
  }
  const auto seq =
      scene::render_sequence(spec, frames, scene_render_options(args.scene)).light_fields;
  SimulateInput in;
  in.scene_effects = spec.sensor;
  in.source = {{"kind", "scene"}, {"path", fs::absolute(args.scene).string()}, {"frames", frames}};
  std::vector<LightField> out;
  for (int64_t t = 0; t < frames; ++t) out.push_back(window_input(seq.frame(t), args, in));
  in.lf = LightFieldSequence(out).stacked();
  return in;
}
}  // namespace

SimulateInput load_simulate_input(const SimulateSource& args, int64_t frames) {
  LFNET_CHECK_AS(ConfigError, frames >= 1, "a camera codes at least one frame");
  const int64_t folder_frames = args.lf.empty() ? 0 : io::sequence_frames(args.lf);
  if (frames == 1 && folder_frames == 0) return load_still_input(args);
  LFNET_CHECK_AS(ConfigError, folder_frames == 0 || folder_frames == frames, args.lf,
                 " is a sequence of ", folder_frames,
                 " frames: code it with a time-coded camera of as many sub-frames (NAME:N@",
                 folder_frames, ", docs/video.md)");
  if (!args.scene.empty()) return load_scene_sequence(args, frames);
  if (folder_frames > 0) {
    std::vector<LightField> out;
    SimulateInput in;
    for (int64_t t = 0; t < frames; ++t) {
      auto frame = args;
      frame.lf = sequence_frame_dir(args.lf, t);
      in = load_still_input(frame);
      out.push_back(in.lf);
    }
    in.lf = LightFieldSequence(out).stacked();
    in.source["path"] = fs::absolute(args.lf).string();
    in.source["frames"] = frames;
    return in;
  }
  // A still light field or white frame: the same in every sub-frame.
  spdlog::info("a still source, coded as a scene that does not move over {} sub-frames", frames);
  auto in = load_still_input(args);
  in.lf =
      LightFieldSequence(in.lf.data().unsqueeze(0).expand({frames, -1, -1, -1, -1, -1})).stacked();
  return in;
}

std::pair<int64_t, int64_t> window_size(const std::string& views) {
  if (views.empty()) return {5, 5};
  auto [ru, rv] = parse_views(views);
  return {ru.size(), rv.size()};
}

optics::PhiSpec phi_for_window(const std::string& arg, int64_t rows, int64_t cols) {
  optics::PhiSpec spec;
  if (phi_argument_is_file(arg)) {
    spec = phi_from_argument(arg);
    LFNET_CHECK_AS(ConfigError, spec.rows == rows && spec.cols == cols, arg, " codes ", spec.rows,
                   "x", spec.cols, " views, but the light field window has ", rows, "x", cols,
                   ": set rows and cols in the file or choose --views to match");
  } else {
    spec = optics::PhiSpec::parse(arg);
    spec.rows = rows;
    spec.cols = cols;
  }
  return spec;
}

optics::SensorOptions simulation_effects(const std::string& effects_file, double noise,
                                         const SimulateInput& input,
                                         const std::string& scene_path) {
  optics::SensorOptions effects;
  if (effects_file.empty() && input.scene_effects) {
    effects = optics::SensorOptions::from_json(*input.scene_effects, scene_path + ":$.sensor");
  }
  if (!effects_file.empty()) {
    effects = optics::SensorOptions::from_json(read_json_file(effects_file), effects_file + ":$");
  }
  if (noise >= 0) {
    if (effects.gaussian && effects.gaussian->sigma != noise) {
      spdlog::warn("--noise {} replaces gaussian.sigma {} of {}", noise, effects.gaussian->sigma,
                   effects_file);
    }
    effects.gaussian = optics::SensorOptions::Gaussian{noise};
  }
  effects.validate();
  return effects;
}

namespace {

std::string format_values(const torch::Tensor& values, int64_t max_count) {
  std::string text;
  const int64_t n = values.numel();
  char buffer[32];
  for (int64_t i = 0; i < n; ++i) {
    if (n > max_count && i == max_count / 2) {
      text += " ...";
      i = n - max_count / 2;
    }
    std::snprintf(buffer, sizeof buffer, "%s%.4g", text.empty() ? "" : " ",
                  values[i].item<double>());
    text += buffer;
  }
  return text;
}

}  // namespace

std::string describe_phi(const optics::Phi& phi) {
  std::string text;
  auto print = [&text](const char* format, auto... args) { text += format_text(format, args...); };
  const auto c = optics::conditioning(phi);
  const auto& spec = phi.spec();
  if (spec.frames > 1) {
    print("phi:        %s on %lld frames of %lldx%lld views, compression %.1f%% (N / (T U V))\n",
          spec.label().c_str(), static_cast<long long>(spec.frames),
          static_cast<long long>(spec.rows), static_cast<long long>(spec.cols),
          100.0 * spec.n / (spec.coded_rows() * spec.cols));
  } else {
    print("phi:        %s on %lldx%lld views, compression %.1f%% (N / (U V))\n",
          spec.label().c_str(), static_cast<long long>(spec.rows),
          static_cast<long long>(spec.cols), 100.0 * spec.n / (spec.rows * spec.cols));
  }
  print("spec:       %s\n", spec.to_json().dump().c_str());
  if (spec.name == "asp") {
    const auto table = optics::asp_table(
        spec.rows, spec.cols, spec.n, spec.params.value("layout", "") == "pairs",
        spec.params.value("pair_gamma", 0.0), spec.params.value("pair_alpha", 0.0));
    print("asp table:\n   n   beta (rad)  gamma (deg)  alpha (deg)  k (theta, phi)  role\n");
    for (size_t i = 0; i < table.size(); ++i) {
      const auto& r = table[i];
      print("  %2zu  %10.4f  %11.2f  %11.1f  (%2lld, %2lld)        %s\n", i, r.beta,
            r.gamma * 180 / M_PI, r.alpha * 180 / M_PI, static_cast<long long>(r.k_theta),
            static_cast<long long>(r.k_phi), r.role.c_str());
    }
  }
  const int64_t pieces = c.singular_values.size(0);
  print("pieces:     %lld %s matri%s of %lld x %lld\n", static_cast<long long>(pieces),
        c.piece.c_str(), pieces == 1 ? "x" : "ces", static_cast<long long>(c.piece_rows),
        static_cast<long long>(c.piece_cols));
  auto cond_text = [](double k) {
    char b[32];
    if (std::isinf(k)) return std::string("inf (rank-deficient)");
    std::snprintf(b, sizeof b, "%.4g", k);
    return std::string(b);
  };
  if (pieces == 1) {
    print("singular values: %s\n", format_values(c.singular_values[0], 30).c_str());
    print("condition:  %s, rank %lld of %lld\n", cond_text(c.condition[0].item<double>()).c_str(),
          static_cast<long long>(c.rank[0].item<int64_t>()),
          static_cast<long long>(c.singular_values.size(1)));
    return text;
  }
  // Periodic models: one matrix per pixel phase; summarise, then list by phase.
  auto sorted = std::get<0>(c.condition.sort());
  print("condition:  min %s, median %s, max %s; rank min %lld, max %lld of %lld\n",
        cond_text(sorted[0].item<double>()).c_str(),
        cond_text(sorted[pieces / 2].item<double>()).c_str(),
        cond_text(sorted[pieces - 1].item<double>()).c_str(),
        static_cast<long long>(c.rank.min().item<int64_t>()),
        static_cast<long long>(c.rank.max().item<int64_t>()),
        static_cast<long long>(c.singular_values.size(1)));
  print("mean singular values over phases: %s\n",
        format_values(c.singular_values.mean(0), 30).c_str());
  const int64_t t = phi.period();
  print("condition by pixel phase (y mod %lld down, x mod %lld across):\n",
        static_cast<long long>(t), static_cast<long long>(t));
  for (int64_t y = 0; y < t; ++y) {
    std::string line = " ";
    for (int64_t x = 0; x < t; ++x) {
      char b[16];
      const double k = c.condition[y * t + x].item<double>();
      if (std::isinf(k)) {
        std::snprintf(b, sizeof b, " %8s", "inf");
      } else {
        std::snprintf(b, sizeof b, " %8.3g", k);
      }
      line += b;
    }
    print("%s\n", line.c_str());
  }
  return text;
}

namespace {

// lfnet simulate as a controller: check() reads the arguments and checks the outputs before any
// work; run() loads the light field, makes the camera and writes what was asked.
class Simulation {
 public:
  explicit Simulation(const SimulateOptions& options) : a_(options) {}

  void check() {
    // --cfa, or the one a calibrated Phi's folder names.
    cfa_ = cfa_of_arguments(a_.cfa, a_.phi);
    if (cfa_) a_.source.color = true;
    const auto& source = a_.source;
    LFNET_CHECK_AS(ConfigError, a_.patch >= 1 && a_.stride >= 1,
                   "--patch and --stride must be >= 1");
    const int sources = (source.lf.empty() ? 0 : 1) + (source.scene.empty() ? 0 : 1) +
                        (source.white.empty() ? 0 : 1);
    simulate_ = sources > 0 || !a_.out.empty();
    LFNET_CHECK_AS(ConfigError, sources <= 1,
                   "give one of --lf DIR, --scene SCENE.json and --white HxW");
    LFNET_CHECK_AS(ConfigError, simulate_ || a_.describe || !a_.plot_weights.empty(),
                   "nothing to do: give --lf and --out to simulate, or --describe / "
                   "--plot-weights DIR");
    LFNET_CHECK_AS(ConfigError, !simulate_ || sources == 1,
                   "--lf DIR, --scene SCENE.json or --white HxW is required to simulate");
    LFNET_CHECK_AS(ConfigError, !simulate_ || !a_.out.empty(), "--out DIR is required to simulate");
    if (!a_.camera_error.empty()) {
      camera_error_ = optics::CalibrationError::from_json(
          read_json_argument(a_.camera_error, "--camera-error"),
          json_argument_source(a_.camera_error, "--camera-error"));
      LFNET_CHECK_AS(ConfigError, a_.mode == optics::SimulationMode::kSensor,
                     "--camera-error is simulated in sensor mode only");
    }
    check_outputs();
  }

  SimulateResult run() {
    SimulateInput input;
    // The window is --views or the central 5 x 5, whatever the source holds.
    const auto [rows, cols] = window_size(a_.source.views);
    const auto phi = optics::make_phi(phi_for_window(a_.phi, rows, cols));
    if (simulate_) {
      Stopwatch load;
      input = load_simulate_input(a_.source, phi->frames());
      spdlog::info("light field {} ({} s)", input.lf.shape_string(), load.seconds());
    }
    SimulateResult r;
    if (a_.describe) r.description = describe_phi(*phi);
    if (!a_.plot_weights.empty()) r.weights_file = plot_weights(*phi, a_.plot_weights, weights_);
    if (!simulate_) return r;
    SimulateRequest request;
    request.lf = input.lf;
    request.phi = phi.get();
    request.effects = simulation_effects(a_.effects, a_.noise, input, a_.source.scene);
    request.camera_error = camera_error_;
    request.cfa = cfa_;
    request.mode = a_.mode;
    request.seed = a_.seed;
    request.patch = a_.patch;
    request.stride = a_.stride;
    request.views = input.views;
    request.source = input.source;
    write_folder(a_.out, policy_, [&](const std::string& dir) { write_acquisition(request, dir); });
    r.simulated = true;
    return r;
  }

 private:
  // Every file it reads (a noise switch's members and the files of its JSON options too) is
  // kept from --out and --plot-weights, which are kept apart.
  void check_outputs() {
    policy_.force = a_.force;
    policy_.inputs = {a_.source.lf, a_.source.scene, a_.effects,
                      json_argument_file(a_.camera_error), json_argument_file(a_.cfa)};
    if (fs::exists(a_.phi)) {  // a spec, a calibrated Phi or a model
      for (const auto& path : model_input_files(a_.phi)) policy_.inputs.push_back(path);
    }
    weights_ = policy_;
    weights_.option = "--plot-weights";
    weights_.inputs.push_back(a_.out);
    policy_.inputs.push_back(a_.plot_weights);
    if (simulate_) check_output_folder(a_.out, policy_);
    if (!a_.plot_weights.empty()) {
      check_output_apart(a_.plot_weights, weights_.inputs, weights_.option);
    }
  }

  SimulateOptions a_;  // a copy: a colour filter array implies a colour light field
  std::optional<optics::ColourFilterArray> cfa_;
  bool simulate_ = false;  // an acquisition folder to write, not only the Phi to show
  optics::CalibrationError camera_error_;
  OutputFolderPolicy policy_;   // --out
  OutputFolderPolicy weights_;  // --plot-weights
};

}  // namespace

SimulateResult simulate(const SimulateOptions& options) {
  Simulation simulation(options);
  simulation.check();
  return simulation.run();
}

}  // namespace lfnet::pipeline

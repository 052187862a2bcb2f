// lfnet simulate: coded capture of a light field; writes the acquisition folder that
// `lfnet reconstruct` reads (docs/acquisition.md).
#include <spdlog/spdlog.h>
#include <torch/torch.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/light_field.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/asp.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"
#include "lfnet/optics/weights_image.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/simulate.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"

namespace fs = std::filesystem;

namespace lfnet::app {

namespace {

struct SimulateArgs {
  std::string lf;             // light-field folder
  std::string scene;          // or a scene spec to render
  std::string phi = "asp:2";  // NAME[:N] or PHI.json
  std::string mode = "sensor";
  double noise = -1;  // < 0: not given
  uint64_t seed = 0;
  std::string out;
  std::string views;   // R0:R1,C0:C1, 1-based; default the central 5 x 5
  std::string orient;  // angular reorientation of the folder (docs/conventions.md)
  std::string layout;  // file-naming pattern of the folder (io::parse_layout)
  bool color = false;
  std::string effects;  // EFFECTS.json
  int64_t stride = 5;
  int64_t patch = 9;
  bool force = false;
  bool describe = false;
  std::string plot_weights;  // folder for the angular-response PNG
};

// What the simulation codes: the windowed light field and a record of where it came from.
struct Input {
  LightField lf;
  nlohmann::json source;
  nlohmann::json views;  // the angular window in the source grid, 1-based inclusive
  std::optional<nlohmann::json> scene_effects;  // a scene's own sensor block, if it names one
};

// The light field to code: read, windowed, grey unless --color. The one step that a scene
// renderer (--scene SCENE.json) replaces.
Input load_input(const SimulateArgs& args) {
  Input in;
  LightField lf;
  if (!args.scene.empty()) {
    scene::SceneSpec spec;
    try {
      spec = scene::load_scene(args.scene);
    } catch (const ConfigError& e) {
      throw ConfigError(args.scene + ": " + e.what());
    }
    lf = scene::render_scene(spec, pipeline::scene_render_options(args.scene)).light_field;
    in.scene_effects = spec.sensor;
    in.source = {{"kind", "scene"}, {"path", fs::absolute(args.scene).string()}};
  } else {
    lf = pipeline::read_oriented(args.lf, args.orient, "--orient", args.layout);
    in.source = {{"kind", "light_field"}, {"path", fs::absolute(args.lf).string()}};
    if (!args.orient.empty()) in.source["orient"] = args.orient;
    if (!args.layout.empty()) in.source["layout"] = args.layout;
  }
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
  in.lf = lf;
  return in;
}

// The views a Phi codes when there is no light field to look at (--describe, --plot-weights).
std::pair<int64_t, int64_t> window_size(const SimulateArgs& args) {
  if (args.views.empty()) return {5, 5};
  auto [ru, rv] = parse_views(args.views);
  return {ru.size(), rv.size()};
}

optics::PhiSpec resolve_phi(const std::string& arg, int64_t rows, int64_t cols) {
  optics::PhiSpec spec;
  if (pipeline::phi_argument_is_file(arg)) {
    spec = pipeline::phi_from_argument(arg);
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

optics::SensorOptions resolve_effects(const SimulateArgs& args, const Input& input) {
  optics::SensorOptions effects;
  if (args.effects.empty() && input.scene_effects) {
    effects = optics::SensorOptions::from_json(*input.scene_effects, args.scene + ":$.sensor");
  }
  if (!args.effects.empty()) {
    effects = optics::SensorOptions::from_json(read_json_file(args.effects), args.effects + ":$");
  }
  if (args.noise >= 0) {
    if (effects.gaussian && effects.gaussian->sigma != args.noise) {
      spdlog::warn("--noise {} replaces gaussian.sigma {} of {}", args.noise,
                   effects.gaussian->sigma, args.effects);
    }
    effects.gaussian = optics::SensorOptions::Gaussian{args.noise};
  }
  effects.validate();
  return effects;
}

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

// Prints how much each piece of the camera can recover: singular values and condition numbers.
void describe(const optics::Phi& phi) {
  const auto c = optics::conditioning(phi);
  const auto& spec = phi.spec();
  std::printf("phi:        %s on %lldx%lld views, compression %.1f%% (N / (U V))\n",
              spec.label().c_str(), static_cast<long long>(spec.rows),
              static_cast<long long>(spec.cols), 100.0 * spec.n / (spec.rows * spec.cols));
  std::printf("spec:       %s\n", spec.to_json().dump().c_str());
  if (spec.name == "asp") {
    const auto table = optics::asp_table(
        spec.rows, spec.cols, spec.n, spec.params.value("layout", "") == "pairs",
        spec.params.value("pair_gamma", 0.0), spec.params.value("pair_alpha", 0.0));
    std::printf("asp table:\n   n   beta (rad)  gamma (deg)  alpha (deg)  k (theta, phi)  role\n");
    for (size_t i = 0; i < table.size(); ++i) {
      const auto& r = table[i];
      std::printf("  %2zu  %10.4f  %11.2f  %11.1f  (%2lld, %2lld)        %s\n", i, r.beta,
                  r.gamma * 180 / M_PI, r.alpha * 180 / M_PI, static_cast<long long>(r.k_theta),
                  static_cast<long long>(r.k_phi), r.role.c_str());
    }
  }
  const int64_t pieces = c.singular_values.size(0);
  std::printf("pieces:     %lld %s matri%s of %lld x %lld\n", static_cast<long long>(pieces),
              c.piece.c_str(), pieces == 1 ? "x" : "ces", static_cast<long long>(c.piece_rows),
              static_cast<long long>(c.piece_cols));
  auto cond_text = [](double k) {
    char b[32];
    if (std::isinf(k)) return std::string("inf (rank-deficient)");
    std::snprintf(b, sizeof b, "%.4g", k);
    return std::string(b);
  };
  if (pieces == 1) {
    std::printf("singular values: %s\n", format_values(c.singular_values[0], 30).c_str());
    std::printf("condition:  %s, rank %lld of %lld\n",
                cond_text(c.condition[0].item<double>()).c_str(),
                static_cast<long long>(c.rank[0].item<int64_t>()),
                static_cast<long long>(c.singular_values.size(1)));
    return;
  }
  // Periodic models: one matrix per pixel phase; summarise, then list by phase.
  auto sorted = std::get<0>(c.condition.sort());
  std::printf("condition:  min %s, median %s, max %s; rank min %lld, max %lld of %lld\n",
              cond_text(sorted[0].item<double>()).c_str(),
              cond_text(sorted[pieces / 2].item<double>()).c_str(),
              cond_text(sorted[pieces - 1].item<double>()).c_str(),
              static_cast<long long>(c.rank.min().item<int64_t>()),
              static_cast<long long>(c.rank.max().item<int64_t>()),
              static_cast<long long>(c.singular_values.size(1)));
  std::printf("mean singular values over phases: %s\n",
              format_values(c.singular_values.mean(0), 30).c_str());
  const int64_t t = phi.period();
  std::printf("condition by pixel phase (y mod %lld down, x mod %lld across):\n",
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
    std::printf("%s\n", line.c_str());
  }
}

void run_simulate(const SimulateArgs& args) {
  const auto mode = optics::parse_simulation_mode(args.mode);
  LFNET_CHECK_AS(ConfigError, args.patch >= 1 && args.stride >= 1,
                 "--patch and --stride must be >= 1");
  const bool simulate = !args.lf.empty() || !args.scene.empty() || !args.out.empty();
  LFNET_CHECK_AS(ConfigError, args.lf.empty() || args.scene.empty(),
                 "give either --lf DIR or --scene SCENE.json, not both");
  LFNET_CHECK_AS(ConfigError, simulate || args.describe || !args.plot_weights.empty(),
                 "nothing to do: give --lf and --out to simulate, or --describe / "
                 "--plot-weights DIR");
  LFNET_CHECK_AS(ConfigError, !simulate || !args.lf.empty() || !args.scene.empty(),
                 "--lf DIR or --scene SCENE.json is required to simulate");
  LFNET_CHECK_AS(ConfigError, !simulate || !args.out.empty(), "--out DIR is required to simulate");

  OutputFolderPolicy policy;
  policy.force = args.force;
  policy.inputs = {args.lf, args.scene, args.plot_weights};
  if (simulate) check_output_folder(args.out, policy);
  Input input;
  int64_t rows = 0, cols = 0;
  if (simulate) {
    Stopwatch load;
    input = load_input(args);
    rows = input.lf.rows();
    cols = input.lf.cols();
    spdlog::info("light field {} ({} s)", input.lf.shape_string(), load.seconds());
  } else {
    std::tie(rows, cols) = window_size(args);
  }
  const auto phi = optics::make_phi(resolve_phi(args.phi, rows, cols));
  if (args.describe) describe(*phi);
  if (!args.plot_weights.empty()) {
    fs::create_directories(args.plot_weights);
    const auto& s = phi->spec();
    const std::string path =
        (fs::path(args.plot_weights) / (s.name + "-n" + std::to_string(s.n) + ".png")).string();
    io::write_image(path, optics::weights_image(*phi), 8);
    spdlog::info("wrote {}", path);
  }
  if (!simulate) return;

  pipeline::SimulateRequest request;
  request.lf = input.lf;
  request.phi = phi.get();
  request.effects = resolve_effects(args, input);
  request.mode = mode;
  request.seed = args.seed;
  request.patch = args.patch;
  request.stride = args.stride;
  request.views = input.views;
  request.source = input.source;
  write_folder(args.out, policy,
               [&](const std::string& dir) { pipeline::write_acquisition(request, dir); });
  spdlog::info("wrote {}", args.out);
}

}  // namespace

void add_simulate_command(CLI::App& app, const GlobalOptions& /*global*/) {
  auto* cmd = app.add_subcommand(
      "simulate", "Simulate coded capture of a light field with a Phi model and sensor effects");
  auto args = std::make_shared<SimulateArgs>();
  cmd->add_option("--lf", args->lf, "light field folder of sub-aperture images");
  cmd->add_option("--scene", args->scene,
                  "procedural scene spec to render and simulate (configs/scenes)");
  cmd->add_option("--phi", args->phi,
                  "Phi model NAME[:N] (asp, mask, aperture, random, lenslet), a PHI.json spec, a "
                  "calibrated-Phi folder or a model file")
      ->capture_default_str();
  cmd->add_option("--mode", args->mode,
                  "sensor: one sensor image; per_patch: every patch measured alone (the paper's "
                  "protocol)")
      ->check(CLI::IsMember({"sensor", "per_patch"}))
      ->capture_default_str();
  cmd->add_option("--noise", args->noise,
                  "Gaussian noise sigma, relative to a white scene's mean measurement (1)")
      ->check(kFiniteNonNegative);
  cmd->add_option("--seed", args->seed, "seed of the noise")->capture_default_str();
  cmd->add_option("--out", args->out, "output folder (see docs/acquisition.md)");
  cmd->add_option("--views", args->views,
                  "angular window R0:R1,C0:C1, 1-based inclusive (default: the central 5x5)");
  cmd->add_option(
      "--orient", args->orient,
      "reorient the folder's angular axes: flip-u, flip-v, transpose (comma-separated)");
  cmd->add_option("--layout", args->layout,
                  "file-naming pattern of --lf: view_{row}_{col}.png, or "
                  "img{index}.png:cols=9[:col-major] (docs/conventions.md)");
  cmd->add_flag("--color", args->color, "simulate every colour channel (default: grey luma)");
  cmd->add_option("--effects", args->effects, "sensor effects JSON (docs/acquisition.md)");
  cmd->add_option("--stride", args->stride, "patch stride, per_patch mode")
      ->check(kStride)
      ->capture_default_str();
  cmd->add_option("--patch", args->patch, "patch size, per_patch mode")->capture_default_str();
  cmd->add_flag("--force", args->force, "replace an existing non-empty --out folder");
  cmd->add_flag("--describe", args->describe,
                "print the singular values and condition numbers of the Phi's per-pixel (or "
                "per-block) matrices");
  cmd->add_option("--plot-weights", args->plot_weights,
                  "write a PNG of every measurement's angular response M_n(u, v) into DIR");
  cmd->callback([args] { run_simulate(*args); });
}

}  // namespace lfnet::app

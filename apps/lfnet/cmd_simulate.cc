// lfnet simulate: coded capture of a light field; writes the acquisition folder that
// `lfnet reconstruct` reads (docs/acquisition.md, pipeline/simulate.h).
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include "command.h"
#include "flags.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/figures.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/simulate.h"

namespace lfnet::app {

namespace {

struct SimulateArgs {
  pipeline::SimulateSource source;  // the light field (or scene), window, orientation, colour
  std::string phi = "asp:2";        // NAME[:N] or PHI.json
  optics::SimulationMode mode = optics::SimulationMode::kSensor;
  double noise = -1;  // < 0: not given
  uint64_t seed = 0;
  std::string out;
  std::string effects;       // EFFECTS.json
  std::string camera_error;  // JSON or a file (optics/calibration.h)
  std::string cfa;  // a Bayer pattern or JSON, inline or a file (optics/cfa.h); implies --color
  int64_t stride = 5;
  int64_t patch = 9;
  bool force = false;
  bool describe = false;
  std::string plot_weights;  // folder for the angular-response PNG
};

void run_simulate(const SimulateArgs& given) {
  SimulateArgs args = given;
  // --cfa, or the one a calibrated Phi's folder names; read before any work.
  const auto cfa = pipeline::cfa_of_arguments(args.cfa, args.phi);
  if (cfa) args.source.color = true;
  const auto& source = args.source;
  const auto mode = args.mode;
  LFNET_CHECK_AS(ConfigError, args.patch >= 1 && args.stride >= 1,
                 "--patch and --stride must be >= 1");
  const bool simulate =
      !source.lf.empty() || !source.scene.empty() || !source.white.empty() || !args.out.empty();
  LFNET_CHECK_AS(ConfigError,
                 (source.lf.empty() ? 0 : 1) + (source.scene.empty() ? 0 : 1) +
                         (source.white.empty() ? 0 : 1) <=
                     1,
                 "give one of --lf DIR, --scene SCENE.json and --white HxW");
  LFNET_CHECK_AS(ConfigError, simulate || args.describe || !args.plot_weights.empty(),
                 "nothing to do: give --lf and --out to simulate, or --describe / "
                 "--plot-weights DIR");
  LFNET_CHECK_AS(ConfigError,
                 !simulate || !source.lf.empty() || !source.scene.empty() || !source.white.empty(),
                 "--lf DIR, --scene SCENE.json or --white HxW is required to simulate");
  LFNET_CHECK_AS(ConfigError, !simulate || !args.out.empty(), "--out DIR is required to simulate");
  optics::CalibrationError camera_error;  // read before any work
  if (!args.camera_error.empty()) {
    camera_error = optics::CalibrationError::from_json(
        read_json_argument(args.camera_error, "--camera-error"),
        json_argument_source(args.camera_error, "--camera-error"));
    LFNET_CHECK_AS(ConfigError, mode == optics::SimulationMode::kSensor,
                   "--camera-error is simulated in sensor mode only");
  }

  OutputFolderPolicy policy;
  policy.force = args.force;
  // Every file it reads: a noise switch's members and the files of its JSON options too.
  policy.inputs = {source.lf, source.scene, args.effects, json_argument_file(args.camera_error),
                   json_argument_file(args.cfa)};
  if (std::filesystem::exists(args.phi)) {  // a spec, a calibrated Phi or a model
    for (const auto& path : pipeline::model_input_files(args.phi)) policy.inputs.push_back(path);
  }
  // --plot-weights DIR receives files under the same policy, apart from the inputs and --out.
  OutputFolderPolicy weights_policy = policy;
  weights_policy.option = "--plot-weights";
  weights_policy.inputs.push_back(args.out);
  policy.inputs.push_back(args.plot_weights);
  if (simulate) check_output_folder(args.out, policy);
  if (!args.plot_weights.empty()) {
    check_output_apart(args.plot_weights, weights_policy.inputs, weights_policy.option);
  }
  pipeline::SimulateInput input;
  int64_t rows = 0, cols = 0;
  if (simulate) {
    Stopwatch load;
    input = pipeline::load_simulate_input(source);
    rows = input.lf.rows();
    cols = input.lf.cols();
    spdlog::info("light field {} ({} s)", input.lf.shape_string(), load.seconds());
  } else {
    std::tie(rows, cols) = pipeline::window_size(source.views);
  }
  const auto phi = optics::make_phi(pipeline::phi_for_window(args.phi, rows, cols));
  if (args.describe) std::fputs(pipeline::describe_phi(*phi).c_str(), stdout);
  if (!args.plot_weights.empty()) {
    spdlog::info("wrote {}", pipeline::plot_weights(*phi, args.plot_weights, weights_policy));
  }
  if (!simulate) return;

  pipeline::SimulateRequest request;
  request.lf = input.lf;
  request.phi = phi.get();
  request.effects = pipeline::simulation_effects(args.effects, args.noise, input, source.scene);
  request.camera_error = camera_error;
  request.cfa = cfa;
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
  add_lf_option(cmd, args->source.lf);
  cmd->add_option("--white", args->source.white,
                  "or a uniform white light field of HxW pixels: the camera's white frame, for "
                  "--flat-field (docs/acquisition.md)");
  add_scene_option(cmd, args->source.scene);
  add_phi_option(cmd, args->phi)->capture_default_str();
  add_mode_option(cmd, args->mode);
  add_noise_option(cmd, args->noise);
  add_seed_option(cmd, args->seed)->capture_default_str();
  output_folder(cmd->add_option("--out", args->out, "output folder (see docs/acquisition.md)"));
  add_views_option(cmd, args->source.views);
  add_orient_option(cmd, args->source.orient);
  add_layout_option(cmd, args->source.layout);
  cmd->add_flag("--color", args->source.color,
                "simulate every colour channel (default: grey luma)");
  add_effects_option(cmd, args->effects);
  add_cfa_option(cmd, args->cfa);  // implies --color
  add_camera_error_option(cmd, args->camera_error);
  cmd->add_option("--stride", args->stride, "patch stride, per_patch mode")
      ->check(kStride)
      ->capture_default_str();
  cmd->add_option("--patch", args->patch, "patch size, per_patch mode")
      ->check(whole_number_in(1, 64, "pixels"))
      ->capture_default_str();
  add_force_flag(cmd, args->force);  // --out, and --plot-weights files
  cmd->add_flag("--describe", args->describe,
                "print the singular values and condition numbers of the Phi's per-pixel (or "
                "per-block) matrices");
  cmd->add_option("--plot-weights", args->plot_weights,
                  "draw every measurement's angular response M_n(u, v) into DIR/NAME-nN.png (and "
                  ".svg, .json; existing ones are replaced with --force)");
  cmd->callback([args] { run_simulate(*args); });
}

}  // namespace lfnet::app

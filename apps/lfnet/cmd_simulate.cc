// lfnet simulate: coded capture of a light field; writes the acquisition folder that
// `lfnet reconstruct` reads (docs/acquisition.md, pipeline/simulate.h).
#include <spdlog/spdlog.h>

#include <cstdio>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/simulate.h"

namespace lfnet::app {

namespace {

void run_simulate(const pipeline::SimulateOptions& options) {
  const auto r = pipeline::simulate(options);
  if (!r.description.empty()) std::fputs(r.description.c_str(), stdout);
  if (!r.weights_file.empty()) spdlog::info("wrote {}", r.weights_file);
  if (r.simulated) spdlog::info("wrote {}", options.out);
}

}  // namespace

void add_simulate_command(CLI::App& app, const GlobalOptions& /*global*/) {
  auto* cmd = app.add_subcommand(
      "simulate", "Simulate coded capture of a light field with a Phi model and sensor effects");
  auto args = std::make_shared<pipeline::SimulateOptions>();
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

// lfnet render: a procedural scene (or a random one) into a light-field folder with its true
// disparity map, previews and the resolved spec.
#include <spdlog/spdlog.h>

#include <string>
#include <utility>

#include "command.h"
#include "flags.h"
#include "lfnet/core/error.h"
#include "lfnet/pipeline/render.h"

namespace lfnet::app {
namespace {

struct RenderArgs {
  pipeline::RenderRequest request;
  std::string size, views, disparity_range, shift;  // as typed: HxW, RxC, MIN:MAX, DX,DY
};

// Parses "AxB" into two positive integers.
std::pair<int64_t, int64_t> parse_pair(const std::string& text, char sep, const std::string& flag) {
  const auto at = text.find(sep);
  try {
    if (at == std::string::npos) throw std::invalid_argument(text);
    size_t used = 0;
    const int64_t a = std::stoll(text.substr(0, at), &used);
    if (used != at) throw std::invalid_argument(text);
    const std::string rest = text.substr(at + 1);
    const int64_t b = std::stoll(rest, &used);
    if (used != rest.size()) throw std::invalid_argument(text);
    return {a, b};
  } catch (const std::exception&) {
    throw ConfigError(flag + " '" + text + "': expected two integers separated by '" +
                      std::string(1, sep) + "'");
  }
}

std::pair<double, double> parse_range(const std::string& text) {
  const auto at = text.find(':');
  try {
    if (at == std::string::npos) throw std::invalid_argument(text);
    size_t used = 0;
    const double a = std::stod(text.substr(0, at), &used);
    if (used != at) throw std::invalid_argument(text);
    const std::string rest = text.substr(at + 1);
    const double b = std::stod(rest, &used);
    if (used != rest.size()) throw std::invalid_argument(text);
    return {a, b};
  } catch (const std::exception&) {
    throw ConfigError("--disparity-range '" + text + "': expected MIN:MAX, e.g. -3:3");
  }
}

void run_render(RenderArgs& a) {
  auto& q = a.request;
  if (!a.size.empty()) q.size = parse_pair(a.size, 'x', "--size");
  if (!a.views.empty()) q.views = parse_pair(a.views, 'x', "--views");
  if (!a.disparity_range.empty()) q.disparity_range = parse_range(a.disparity_range);
  if (!a.shift.empty()) q.shift = parse_pair(a.shift, ',', "--shift");
  const auto s = pipeline::render_to_folder(q);
  std::string effects;
  for (const auto& e : s.effects) effects += (effects.empty() ? "" : ", ") + e;
  spdlog::info("rendered {} ({} {}C x U x V x H x W) in {:.3f} s on {} threads; effects: {}",
               s.name, s.shape, s.frames > 1 ? "T x " : "", s.seconds, s.threads,
               effects.empty() ? "none" : effects);
  if (q.lf.empty()) {
    spdlog::info("disparity {:.3f} .. {:.3f} px per view; written to {}", s.min_disparity,
                 s.max_disparity, q.out);
  } else {
    spdlog::info("written to {}", q.out);
  }
}

}  // namespace

void add_render_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "render", "Render a procedural scene into a light field folder with its true disparity map");
  auto args = std::make_shared<RenderArgs>();
  add_scene_option(cmd, args->request.scene);
  cmd->add_option("--random", args->request.random_seed,
                  "render the random training scene of this seed")
      ->check(kWhole);
  input_path(
      cmd->add_option("--random-options", args->request.random_options,
                      "with --random: the random scene's options (docs/scenes.md), a JSON object "
                      "or file, e.g. '{\"frame_probability\": 1}'"));
  cmd->add_option("--size", args->size, "HxW of a random scene (default 256x256)");
  cmd->add_option("--views", args->views, "RxC angular grid of a random scene (default 5x5)");
  cmd->add_option("--disparity-range", args->disparity_range,
                  "MIN:MAX disparity of a random scene in px per view (default -3:3)");
  cmd->add_flag("--grey", args->request.grey, "render one luma channel");
  output_folder(cmd->add_option("--out", args->request.out,
                                "output folder: lf_R_C.png, disparity.pfm, previews, scene.json"))
      ->required();
  add_force_flag(cmd, args->request.force);
  cmd->add_option("--bits", args->request.bits, "bits per PNG sample, 8 or 16")
      ->check(CLI::IsMember({8, 16}));
  cmd->add_option("--frames", args->request.frames,
                  "sub-frames of a moving scene (1..64): frame_0/ .. frame_{T-1}/ (default 1)");
  add_lf_option(cmd, args->request.lf);
  cmd->add_option("--shift", args->shift,
                  "with --lf, a real still light field given synthetic motion over --frames: DX,DY "
                  "whole px the image moves per sub-frame (default 0,0; docs/video.md)");
  cmd->add_option("--walk", args->request.walk,
                  "with --lf: view columns the camera moves per sub-frame, so each point moves by "
                  "its disparity (default 0)")
      ->check(kWhole);
  cmd->add_option("--epi-row", args->request.epi_row,
                  "spatial row of the EPI in preview.png (default: the centre row)")
      ->check(kWhole);
  cmd->callback([args] { run_render(*args); });
}

}  // namespace lfnet::app

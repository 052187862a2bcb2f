// lfnet render: a procedural scene (or a random one) into a light-field folder with its true
// disparity map, previews and the resolved spec.
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/scene/scene.h"

namespace lfnet::app {
namespace {

namespace fs = std::filesystem;

struct RenderArgs {
  std::string scene;
  int64_t random_seed = -1;
  std::string random_options;
  std::string size;
  std::string views;
  std::string disparity_range;
  bool grey = false;
  std::string out;
  bool force = false;
  int bits = 16;
  int64_t epi_row = -1;
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

// OpenCV's viridis as a (256, 3) RGB table in [0, 1].
const torch::Tensor& viridis_table() {
  static const torch::Tensor table = [] {
    cv::Mat levels(1, 256, CV_8UC1);
    for (int i = 0; i < 256; ++i) levels.at<uint8_t>(0, i) = static_cast<uint8_t>(i);
    cv::Mat bgr;
    cv::applyColorMap(levels, bgr, cv::COLORMAP_VIRIDIS);
    auto t = torch::empty({256, 3});
    for (int i = 0; i < 256; ++i) {
      const auto c = bgr.at<cv::Vec3b>(0, i);
      for (int k = 0; k < 3; ++k) t[i][k] = static_cast<float>(c[2 - k]) / 255.0f;
    }
    return t;
  }();
  return table;
}

// The colour map of disparity maps (OpenCV's viridis): values in [0, 1] of any shape S to RGB
// (3, S...) float32 in [0, 1]; values outside are clamped.
torch::Tensor viridis(const torch::Tensor& t) {
  auto index = (t.to(torch::kFloat32).clamp(0, 1) * 255).round().to(torch::kLong);
  auto rgb = viridis_table().index({index});  // (S..., 3)
  return rgb.movedim(-1, 0).contiguous();
}

// Disparity maps in viridis: far (small) is dark blue, near (large) is yellow.
torch::Tensor colour_map(const torch::Tensor& disparity) {
  const float lo = disparity.min().item<float>();
  const float hi = disparity.max().item<float>();
  return viridis(hi > lo ? (disparity - lo) / (hi - lo) : torch::full_like(disparity, 0.5f));
}

// A small image to look at: the centre view and the disparity map side by side, area-downscaled
// to at most 640 px wide, over a full-resolution crop of the horizontal EPI through the centre
// row or `epi_row` (8 rows per view), whose ends are ticked in red on the centre view.
torch::Tensor preview_image(const LightField& lf, const torch::Tensor& disparity, int64_t epi_row) {
  const int64_t gap = 4;
  const int64_t w = lf.width();
  const int64_t h = lf.height();
  const int64_t factor = std::max<int64_t>(1, (2 * w + gap + 639) / 640);
  auto colour = [&](const torch::Tensor& x) {
    return x.size(0) == 3 ? x : x.expand({3, x.size(1), x.size(2)});
  };
  auto top = torch::ones({3, h, 2 * w + gap});
  top.slice(2, 0, w).copy_(colour(lf.view(lf.rows() / 2, lf.cols() / 2)));
  top.slice(2, w + gap, 2 * w + gap).copy_(colour_map(disparity));
  if (factor > 1) top = torch::avg_pool2d(top.unsqueeze(0), factor).squeeze(0);
  const int64_t width = top.size(2);
  const int64_t crop = std::min(width, w);
  const int64_t x0 = (w - crop) / 2;
  if (epi_row < 0 || epi_row >= h) epi_row = h / 2;
  const auto epi = colour(io::horizontal_epi(lf, epi_row, 8)).slice(2, x0, x0 + crop);
  // Ticks above and below the EPI's row at the ends of its crop.
  const int64_t row = epi_row / factor;
  for (const int64_t x : {x0 / factor, std::min((x0 + crop - 1) / factor, top.size(2) - 1)}) {
    for (const int64_t y : {row - 6, row + 2}) {
      if (y < 0 || y + 4 > top.size(1)) continue;
      auto tick = top.slice(1, y, y + 4).slice(2, x, x + 1);
      tick.select(0, 0).fill_(1.0f);
      tick.select(0, 1).fill_(0.0f);
      tick.select(0, 2).fill_(0.0f);
    }
  }
  auto canvas = torch::ones({3, top.size(1) + gap + epi.size(1), width});
  canvas.slice(1, 0, top.size(1)).copy_(top);
  canvas.slice(1, top.size(1) + gap).slice(2, 0, crop).copy_(epi);
  return canvas.clamp(0.0, 1.0);
}

void run_render(const RenderArgs& args) {
  const bool random = args.random_seed >= 0;
  if (random == !args.scene.empty()) {
    throw ConfigError("give exactly one of --scene SCENE.json and --random SEED");
  }
  if (!random && (!args.random_options.empty() || !args.size.empty() || !args.views.empty() ||
                  !args.disparity_range.empty())) {
    throw ConfigError(
        "--random-options, --size, --views and --disparity-range apply to --random only");
  }
  scene::SceneSpec spec;
  scene::RandomSceneOptions options;
  if (random) {
    if (!args.random_options.empty()) {
      const auto doc = read_json_file(args.random_options);
      JsonReader reader(doc, args.random_options + ":$");
      options = scene::RandomSceneOptions::from_json(reader);
    }
    if (!args.size.empty())
      std::tie(options.height, options.width) = parse_pair(args.size, 'x', "--size");
    if (!args.views.empty())
      std::tie(options.rows, options.cols) = parse_pair(args.views, 'x', "--views");
    if (!args.disparity_range.empty()) {
      std::tie(options.min_disparity, options.max_disparity) = parse_range(args.disparity_range);
    }
    if (args.grey) options.color = false;
    options.validate("options");
    spec = scene::random_scene(static_cast<uint64_t>(args.random_seed), options);
  } else {
    try {
      spec = scene::load_scene(args.scene);
    } catch (const ConfigError& e) {
      throw ConfigError(args.scene + ": " + e.what());
    }
    if (args.grey) spec.color = false;
  }
  if (args.epi_row >= spec.height) {
    throw ConfigError("--epi-row " + std::to_string(args.epi_row) + " is outside the " +
                      std::to_string(spec.height) + "-row view");
  }
  OutputFolderPolicy policy;
  policy.force = args.force;
  policy.inputs = {args.scene, args.random_options};
  check_output_folder(args.out, policy);

  const scene::RenderOptions render_options =
      pipeline::scene_render_options(random ? "" : args.scene);
  const auto start = std::chrono::steady_clock::now();
  const scene::RenderResult result = scene::render_scene(spec, render_options);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  nlohmann::json record = spec.to_json();
  record["rendered"] = {
      {"effects_run", result.effects_run},
      {"seconds", seconds},
      {"threads", torch::get_num_threads()},
      {"source", random ? "random " + std::to_string(args.random_seed) : args.scene}};
  if (random) record["rendered"]["random_options"] = options.to_json();
  write_folder(args.out, policy, [&](const std::string& dir) {
    io::write_light_field(result.light_field, dir, {"png", args.bits});
    io::write_pfm((fs::path(dir) / "disparity.pfm").string(), result.disparity);
    io::write_previews(result.light_field, dir);
    io::write_image((fs::path(dir) / "preview.png").string(),
                    preview_image(result.light_field, result.disparity, args.epi_row), 8);
    write_json_file((fs::path(dir) / "scene.json").string(), record);
  });

  std::string effects;
  for (const auto& e : result.effects_run) effects += (effects.empty() ? "" : ", ") + e;
  spdlog::info("rendered {} ({} C x U x V x H x W) in {:.3f} s on {} threads; effects: {}",
               spec.name.empty() ? "scene" : spec.name, result.light_field.shape_string(), seconds,
               torch::get_num_threads(), effects.empty() ? "none" : effects);
  const auto& d = result.disparity;
  spdlog::info("disparity {:.3f} .. {:.3f} px per view; written to {}", d.min().item<double>(),
               d.max().item<double>(), args.out);
}

}  // namespace

void add_render_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "render", "Render a procedural scene into a light field folder with its true disparity map");
  auto args = std::make_shared<RenderArgs>();
  cmd->add_option("--scene", args->scene, "scene spec (JSON); see docs/scenes.md");
  cmd->add_option("--random", args->random_seed, "render the random training scene of this seed")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--random-options", args->random_options,
                  "RandomSceneOptions as JSON (with --random)");
  cmd->add_option("--size", args->size, "HxW of a random scene (default 256x256)");
  cmd->add_option("--views", args->views, "RxC angular grid of a random scene (default 5x5)");
  cmd->add_option("--disparity-range", args->disparity_range,
                  "MIN:MAX disparity of a random scene in px per view (default -3:3)");
  cmd->add_flag("--grey", args->grey, "render one luma channel");
  cmd->add_option("--out", args->out,
                  "output folder: lf_R_C.png, disparity.pfm, previews, scene.json")
      ->required();
  cmd->add_flag("--force", args->force, "replace an existing --out folder");
  cmd->add_option("--bits", args->bits, "bits per PNG sample, 8 or 16")
      ->check(CLI::IsMember({8, 16}));
  cmd->add_option("--epi-row", args->epi_row,
                  "spatial row of the EPI in preview.png (default: the centre row)")
      ->check(CLI::NonNegativeNumber);
  cmd->callback([args] { run_render(*args); });
}

}  // namespace lfnet::app

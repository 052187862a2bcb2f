#include "lfnet/pipeline/render.h"

#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <filesystem>

#include "lfnet/core/colour_map.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/sequence.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/scene/scene.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// Disparity maps in viridis: far (small) is dark blue, near (large) is yellow.
torch::Tensor colour_map(const torch::Tensor& disparity) {
  const float lo = disparity.min().item<float>();
  const float hi = disparity.max().item<float>();
  return viridis(hi > lo ? (disparity - lo) / (hi - lo) : torch::full_like(disparity, 0.5f));
}

}  // namespace

torch::Tensor render_preview(const LightField& lf, const torch::Tensor& disparity,
                             int64_t epi_row) {
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

namespace {
// render --lf: a real light field moved synthetically.
RenderSummary synthetic_sequence_to_folder(const RenderRequest& args) {
  LFNET_CHECK_AS(ConfigError, args.random_seed < 0 && args.scene.empty(),
                 "give one of --lf DIR, --scene SCENE.json and --random SEED");
  LFNET_CHECK_AS(ConfigError, args.frames >= 2 && args.frames <= kMaxFrames,
                 "--lf makes a sequence: --frames must lie in [2, ", kMaxFrames, "], got ",
                 args.frames);
  OutputFolderPolicy policy;
  policy.force = args.force;
  policy.inputs = {args.lf};
  check_output_folder(args.out, policy);
  const auto start = std::chrono::steady_clock::now();
  LightField lf = read_oriented(args.lf, "", "--lf");
  if (args.grey) lf = lf.grey();
  const auto seq =
      synthetic_motion(lf, args.frames, {args.shift.first, args.shift.second, args.walk});
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const nlohmann::json record = {
      {"frames", args.frames},
      {"source", fs::absolute(args.lf).string()},
      {"synthetic_motion",
       {{"shift", {args.shift.first, args.shift.second}},
        {"walk", args.walk},
        {"note",
         "a still light field moved synthetically: whole-image shifts (px per "
         "sub-frame) and a sideways walk of the view window (views per sub-frame)"}}}};
  write_folder(args.out, policy, [&](const std::string& dir) {
    for (int64_t t = 0; t < args.frames; ++t) {
      const auto frame_dir = sequence_frame_dir(dir, t);
      io::write_light_field(seq.frame(t), frame_dir, {"png", args.bits});
      io::write_previews(seq.frame(t), frame_dir);
    }
    write_json_file((fs::path(dir) / "sequence.json").string(), record);
  });
  RenderSummary summary;
  summary.name = fs::path(args.lf).filename().string() + " (synthetic motion)";
  summary.frames = args.frames;
  summary.shape = seq.shape_string();
  summary.effects = {"synthetic motion"};
  summary.seconds = seconds;
  summary.threads = torch::get_num_threads();
  return summary;
}
}  // namespace

RenderSummary render_to_folder(const RenderRequest& args) {
  if (!args.lf.empty()) return synthetic_sequence_to_folder(args);
  LFNET_CHECK_AS(ConfigError, args.shift.first == 0 && args.shift.second == 0 && args.walk == 0,
                 "--shift and --walk move a real light field: they apply to --lf only");
  const bool random = args.random_seed >= 0;
  if (random == !args.scene.empty()) {
    throw ConfigError("give exactly one of --scene SCENE.json, --random SEED and --lf DIR");
  }
  if (!random &&
      (!args.random_options.empty() || args.size || args.views || args.disparity_range)) {
    throw ConfigError(
        "--random-options, --size, --views and --disparity-range apply to --random only");
  }
  if (args.frames < 1 || args.frames > kMaxFrames) {
    throw ConfigError("--frames must lie in [1, " + std::to_string(kMaxFrames) + "], got " +
                      std::to_string(args.frames));
  }
  scene::SceneSpec spec;
  scene::RandomSceneOptions options;
  if (random) {
    bool motion_set = false;
    if (!args.random_options.empty()) {
      const auto doc = read_json_argument(args.random_options, "--random-options");
      JsonReader reader(doc, json_argument_source(args.random_options, "--random-options") + ":$");
      options = scene::RandomSceneOptions::from_json(reader);
      for (const char* key : {"max_speed", "max_disparity_speed", "max_rotation"}) {
        motion_set = motion_set || doc.contains(key);
      }
    }
    if (args.frames > 1 && !motion_set) options.max_speed = kRandomVideoSpeed;
    if (args.size) std::tie(options.height, options.width) = *args.size;
    if (args.views) std::tie(options.rows, options.cols) = *args.views;
    if (args.disparity_range) {
      std::tie(options.min_disparity, options.max_disparity) = *args.disparity_range;
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
  policy.inputs = {args.scene, is_inline_json(args.random_options) ? "" : args.random_options};
  check_output_folder(args.out, policy);

  const scene::RenderOptions render_options = scene_render_options(random ? "" : args.scene);
  const auto start = std::chrono::steady_clock::now();
  // One frame is a still render; several are a sequence (a still scene filmed, without motion).
  scene::SequenceResult result;
  if (args.frames == 1) {
    scene::RenderResult still = scene::render_scene(spec, render_options);
    result.light_fields = LightFieldSequence(still.light_field.data().unsqueeze(0));
    result.disparity = still.disparity.unsqueeze(0);
    result.effects_run = still.effects_run;
  } else {
    try {
      result = scene::render_sequence(spec, args.frames, render_options);
    } catch (const ConfigError& e) {
      throw ConfigError((random ? "random scene " + std::to_string(args.random_seed) : args.scene) +
                        ": " + e.what());
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  nlohmann::json record = spec.to_json();
  record["rendered"] = {
      {"effects_run", result.effects_run},
      {"seconds", seconds},
      {"threads", torch::get_num_threads()},
      {"source", random ? "random " + std::to_string(args.random_seed) : args.scene}};
  if (args.frames > 1) record["rendered"]["frames"] = args.frames;
  if (random) record["rendered"]["random_options"] = options.to_json();
  write_folder(args.out, policy, [&](const std::string& dir) {
    for (int64_t t = 0; t < args.frames; ++t) {
      const std::string frame_dir = args.frames == 1 ? dir : sequence_frame_dir(dir, t);
      if (args.frames > 1) fs::create_directories(frame_dir);
      const LightField lf = result.light_fields.frame(t);
      const torch::Tensor disparity = result.disparity[t];
      io::write_light_field(lf, frame_dir, {"png", args.bits});
      io::write_pfm((fs::path(frame_dir) / "disparity.pfm").string(), disparity);
      io::write_previews(lf, frame_dir);
      io::write_image((fs::path(frame_dir) / "preview.png").string(),
                      render_preview(lf, disparity, args.epi_row), 8);
    }
    write_json_file((fs::path(dir) / "scene.json").string(), record);
  });

  RenderSummary summary;
  summary.name = spec.name.empty() ? "scene" : spec.name;
  summary.frames = args.frames;
  summary.shape = args.frames == 1 ? result.light_fields.frame(0).shape_string()
                                   : result.light_fields.shape_string();
  summary.effects = result.effects_run;
  summary.seconds = seconds;
  summary.threads = torch::get_num_threads();
  summary.min_disparity = result.disparity.min().item<double>();
  summary.max_disparity = result.disparity.max().item<double>();
  return summary;
}

}  // namespace lfnet::pipeline

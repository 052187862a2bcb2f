#include "lfnet/pipeline/sources.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <mutex>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/core/file_backed.h"
#include "lfnet/core/parallax.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/sequence.h"
#include "lfnet/core/text.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

void LightFieldSources::read(JsonReader& r) {
  read_fields(r, *this);
  r.finish();
  // The scene options are checked now, not when the first scene is drawn.
  JsonReader scene_reader(random_options, r.path_of("random_options"));
  (void)scene::RandomSceneOptions::from_json(scene_reader);
  AngularOrientation::parse(orient, r.path_of("orient"));
  if (!layout.empty()) io::parse_layout(layout, r.path_of("layout"));
}

nlohmann::json LightFieldSources::to_json() const { return fields_to_json(*this); }

namespace {
// Warns once per folder when its horizontal and vertical parallax disagree in sign.
void check_folder_parallax(const std::string& dir, const LightFieldViews& lf,
                           const std::string& what) {
  const auto check = check_parallax(lf);
  if (check.verdict == ParallaxVerdict::kDisagree) {
    static std::mutex mutex;
    static std::set<std::string> warned;
    std::lock_guard<std::mutex> lock(mutex);
    if (warned.insert(fs::absolute(dir).lexically_normal().string()).second) {
      spdlog::warn(
          "{}: {}; if its views are named from the bottom row, load it with {} flip-u "
          "(docs/conventions.md)",
          dir, check.summary(), what);
    }
  }
}

// The angular window of `rows` x `cols` views a source keeps: its `views` option, else the
// central one (every view with `whole`, for a data set that draws its own windows).
std::pair<AngularRange, AngularRange> view_window(const LightFieldViews& lf,
                                                  const std::string& views, int64_t rows,
                                                  int64_t cols, const std::string& name,
                                                  bool whole) {
  if (views.empty()) {
    LFNET_CHECK_AS(ConfigError, lf.rows() >= rows && lf.cols() >= cols, name, " has ", lf.rows(),
                   "x", lf.cols(), " views, fewer than the ", rows, "x", cols, " the Phi codes");
    if (whole) return {{0, lf.rows()}, {0, lf.cols()}};
    const int64_t u0 = central_start(lf.rows(), rows), v0 = central_start(lf.cols(), cols);
    return {{u0, u0 + rows}, {v0, v0 + cols}};
  }
  auto [ru, rv] = parse_views(views);
  lf.window(ru, rv);  // that it fits the grid, before its size
  LFNET_CHECK_AS(ConfigError, ru.size() == rows && rv.size() == cols, "views ", views, " select ",
                 ru.size(), "x", rv.size(), " views but the Phi codes ", rows, "x", cols);
  return {ru, rv};
}

LightField select_views(const LightField& lf, const std::string& views, int64_t rows, int64_t cols,
                        const std::string& name, bool colour, bool whole = false) {
  const auto [ru, rv] = view_window(lf, views, rows, cols, name, whole);
  const auto out = lf.window(ru, rv);
  return colour ? out : out.grey();
}
// A sequence folder of `folder_frames` frames (0: a still one, filmed still) as the stacked
// light field of `frames` frames that a time-coded Phi of rows x cols (rows = frames U) codes,
// each frame windowed.
LightField read_sequence_source(const std::string& dir, int64_t folder_frames,
                                const LightFieldSources& sources, int64_t rows, int64_t cols,
                                int64_t frames, bool colour) {
  LFNET_CHECK_AS(ConfigError, frames > 1, dir, " is a sequence of ", folder_frames,
                 " frames: code it with a time-coded Phi of as many sub-frames (NAME:N@",
                 folder_frames, ", docs/video.md)");
  LFNET_CHECK_AS(ConfigError, folder_frames == 0 || folder_frames == frames, dir,
                 " is a sequence of ", folder_frames, " frames, but the Phi codes ", frames,
                 " sub-frames");
  std::vector<LightField> out;
  for (int64_t t = 0; t < frames; ++t) {
    if (folder_frames == 0 && t > 0) {  // a still light field: the same in every sub-frame
      out.push_back(out.front());
      continue;
    }
    const auto frame = folder_frames == 0 ? dir : sequence_frame_dir(dir, t);
    const auto lf = read_oriented(frame, sources.orient, "orient", sources.layout);
    out.push_back(select_views(lf, sources.views, rows / frames, cols, frame, colour));
  }
  if (folder_frames == 0) {
    spdlog::info(
        "{} is a still light field: coded as a scene that does not move over the {} "
        "sub-frames",
        dir, frames);
  }
  return LightFieldSequence(out).stacked();
}
}  // namespace

LightField read_oriented(const std::string& dir, const std::string& orient, const std::string& what,
                         const std::string& layout) {
  const auto orientation = AngularOrientation::parse(orient, what);
  LightField lf = reorient(io::read_light_field(dir, 0, layout), orientation);
  check_folder_parallax(dir, lf, what);
  return lf;
}

torch::Tensor read_flat_field(const std::string& path, const optics::Phi& phi,
                              const std::optional<optics::ColourFilterArray>& cfa,
                              const std::string& option) {
  torch::Tensor white;  // (N, H, W)
  if (fs::is_directory(path)) {
    io::Acquisition acq;
    try {
      acq = io::read_acquisition(path);
    } catch (const IoError& e) {
      throw IoError(option + ": " + e.what());
    }
    LFNET_CHECK_AS(ConfigError, acq.sensor.defined() && acq.sensor.size(0) == 1, option, " ", path,
                   ": a white frame is a grey sensor image (an acquisition in sensor mode)");
    // The white frame of this camera, behind this colour filter array (or none), or nothing.
    const auto white_phi = optics::make_phi(
        optics::PhiSpec::from_json(acq.meta.at("phi"), path + "/sensor.json:$.phi"));
    LFNET_CHECK_AS(ConfigError, white_phi->spec() == phi.spec(), option, " ", path,
                   " is a white frame of the camera ", white_phi->spec().label(),
                   white_phi->spec().label() == phi.spec().label() ? " with other parameters" : "",
                   "; the sensor image's camera is ", phi.spec().label());
    const bool white_cfa = acq.meta.contains("cfa");
    LFNET_CHECK_AS(ConfigError, white_cfa == cfa.has_value(), option, " ", path,
                   white_cfa ? " was taken behind a colour filter array; the sensor image is grey"
                             : " is grey; the sensor image is behind a colour filter array");
    LFNET_CHECK_AS(ConfigError, !white_cfa || acq.meta["cfa"] == cfa->to_json(), option, " ", path,
                   " was taken behind another colour filter array than the sensor image");
    white = acq.sensor[0];
  } else {
    LFNET_CHECK_AS(IoError, fs::exists(path), option, " ", path, ": no such file or folder");
    white = io::read_image_channels(path);
  }
  LFNET_CHECK_AS(ConfigError, white.size(0) == phi.measurements(), option, " ", path, " has ",
                 white.size(0), " measurement channel(s); the camera '", phi.spec().label(),
                 "' takes ", phi.measurements());
  try {
    auto nominal = optics::nominal_white(phi, white.size(1), white.size(2));
    // Behind a colour filter array: the code on each colour, then each pixel's own colours.
    if (cfa) nominal = optics::mosaic(nominal.unsqueeze(0).expand({3, -1, -1, -1}), *cfa)[0];
    return optics::flat_field_gain(white, nominal);
  } catch (const ConfigError& e) {
    throw ConfigError(option + " " + path + ": " + e.what());
  }
}

std::vector<NamedLightField> load_sources(const LightFieldSources& sources, int64_t rows,
                                          int64_t cols, bool whole_grids, bool colour, bool coded,
                                          int64_t frames) {
  std::vector<NamedLightField> out;
  const int64_t total = static_cast<int64_t>(sources.light_fields.size() + sources.scenes.size()) +
                        sources.random_scenes;
  ProgressBar bar("loading light fields", total);
  const bool whole = whole_grids && sources.views.empty();
  for (const auto& dir : sources.light_fields) {
    const std::string name = fs::path(dir).filename().string();
    const int64_t folder_frames = io::sequence_frames(dir);
    if (frames > 1 || folder_frames > 0) {
      out.push_back({name,
                     read_sequence_source(dir, folder_frames, sources, rows, cols, frames, colour),
                     {}});
      bar.advance();
      continue;
    }
    LightField lf;
    if (coded && !colour) {
      const auto orientation = AngularOrientation::parse(sources.orient, "orient");
      const auto views = reorient(io::read_light_field_views(dir, 0, sources.layout), orientation);
      check_folder_parallax(dir, views, "orient");
      if (views.coded()) {  // grey 16-bit views, held in 16-bit codes
        const auto [ru, rv] = view_window(views, sources.views, rows, cols, dir, whole);
        // A large one in a temporary file, so that phases that do not read it can give its
        // memory back (core/file_backed.h).
        out.push_back({name, LightField(), file_backed_copy(views.window(ru, rv).raw())});
        bar.advance();
        continue;
      }
      lf = LightField(views.raw());
    } else {
      lf = read_oriented(dir, sources.orient, "orient", sources.layout);
    }
    out.push_back({name, select_views(lf, sources.views, rows, cols, dir, colour, whole), {}});
    bar.advance();
  }
  release_free_memory();  // the decoding's buffers, before the light fields are used
  for (const auto& path : sources.scenes) {
    scene::SceneSpec spec;
    try {
      spec = scene::load_scene(path);
    } catch (const ConfigError& e) {
      throw ConfigError(path + ": " + e.what());
    }
    spec.color = colour;
    const auto name = fs::path(path).stem().string();
    if (frames > 1) {
      const auto seq = scene::render_sequence(spec, frames, scene_render_options(path));
      std::vector<LightField> views;
      for (int64_t t = 0; t < frames; ++t) {
        views.push_back(
            select_views(seq.light_fields.frame(t), "", rows / frames, cols, path, colour));
      }
      out.push_back({name, LightFieldSequence(views).stacked(), {}});
      bar.advance();
      continue;
    }
    auto lf = scene::render_scene(spec, scene_render_options(path)).light_field;
    out.push_back({name, select_views(lf, "", rows, cols, path, colour), {}});
    bar.advance();
  }
  if (sources.random_scenes > 0) {
    JsonReader reader(sources.random_options, "$.random_options");
    auto options = scene::RandomSceneOptions::from_json(reader);
    options.rows = rows / frames;
    options.cols = cols;
    options.color = colour;
    for (int64_t i = 0; i < sources.random_scenes; ++i) {
      const uint64_t seed = sources.random_seed + static_cast<uint64_t>(i);
      const auto spec = scene::random_scene(seed, options);
      auto lf = frames > 1 ? scene::render_sequence(spec, frames, scene_render_options(""))
                                 .light_fields.stacked()
                           : scene::render_scene(spec, scene_render_options("")).light_field;
      out.push_back({"random-" + std::to_string(seed), colour ? lf : lf.grey(), {}});
      bar.advance();
    }
  }
  return out;
}

scene::RenderOptions scene_render_options(const std::string& scene_file) {
  scene::RenderOptions options;
  options.image_loader = [](const std::string& path) { return io::read_image(path); };
  if (!scene_file.empty()) options.base_dir = fs::path(scene_file).parent_path().string();
  return options;
}

void check_sources(const LightFieldSources& sources, const std::string& where) {
  for (size_t i = 0; i < sources.light_fields.size(); ++i) {
    const std::string path = where + ".light_fields[" + std::to_string(i) + "]";
    try {
      const auto& dir = sources.light_fields[i];
      const int64_t frames = io::sequence_frames(dir);
      for (int64_t t = 0; t < std::max<int64_t>(frames, 1); ++t) {
        io::scan_folder(frames == 0 ? dir : sequence_frame_dir(dir, t), sources.layout);
      }
    } catch (const Error& e) {
      throw ConfigError(path + ": " + e.what());
    }
  }
  for (size_t i = 0; i < sources.scenes.size(); ++i) {
    std::error_code ec;
    LFNET_CHECK_AS(ConfigError, fs::is_regular_file(sources.scenes[i], ec), where, ".scenes[", i,
                   "]: ", sources.scenes[i], " is not a file");
  }
}

LightFieldFolderInfo describe_light_field_folder(const std::string& dir, const std::string& orient,
                                                 const std::string& layout_text) {
  const auto orientation = AngularOrientation::parse(orient, "--orient");
  const auto layout = io::scan_folder(dir, layout_text);
  Stopwatch clock;
  const LightField lf = reorient(io::read_light_field(dir, 0, layout_text), orientation);
  const double seconds = clock.seconds();
  const auto& d = lf.data();
  const auto count = [](int64_t v) { return static_cast<long long>(v); };
  std::string text =
      format_text("folder:    %s\n", dir.c_str()) +
      format_text("scheme:    %s\n", io::to_string(layout.scheme).c_str()) +
      format_text("grid:      %lld x %lld views (U x V)\n", count(lf.rows()), count(lf.cols())) +
      format_text("view size: %lld x %lld (W x H), %lld channel(s)\n", count(lf.width()),
                  count(lf.height()), count(lf.channels())) +
      format_text("shape:     %s (C x U x V x H x W)\n", lf.shape_string().c_str()) +
      format_text("values:    min %.4f, max %.4f, mean %.4f\n", d.min().item<double>(),
                  d.max().item<double>(), d.mean().item<double>()) +
      format_text("loaded in: %.3f s\n", seconds);
  if (!orientation.identity()) {
    text += format_text("oriented:  %s\n", orientation.to_string().c_str());
  }
  const auto parallax = check_parallax(lf);
  text += format_text("parallax:  %s\n", parallax.summary().c_str());
  return {text, parallax.verdict == ParallaxVerdict::kDisagree};
}

}  // namespace lfnet::pipeline

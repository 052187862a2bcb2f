#include "lfnet/scene/random_scene.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "json_read.h"
#include "lfnet/core/constants.h"
#include "rng.h"

namespace lfnet::scene {
namespace {

using detail::Rng;
Rgb hsv_to_rgb(double h, double s, double v) {
  h = std::fmod(h, 1.0) * 6.0;
  const double c = v * s;
  const double x = c * (1.0 - std::abs(std::fmod(h, 2.0) - 1.0));
  const double m = v - c;
  Rgb rgb{};
  switch (static_cast<int>(h)) {
    case 0:
      rgb = {c, x, 0};
      break;
    case 1:
      rgb = {x, c, 0};
      break;
    case 2:
      rgb = {0, c, x};
      break;
    case 3:
      rgb = {0, x, c};
      break;
    case 4:
      rgb = {x, 0, c};
      break;
    default:
      rgb = {c, 0, x};
      break;
  }
  for (auto& ch : rgb) ch = std::clamp(ch + m, 0.0, 1.0);
  return rgb;
}

// A natural-looking colour ramp: mostly muted hues, 2 or 3 colours whose brightness differs by
// a contrast drawn log-uniformly from very low to high.
std::vector<Rgb> random_palette(Rng& rng) {
  const double hue = rng.uniform();
  const double sat = std::pow(rng.uniform(), 2.0) * 0.75;
  const double contrast = rng.log_uniform(0.04, 0.85);
  const double mid = rng.uniform(0.15 + contrast / 2.0 * 0.8, 0.85 - contrast / 2.0 * 0.8);
  const int64_t n = rng.bernoulli(0.35) ? 3 : 2;
  std::vector<Rgb> colors;
  for (int64_t i = 0; i < n; ++i) {
    const double f = static_cast<double>(i) / static_cast<double>(n - 1) - 0.5;  // -0.5 .. 0.5
    const double v = std::clamp(mid + f * contrast, 0.02, 0.98);
    const double h = hue + rng.uniform(-0.06, 0.06);
    const double s = std::clamp(sat + rng.uniform(-0.15, 0.15), 0.0, 1.0);
    colors.push_back(hsv_to_rgb(h + 1.0, s, v));
  }
  if (rng.bernoulli(0.5)) std::reverse(colors.begin(), colors.end());
  return colors;
}

// A vivid palette: 2 or 3 saturated colours of distinct hues whose brightness differs little, so
// that much of the texture's contrast is in chroma alone (dyed fabric, flowers, painted signs):
// what a colour filter array aliases most.
std::vector<Rgb> vivid_palette(Rng& rng) {
  const double hue = rng.uniform();
  const double contrast = rng.log_uniform(0.02, 0.5);
  const double mid = rng.uniform(0.3 + contrast / 2.0 * 0.8, 0.9 - contrast / 2.0 * 0.8);
  const int64_t n = rng.bernoulli(0.35) ? 3 : 2;
  std::vector<Rgb> colors;
  double h = hue;
  for (int64_t i = 0; i < n; ++i) {
    const double f = static_cast<double>(i) / static_cast<double>(n - 1) - 0.5;  // -0.5 .. 0.5
    const double v = std::clamp(mid + f * contrast, 0.02, 0.98);
    colors.push_back(hsv_to_rgb(h + 1.0, rng.uniform(0.5, 1.0), v));
    h += rng.uniform(0.2, 0.8);  // the next colour's hue is at least 72 degrees away
  }
  return colors;
}

TextureSpec random_texture(Rng& rng, const RandomSceneOptions& o, bool background,
                           const std::vector<std::string>& images) {
  const double extent = static_cast<double>(std::max(o.height, o.width));
  // Drawn only when images are in play, so that scenes without them stay as they were.
  if (!images.empty() && rng.bernoulli(o.image_probability)) {
    TextureSpec t = TextureSpec::defaults(TextureKind::kImage);
    t.path = images[static_cast<size_t>(rng.next() % images.size())];
    t.zoom = rng.log_uniform(1.0, 4.0);
    t.offset = Point{rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)};
    return t;
  }
  // Probabilities of fractal, noise, stripes, checker, gradient and constant textures.
  const std::array<double, 6> weights =
      background ? std::array<double, 6>{0.5, 0.12, 0.07, 0.05, 0.2, 0.06}
                 : std::array<double, 6>{0.48, 0.16, 0.12, 0.08, 0.1, 0.06};
  double pick = rng.uniform();
  size_t which = 0;
  while (which + 1 < weights.size() && pick >= weights[which]) pick -= weights[which++];
  TextureSpec t;
  switch (which) {
    case 0:
      t = TextureSpec::defaults(TextureKind::kFractal);
      t.scale = rng.log_uniform(8.0, std::max(16.0, extent));
      t.beta = rng.uniform(1.6, 3.0);
      t.contrast = rng.log_uniform(0.4, 2.5);
      break;
    case 1:
      t = TextureSpec::defaults(TextureKind::kNoise);
      t.scale = rng.log_uniform(1.0, 12.0);
      t.contrast = rng.log_uniform(0.4, 2.5);
      break;
    case 2:
      t = TextureSpec::defaults(TextureKind::kStripes);
      t.period = rng.log_uniform(3.0, 40.0);
      t.profile = rng.bernoulli(0.7) ? "square" : "sine";
      t.duty = rng.uniform(0.2, 0.8);
      t.phase = rng.uniform();
      t.angle = rng.uniform(0.0, 180.0);
      break;
    case 3:
      t = TextureSpec::defaults(TextureKind::kChecker);
      t.size = rng.log_uniform(2.0, 24.0);
      t.angle = rng.bernoulli(0.5) ? 0.0 : rng.uniform(0.0, 90.0);
      break;
    case 4:
      t = TextureSpec::defaults(TextureKind::kGradient);
      t.profile = rng.bernoulli(0.7) ? "linear" : "radial";
      t.angle = rng.uniform(0.0, 360.0);
      if (t.profile == "radial") {
        t.center = Point{rng.uniform(0.0, o.width - 1.0), rng.uniform(0.0, o.height - 1.0)};
        t.length = rng.log_uniform(0.2, 1.5) * extent;
      }
      break;
    default:
      t = TextureSpec::defaults(TextureKind::kConstant);
      break;
  }
  // Drawn only when vivid palettes are in play, so that scenes without them stay as they were.
  const bool vivid = o.vivid_probability > 0.0 && rng.bernoulli(o.vivid_probability);
  t.colors = vivid ? vivid_palette(rng) : random_palette(rng);
  if (t.kind == TextureKind::kConstant) t.colors.resize(1);
  if (t.kind == TextureKind::kFractal || t.kind == TextureKind::kNoise) t.seed = rng.next() >> 11;
  return t;
}

// A star-shaped blob with a fractal outline: r(theta) = R exp(sum_k a_k cos(k theta + phi_k)).
ShapeSpec random_blob(Rng& rng, Point center, double radius) {
  ShapeSpec s = ShapeSpec::defaults(ShapeKind::kPolygon);
  std::array<double, 8> amp{};
  std::array<double, 8> phase{};
  const double roughness = rng.uniform(0.1, 0.45);
  for (size_t k = 0; k < amp.size(); ++k) {
    amp[k] = roughness * rng.normal() / std::pow(static_cast<double>(k + 1), 1.3);
    phase[k] = rng.uniform(0.0, 2.0 * kPi);
  }
  const double aspect = rng.log_uniform(0.5, 2.0);
  const double rot = rng.uniform(0.0, kPi);
  const int64_t n = std::clamp<int64_t>(static_cast<int64_t>(radius), 24, 96);
  for (int64_t i = 0; i < n; ++i) {
    const double th = 2.0 * kPi * static_cast<double>(i) / static_cast<double>(n);
    double lr = 0.0;
    for (size_t k = 0; k < amp.size(); ++k) lr += amp[k] * std::cos((k + 1) * th + phase[k]);
    const double r = radius * std::exp(std::clamp(lr, -1.2, 1.2));
    const double x = r * std::cos(th) * std::sqrt(aspect);
    const double y = r * std::sin(th) / std::sqrt(aspect);
    s.points.push_back(Point{center.x + x * std::cos(rot) - y * std::sin(rot),
                             center.y + x * std::sin(rot) + y * std::cos(rot)});
  }
  return s;
}

// A thin branch: a wandering polyline thickened into a polygon.
ShapeSpec random_branch(Rng& rng, const RandomSceneOptions& o) {
  ShapeSpec s = ShapeSpec::defaults(ShapeKind::kPolygon);
  const double w = static_cast<double>(o.width);
  const double h = static_cast<double>(o.height);
  const double thickness = rng.log_uniform(1.2, 6.0);
  // Start outside one border and wander across the image.
  double heading = rng.uniform(0.0, 2.0 * kPi);
  Point p{w / 2.0 - std::cos(heading) * 0.75 * (w + h) / 2.0,
          h / 2.0 - std::sin(heading) * 0.75 * (w + h) / 2.0};
  p.x += rng.uniform(-0.3, 0.3) * w;
  p.y += rng.uniform(-0.3, 0.3) * h;
  const int64_t steps = rng.integer(5, 10);
  const double step = 1.6 * (w + h) / 2.0 / static_cast<double>(steps);
  std::vector<Point> line{p};
  for (int64_t i = 0; i < steps; ++i) {
    heading += rng.uniform(-0.35, 0.35);
    p = Point{p.x + step * std::cos(heading), p.y + step * std::sin(heading)};
    line.push_back(p);
  }
  std::vector<Point> left;
  std::vector<Point> right;
  for (size_t i = 0; i < line.size(); ++i) {
    const Point& a = line[i == 0 ? 0 : i - 1];
    const Point& b = line[i + 1 < line.size() ? i + 1 : i];
    const double dx = b.x - a.x;
    const double dy = b.y - a.y;
    const double len = std::max(1e-9, std::hypot(dx, dy));
    // Taper towards the far end, like a twig.
    const double half = 0.5 * thickness * (1.0 - 0.5 * static_cast<double>(i) / line.size());
    left.push_back(Point{line[i].x - dy / len * half, line[i].y + dx / len * half});
    right.push_back(Point{line[i].x + dy / len * half, line[i].y - dx / len * half});
  }
  s.points = left;
  s.points.insert(s.points.end(), right.rbegin(), right.rend());
  s.softness = rng.uniform(0.6, 1.2);
  return s;
}

ShapeSpec random_bars(Rng& rng) {
  ShapeSpec s = ShapeSpec::defaults(ShapeKind::kBars);
  s.width = rng.log_uniform(1.0, 7.0);
  s.period = s.width + rng.log_uniform(8.0, 80.0);
  s.count = rng.bernoulli(0.4) ? 0 : rng.integer(1, 6);
  s.angle = rng.bernoulli(0.6) ? rng.uniform(-10.0, 10.0) : rng.uniform(0.0, 180.0);
  s.softness = rng.uniform(0.6, 1.2);
  return s;
}

ShapeSpec random_object(Rng& rng, const RandomSceneOptions& o) {
  const double w = static_cast<double>(o.width);
  const double h = static_cast<double>(o.height);
  const Point center{rng.uniform(-0.1, 1.1) * w, rng.uniform(-0.1, 1.1) * h};
  const double area = rng.log_uniform(0.01, 0.25) * w * h;
  const double pick = rng.uniform();
  ShapeSpec s;
  if (pick < 0.55) {
    s = random_blob(rng, center, std::sqrt(area / kPi));
  } else if (pick < 0.85) {
    s = ShapeSpec::defaults(ShapeKind::kRectangle);
    const double aspect = rng.log_uniform(0.25, 4.0);
    s.center = center;
    s.width = std::sqrt(area * aspect);
    s.height = std::sqrt(area / aspect);
    s.angle = rng.bernoulli(0.6) ? rng.uniform(-4.0, 4.0) : rng.uniform(0.0, 180.0);
  } else {
    s = ShapeSpec::defaults(ShapeKind::kDisk);
    s.center = center;
    s.radius = std::sqrt(area / kPi);
  }
  s.softness = rng.bernoulli(0.85) ? rng.uniform(0.6, 1.4) : rng.uniform(1.5, 4.0);
  return s;
}

// A frame at a disparity in [front_from, hi]: two layers of bars at right angles sharing one
// texture (flat with probability 0.6) and one crossing point, and with probability 0.5 a wall
// just behind them with a rectangular opening around that point.
std::vector<LayerSpec> random_frame(Rng& rng, const RandomSceneOptions& o, double front_from,
                                    double hi, const std::vector<std::string>& images) {
  const double w = static_cast<double>(o.width);
  const double h = static_cast<double>(o.height);
  const double disparity = rng.uniform(front_from, hi);
  TextureSpec texture;
  if (rng.bernoulli(0.6)) {
    texture = TextureSpec::defaults(TextureKind::kConstant);
    texture.colors = random_palette(rng);
    texture.colors.resize(1);
  } else {
    texture = random_texture(rng, o, false, images);
  }
  const Point center{rng.uniform(0.2, 0.8) * w, rng.uniform(0.2, 0.8) * h};
  const double angle = rng.bernoulli(0.8) ? rng.uniform(-5.0, 5.0) : rng.uniform(0.0, 180.0);
  std::vector<LayerSpec> layers;
  if (rng.bernoulli(0.5)) {
    LayerSpec wall;
    wall.name = "wall";
    wall.texture = random_texture(rng, o, false, images);
    wall.shape = ShapeSpec::defaults(ShapeKind::kRectangle);
    wall.shape.center = center;
    wall.shape.width = rng.uniform(0.3, 0.9) * w;
    wall.shape.height = rng.uniform(0.3, 0.9) * h;
    wall.shape.angle = angle;
    wall.shape.invert = true;
    wall.shape.softness = rng.uniform(0.6, 1.2);
    wall.disparity = std::max(front_from, disparity - rng.uniform(0.0, 0.3));
    layers.push_back(wall);
  }
  for (int k = 0; k < 2; ++k) {
    LayerSpec bars;
    bars.name = k == 0 ? "frame-posts" : "frame-rails";
    bars.texture = texture;
    bars.shape = ShapeSpec::defaults(ShapeKind::kBars);
    bars.shape.center = center;
    bars.shape.width = rng.log_uniform(2.0, 14.0);
    bars.shape.period = bars.shape.width + rng.log_uniform(30.0, 200.0);
    bars.shape.count = rng.bernoulli(0.3) ? 0 : rng.integer(1, 4);
    bars.shape.angle = angle + 90.0 * k;
    bars.shape.softness = rng.uniform(0.6, 1.2);
    bars.disparity = disparity;
    layers.push_back(bars);
  }
  return layers;
}

// Rounds every number of a JSON document to 5 significant digits: readable specs.
nlohmann::json rounded(const nlohmann::json& j) {
  if (j.is_number_float()) {
    char text[32];
    std::snprintf(text, sizeof text, "%.5g", j.get<double>());
    return std::strtod(text, nullptr);
  }
  if (j.is_object()) {
    nlohmann::json out = nlohmann::json::object();
    for (auto it = j.begin(); it != j.end(); ++it) out[it.key()] = rounded(it.value());
    return out;
  }
  if (j.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& x : j) out.push_back(rounded(x));
    return out;
  }
  return j;
}

// The steepest gradient that keeps the slanted-plane warp well conditioned.
double max_gradient(const RandomSceneOptions& o) {
  const double smax = std::max(o.rows - 1, o.cols - 1) / 2.0;
  return smax > 0 ? 0.45 / smax : 1.0;
}

// Draws the layers' motion from a stream of its own. The layers of a frame (wall, posts, rails)
// move as one.
void add_motion(SceneSpec& s, uint64_t seed, const RandomSceneOptions& o) {
  Rng rng(detail::derive_seed(seed, 0x6d6f74696f6eULL));
  std::optional<MotionSpec> frame_motion;
  for (size_t i = 0; i < s.layers.size(); ++i) {
    LayerSpec& layer = s.layers[i];
    const bool moves = rng.bernoulli(o.motion_probability);
    const double heading = rng.uniform(0.0, 2.0 * kPi);
    MotionSpec m;
    const double speed = rng.uniform(0.0, o.max_speed);
    m.shift = Point{speed * std::cos(heading), speed * std::sin(heading)};
    m.disparity = rng.uniform(-o.max_disparity_speed, o.max_disparity_speed);
    m.rotation = i == 0 ? 0.0 : rng.uniform(-o.max_rotation, o.max_rotation);
    const bool in_frame = layer.name.rfind("frame-", 0) == 0 || layer.name.rfind("wall", 0) == 0;
    if (in_frame) {
      if (!frame_motion) frame_motion = moves ? m : MotionSpec{};
      m = *frame_motion;
    } else if (!moves) {
      continue;
    }
    if (m.moves()) layer.motion = m;
  }
}

}  // namespace

RandomSceneOptions RandomSceneOptions::from_json(JsonReader& r) {
  RandomSceneOptions o;
  read_fields(r, o);
  r.finish();
  o.validate(r.path());
  return o;
}

nlohmann::json RandomSceneOptions::to_json() const { return fields_to_json(*this); }

void RandomSceneOptions::validate(const std::string& p) const {
  using detail::fail;
  if (height < 8 || height > 16384) fail(p + ".height", "must lie in [8, 16384]");
  if (width < 8 || width > 16384) fail(p + ".width", "must lie in [8, 16384]");
  if (rows < 1 || rows > 64) fail(p + ".rows", "must lie in [1, 64]");
  if (cols < 1 || cols > 64) fail(p + ".cols", "must lie in [1, 64]");
  // Beyond +-64 px per view step every layer leaves the views of a 5 x 5 grid.
  if (!(std::abs(min_disparity) <= 64)) fail(p + ".min_disparity", "must lie in [-64, 64]");
  if (!(std::abs(max_disparity) <= 64)) fail(p + ".max_disparity", "must lie in [-64, 64]");
  if (!(min_disparity <= max_disparity)) {
    fail(p + ".max_disparity", "must be >= min_disparity");
  }
  if (min_layers < 1) fail(p + ".min_layers", "must be >= 1");
  if (max_layers < min_layers || max_layers > 64) {
    fail(p + ".max_layers", "must lie in [min_layers, 64]");
  }
  const std::pair<const char*, double> probabilities[] = {
      {"thin_occluder_probability", thin_occluder_probability},
      {"slanted_probability", slanted_probability},
      {"specular_probability", specular_probability},
      {"vignetting_probability", vignetting_probability},
      {"defocus_probability", defocus_probability},
      {"frame_probability", frame_probability},
      {"image_probability", image_probability},
      {"vivid_probability", vivid_probability},
      {"motion_probability", motion_probability}};
  for (const auto& [key, value] : probabilities) {
    if (!(value >= 0.0 && value <= 1.0)) fail(p + "." + key, "a probability must lie in [0, 1]");
  }
  if (!(max_speed >= 0.0 && max_speed <= 64.0)) fail(p + ".max_speed", "must lie in [0, 64]");
  if (!(max_disparity_speed >= 0.0 && max_disparity_speed <= 4.0)) {
    fail(p + ".max_disparity_speed", "must lie in [0, 4]");
  }
  if (!(max_rotation >= 0.0 && max_rotation <= 30.0)) {
    fail(p + ".max_rotation", "must lie in [0, 30]");
  }
  if (image_probability > 0.0 && texture_images.empty()) {
    fail(p + ".texture_images", "image_probability > 0 needs at least one image or folder");
  }
}

std::vector<std::string> texture_image_files(const std::vector<std::string>& paths) {
  namespace fs = std::filesystem;
  auto is_image = [](const fs::path& f) {
    std::string ext = f.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".tif" || ext == ".tiff";
  };
  std::vector<std::string> files;
  for (const auto& path : paths) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
      std::vector<std::string> found;
      for (const auto& e : fs::directory_iterator(path, ec)) {
        if (e.is_regular_file(ec) && is_image(e.path())) found.push_back(e.path().string());
      }
      LFNET_CHECK_AS(ConfigError, !found.empty(), "texture_images: ", path,
                     " holds no png, jpg or tif file");
      std::sort(found.begin(), found.end());
      files.insert(files.end(), found.begin(), found.end());
    } else {
      LFNET_CHECK_AS(ConfigError, fs::is_regular_file(path, ec) && is_image(path),
                     "texture_images: ", path, " is neither an image file nor a folder");
      files.push_back(path);
    }
  }
  return files;
}

SceneSpec random_scene(uint64_t seed, const RandomSceneOptions& o) {
  o.validate();
  const std::vector<std::string> images = o.image_probability > 0.0
                                              ? texture_image_files(o.texture_images)
                                              : std::vector<std::string>{};
  Rng rng(detail::derive_seed(seed, 0x72616e646f6dULL));
  SceneSpec s;
  s.name = "random-" + std::to_string(seed);
  s.height = o.height;
  s.width = o.width;
  s.rows = o.rows;
  s.cols = o.cols;
  s.color = o.color;
  s.seed = seed;
  const double lo = o.min_disparity;
  const double hi = o.max_disparity;

  // Background: uniform over the whole range, so that far and near scenes are equally likely;
  // everything in front lies between it and the near end. A slanted background spans part of
  // the range (a floor, a wall seen at an angle).
  LayerSpec back;
  back.name = "background";
  back.texture = random_texture(rng, o, true, images);
  double front_from = 0.0;
  if (rng.bernoulli(o.slanted_probability) && hi > lo && o.height > 1 && o.width > 1) {
    const double far = rng.uniform(lo, hi);
    const double near = far + rng.uniform(0.0, 0.7) * (hi - far);
    const bool vertical = rng.bernoulli(0.7);  // a floor: nearer towards the bottom
    const double extent = static_cast<double>(vertical ? o.height - 1 : o.width - 1);
    double g = std::min((near - far) / extent, max_gradient(o));
    if (!vertical && rng.bernoulli(0.5)) g = -g;
    back.disparity = far + 0.5 * std::abs(g) * extent;
    (vertical ? back.disparity_gradient.y : back.disparity_gradient.x) = g;
    front_from = back.disparity + 0.5 * std::abs(g) * extent;
  } else {
    back.disparity = rng.uniform(lo, hi);
    front_from = back.disparity;
  }
  s.layers.push_back(back);

  const int64_t n = rng.integer(o.min_layers, o.max_layers);
  std::vector<LayerSpec> front;
  const bool thin = rng.bernoulli(o.thin_occluder_probability);
  const int64_t thin_layers = thin ? rng.integer(1, 2) : 0;
  for (int64_t i = 1; i < n; ++i) {
    LayerSpec layer;
    layer.disparity = rng.uniform(front_from, hi);
    layer.texture = random_texture(rng, o, false, images);
    if (i > n - 1 - thin_layers) {
      layer.name = "occluder";
      layer.shape = rng.bernoulli(0.5) ? random_bars(rng) : random_branch(rng, o);
      // Thin occluders sit in front: a fence or branches close to the camera.
      layer.disparity = rng.uniform(front_from + 0.5 * (hi - front_from), hi);
    } else {
      layer.name = "object";
      layer.shape = random_object(rng, o);
    }
    front.push_back(layer);
  }
  // Drawn only when asked for, so that scenes without frames stay as they were.
  if (o.frame_probability > 0.0 && rng.bernoulli(o.frame_probability)) {
    for (auto& layer : random_frame(rng, o, front_from, hi, images)) front.push_back(layer);
  }
  // Back to front: nearer (larger disparity) layers are composited later and occlude.
  std::stable_sort(front.begin(), front.end(), [](const LayerSpec& a, const LayerSpec& b) {
    return a.disparity < b.disparity;
  });
  for (size_t i = 0; i < front.size(); ++i) {
    front[i].name += "-" + std::to_string(i + 1);
    s.layers.push_back(front[i]);
  }

  if (rng.bernoulli(o.specular_probability)) {
    SpecularSpec sp;
    sp.count = rng.integer(1, 4);
    sp.strength = rng.uniform(0.2, 0.8);
    sp.sigma = rng.log_uniform(1.5, 10.0);
    sp.lobe = rng.uniform(0.7, 2.5);
    sp.disparity_offset = rng.uniform(-1.5, 0.5);
    s.specular = sp;
    for (auto& layer : s.layers) layer.gloss = rng.uniform();
  }
  if (rng.bernoulli(o.vignetting_probability)) {
    VignettingSpec v;
    v.strength = rng.uniform(0.1, 0.5);
    v.angular = rng.uniform(0.0, 0.3);
    v.shift = rng.uniform(-0.2, 0.2);
    s.vignetting = v;
  }
  if (rng.bernoulli(o.defocus_probability)) {
    DefocusSpec d;
    d.focus_disparity = rng.uniform(lo, hi);
    d.blur = rng.uniform(0.1, 0.5);
    s.defocus = d;
  }
  if (o.moves()) add_motion(s, seed, o);
  // The spec is what gets saved beside the render; round it so that a file and the spec it came
  // from are the same scene.
  return SceneSpec::from_json(rounded(s.to_json()));
}

}  // namespace lfnet::scene

#include "lfnet/scene/scene_spec.h"

#include <algorithm>
#include <cmath>

#include "json_read.h"
#include "lfnet/core/error.h"
#include "lfnet/core/text.h"

namespace lfnet::scene {
namespace {

using detail::fail;
using nlohmann::json;

Point parse_point(const json& v, const std::string& path) {
  if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number()) {
    fail(path, "expected a point [x, y], got " + v.dump());
  }
  return Point{v[0].get<double>(), v[1].get<double>()};
}

bool read_point(JsonReader& r, const std::string& key, Point& out) {
  json v;
  if (!r.get(key, v)) return false;
  out = parse_point(v, r.path_of(key));
  return true;
}

Rgb parse_color(const json& v, const std::string& path) {
  Rgb c{};
  if (v.is_number()) {
    c.fill(v.get<double>());
  } else if (v.is_array() && v.size() == 3 && v[0].is_number() && v[1].is_number() &&
             v[2].is_number()) {
    for (int i = 0; i < 3; ++i) c[i] = v[i].get<double>();
  } else {
    fail(path, "expected a colour [r, g, b] or a grey number, got " + v.dump());
  }
  return c;
}

json color_json(const Rgb& c) {
  if (c[0] == c[1] && c[1] == c[2]) return c[0];
  return json::array({c[0], c[1], c[2]});
}

json point_json(const Point& p) { return json::array({p.x, p.y}); }

void check_color(const Rgb& c, const std::string& path) {
  for (double x : c) {
    if (!(x >= 0.0 && x <= 1.0)) fail(path, "colour components must lie in [0, 1]");
  }
}

std::string number(double value) { return format_text("%g", value); }

void check_positive(double value, const std::string& path) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    fail(path, "must be a positive number, got " + number(value));
  }
}

void check_range(double value, double lo, double hi, const std::string& path) {
  if (!(value >= lo && value <= hi)) {
    fail(path, "must lie in [" + number(lo) + ", " + number(hi) + "], got " + number(value));
  }
}

template <typename Kind, size_t N>
Kind kind_from_string(const std::string& name, const std::array<Kind, N>& kinds,
                      const std::string& what, const std::string& path) {
  std::string known;
  for (Kind k : kinds) {
    if (to_string(k) == name) return k;
    known += (known.empty() ? "" : ", ") + to_string(k);
  }
  fail(path, "unknown " + what + " kind '" + name + "' (known: " + known + ")");
}

constexpr std::array<TextureKind, 7> kTextureKinds = {
    TextureKind::kConstant, TextureKind::kNoise,    TextureKind::kFractal, TextureKind::kStripes,
    TextureKind::kChecker,  TextureKind::kGradient, TextureKind::kImage};
constexpr std::array<ShapeKind, 5> kShapeKinds = {ShapeKind::kFull, ShapeKind::kRectangle,
                                                  ShapeKind::kDisk, ShapeKind::kPolygon,
                                                  ShapeKind::kBars};

}  // namespace

std::string to_string(TextureKind kind) {
  switch (kind) {
    case TextureKind::kConstant:
      return "constant";
    case TextureKind::kNoise:
      return "noise";
    case TextureKind::kFractal:
      return "fractal";
    case TextureKind::kStripes:
      return "stripes";
    case TextureKind::kChecker:
      return "checker";
    case TextureKind::kGradient:
      return "gradient";
    case TextureKind::kImage:
      return "image";
  }
  return "?";
}

std::string to_string(ShapeKind kind) {
  switch (kind) {
    case ShapeKind::kFull:
      return "full";
    case ShapeKind::kRectangle:
      return "rectangle";
    case ShapeKind::kDisk:
      return "disk";
    case ShapeKind::kPolygon:
      return "polygon";
    case ShapeKind::kBars:
      return "bars";
  }
  return "?";
}

// ---- TextureSpec ----------------------------------------------------------------------------

TextureSpec TextureSpec::defaults(TextureKind kind) {
  TextureSpec t;
  t.kind = kind;
  if (kind == TextureKind::kFractal) t.scale = 128.0;
  if (kind == TextureKind::kGradient) t.profile = "linear";
  if (kind == TextureKind::kConstant) t.colors = {Rgb{0.5, 0.5, 0.5}};
  return t;
}

TextureSpec TextureSpec::from_json(JsonReader& r) {
  std::string kind_name;
  if (!r.get("kind", kind_name)) fail(r.path_of("kind"), "required key is missing");
  TextureSpec t =
      defaults(kind_from_string(kind_name, kTextureKinds, "texture", r.path_of("kind")));
  if (t.kind != TextureKind::kImage) {
    json colors;
    if (r.get("colors", colors)) {
      if (!colors.is_array() || colors.empty()) {
        fail(r.path_of("colors"), "expected a non-empty list of colours, got " + colors.dump());
      }
      t.colors.clear();
      for (size_t i = 0; i < colors.size(); ++i) {
        t.colors.push_back(
            parse_color(colors[i], r.path_of("colors") + "[" + std::to_string(i) + "]"));
      }
    }
  }
  uint64_t seed = 0;
  switch (t.kind) {
    case TextureKind::kConstant:
      break;
    case TextureKind::kNoise:
    case TextureKind::kFractal:
      r.get("scale", t.scale);
      r.get("contrast", t.contrast);
      if (t.kind == TextureKind::kFractal) r.get("beta", t.beta);
      if (r.get("seed", seed)) t.seed = seed;
      break;
    case TextureKind::kStripes:
      r.get("period", t.period);
      r.get("duty", t.duty);
      r.get("profile", t.profile);
      r.get("phase", t.phase);
      r.get("angle", t.angle);
      break;
    case TextureKind::kChecker:
      r.get("size", t.size);
      r.get("angle", t.angle);
      break;
    case TextureKind::kGradient: {
      r.get("profile", t.profile);
      r.get("angle", t.angle);
      Point c;
      if (read_point(r, "center", c)) t.center = c;
      double length = 0;
      if (r.get("length", length)) t.length = length;
      break;
    }
    case TextureKind::kImage:
      if (!r.get("path", t.path)) fail(r.path_of("path"), "required key is missing");
      r.get("fit", t.fit);
      r.get("zoom", t.zoom);
      read_point(r, "offset", t.offset);
      break;
  }
  r.finish();
  t.validate(r.path());
  return t;
}

json TextureSpec::to_json() const {
  json j;
  j["kind"] = to_string(kind);
  if (kind != TextureKind::kImage) {
    j["colors"] = json::array();
    for (const auto& c : colors) j["colors"].push_back(color_json(c));
  }
  switch (kind) {
    case TextureKind::kConstant:
      break;
    case TextureKind::kNoise:
    case TextureKind::kFractal:
      j["scale"] = scale;
      j["contrast"] = contrast;
      if (kind == TextureKind::kFractal) j["beta"] = beta;
      if (seed) j["seed"] = *seed;
      break;
    case TextureKind::kStripes:
      j["period"] = period;
      j["duty"] = duty;
      j["profile"] = profile;
      j["phase"] = phase;
      j["angle"] = angle;
      break;
    case TextureKind::kChecker:
      j["size"] = size;
      j["angle"] = angle;
      break;
    case TextureKind::kGradient:
      j["profile"] = profile;
      j["angle"] = angle;
      if (center) j["center"] = point_json(*center);
      if (length) j["length"] = *length;
      break;
    case TextureKind::kImage:
      j["path"] = path;
      j["fit"] = fit;
      if (zoom != 1.0) j["zoom"] = zoom;
      if (offset.x != 0.0 || offset.y != 0.0) j["offset"] = point_json(offset);
      break;
  }
  return j;
}

void TextureSpec::validate(const std::string& json_path) const {
  check_range(angle, -3600.0, 3600.0, json_path + ".angle");
  if (kind != TextureKind::kImage) {
    if (colors.empty()) fail(json_path + ".colors", "needs at least one colour");
    for (size_t i = 0; i < colors.size(); ++i) {
      check_color(colors[i], json_path + ".colors[" + std::to_string(i) + "]");
    }
  }
  switch (kind) {
    case TextureKind::kConstant:
      break;
    case TextureKind::kNoise:
    case TextureKind::kFractal:
      check_range(scale, 0.5, 1e5, json_path + ".scale");
      check_range(contrast, 0.0, 100.0, json_path + ".contrast");
      check_range(beta, 0.0, 6.0, json_path + ".beta");
      break;
    case TextureKind::kStripes:
      check_range(period, 1.0, 1e6, json_path + ".period");
      check_range(duty, 0.0, 1.0, json_path + ".duty");
      if (profile != "square" && profile != "sine") {
        fail(json_path + ".profile",
             "stripes profile must be 'square' or 'sine', got '" + profile + "'");
      }
      break;
    case TextureKind::kChecker:
      check_range(size, 0.5, 1e6, json_path + ".size");
      break;
    case TextureKind::kGradient:
      if (profile != "linear" && profile != "radial") {
        fail(json_path + ".profile",
             "gradient profile must be 'linear' or 'radial', got '" + profile + "'");
      }
      if (length) {
        check_positive(*length, json_path + ".length");
        check_range(*length, 0.0, 1e5, json_path + ".length");
      }
      if (center) {
        check_range(center->x, -1e5, 1e5, json_path + ".center");
        check_range(center->y, -1e5, 1e5, json_path + ".center");
      }
      break;
    case TextureKind::kImage:
      if (path.empty()) fail(json_path + ".path", "image texture needs a file path");
      if (fit != "cover" && fit != "stretch") {
        fail(json_path + ".fit", "image fit must be 'cover' or 'stretch', got '" + fit + "'");
      }
      if (!(std::isfinite(zoom) && zoom >= 1.0 && zoom <= 64.0)) {
        fail(json_path + ".zoom", "image zoom must lie in [1, 64]");
      }
      if (!(std::abs(offset.x) <= 1.0 && std::abs(offset.y) <= 1.0)) {
        fail(json_path + ".offset", "image offset must lie in [-1, 1] on both axes");
      }
      break;
  }
}

// ---- ShapeSpec ------------------------------------------------------------------------------

ShapeSpec ShapeSpec::defaults(ShapeKind kind) {
  ShapeSpec s;
  s.kind = kind;
  return s;
}

ShapeSpec ShapeSpec::from_json(JsonReader& r) {
  std::string kind_name = "full";
  r.get("kind", kind_name);
  ShapeSpec s = defaults(kind_from_string(kind_name, kShapeKinds, "shape", r.path_of("kind")));
  auto require = [&](bool found, const std::string& key) {
    if (!found) fail(r.path_of(key), "required key for a " + kind_name + " shape is missing");
  };
  Point c;
  switch (s.kind) {
    case ShapeKind::kFull:
      break;
    case ShapeKind::kRectangle: {
      if (read_point(r, "center", c)) s.center = c;
      json size;
      require(r.get("size", size), "size");
      const Point wh = parse_point(size, r.path_of("size"));
      s.width = wh.x;
      s.height = wh.y;
      r.get("angle", s.angle);
      break;
    }
    case ShapeKind::kDisk:
      if (read_point(r, "center", c)) s.center = c;
      require(r.get("radius", s.radius), "radius");
      break;
    case ShapeKind::kPolygon: {
      json points;
      require(r.get("points", points), "points");
      if (!points.is_array()) fail(r.path_of("points"), "expected a list of [x, y] points");
      for (size_t i = 0; i < points.size(); ++i) {
        s.points.push_back(
            parse_point(points[i], r.path_of("points") + "[" + std::to_string(i) + "]"));
      }
      break;
    }
    case ShapeKind::kBars:
      if (read_point(r, "center", c)) s.center = c;
      require(r.get("width", s.width), "width");
      require(r.get("period", s.period), "period");
      r.get("angle", s.angle);
      r.get("count", s.count);
      break;
  }
  if (s.kind != ShapeKind::kFull) {
    r.get("softness", s.softness);
    r.get("invert", s.invert);
  }
  r.finish();
  s.validate(r.path());
  return s;
}

json ShapeSpec::to_json() const {
  json j;
  j["kind"] = to_string(kind);
  switch (kind) {
    case ShapeKind::kFull:
      return j;
    case ShapeKind::kRectangle:
      if (center) j["center"] = point_json(*center);
      j["size"] = json::array({width, height});
      j["angle"] = angle;
      break;
    case ShapeKind::kDisk:
      if (center) j["center"] = point_json(*center);
      j["radius"] = radius;
      break;
    case ShapeKind::kPolygon:
      j["points"] = json::array();
      for (const auto& p : points) j["points"].push_back(point_json(p));
      break;
    case ShapeKind::kBars:
      if (center) j["center"] = point_json(*center);
      j["width"] = width;
      j["period"] = period;
      j["angle"] = angle;
      j["count"] = count;
      break;
  }
  j["softness"] = softness;
  j["invert"] = invert;
  return j;
}

void ShapeSpec::validate(const std::string& path) const {
  switch (kind) {
    case ShapeKind::kFull:
      return;
    case ShapeKind::kRectangle:
      check_positive(width, path + ".size");
      check_positive(height, path + ".size");
      break;
    case ShapeKind::kDisk:
      check_positive(radius, path + ".radius");
      break;
    case ShapeKind::kPolygon:
      if (points.size() < 3) fail(path + ".points", "a polygon needs at least 3 points");
      break;
    case ShapeKind::kBars:
      check_positive(width, path + ".width");
      check_positive(period, path + ".period");
      if (width >= period) fail(path + ".width", "bars must be narrower than their period");
      if (count < 0 || count > 100000) {
        fail(path + ".count", "must lie in [0, 100000] (0: unlimited)");
      }
      break;
  }
  // Positions and sizes in pixels: a scene is at most 16384 px a side, so 1e5 is far outside it.
  constexpr double kFar = 1e5;
  if (center) {
    check_range(center->x, -kFar, kFar, path + ".center");
    check_range(center->y, -kFar, kFar, path + ".center");
  }
  for (const auto& p : points) {
    check_range(p.x, -kFar, kFar, path + ".points");
    check_range(p.y, -kFar, kFar, path + ".points");
  }
  if (width > kFar || height > kFar) {
    fail(path + (kind == ShapeKind::kBars ? ".width" : ".size"), "must be at most 1e+05 px");
  }
  if (radius > kFar) fail(path + ".radius", "must be at most 1e+05 px");
  if (period > kFar) fail(path + ".period", "must be at most 1e+05 px");
  check_range(angle, -3600.0, 3600.0, path + ".angle");
  check_range(softness, 0.05, 1e4, path + ".softness");
}

// ---- MotionSpec -----------------------------------------------------------------------------

MotionSpec MotionSpec::from_json(JsonReader& r) {
  MotionSpec m;
  read_point(r, "shift", m.shift);
  r.get("disparity", m.disparity);
  r.get("rotation", m.rotation);
  r.get("scale", m.scale);
  r.finish();
  m.validate(r.path());
  return m;
}

json MotionSpec::to_json() const {
  return {{"shift", point_json(shift)},
          {"disparity", disparity},
          {"rotation", rotation},
          {"scale", scale}};
}

void MotionSpec::validate(const std::string& path) const {
  check_range(shift.x, -256.0, 256.0, path + ".shift");
  check_range(shift.y, -256.0, 256.0, path + ".shift");
  check_range(disparity, -64.0, 64.0, path + ".disparity");
  check_range(rotation, -180.0, 180.0, path + ".rotation");
  check_range(scale, 0.5, 2.0, path + ".scale");
}

// ---- LayerSpec ------------------------------------------------------------------------------

LayerSpec LayerSpec::from_json(JsonReader& r) {
  LayerSpec layer;
  r.get("name", layer.name);
  {
    JsonReader tex = r.child("texture");
    layer.texture = TextureSpec::from_json(tex);
  }
  json shape;
  if (r.get("shape", shape)) {
    JsonReader sr(shape, r.path_of("shape"));
    layer.shape = ShapeSpec::from_json(sr);
  }
  r.get("disparity", layer.disparity);
  json gradient;
  if (r.get("disparity_gradient", gradient)) {
    layer.disparity_gradient = parse_point(gradient, r.path_of("disparity_gradient"));
  }
  r.get("opacity", layer.opacity);
  r.get("gloss", layer.gloss);
  if (r.has("motion")) {
    JsonReader mr = r.child("motion");
    layer.motion = MotionSpec::from_json(mr);
  }
  r.finish();
  layer.validate(r.path());
  return layer;
}

json LayerSpec::to_json() const {
  json j;
  if (!name.empty()) j["name"] = name;
  j["texture"] = texture.to_json();
  j["shape"] = shape.to_json();
  j["disparity"] = disparity;
  if (slanted()) j["disparity_gradient"] = point_json(disparity_gradient);
  j["opacity"] = opacity;
  j["gloss"] = gloss;
  if (motion) j["motion"] = motion->to_json();
  return j;
}

void LayerSpec::validate(const std::string& path) const {
  texture.validate(path + ".texture");
  shape.validate(path + ".shape");
  check_range(disparity, -1024.0, 1024.0, path + ".disparity");
  check_range(opacity, 0.0, 1.0, path + ".opacity");
  check_range(gloss, 0.0, 10.0, path + ".gloss");
  if (motion) motion->validate(path + ".motion");
}

// ---- Effects --------------------------------------------------------------------------------

SpecularSpec SpecularSpec::from_json(JsonReader& r) {
  SpecularSpec s;
  r.get("count", s.count);
  r.get("strength", s.strength);
  r.get("sigma", s.sigma);
  r.get("lobe", s.lobe);
  r.get("disparity_offset", s.disparity_offset);
  json color;
  if (r.get("color", color)) s.color = parse_color(color, r.path_of("color"));
  uint64_t seed = 0;
  if (r.get("seed", seed)) s.seed = seed;
  r.finish();
  s.validate(r.path());
  return s;
}

json SpecularSpec::to_json() const {
  json j = {{"count", count},
            {"strength", strength},
            {"sigma", sigma},
            {"lobe", lobe},
            {"disparity_offset", disparity_offset},
            {"color", color_json(color)}};
  if (seed) j["seed"] = *seed;
  return j;
}

void SpecularSpec::validate(const std::string& path) const {
  if (count < 0 || count > 1000) fail(path + ".count", "must lie in [0, 1000]");
  check_range(strength, 0.0, 10.0, path + ".strength");
  check_range(sigma, 0.1, 1e4, path + ".sigma");
  check_range(lobe, 0.05, 1e3, path + ".lobe");
  check_range(disparity_offset, -1024.0, 1024.0, path + ".disparity_offset");
  check_color(color, path + ".color");
}

VignettingSpec VignettingSpec::from_json(JsonReader& r) {
  VignettingSpec v;
  r.get("strength", v.strength);
  r.get("power", v.power);
  r.get("angular", v.angular);
  r.get("shift", v.shift);
  r.finish();
  v.validate(r.path());
  return v;
}

json VignettingSpec::to_json() const {
  return {{"strength", strength}, {"power", power}, {"angular", angular}, {"shift", shift}};
}

void VignettingSpec::validate(const std::string& path) const {
  check_range(strength, 0.0, 1.0, path + ".strength");
  check_range(power, 0.1, 16.0, path + ".power");
  check_range(angular, 0.0, 1.0, path + ".angular");
  check_range(shift, -1.0, 1.0, path + ".shift");
}

DefocusSpec DefocusSpec::from_json(JsonReader& r) {
  DefocusSpec d;
  r.get("focus_disparity", d.focus_disparity);
  r.get("blur", d.blur);
  r.get("max_sigma", d.max_sigma);
  r.finish();
  d.validate(r.path());
  return d;
}

json DefocusSpec::to_json() const {
  return {{"focus_disparity", focus_disparity}, {"blur", blur}, {"max_sigma", max_sigma}};
}

void DefocusSpec::validate(const std::string& path) const {
  check_range(focus_disparity, -1024.0, 1024.0, path + ".focus_disparity");
  check_range(blur, 0.0, 100.0, path + ".blur");
  check_range(max_sigma, 0.0, 64.0, path + ".max_sigma");
}

// ---- SceneSpec ------------------------------------------------------------------------------

SceneSpec SceneSpec::from_json(const json& doc) {
  JsonReader r(doc, "$");
  SceneSpec s;
  r.get("name", s.name);
  r.get("description", s.description);
  if (!r.get("height", s.height)) fail("$.height", "required key is missing");
  if (!r.get("width", s.width)) fail("$.width", "required key is missing");
  r.get("rows", s.rows);
  r.get("cols", s.cols);
  r.get("color", s.color);
  r.get("seed", s.seed);
  json layers;
  if (!r.get("layers", layers)) fail("$.layers", "required key is missing");
  if (!layers.is_array() || layers.empty()) fail("$.layers", "expected a non-empty list of layers");
  for (size_t i = 0; i < layers.size(); ++i) {
    JsonReader lr(layers[i], "$.layers[" + std::to_string(i) + "]");
    s.layers.push_back(LayerSpec::from_json(lr));
  }
  if (r.has("effects")) {
    JsonReader er = r.child("effects");
    if (er.has("specular")) {
      JsonReader x = er.child("specular");
      s.specular = SpecularSpec::from_json(x);
    }
    if (er.has("vignetting")) {
      JsonReader x = er.child("vignetting");
      s.vignetting = VignettingSpec::from_json(x);
    }
    if (er.has("defocus")) {
      JsonReader x = er.child("defocus");
      s.defocus = DefocusSpec::from_json(x);
    }
    er.finish();
  }
  json sensor;
  if (r.get("sensor", sensor)) {
    if (!sensor.is_object()) fail("$.sensor", "expected a JSON object, got " + sensor.dump());
    s.sensor = sensor;
  }
  json rendered;
  r.get("rendered", rendered);  // a record written by `lfnet render`, not an input
  r.finish();
  s.validate();
  return s;
}

json SceneSpec::to_json() const {
  json j;
  if (!name.empty()) j["name"] = name;
  if (!description.empty()) j["description"] = description;
  j["height"] = height;
  j["width"] = width;
  j["rows"] = rows;
  j["cols"] = cols;
  j["color"] = color;
  j["seed"] = seed;
  j["layers"] = json::array();
  for (const auto& layer : layers) j["layers"].push_back(layer.to_json());
  if (specular || vignetting || defocus) {
    json effects = json::object();
    if (specular) effects["specular"] = specular->to_json();
    if (vignetting) effects["vignetting"] = vignetting->to_json();
    if (defocus) effects["defocus"] = defocus->to_json();
    j["effects"] = effects;
  }
  if (sensor) j["sensor"] = *sensor;
  return j;
}

void SceneSpec::validate() const {
  if (height < 1 || height > 16384) fail("$.height", "must lie in [1, 16384]");
  if (width < 1 || width > 16384) fail("$.width", "must lie in [1, 16384]");
  if (rows < 1 || rows > 64) fail("$.rows", "must lie in [1, 64]");
  if (cols < 1 || cols > 64) fail("$.cols", "must lie in [1, 64]");
  if (layers.empty()) fail("$.layers", "a scene needs at least one layer");
  const double umax = (rows - 1) / 2.0;
  const double vmax = (cols - 1) / 2.0;
  for (size_t i = 0; i < layers.size(); ++i) {
    const std::string path = "$.layers[" + std::to_string(i) + "]";
    layers[i].validate(path);
    const auto& g = layers[i].disparity_gradient;
    // The inverse warp of a slanted plane divides by 1 + g . s; keep it well away from zero.
    if (std::abs(g.x) * vmax + std::abs(g.y) * umax > 0.5) {
      fail(path + ".disparity_gradient",
           "too steep: |gx| (cols-1)/2 + |gy| (rows-1)/2 must stay <= 0.5");
    }
  }
  const double max_shift = max_abs_disparity() * std::max(umax, vmax);
  if (max_shift > 1024.0) {
    fail("$.layers", "disparities shift views by up to " +
                         std::to_string(static_cast<int64_t>(max_shift)) +
                         " px; the limit is 1024");
  }
  if (specular) specular->validate("$.effects.specular");
  if (vignetting) vignetting->validate("$.effects.vignetting");
  if (defocus) defocus->validate("$.effects.defocus");
  if (sensor && !sensor->is_object()) fail("$.sensor", "expected a JSON object");
}

double SceneSpec::max_abs_disparity() const {
  double m = 0.0;
  for (const auto& layer : layers) {
    const double d = std::abs(layer.disparity) +
                     std::abs(layer.disparity_gradient.x) * (width - 1) / 2.0 +
                     std::abs(layer.disparity_gradient.y) * (height - 1) / 2.0;
    m = std::max(m, d);
  }
  return m;
}

bool SceneSpec::moves() const {
  return std::any_of(layers.begin(), layers.end(), [](const LayerSpec& l) { return l.moves(); });
}

Point motion_center(const LayerSpec& layer, const SceneSpec& spec) {
  const Point image{(spec.width - 1) / 2.0, (spec.height - 1) / 2.0};
  const ShapeSpec& shape = layer.shape;
  if (shape.kind == ShapeKind::kPolygon && !shape.points.empty()) {
    Point c;
    for (const auto& p : shape.points) {
      c.x += p.x;
      c.y += p.y;
    }
    const auto n = static_cast<double>(shape.points.size());
    return Point{c.x / n, c.y / n};
  }
  if (shape.kind == ShapeKind::kFull) return image;
  return shape.center.value_or(image);
}

SceneSpec load_scene(const std::string& path) { return SceneSpec::from_json(read_json_file(path)); }

}  // namespace lfnet::scene

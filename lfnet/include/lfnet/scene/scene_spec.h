// Procedural scene specs: a stack of textured, shaped layers at given disparities, plus the
// optional effects a scene names. Parsed strictly from JSON; docs/scenes.md lists every key.
#pragma once

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/core/json.h"

namespace lfnet::scene {

// An RGB colour in [0, 1]. In JSON a colour is [r, g, b] or one grey number.
using Rgb = std::array<double, 3>;

// A point in centre-view pixel coordinates: x to the right, y down, (0, 0) the centre of the
// top-left pixel. In JSON [x, y].
struct Point {
  double x = 0.0;
  double y = 0.0;
};

// What a texture paints: a scalar field t in [0, 1] mapped through a colour ramp, or an image.
enum class TextureKind { kConstant, kNoise, kFractal, kStripes, kChecker, kGradient, kImage };
std::string to_string(TextureKind kind);

// A layer's texture. Which fields apply depends on `kind`; the JSON reader rejects the others.
// All textures are functions of centre-view pixel coordinates and the seed alone, so they do
// not change when another layer or the canvas margin does.
struct TextureSpec {
  TextureKind kind = TextureKind::kConstant;
  // Colour ramp from t = 0 to t = 1, evenly spaced (constant: the first colour). Not for image.
  std::vector<Rgb> colors = {Rgb{0.0, 0.0, 0.0}, Rgb{1.0, 1.0, 1.0}};
  // noise: lattice spacing of smooth value noise in px (default 4); fractal: the longest
  // wavelength in px (default 128).
  double scale = 4.0;
  double contrast = 1.0;           // noise, fractal: t = Phi(contrast * z) with z of unit variance
  double beta = 2.0;               // fractal: power spectrum ~ 1 / f^beta (natural images: about 2)
  double period = 8.0;             // stripes: period in px
  double duty = 0.5;               // stripes: fraction of a period at t = 1 (square profile)
  std::string profile = "square";  // stripes: square | sine; gradient: linear | radial
  double phase = 0.0;              // stripes: offset in periods
  double size = 8.0;               // checker: square side in px
  double angle = 0.0;              // stripes, checker, gradient: degrees from +x towards +y
  std::optional<Point> center;     // gradient: default the image centre
  std::optional<double> length;    // gradient: ramp length (linear) or radius (radial) in px;
                                   // default the image extent along the ramp / half-diagonal
  std::string path;                // image: file, relative to the scene file's folder
  std::string fit = "cover";       // image: cover (keep aspect, crop) | stretch
  double zoom = 1.0;               // image: >= 1 magnifies, showing 1 / zoom of the fitted image
  Point offset;                    // image: where that part lies, -1..1 across the part left out
                                   // along x and y (0, 0: the middle)
  std::optional<uint64_t> seed;    // noise, fractal: default derived from the scene seed and
                                   // the layer index

  // A texture of `kind` with that kind's defaults.
  static TextureSpec defaults(TextureKind kind);
  static TextureSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  // Throws ConfigError naming `json_path` (e.g. "$.layers[2].texture") and the bad key.
  void validate(const std::string& json_path) const;
};

// What a shape gives: the layer's alpha (coverage).
enum class ShapeKind { kFull, kRectangle, kDisk, kPolygon, kBars };
std::string to_string(ShapeKind kind);

// A layer's shape. Edges are anti-aliased: alpha falls linearly from 1 to 0 over `softness`
// pixels across the boundary.
struct ShapeSpec {
  ShapeKind kind = ShapeKind::kFull;
  std::optional<Point> center;  // rectangle, disk, bars (a point on bar 0); default image centre
  double width = 0.0;           // rectangle: [width, height] as "size"; bars: bar width in px
  double height = 0.0;          // rectangle
  double radius = 0.0;          // disk
  double angle = 0.0;           // rectangle, bars: degrees (bars: direction of the bars' normal)
  std::vector<Point> points;    // polygon: vertices, even-odd fill
  double period = 0.0;          // bars: distance between bar centres in px
  int64_t count = 0;            // bars: number of bars around bar 0 (0: unlimited)
  double softness = 1.0;        // edge width in px
  bool invert = false;          // alpha -> 1 - alpha (holes, windows)

  static ShapeSpec defaults(ShapeKind kind);
  static ShapeSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate(const std::string& path) const;
};

// How a layer moves during an exposure (render_sequence), per sub-frame. Sub-frame t of T shows
// the layer moved by tau = t - (T - 1) / 2 steps: the middle of the exposure is the spec's pose.
// A point p of the layer goes to c + tau shift + scale^tau R(tau rotation) (p - c), c the
// shape's centre (motion_center), and its disparity grows by tau disparity.
struct MotionSpec {
  Point shift;             // px per sub-frame along x and y
  double disparity = 0.0;  // change of disparity per sub-frame (motion in depth)
  double rotation = 0.0;   // degrees per sub-frame, from +x towards +y
  double scale = 1.0;      // size factor per sub-frame (> 1: growing, coming nearer)

  // False for the zero motion: such a layer renders as a still one.
  bool moves() const {
    return shift.x != 0.0 || shift.y != 0.0 || disparity != 0.0 || rotation != 0.0 || scale != 1.0;
  }
  static MotionSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate(const std::string& path) const;
};

// One layer: a texture cut out by a shape, at a disparity in px per view step.
struct LayerSpec {
  std::string name;  // optional, for people
  TextureSpec texture;
  ShapeSpec shape;                   // default full
  double disparity = 0.0;            // px per view step at the image centre
  Point disparity_gradient;          // slanted plane: d(p) = disparity + g . (p - image centre)
  double opacity = 1.0;              // multiplies the shape's alpha
  double gloss = 1.0;                // scales specular highlights (used only with "specular")
  std::optional<MotionSpec> motion;  // none: still in every sub-frame

  bool slanted() const { return disparity_gradient.x != 0.0 || disparity_gradient.y != 0.0; }
  bool moves() const { return motion && motion->moves(); }
  static LayerSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate(const std::string& path) const;
};

// View-dependent highlights: bright spots on glossy layers that move with a disparity other than
// the surface's and brighten in some views only (a reflected light source).
struct SpecularSpec {
  int64_t count = 3;      // highlights per layer, at seeded points of its surface
  double strength = 0.6;  // peak added value (times the layer's gloss)
  double sigma = 4.0;     // spot size (Gaussian sigma) in px
  double lobe = 1.5;      // angular width in view steps: gain exp(-|view - peak|^2 / 2 lobe^2)
  double disparity_offset = -1.0;  // the spot moves with disparity d(surface) + offset
  Rgb color = {1.0, 1.0, 1.0};     // light colour
  std::optional<uint64_t> seed;    // default derived from the scene seed

  static SpecularSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate(const std::string& path) const;
};

// Lens vignetting: a radial fall-off that darkens the outer views more and moves with the view.
struct VignettingSpec {
  double strength = 0.35;  // darkening at the image corners: factor 1 - strength (r / R)^power
  double power = 2.0;      // fall-off exponent; R is the half-diagonal
  double angular = 0.15;   // extra darkening of the corner views: factor 1 - angular * rho^2
  double shift = 0.1;      // the fall-off centre moves by shift * half the image size per
                           // normalised view offset

  static VignettingSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate(const std::string& path) const;
};

// Defocus: every layer is blurred by a Gaussian whose sigma grows with its distance in
// disparity from the focal plane (a layered approximation: occlusion edges are not exact).
struct DefocusSpec {
  double focus_disparity = 0.0;  // disparity of the plane in focus
  double blur = 0.3;             // sigma in px per px of |disparity - focus_disparity|
  double max_sigma = 8.0;        // cap on sigma

  static DefocusSpec from_json(JsonReader& reader);
  nlohmann::json to_json() const;
  void validate(const std::string& path) const;
};

// A whole scene. Layers are listed back to front. Disparity convention: a point at disparity d
// seen at (x, y) in the centre view appears at (x + d (v - vc), y + d (u - uc)) in view (u, v),
// uc = (rows - 1) / 2, vc = (cols - 1) / 2; larger disparity is nearer (as the HCI benchmark).
struct SceneSpec {
  std::string name;
  std::string description;
  int64_t height = 0;  // view height in px (required)
  int64_t width = 0;   // view width in px (required)
  int64_t rows = 5;    // U, angular rows
  int64_t cols = 5;    // V, angular columns
  bool color = true;   // false: one luma channel
  uint64_t seed = 0;   // default seed of every seeded texture and effect
  std::vector<LayerSpec> layers;
  std::optional<SpecularSpec> specular;
  std::optional<VignettingSpec> vignetting;
  std::optional<DefocusSpec> defocus;
  // Sensor effects for the simulator, kept verbatim (the renderer does not interpret them).
  std::optional<nlohmann::json> sensor;

  // Strict parse; unknown keys and bad values are ConfigErrors naming the JSON path. A
  // "rendered" object (written by `lfnet render` beside the spec) is accepted and ignored.
  static SceneSpec from_json(const nlohmann::json& json);
  nlohmann::json to_json() const;
  void validate() const;

  // The largest |disparity| anywhere in the image over all layers.
  double max_abs_disparity() const;
  // True when some layer declares a non-zero motion.
  bool moves() const;
};

// The point a layer's rotation and scaling turn about: its shape's `center` (rectangle, disk,
// bars), the mean of a polygon's vertices, or the image centre (full shapes).
Point motion_center(const LayerSpec& layer, const SceneSpec& spec);

// Reads and parses a scene file.
SceneSpec load_scene(const std::string& path);

}  // namespace lfnet::scene

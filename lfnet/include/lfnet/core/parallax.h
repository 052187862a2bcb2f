// Whether a light field's angular axes follow lfnet's orientation (docs/conventions.md):
// a scene point moves by d * du in y and d * dv in x with the same disparity d, so horizontal
// and vertical parallax agree in sign. A loader that reverses one angular axis (a camera
// whose Y axis points up, read from the top) makes them disagree; this finds out.
#pragma once

#include <cstdint>
#include <string>

#include "lfnet/core/light_field.h"

namespace lfnet {

// Options of check_parallax.
struct ParallaxCheckOptions {
  int64_t block = 16;           // side of the square blocks disparity is estimated on, pixels
  double max_disparity = 4.0;   // candidates -max..+max pixels per view step
  double step = 0.125;          // spacing of the candidates, pixels per view step
  double min_disparity = 0.25;  // a block counts only when both |d| reach this (Lytro
                                // cameras see about -1..+1 px per view step)
  double min_contrast = 0.01;   // and its central view's standard deviation does (values 0..1;
                                // Lytro views are dark)
  int64_t min_blocks = 8;       // fewer usable blocks: the verdict is kUndetermined
  int64_t max_side = 1024;      // blocks are taken from the central max_side x max_side pixels
                                // at most: time and memory stay bounded for any view size
};

// What the check found.
enum class ParallaxVerdict {
  kAgree,         // horizontal and vertical parallax have the same sign: oriented correctly
  kDisagree,      // opposite signs: one angular axis is reversed (flip u or v)
  kUndetermined,  // too little texture or parallax to tell (a flat scene, one row of views)
};
std::string to_string(ParallaxVerdict verdict);

struct ParallaxCheck {
  ParallaxVerdict verdict = ParallaxVerdict::kUndetermined;
  int64_t blocks = 0;           // blocks with texture and parallax on both axes
  double agreement = 0.0;       // fraction of those whose two disparities share a sign
  double correlation = 0.0;     // Pearson correlation of horizontal and vertical disparity
  std::string summary() const;  // one line for `lfnet info` and warnings
};

// Estimates, per textured block, the disparity along the central row of views (horizontal)
// and along the central column (vertical) by matching the views within two of the centre
// against the central view over a range of candidate disparities, then compares their signs.
// Works on grey; needs at least 2 views along each axis. Cost: one bilinear warp per view
// and candidate of the central row and column (about 0.3 s for 512 x 512 x 9 x 9).
ParallaxCheck check_parallax(const LightFieldViews& lf, const ParallaxCheckOptions& options = {});

// Reorientations of the angular axes alone, for a folder whose naming maps views onto the
// grid differently from lfnet's convention. Applied in this order: swap u and v (views named
// column-major), then reverse u (a camera Y axis pointing up), then reverse v.
struct AngularOrientation {
  bool transpose = false;
  bool flip_u = false;
  bool flip_v = false;

  bool identity() const { return !transpose && !flip_u && !flip_v; }
  // "flip-u", "flip-v", "transpose" joined by commas; "" for the identity.
  std::string to_string() const;
  // Parses a comma-separated list of those words ("" or "none": identity). Throws
  // ConfigError naming `what` (an option or JSON path) on anything else.
  static AngularOrientation parse(const std::string& text, const std::string& what);
};

// `lf` reoriented; the identity returns it unchanged.
LightField reorient(const LightField& lf, const AngularOrientation& orientation);
LightFieldViews reorient(const LightFieldViews& lf, const AngularOrientation& orientation);

}  // namespace lfnet

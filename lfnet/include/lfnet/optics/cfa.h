// Colour filter arrays: a single-sensor colour camera, each of whose pixels measures its N coded
// values of one colour (docs/acquisition.md, "Colour filter arrays").
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>

namespace lfnet::optics {

// The colour response of the sensor's pixels, periodic over a P x P tile: response (3, P, P),
// the weights of red, green and blue at each pixel phase. Bayer patterns are named by the
// colours of their tile's four pixels in row-major order: "RGGB" (red at (0, 0)), "BGGR",
// "GRBG", "GBRG". Any other response comes from a file as a P x P grid of [r, g, b] triplets.
class ColourFilterArray {
 public:
  // A Bayer pattern by name; ConfigError naming the known ones otherwise.
  static ColourFilterArray bayer(const std::string& pattern);
  // {"pattern": "RGGB"} or {"response": [[[r, g, b], ...], ...]} (rows of pixels, each an RGB
  // triplet of non-negative weights, at least one positive per pixel); `path` names it in errors.
  static ColourFilterArray from_json(const nlohmann::json& j, const std::string& path = "$");
  // --cfa: a Bayer pattern's name, one of the objects above inline, or a JSON file holding one.
  static ColourFilterArray parse(const std::string& text);

  nlohmann::json to_json() const;
  const std::string& pattern() const { return pattern_; }  // "custom" for a response from a file
  int64_t period() const { return response_.size(1); }
  const torch::Tensor& response() const { return response_; }  // (3, P, P) float32
  // Whether every pixel sees exactly one colour (a Bayer pattern does): what demosaic needs.
  bool one_colour_per_pixel() const;
  // A ConfigError unless one_colour_per_pixel(): the check every command makes before any work.
  void check_demosaicable() const;
  // The response of every pixel of an H x W sensor: (3, H, W), the tile repeated from (0, 0).
  torch::Tensor response_image(int64_t height, int64_t width) const;

 private:
  std::string pattern_ = "RGGB";
  torch::Tensor response_;
};

// The colour filter array a camera's Phi names: a calibrated Phi whose phi.json has "cfa"
// (docs/acquisition.md, "Calibrated Phi"); none for any other.
std::optional<ColourFilterArray> camera_cfa(const nlohmann::json& phi_spec);

// The colour filter array of a command: `--cfa` (`given`, empty for none) and the one the
// camera's Phi names, which must agree when both are given (a ConfigError otherwise).
std::optional<ColourFilterArray> resolve_cfa(const std::string& given,
                                             const nlohmann::json& phi_spec);

// The single sensor image (1, N, H, W) of a colour camera from the sensor images of its three
// colours (3, N, H, W) (each Phi applied to one colour of the light field): each pixel sums
// its colours' measurements weighted by its response. Sensor effects come after.
torch::Tensor mosaic(const torch::Tensor& colour_sensor, const ColourFilterArray& cfa);

// How a demosaic fills in a pixel's missing colours: "bilinear", the weighted mean of that
// colour's pixels among its 3 x 3 neighbours, or "malvar", Malvar, He and Cutler's
// gradient-corrected bilinear interpolation (ICASSP 2004; Bayer patterns only), which adds to
// the bilinear estimate a share of the pixel's own colour's Laplacian over 5 x 5 pixels, so that
// an edge in one colour is an edge in all three.
enum class Demosaic { kBilinear, kMalvar };
std::string to_string(Demosaic value);
Demosaic from_string(const std::string& name, Demosaic);

// Demosaicing of images (..., H, W) whose pixels each measure one colour of `cfa`:
// (3, ..., H, W). A pixel keeps its own colour's value; the missing colours are interpolated
// by `method`, the edges mirrored. Bilinear is, for a Bayer pattern, OpenCV's bilinear
// demosaicing; "malvar" needs a Bayer pattern (a ConfigError otherwise).
torch::Tensor demosaic(const torch::Tensor& mosaicked, const ColourFilterArray& cfa,
                       Demosaic method = Demosaic::kBilinear);

// Malvar-He-Cutler demosaicing of `own` (B, K, h, w), each pixel's K values in the one colour
// that `response` (B, 3, h, w) gives it (a Bayer pattern at any phase): (B, 3, K, h, w), the
// edges mirrored (h, w >= 3). The core of demosaic(..., kMalvar) and of a colour net's input.
torch::Tensor demosaic_malvar(const torch::Tensor& own, const torch::Tensor& response);

// Each channel of `images` (B, K, h, w) filtered by each of `filters` (F, 1, kh, kw), with
// `padding` zeros on every side: (B, K, F, h', w'), as one grouped convolution. Not as B K
// images of one channel: oneDNN pads a single input channel to a block of 16, 16 times the
// images' memory (800 MB for a colour net's 593 x 840 x 5 x 5 input).
torch::Tensor filter_channels(const torch::Tensor& images, const torch::Tensor& filters,
                              int64_t padding = 0);

}  // namespace lfnet::optics

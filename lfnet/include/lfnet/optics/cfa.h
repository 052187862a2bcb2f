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

// Bilinear demosaicing of images (..., H, W) whose pixels each measure one colour of `cfa`:
// (3, ..., H, W). A pixel keeps its own colour's value; each missing colour is the
// bilinear-weighted mean of that colour's pixels in its 3 x 3 neighbourhood (the edges
// mirrored), which for a Bayer pattern is OpenCV's bilinear demosaicing.
torch::Tensor demosaic(const torch::Tensor& mosaicked, const ColourFilterArray& cfa);

}  // namespace lfnet::optics

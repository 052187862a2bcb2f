// Figures of `lfnet report`: plots drawn with OpenCV, light-field pictures, a parallax GIF.
#pragma once

#include <torch/types.h>

#include <string>
#include <vector>

#include "lfnet/core/light_field.h"

namespace lfnet::app {

// One point of the accuracy-against-time plot.
struct ParetoPoint {
  std::string label;   // e.g. "net s5 N2"
  std::string method;  // colours the point
  double seconds = 0;
  double psnr_db = 0;
  bool front = false;  // on the Pareto front (no other point is both faster and better)
};

// The colour map of every lfnet figure (OpenCV's viridis): values in [0, 1] of any shape S
// to RGB (3, S...) float32 in [0, 1]; values outside are clamped.
torch::Tensor viridis(const torch::Tensor& t);

// Marks the Pareto front: a point is on it when every faster point has a lower PSNR.
void mark_pareto_front(std::vector<ParetoPoint>& points);

// PSNR (y) against seconds (x, logarithmic) with the front joined and labelled; PNG.
void plot_pareto(const std::vector<ParetoPoint>& points, const std::string& title,
                 const std::string& path);

// A U x V heatmap of per-view PSNR with the values written in the cells; PNG.
void plot_view_heatmap(const std::vector<std::vector<double>>& psnr, const std::string& title,
                       const std::string& path);

// The centre view of each light field side by side with a title over each, then their
// horizontal EPIs through the middle row, then |error| maps against the first (the truth),
// scaled so 0.1 is white; PNG. All light fields are grey and of one size.
void plot_views(const std::vector<LightField>& lfs, const std::vector<std::string>& titles,
                const std::string& path, int64_t crop = 160);

// An animated GIF that walks the views of `lf` along a loop of the angular border.
void write_parallax_gif(const LightField& lf, const std::string& path, int64_t crop = 160);

}  // namespace lfnet::app

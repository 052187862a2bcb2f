#include "lfnet/core/colour_map.h"

#include <torch/torch.h>

#include <cmath>

#include "lfnet/core/error.h"

namespace lfnet {

namespace {

// matplotlib's viridis at 33 evenly spaced levels; linear interpolation between them stays
// within 2.5 / 255 of its 256-entry table.
constexpr uint8_t kStops[33][3] = {
    {68, 1, 84},    {71, 13, 96},   {72, 24, 106},  {72, 35, 116},  {71, 45, 123},  {69, 55, 129},
    {66, 64, 134},  {62, 73, 137},  {59, 82, 139},  {55, 91, 141},  {51, 99, 141},  {47, 107, 142},
    {44, 114, 142}, {41, 122, 142}, {38, 130, 142}, {35, 137, 142}, {33, 145, 140}, {31, 152, 139},
    {31, 160, 136}, {34, 167, 133}, {40, 174, 128}, {50, 182, 122}, {63, 188, 115}, {78, 195, 107},
    {94, 201, 98},  {112, 207, 87}, {132, 212, 75}, {152, 216, 62}, {173, 220, 48}, {194, 223, 35},
    {216, 226, 25}, {236, 229, 27}, {253, 231, 37}};
constexpr int kLast = 32;

}  // namespace

torch::Tensor viridis(const torch::Tensor& values) {
  auto stops = torch::empty({kLast + 1, 3});
  for (int i = 0; i <= kLast; ++i) {
    for (int c = 0; c < 3; ++c) stops[i][c] = kStops[i][c] / 255.0f;
  }
  auto t = torch::nan_to_num(values.to(torch::kFloat32), 0.0).clamp(0, 1) * kLast;
  auto low = t.floor().clamp_max(kLast - 1);
  auto f = (t - low).unsqueeze(-1);
  auto index = low.to(torch::kLong);
  auto rgb = stops.index({index}) * (1 - f) + stops.index({index + 1}) * f;  // (S..., 3)
  return rgb.movedim(-1, 0).contiguous();
}

std::vector<std::array<uint8_t, 3>> viridis_table(int levels) {
  LFNET_CHECK(levels >= 2, "viridis_table needs at least 2 levels");
  const auto rgb = viridis(torch::linspace(0, 1, levels));  // (3, levels)
  std::vector<std::array<uint8_t, 3>> out(levels);
  for (int i = 0; i < levels; ++i) {
    for (int c = 0; c < 3; ++c) {
      out[i][c] = static_cast<uint8_t>(std::lround(rgb[c][i].item<float>() * 255.0f));
    }
  }
  return out;
}

}  // namespace lfnet

#include "lfnet/core/parallax.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "lfnet/core/error.h"

namespace lfnet {

std::string to_string(ParallaxVerdict verdict) {
  switch (verdict) {
    case ParallaxVerdict::kAgree:
      return "agree";
    case ParallaxVerdict::kDisagree:
      return "disagree";
    case ParallaxVerdict::kUndetermined:
      return "undetermined";
  }
  return "unknown";
}

std::string ParallaxCheck::summary() const {
  std::ostringstream s;
  s.precision(2);
  s << std::fixed;
  switch (verdict) {
    case ParallaxVerdict::kAgree:
      s << "horizontal and vertical parallax agree in sign";
      break;
    case ParallaxVerdict::kDisagree:
      s << "horizontal and vertical parallax have OPPOSITE signs (one angular axis is reversed)";
      break;
    case ParallaxVerdict::kUndetermined:
      s << "parallax orientation undetermined (too little texture or parallax)";
      break;
  }
  s << " (" << blocks << " blocks, " << 100.0 * agreement << " % same sign, correlation "
    << correlation << ")";
  return s.str();
}

namespace {

// Per-block matching cost of the views of one axis against the central view, for every
// candidate disparity: (candidates, blocks_y, blocks_x). `views` (each H, W) lie at angular
// offsets `offsets` from the centre along the axis; `along_x` says whether that axis moves
// the scene in x (the row of views) or in y (the column). Each candidate's cost map is pooled
// into blocks at once, so only one full-size map is held at a time.
torch::Tensor matching_cost(const torch::Tensor& centre, const std::vector<torch::Tensor>& views,
                            const std::vector<int64_t>& offsets, bool along_x,
                            const std::vector<double>& candidates, int64_t margin, int64_t block) {
  const int64_t h = centre.size(0) - 2 * margin, w = centre.size(1) - 2 * margin;
  const int64_t dim = along_x ? 1 : 0;
  const auto target = centre.narrow(0, margin, h).narrow(1, margin, w);
  std::vector<torch::Tensor> costs;
  costs.reserve(candidates.size());
  for (double d : candidates) {
    auto cost = torch::zeros({h, w}, centre.options());
    for (size_t i = 0; i < offsets.size(); ++i) {
      // The central view at x equals this view at x + d * k (docs/conventions.md): sample
      // there, linearly between the two nearest pixels.
      const double s = d * static_cast<double>(offsets[i]);
      const auto i0 = static_cast<int64_t>(std::floor(s));
      const double f = s - static_cast<double>(i0);
      const auto& view = views[i];
      auto crop = [&](int64_t shift) {
        auto c = view.narrow(dim, margin + shift, along_x ? w : h);
        return c.narrow(1 - dim, margin, along_x ? h : w);
      };
      cost.add_(torch::lerp(crop(i0), crop(i0 + 1), f).sub_(target).abs_());
    }
    costs.push_back(torch::avg_pool2d(cost.unsqueeze(0), {block, block}).squeeze(0));
  }
  return torch::stack(costs);
}

}  // namespace

ParallaxCheck check_parallax(const LightFieldViews& lf, const ParallaxCheckOptions& o) {
  LFNET_CHECK_AS(ConfigError, o.block > 0 && o.step > 0 && o.max_disparity > 0,
                 "check_parallax: block, step and max_disparity must be positive");
  ParallaxCheck out;
  if (!lf.raw().defined() || lf.rows() < 2 || lf.cols() < 2) return out;
  torch::NoGradGuard no_grad;
  // The two nearest views on each side of the centre: enough to see the sign, and the
  // margin (the largest shift) stays small. Only those views are converted to grey.
  const int64_t reach = 2;
  const AngularRange ru{std::max<int64_t>(0, lf.rows() / 2 - reach),
                        std::min(lf.rows(), lf.rows() / 2 + reach + 1)};
  const AngularRange rv{std::max<int64_t>(0, lf.cols() / 2 - reach),
                        std::min(lf.cols(), lf.cols() / 2 + reach + 1)};
  const int64_t cu = lf.rows() / 2 - ru.begin, cv = lf.cols() / 2 - rv.begin;
  int64_t max_offset = 0;
  for (int64_t k : {cu, ru.size() - 1 - cu, cv, rv.size() - 1 - cv}) {
    max_offset = std::max(max_offset, k);
  }
  const auto margin =
      static_cast<int64_t>(std::ceil(o.max_disparity * static_cast<double>(max_offset))) + 1;
  // The central max_side x max_side pixels (and the margin around them) of those views.
  const int64_t crop_h = std::min(lf.height(), o.max_side + 2 * margin);
  const int64_t crop_w = std::min(lf.width(), o.max_side + 2 * margin);
  const auto crop = lf.raw()
                        .slice(axis::kU, ru.begin, ru.end)
                        .slice(axis::kV, rv.begin, rv.end)
                        .narrow(axis::kH, (lf.height() - crop_h) / 2, crop_h)
                        .narrow(axis::kW, (lf.width() - crop_w) / 2, crop_w);
  // (U', V', h, w) around the centre
  const auto g = LightField(lf.coded() ? decode_codes(crop) : crop).grey().data()[0];
  std::vector<int64_t> off_h, off_v;
  std::vector<torch::Tensor> row_views, col_views;
  for (int64_t v = 0; v < g.size(1); ++v) {
    if (v == cv) continue;
    off_h.push_back(v - cv);
    row_views.push_back(g[cu][v]);
  }
  for (int64_t u = 0; u < g.size(0); ++u) {
    if (u == cu) continue;
    off_v.push_back(u - cu);
    col_views.push_back(g[u][cv]);
  }
  const auto centre = g[cu][cv];
  if (centre.size(0) - 2 * margin < o.block || centre.size(1) - 2 * margin < o.block) return out;

  std::vector<double> candidates;
  const auto steps = static_cast<int64_t>(std::llround(o.max_disparity / o.step));
  for (int64_t i = -steps; i <= steps; ++i) candidates.push_back(static_cast<double>(i) * o.step);
  auto cand = torch::tensor(candidates, torch::kFloat64);

  auto cost_h = matching_cost(centre, row_views, off_h, true, candidates, margin, o.block);
  auto cost_v = matching_cost(centre, col_views, off_v, false, candidates, margin, o.block);
  auto d_h = cand.index_select(0, cost_h.argmin(0).flatten());
  auto d_v = cand.index_select(0, cost_v.argmin(0).flatten());
  // Texture of the central view per block, over the same interior.
  const int64_t h = centre.size(0) - 2 * margin, w = centre.size(1) - 2 * margin;
  auto interior = centre.narrow(0, margin, h).narrow(1, margin, w).unsqueeze(0).unsqueeze(0);
  auto mean = torch::avg_pool2d(interior, {o.block, o.block});
  auto mean_sq = torch::avg_pool2d(interior * interior, {o.block, o.block});
  auto sd = (mean_sq - mean * mean).clamp_min(0).sqrt().flatten().to(torch::kFloat64);

  auto usable =
      sd.ge(o.min_contrast) & d_h.abs().ge(o.min_disparity) & d_v.abs().ge(o.min_disparity);
  auto dh = d_h.masked_select(usable), dv = d_v.masked_select(usable);
  out.blocks = dh.numel();
  if (out.blocks == 0) return out;
  out.agreement = (dh.sign() == dv.sign()).to(torch::kFloat64).mean().item<double>();
  auto ch = dh - dh.mean(), cvv = dv - dv.mean();
  const double denom = std::sqrt((ch * ch).sum().item<double>() * (cvv * cvv).sum().item<double>());
  out.correlation = denom > 0 ? (ch * cvv).sum().item<double>() / denom : 0.0;
  if (out.blocks >= o.min_blocks) {
    if (out.agreement >= 0.75) out.verdict = ParallaxVerdict::kAgree;
    if (out.agreement <= 0.25) out.verdict = ParallaxVerdict::kDisagree;
  }
  return out;
}

std::string AngularOrientation::to_string() const {
  std::string s;
  auto add = [&](bool on, const char* word) {
    if (on) s += (s.empty() ? "" : ",") + std::string(word);
  };
  add(transpose, "transpose");
  add(flip_u, "flip-u");
  add(flip_v, "flip-v");
  return s;
}

AngularOrientation AngularOrientation::parse(const std::string& text, const std::string& what) {
  AngularOrientation o;
  if (text.empty() || text == "none") return o;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    const std::string word = text.substr(start, comma - start);
    start = comma + 1;
    if (word == "transpose") {
      o.transpose = true;
    } else if (word == "flip-u") {
      o.flip_u = true;
    } else if (word == "flip-v") {
      o.flip_v = true;
    } else {
      std::string message = what;
      message += ": unknown angular reorientation '";
      message += word;
      message += "'; use a comma-separated list of flip-u, flip-v, transpose (or none)";
      throw ConfigError(message);
    }
  }
  return o;
}

namespace {
torch::Tensor reoriented(torch::Tensor t, const AngularOrientation& o) {
  if (o.transpose) t = t.transpose(axis::kU, axis::kV);
  if (o.flip_u) t = t.flip({axis::kU});
  if (o.flip_v) t = t.flip({axis::kV});
  return t.contiguous();
}
}  // namespace

LightField reorient(const LightField& lf, const AngularOrientation& o) {
  if (o.identity()) return lf;
  return LightField(reoriented(lf.data(), o));
}

LightFieldViews reorient(const LightFieldViews& lf, const AngularOrientation& o) {
  if (o.identity()) return lf;
  return LightFieldViews(reoriented(lf.raw(), o));
}

}  // namespace lfnet

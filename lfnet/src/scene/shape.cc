// Shapes as alpha: a signed distance to the boundary mapped to coverage with a linear ramp
// `softness` px wide, which approximates box-filtered (anti-aliased) edges.
#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lfnet/core/constants.h"
#include "raster.h"

namespace lfnet::scene::detail {
namespace {

inline float coverage(double signed_distance, double softness, bool invert) {
  const double a = std::clamp(0.5 - signed_distance / softness, 0.0, 1.0);
  return static_cast<float>(invert ? 1.0 - a : a);
}

Point default_center(const Canvas& canvas) {
  return Point{(canvas.image_width - 1) / 2.0, (canvas.image_height - 1) / 2.0};
}

// Alpha from a signed distance function of image coordinates (negative inside).
template <typename Fn>
torch::Tensor alpha_from(const Canvas& canvas, const ShapeSpec& shape, Fn sd) {
  auto alpha = torch::empty({canvas.height(), canvas.width()}, torch::kFloat32);
  float* a = alpha.data_ptr<float>();
  const int64_t w = canvas.width();
  const auto my = static_cast<double>(canvas.origin_y());
  const auto mx = static_cast<double>(canvas.origin_x());
  parallel_items(canvas.height(), 20 * w, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const double y = static_cast<double>(i) - my;
      for (int64_t j = 0; j < w; ++j) {
        a[i * w + j] = coverage(sd(static_cast<double>(j) - mx, y), shape.softness, shape.invert);
      }
    }
  });
  return alpha;
}

double segment_distance(double px, double py, const Point& a, const Point& b) {
  const double dx = b.x - a.x;
  const double dy = b.y - a.y;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0.0 ? ((px - a.x) * dx + (py - a.y) * dy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return std::hypot(px - (a.x + t * dx), py - (a.y + t * dy));
}

// Even-odd fill by scanlines, then exact distances only near the edges (within half the
// softness), so the cost grows with the outline, not with pixels times vertices.
torch::Tensor polygon_alpha(const ShapeSpec& shape, const Canvas& canvas) {
  const auto& pts = shape.points;
  const auto n = static_cast<int64_t>(pts.size());
  const int64_t hc = canvas.height();
  const int64_t wc = canvas.width();
  const auto my = static_cast<double>(canvas.origin_y());
  const auto mx = static_cast<double>(canvas.origin_x());
  const double reach = 0.5 * shape.softness + 1.0;
  auto alpha = torch::empty({hc, wc}, torch::kFloat32);
  float* out = alpha.data_ptr<float>();
  parallel_items(hc, 10 * wc + 10 * n, [&](int64_t b, int64_t e) {
    std::vector<double> xs;
    std::vector<double> dist(static_cast<size_t>(wc));
    for (int64_t i = b; i < e; ++i) {
      const double y = static_cast<double>(i) - my;
      xs.clear();
      std::fill(dist.begin(), dist.end(), std::numeric_limits<double>::infinity());
      for (int64_t k = 0; k < n; ++k) {
        const Point& p = pts[k];
        const Point& q = pts[(k + 1) % n];
        if ((p.y <= y && y < q.y) || (q.y <= y && y < p.y)) {
          xs.push_back(p.x + (y - p.y) * (q.x - p.x) / (q.y - p.y));
        }
        if (y < std::min(p.y, q.y) - reach || y > std::max(p.y, q.y) + reach) continue;
        const auto j0 =
            std::max<int64_t>(0, static_cast<int64_t>(std::floor(std::min(p.x, q.x) - reach + mx)));
        const auto j1 = std::min<int64_t>(
            wc - 1, static_cast<int64_t>(std::ceil(std::max(p.x, q.x) + reach + mx)));
        for (int64_t j = j0; j <= j1; ++j) {
          dist[j] = std::min(dist[j], segment_distance(static_cast<double>(j) - mx, y, p, q));
        }
      }
      std::sort(xs.begin(), xs.end());
      float* row = out + i * wc;
      size_t next = 0;
      bool inside = false;
      for (int64_t j = 0; j < wc; ++j) {
        const double x = static_cast<double>(j) - mx;
        while (next < xs.size() && xs[next] <= x) {
          inside = !inside;
          ++next;
        }
        const double d = std::isfinite(dist[j]) ? dist[j] : 1e30;
        row[j] = coverage(inside ? -d : d, shape.softness, shape.invert);
      }
    }
  });
  return alpha;
}

}  // namespace

torch::Tensor render_alpha(const ShapeSpec& shape, const Canvas& canvas) {
  const Point c = shape.center.value_or(default_center(canvas));
  const double ca = std::cos(shape.angle * kPi / 180.0);
  const double sa = std::sin(shape.angle * kPi / 180.0);
  switch (shape.kind) {
    case ShapeKind::kFull:
      return torch::ones({canvas.height(), canvas.width()}, torch::kFloat32);
    case ShapeKind::kRectangle: {
      const double hw = 0.5 * shape.width;
      const double hh = 0.5 * shape.height;
      return alpha_from(canvas, shape, [&](double x, double y) {
        const double u = std::abs((x - c.x) * ca + (y - c.y) * sa) - hw;
        const double v = std::abs(-(x - c.x) * sa + (y - c.y) * ca) - hh;
        const double outside = std::hypot(std::max(u, 0.0), std::max(v, 0.0));
        return outside + std::min(std::max(u, v), 0.0);
      });
    }
    case ShapeKind::kDisk:
      return alpha_from(canvas, shape, [&](double x, double y) {
        return std::hypot(x - c.x, y - c.y) - shape.radius;
      });
    case ShapeKind::kPolygon:
      return polygon_alpha(shape, canvas);
    case ShapeKind::kBars: {
      // Bar k is centred at distance k * period from `center` along the normal (cos, sin).
      const double kmin = shape.count > 0 ? -std::floor((shape.count - 1) / 2.0) : -1e300;
      const double kmax = shape.count > 0 ? kmin + static_cast<double>(shape.count - 1) : 1e300;
      return alpha_from(canvas, shape, [&](double x, double y) {
        const double s = (x - c.x) * ca + (y - c.y) * sa;
        const double k = std::clamp(std::round(s / shape.period), kmin, kmax);
        return std::abs(s - k * shape.period) - 0.5 * shape.width;
      });
    }
  }
  return torch::ones({canvas.height(), canvas.width()}, torch::kFloat32);
}

}  // namespace lfnet::scene::detail

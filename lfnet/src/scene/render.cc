// The layered light-field renderer: per-layer canvases shifted into every view and composited
// back to front with premultiplied alpha, plus the effects a scene names.
#include "lfnet/scene/render.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <array>
#include <cmath>
#include <memory>
#include <vector>

#include "lfnet/core/constants.h"
#include "lfnet/core/error.h"
#include "raster.h"
#include "rng.h"

namespace lfnet::scene {
namespace {

using detail::Canvas;

// The angular grid: view (u, v) sits (u - uc, v - vc) view steps from the centre.
struct Grid {
  int64_t rows = 0;
  int64_t cols = 0;
  double uc = 0.0;
  double vc = 0.0;
  double du(int64_t u) const { return static_cast<double>(u) - uc; }
  double dv(int64_t v) const { return static_cast<double>(v) - vc; }
  double max_offset() const { return std::max(uc, vc); }
};

// Catmull-Rom (Keys, a = -0.5) weights of the taps at -1, 0, 1, 2 for fraction t: interpolating,
// so t = 0 gives exactly (0, 1, 0, 0).
std::array<float, 4> keys_weights(double t) {
  const double t2 = t * t;
  const double t3 = t2 * t;
  return {
      static_cast<float>(-0.5 * t3 + t2 - 0.5 * t), static_cast<float>(1.5 * t3 - 2.5 * t2 + 1.0),
      static_cast<float>(-1.5 * t3 + 2.0 * t2 + 0.5 * t), static_cast<float>(0.5 * t3 - 0.5 * t2)};
}

// A constant shift along one axis: output index i reads source index i + base + {-1..2}.
struct Shift {
  int64_t base = 0;
  std::array<float, 4> w{};
  bool integer = true;  // the fraction is 0: a pure copy of source index i + base
};

Shift make_shift(double offset) {
  Shift s;
  const double fl = std::floor(offset);
  s.base = static_cast<int64_t>(fl);
  const double t = offset - fl;
  s.integer = t == 0.0;
  s.w = keys_weights(t);
  return s;
}

// The disparity plane of a layer: d(x, y) = d0 + g . ((x, y) - c), c the image centre.
struct Plane {
  double d0 = 0.0;
  double gx = 0.0;
  double gy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  double at(double x, double y) const { return d0 + gx * (x - cx) + gy * (y - cy); }
};

Plane layer_plane(const LayerSpec& layer, const SceneSpec& spec) {
  return Plane{layer.disparity, layer.disparity_gradient.x, layer.disparity_gradient.y,
               (spec.width - 1) / 2.0, (spec.height - 1) / 2.0};
}

// Margin of a layer's canvas: its largest shift, the cubic taps and the blur radius.
int64_t layer_margin(const Plane& plane, const SceneSpec& spec, const Grid& grid,
                     int64_t blur_radius) {
  const double half_w = (spec.width - 1) / 2.0;
  const double half_h = (spec.height - 1) / 2.0;
  const double slope = std::abs(plane.gx) + std::abs(plane.gy);
  double dmax = std::abs(plane.d0) + std::abs(plane.gx) * half_w + std::abs(plane.gy) * half_h;
  // A slanted layer's source points lie up to one shift outside the image, where |d| is larger.
  const double outside = dmax * grid.max_offset();
  dmax += slope * (outside + 1.0);
  return static_cast<int64_t>(std::ceil(dmax * grid.max_offset())) + 3 + blur_radius;
}

// Separable Gaussian blur of each (H, W) plane of `planes` (K, H, W), replicating the border.
void gaussian_blur(torch::Tensor& planes, double sigma) {
  const auto radius = static_cast<int64_t>(std::ceil(3.0 * sigma));
  if (radius == 0) return;
  std::vector<float> w(static_cast<size_t>(2 * radius + 1));
  double total = 0.0;
  for (int64_t t = -radius; t <= radius; ++t) {
    const double g = std::exp(-0.5 * static_cast<double>(t * t) / (sigma * sigma));
    w[t + radius] = static_cast<float>(g);
    total += g;
  }
  for (auto& x : w) x = static_cast<float>(x / total);
  const int64_t k = planes.size(0);
  const int64_t h = planes.size(1);
  const int64_t wd = planes.size(2);
  auto tmp = torch::empty_like(planes);
  float* src = planes.data_ptr<float>();
  float* mid = tmp.data_ptr<float>();
  detail::parallel_items(k * h, wd * (2 * radius + 1), [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const float* in = src + r * wd;
      float* out = mid + r * wd;
      for (int64_t x = 0; x < wd; ++x) {
        float acc = 0.0f;
        for (int64_t t = -radius; t <= radius; ++t) {
          acc += w[t + radius] * in[std::clamp<int64_t>(x + t, 0, wd - 1)];
        }
        out[x] = acc;
      }
    }
  });
  detail::parallel_items(k * h, wd * (2 * radius + 1), [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const int64_t plane = r / h;
      const int64_t y = r % h;
      float* out = src + r * wd;
      std::fill(out, out + wd, 0.0f);
      for (int64_t t = -radius; t <= radius; ++t) {
        const float* in = mid + (plane * h + std::clamp<int64_t>(y + t, 0, h - 1)) * wd;
        const float wt = w[t + radius];
        for (int64_t x = 0; x < wd; ++x) out[x] += wt * in[x];
      }
    }
  });
}

// Where the output light field lives and how one layer's view row is blended into it.
struct Target {
  float* data = nullptr;  // (C, U, V, H, W)
  int64_t channels = 0;
  Grid grid;
  int64_t height = 0;
  int64_t width = 0;
  float* row(int64_t c, int64_t u, int64_t v, int64_t y) const {
    return data + (((c * grid.rows + u) * grid.cols + v) * height + y) * width;
  }
};

// A layer's specular highlights: Gaussian spots, each with its centre and gain in every view.
struct Highlights {
  struct Spot {
    double x = 0.0;
    double y = 0.0;
    double gain = 0.0;
  };
  std::vector<std::vector<Spot>> per_view;  // empty: no highlights
  double sigma = 1.0;
  std::array<float, 3> color{1.0f, 1.0f, 1.0f};

  // Adds the spots of view `view` on row y, columns [x0, x1), into `row`; false if none reach.
  bool fill_row(int64_t view, int64_t y, int64_t x0, int64_t x1, float* row) const {
    if (per_view.empty()) return false;
    const double reach = 4.0 * sigma;
    const double k = -0.5 / (sigma * sigma);
    bool any = false;
    for (const Spot& s : per_view[view]) {
      const double dy = static_cast<double>(y) - s.y;
      if (std::abs(dy) > reach || s.gain <= 0.0) continue;
      const auto b = std::max<int64_t>(x0, static_cast<int64_t>(std::floor(s.x - reach)));
      const auto e = std::min<int64_t>(x1, static_cast<int64_t>(std::ceil(s.x + reach)) + 1);
      if (b >= e) continue;
      if (!any) std::fill(row + x0, row + x1, 0.0f);
      any = true;
      const double gy = s.gain * std::exp(k * dy * dy);
      for (int64_t x = b; x < e; ++x) {
        const double dx = static_cast<double>(x) - s.x;
        row[x] += static_cast<float>(gy * std::exp(k * dx * dx));
      }
    }
    return any;
  }
};

// The canvas rows [i0, i1] and columns [j0, j1] outside which a layer's alpha is zero: the
// layer leaves the views unchanged there, exactly (o = 0 + (1 - 0) o), so that work is skipped.
struct Box {
  int64_t i0 = 0;
  int64_t i1 = -1;
  int64_t j0 = 0;
  int64_t j1 = -1;
  bool empty() const { return i1 < i0 || j1 < j0; }
};

Box support(const torch::Tensor& alpha) {
  const int64_t h = alpha.size(0);
  const int64_t w = alpha.size(1);
  const float* a = alpha.data_ptr<float>();
  std::vector<int64_t> first(static_cast<size_t>(h), w);
  std::vector<int64_t> last(static_cast<size_t>(h), -1);
  detail::parallel_items(h, w, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const float* row = a + i * w;
      int64_t j = 0;
      while (j < w && !(row[j] > 0.0f)) ++j;
      if (j == w) continue;
      first[i] = j;
      int64_t k = w - 1;
      while (!(row[k] > 0.0f)) --k;
      last[i] = k;
    }
  });
  Box box{h, -1, w, -1};
  for (int64_t i = 0; i < h; ++i) {
    if (last[i] < 0) continue;
    box.i0 = std::min(box.i0, i);
    box.i1 = i;
    box.j0 = std::min(box.j0, first[i]);
    box.j1 = std::max(box.j1, last[i]);
  }
  return box;
}

// "Over" for columns [x0, x1) of one row: `planes` holds the layer's premultiplied colour rows
// then its alpha row, each `t.width` long, already resampled into view (u, v). Alpha is clipped
// to [0, 1]; colour is not, so that rendering stays linear in colour (a grey scene is the luma
// of the colour one) and only the finished light field is clipped.
void blend_row(const Target& t, int64_t u, int64_t v, int64_t y, const float* planes,
               const Highlights& hl, int64_t x0, int64_t x1) {
  const int64_t w = t.width;
  const float* alpha = planes + t.channels * w;
  thread_local std::vector<float> light_row;
  light_row.resize(static_cast<size_t>(w));
  const float* spot =
      hl.fill_row(u * t.grid.cols + v, y, x0, x1, light_row.data()) ? light_row.data() : nullptr;
  for (int64_t c = 0; c < t.channels; ++c) {
    float* o = t.row(c, u, v, y);
    const float* p = planes + c * w;
    const float light = hl.color[c];
    if (spot == nullptr) {
      for (int64_t x = x0; x < x1; ++x) {
        const float a = std::min(std::max(alpha[x], 0.0f), 1.0f);
        o[x] = p[x] + (1.0f - a) * o[x];
      }
    } else {
      for (int64_t x = x0; x < x1; ++x) {
        const float a = std::min(std::max(alpha[x], 0.0f), 1.0f);
        o[x] = p[x] + a * spot[x] * light + (1.0f - a) * o[x];
      }
    }
  }
}

// The output range [lo, hi) whose taps (source index i + base + {-1..2}) reach [s0, s1].
std::pair<int64_t, int64_t> reach(const Shift& s, int64_t s0, int64_t s1, int64_t n) {
  return {std::max<int64_t>(0, s0 - s.base - 2), std::min<int64_t>(n, s1 - s.base + 2)};
}

// A fronto-parallel layer: separable shifts, first along x once per view column, then along y
// fused with compositing. Only the views' pixels that the layer's support reaches are touched.
void composite_fronto(const torch::Tensor& planes, const Canvas& canvas, double d, const Box& box,
                      const Target& t, const Highlights& hl) {
  if (box.empty()) return;
  const Grid& g = t.grid;
  const int64_t k = planes.size(0);  // channels + alpha
  const int64_t hc = canvas.height();
  const int64_t wc = canvas.width();
  const int64_t w = t.width;
  const float* src = planes.data_ptr<float>();
  std::vector<Shift> sx(static_cast<size_t>(g.cols));
  std::vector<Shift> sy(static_cast<size_t>(g.rows));
  const auto m = static_cast<double>(canvas.margin);
  for (int64_t v = 0; v < g.cols; ++v) sx[v] = make_shift(m - d * g.dv(v));
  for (int64_t u = 0; u < g.rows; ++u) sy[u] = make_shift(m - d * g.du(u));

  // Rows the vertical taps can read: the support and 3 rows either side (zeros, but read).
  const int64_t r0 = std::max<int64_t>(0, box.i0 - 3);
  const int64_t r1 = std::min<int64_t>(hc, box.i1 + 4);
  const int64_t nr = r1 - r0;
  std::unique_ptr<float[]> hx(new float[static_cast<size_t>(g.cols * k * hc * w)]);
  detail::parallel_items(g.cols * k * nr, 4 * w, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const int64_t v = r / (k * nr);
      const int64_t plane = (r / nr) % k;
      const int64_t row = r0 + r % nr;
      const Shift& s = sx[v];
      const auto [x0, x1] = reach(s, box.j0, box.j1, w);
      if (x1 <= x0) continue;
      const float* in = src + (plane * hc + row) * wc + s.base;
      float* out = hx.get() + ((v * k + plane) * hc + row) * w;
      if (s.integer) {
        std::copy(in + x0, in + x1, out + x0);
        continue;
      }
      const float w0 = s.w[0], w1 = s.w[1], w2 = s.w[2], w3 = s.w[3];
      for (int64_t x = x0; x < x1; ++x) {
        out[x] = w0 * in[x - 1] + w1 * in[x] + w2 * in[x + 1] + w3 * in[x + 2];
      }
    }
  });

  detail::parallel_items(g.rows * g.cols * t.height, (4 * k + 3 * t.channels) * w,
                         [&](int64_t b, int64_t e) {
                           std::vector<float> rows(static_cast<size_t>(k * w));
                           for (int64_t r = b; r < e; ++r) {
                             const int64_t view = r / t.height;
                             const int64_t y = r % t.height;
                             const int64_t u = view / g.cols;
                             const int64_t v = view % g.cols;
                             const Shift& s = sy[u];
                             const auto [y0, y1] = reach(s, box.i0, box.i1, t.height);
                             if (y < y0 || y >= y1) continue;
                             const auto [x0, x1] = reach(sx[v], box.j0, box.j1, w);
                             if (x1 <= x0) continue;
                             const float* base = hx.get() + v * k * hc * w;
                             for (int64_t plane = 0; plane < k; ++plane) {
                               const float* q1 = base + (plane * hc + y + s.base) * w;
                               float* o = rows.data() + plane * w;
                               if (s.integer) {
                                 std::copy(q1 + x0, q1 + x1, o + x0);
                                 continue;
                               }
                               const float* q0 = q1 - w;
                               const float* q2 = q1 + w;
                               const float* q3 = q2 + w;
                               const float w0 = s.w[0], w1 = s.w[1], w2 = s.w[2], w3 = s.w[3];
                               for (int64_t x = x0; x < x1; ++x)
                                 o[x] = w0 * q0[x] + w1 * q1[x] + w2 * q2[x] + w3 * q3[x];
                             }
                             blend_row(t, u, v, y, rows.data(), hl, x0, x1);
                           }
                         });
}

// A slanted layer: every view is an affine warp of the canvas, sampled with 2D Catmull-Rom.
// View point q shows the plane point p with q = p + d(p) s, s = (v - vc, u - uc), so
// p - c = (I - s g^T / (1 + g . s)) (q - c - d0 s).
// Four floats, one pixel's premultiplied colour and alpha (grey: value, alpha, 0, 0).
typedef float Float4 __attribute__((vector_size(16)));

void composite_slanted(const torch::Tensor& planes, const Canvas& canvas, const Plane& plane,
                       const Box& box, const Target& t, const Highlights& hl) {
  if (box.empty()) return;
  const Grid& g = t.grid;
  const int64_t k = planes.size(0);
  const int64_t hc = canvas.height();
  const int64_t wc = canvas.width();
  const int64_t w = t.width;
  // Interleaved (Hc, Wc, 4), so that each tap reads a pixel's values in one vector.
  auto interleaved = torch::zeros({hc, wc, 4}, torch::kFloat32);
  interleaved.slice(2, 0, k).copy_(planes.permute({1, 2, 0}));
  const auto* src = reinterpret_cast<const Float4*>(interleaved.data_ptr<float>());
  const auto m = static_cast<double>(canvas.margin);
  detail::parallel_items(g.rows * g.cols * t.height, 100 * w, [&](int64_t b, int64_t e) {
    std::vector<float> colour(static_cast<size_t>(k * w));
    for (int64_t r = b; r < e; ++r) {
      const int64_t view = r / t.height;
      const int64_t y = r % t.height;
      const int64_t u = view / g.cols;
      const int64_t v = view % g.cols;
      const double sxv = g.dv(v);
      const double syv = g.du(u);
      const double den = 1.0 + plane.gx * sxv + plane.gy * syv;
      const double a00 = 1.0 - sxv * plane.gx / den;
      const double a01 = -sxv * plane.gy / den;
      const double a10 = -syv * plane.gx / den;
      const double a11 = 1.0 - syv * plane.gy / den;
      // The support's corners mapped into this view (q = p + d(p) s is affine), plus the taps.
      double qx0 = 1e300, qx1 = -1e300, qy0 = 1e300, qy1 = -1e300;
      for (const int64_t ci : {box.i0, box.i1}) {
        for (const int64_t cj : {box.j0, box.j1}) {
          const double px = static_cast<double>(cj) - m;
          const double py = static_cast<double>(ci) - m;
          const double dp = plane.at(px, py);
          qx0 = std::min(qx0, px + dp * sxv);
          qx1 = std::max(qx1, px + dp * sxv);
          qy0 = std::min(qy0, py + dp * syv);
          qy1 = std::max(qy1, py + dp * syv);
        }
      }
      if (static_cast<double>(y) < qy0 - 3.0 || static_cast<double>(y) > qy1 + 3.0) continue;
      const auto x_begin = std::max<int64_t>(0, static_cast<int64_t>(std::floor(qx0 - 3.0)));
      const auto x_end = std::min<int64_t>(w, static_cast<int64_t>(std::ceil(qx1 + 3.0)) + 1);
      if (x_end <= x_begin) continue;
      const double ry = static_cast<double>(y) - plane.cy - plane.d0 * syv;
      // p(x) = p(0) + x (a00, a10): affine along the row.
      const double rx0 = -plane.cx - plane.d0 * sxv;
      const double px0 = plane.cx + a00 * rx0 + a01 * ry + m;
      const double py0 = plane.cy + a10 * rx0 + a11 * ry + m;
      for (int64_t x = x_begin; x < x_end; ++x) {
        const double px = px0 + a00 * static_cast<double>(x);
        const double py = py0 + a10 * static_cast<double>(x);
        const double fx = std::floor(px);
        const double fy = std::floor(py);
        const auto wx = keys_weights(px - fx);
        const auto wy = keys_weights(py - fy);
        const auto ix = std::clamp<int64_t>(static_cast<int64_t>(fx), 1, wc - 3);
        const auto iy = std::clamp<int64_t>(static_cast<int64_t>(fy), 1, hc - 3);
        const Float4* p = src + (iy - 1) * wc + ix - 1;
        Float4 acc = {0.0f, 0.0f, 0.0f, 0.0f};
        for (int dy = 0; dy < 4; ++dy) {
          const Float4* row = p + dy * wc;
          acc += wy[dy] * (wx[0] * row[0] + wx[1] * row[1] + wx[2] * row[2] + wx[3] * row[3]);
        }
        for (int64_t c = 0; c < k; ++c) colour[c * w + x] = acc[c];
      }
      blend_row(t, u, v, y, colour.data(), hl, x_begin, x_end);
    }
  });
}

// Each spot sits at a seeded point of the layer's own surface (alpha >= 0.5 in the centre view),
// peaks in a seeded view and moves with the layer's disparity plus the offset.
Highlights specular_spots(const SpecularSpec& spec, const LayerSpec& layer, const Plane& plane,
                          const torch::Tensor& alpha, uint64_t seed, const Grid& grid) {
  Highlights hl;
  hl.sigma = spec.sigma;
  const int64_t width = alpha.size(1);
  const auto surface = (alpha >= 0.5f).contiguous();
  const Box box = support(surface.to(torch::kFloat32));
  if (box.empty()) return hl;
  const auto* on = surface.data_ptr<bool>();
  hl.per_view.resize(static_cast<size_t>(grid.rows * grid.cols));
  detail::Rng rng(seed);
  for (int64_t i = 0; i < spec.count; ++i) {
    double px = 0.0;
    double py = 0.0;
    for (int attempt = 0; attempt < 64; ++attempt) {
      px = rng.uniform(static_cast<double>(box.j0), static_cast<double>(box.j1));
      py = rng.uniform(static_cast<double>(box.i0), static_cast<double>(box.i1));
      if (on[std::lround(py) * width + std::lround(px)]) break;
    }
    const double pu = rng.uniform(0.0, static_cast<double>(grid.rows - 1));
    const double pv = rng.uniform(0.0, static_cast<double>(grid.cols - 1));
    const double d = plane.at(px, py) + spec.disparity_offset;
    for (int64_t u = 0; u < grid.rows; ++u) {
      for (int64_t v = 0; v < grid.cols; ++v) {
        const double du = static_cast<double>(u) - pu;
        const double dv = static_cast<double>(v) - pv;
        const double gain = spec.strength * layer.gloss *
                            std::exp(-(du * du + dv * dv) / (2.0 * spec.lobe * spec.lobe));
        hl.per_view[u * grid.cols + v].push_back({px + d * grid.dv(v), py + d * grid.du(u), gain});
      }
    }
  }
  return hl;
}

// Multiplies every view by its vignetting factor.
void apply_vignetting(const VignettingSpec& spec, const Target& t) {
  const Grid& g = t.grid;
  const double half_w = 0.5 * static_cast<double>(t.width);
  const double half_h = 0.5 * static_cast<double>(t.height);
  const double radius = std::hypot(half_w, half_h);
  detail::parallel_items(
      g.rows * g.cols * t.height, (12 + t.channels) * t.width, [&](int64_t b, int64_t e) {
        std::vector<float> factor(static_cast<size_t>(t.width));
        for (int64_t r = b; r < e; ++r) {
          const int64_t view = r / t.height;
          const int64_t y = r % t.height;
          const int64_t u = view / g.cols;
          const int64_t v = view % g.cols;
          // Normalised view offsets in [-1, 1]; rho is 1 at the corner views.
          const double nu = g.uc > 0 ? g.du(u) / g.uc : 0.0;
          const double nv = g.vc > 0 ? g.dv(v) / g.vc : 0.0;
          const double rho2 = 0.5 * (nu * nu + nv * nv);
          const double angular = 1.0 - spec.angular * rho2;
          const double cx = (static_cast<double>(t.width) - 1.0) / 2.0 + spec.shift * nv * half_w;
          const double cy = (static_cast<double>(t.height) - 1.0) / 2.0 + spec.shift * nu * half_h;
          const double dy = static_cast<double>(y) - cy;
          const double half_power = 0.5 * spec.power;
          for (int64_t x = 0; x < t.width; ++x) {
            const double dx = static_cast<double>(x) - cx;
            const double r2 = (dx * dx + dy * dy) / (radius * radius);
            const double falloff = half_power == 1.0 ? r2 : std::pow(r2, half_power);
            factor[x] =
                static_cast<float>(std::clamp(angular * (1.0 - spec.strength * falloff), 0.0, 1.0));
          }
          for (int64_t c = 0; c < t.channels; ++c) {
            float* o = t.row(c, u, v, y);
            for (int64_t x = 0; x < t.width; ++x) o[x] *= factor[x];
          }
        }
      });
}

// Writes colour * alpha (the texture window over `box`) and alpha into `planes` (C + 1, Hc, Wc).
void premultiply(const torch::Tensor& colour, const torch::Tensor& alpha, const Box& box,
                 torch::Tensor& planes) {
  const int64_t channels = colour.size(0);
  const int64_t bh = box.i1 - box.i0 + 1;
  const int64_t bw = box.j1 - box.j0 + 1;
  const int64_t hc = planes.size(1);
  const int64_t wc = planes.size(2);
  const float* col = colour.data_ptr<float>();
  const float* a = alpha.data_ptr<float>();
  float* out = planes.data_ptr<float>();
  detail::parallel_items(bh, (channels + 1) * bw, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const float* arow = a + (box.i0 + r) * wc + box.j0;
      for (int64_t c = 0; c < channels; ++c) {
        const float* src = col + (c * bh + r) * bw;
        float* dst = out + (c * hc + box.i0 + r) * wc + box.j0;
        for (int64_t j = 0; j < bw; ++j) dst[j] = src[j] * arow[j];
      }
      std::copy(arow, arow + bw, out + (channels * hc + box.i0 + r) * wc + box.j0);
    }
  });
}

// The true disparity of the centre view: the nearest layer whose (unblurred) alpha covers at
// least half the pixel; pixels no layer covers keep the backmost layer's plane.
void update_disparity(torch::Tensor& disparity, const torch::Tensor& alpha, const Canvas& canvas,
                      const Plane& plane, bool backmost) {
  const int64_t h = canvas.image_height;
  const int64_t w = canvas.image_width;
  if (!disparity.defined()) disparity = torch::empty({h, w}, torch::kFloat32);
  float* d = disparity.data_ptr<float>();
  const float* a = alpha.data_ptr<float>();
  const int64_t wc = canvas.width();
  detail::parallel_items(h, 4 * w, [&](int64_t b, int64_t e) {
    for (int64_t y = b; y < e; ++y) {
      const float* arow = a + (y + canvas.margin) * wc + canvas.margin;
      for (int64_t x = 0; x < w; ++x) {
        if (backmost || arow[x] >= 0.5f) {
          d[y * w + x] =
              static_cast<float>(plane.at(static_cast<double>(x), static_cast<double>(y)));
        }
      }
    }
  });
}

// A layer on its canvas, ready to composite.
struct LayerCanvas {
  Canvas canvas;
  torch::Tensor alpha;   // (Hc, Wc) before defocus: coverage for the disparity map and highlights
  torch::Tensor planes;  // (C + 1, Hc, Wc): premultiplied colour, then alpha
  Box box;               // outside it the planes are zero
};

double defocus_sigma(const SceneSpec& spec, double disparity) {
  if (!spec.defocus) return 0.0;
  return std::min(spec.defocus->max_sigma,
                  spec.defocus->blur * std::abs(disparity - spec.defocus->focus_disparity));
}

int64_t blur_radius(double sigma) { return static_cast<int64_t>(std::ceil(3.0 * sigma)); }

// Layer `li` at its spec pose on a canvas of `margin`: premultiplied colour and alpha, unblurred.
// The texture is generated only where the shape covers the canvas (textures depend on position
// alone, so a window gives the same).
LayerCanvas rasterise(const SceneSpec& spec, size_t li, int64_t margin,
                      const RenderOptions& options) {
  const LayerSpec& layer = spec.layers[li];
  const int64_t channels = spec.color ? 3 : 1;
  LayerCanvas lc;
  lc.canvas = Canvas{spec.height, spec.width, margin};
  const Canvas& canvas = lc.canvas;
  lc.alpha = detail::render_alpha(layer.shape, canvas);
  if (layer.opacity != 1.0) lc.alpha.mul_(layer.opacity);
  lc.box = support(lc.alpha);
  lc.planes = torch::zeros({channels + 1, canvas.height(), canvas.width()}, torch::kFloat32);
  const Box& box = lc.box;
  if (!box.empty()) {
    const Canvas window = canvas.window(box.i0, box.j0, box.i1 - box.i0 + 1, box.j1 - box.j0 + 1);
    const torch::Tensor colour = detail::render_texture(
        layer.texture, window, spec.color, detail::derive_seed(spec.seed, li), options);
    premultiply(colour, lc.alpha, box, lc.planes);
  }
  return lc;
}

// Blurs the planes by `sigma`, growing the box by the blur radius: outside the box everything is
// zero, so this is the same as blurring the whole canvas.
void defocus(LayerCanvas& lc, double sigma) {
  if (!(sigma > 0.0) || lc.box.empty()) return;
  const int64_t radius = blur_radius(sigma);
  Box& box = lc.box;
  box = Box{std::max<int64_t>(0, box.i0 - radius),
            std::min<int64_t>(lc.canvas.height() - 1, box.i1 + radius),
            std::max<int64_t>(0, box.j0 - radius),
            std::min<int64_t>(lc.canvas.width() - 1, box.j1 + radius)};
  auto region = lc.planes.slice(1, box.i0, box.i1 + 1).slice(2, box.j0, box.j1 + 1);
  auto blurred = region.contiguous();
  gaussian_blur(blurred, sigma);
  region.copy_(blurred);
}

// Layer `li` of `spec` (whose plane is `plane`) over the target, and into the disparity map.
void composite_layer(const SceneSpec& spec, size_t li, const Plane& plane, const LayerCanvas& lc,
                     const Target& target, torch::Tensor& disparity) {
  const LayerSpec& layer = spec.layers[li];
  const Canvas& canvas = lc.canvas;
  update_disparity(disparity, lc.alpha, canvas, plane, li == 0);
  Highlights hl;
  if (spec.specular && layer.gloss > 0.0 && spec.specular->count > 0 &&
      spec.specular->strength > 0.0) {
    const auto inner = lc.alpha.slice(0, canvas.margin, canvas.margin + spec.height)
                           .slice(1, canvas.margin, canvas.margin + spec.width);
    const uint64_t seed =
        detail::derive_seed(spec.specular->seed.value_or(spec.seed), 0x5370ULL + li);
    hl = specular_spots(*spec.specular, layer, plane, inner, seed, target.grid);
    const Rgb& c = spec.specular->color;
    if (spec.color) {
      hl.color = {static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])};
    } else {
      hl.color[0] = static_cast<float>(detail::luma(c));
    }
  }
  if (plane.gx != 0.0 || plane.gy != 0.0) {
    composite_slanted(lc.planes, canvas, plane, lc.box, target, hl);
  } else {
    composite_fronto(lc.planes, canvas, plane.d0, lc.box, target, hl);
  }
}

std::vector<std::string> effects_of(const SceneSpec& spec, bool motion) {
  std::vector<std::string> run;
  if (spec.layers.size() > 1) run.emplace_back("occlusion");
  if (motion) run.emplace_back("motion");
  if (spec.defocus) run.emplace_back("defocus");
  if (spec.specular) run.emplace_back("specular");
  if (spec.vignetting) run.emplace_back("vignetting");
  return run;
}

// ---- Motion ----------------------------------------------------------------------------------

// An affine map of image points: (x, y) -> (a00 x + a01 y + bx, a10 x + a11 y + by).
struct Affine {
  double a00 = 1.0, a01 = 0.0, a10 = 0.0, a11 = 1.0, bx = 0.0, by = 0.0;
  Point operator()(double x, double y) const {
    return Point{a00 * x + a01 * y + bx, a10 * x + a11 * y + by};
  }
  // A pure translation by whole pixels: resampling is an exact copy.
  bool integer_shift() const {
    return a00 == 1.0 && a01 == 0.0 && a10 == 0.0 && a11 == 1.0 && bx == std::floor(bx) &&
           by == std::floor(by);
  }
};

// A moving layer in one sub-frame: where its points go (p -> c + tau shift + k R (p - c)) and
// back, and its moved disparity plane.
struct Pose {
  Affine forward;
  Affine inverse;
  double disparity = 0.0;  // at the image centre
  Point gradient;
};

Pose layer_pose(const LayerSpec& layer, const SceneSpec& spec, double tau) {
  const MotionSpec& m = *layer.motion;
  const Point c = motion_center(layer, spec);
  const double angle = m.rotation * tau * kPi / 180.0;
  const double k = std::pow(m.scale, tau);
  const double cs = m.rotation == 0.0 ? 1.0 : std::cos(angle);
  const double sn = m.rotation == 0.0 ? 0.0 : std::sin(angle);
  const double tx = tau * m.shift.x;
  const double ty = tau * m.shift.y;
  Pose pose;
  Affine& f = pose.forward;
  f = Affine{k * cs, -k * sn, k * sn, k * cs, 0.0, 0.0};
  f.bx = c.x + tx - (f.a00 * c.x + f.a01 * c.y);
  f.by = c.y + ty - (f.a10 * c.x + f.a11 * c.y);
  // p = c + R^T (q - c - t) / k.
  Affine& i = pose.inverse;
  i = Affine{cs / k, sn / k, -sn / k, cs / k, 0.0, 0.0};
  i.bx = c.x - (i.a00 * (c.x + tx) + i.a01 * (c.y + ty));
  i.by = c.y - (i.a10 * (c.x + tx) + i.a11 * (c.y + ty));
  // d'(q) = d(inverse(q)) + tau dd: still a plane, of gradient R g / k.
  const Point& g = layer.disparity_gradient;
  pose.gradient = Point{(cs * g.x - sn * g.y) / k, (sn * g.x + cs * g.y) / k};
  const Point centre{(spec.width - 1) / 2.0, (spec.height - 1) / 2.0};
  const Point back = pose.inverse(centre.x, centre.y);
  pose.disparity =
      layer.disparity + g.x * (back.x - centre.x) + g.y * (back.y - centre.y) + tau * m.disparity;
  return pose;
}

// The margin a canvas needs so that `inverse` maps every point of a canvas of `margin` (plus
// the cubic taps) inside it.
int64_t source_margin(const Affine& inverse, const SceneSpec& spec, int64_t margin) {
  const double w = static_cast<double>(spec.width - 1);
  const double h = static_cast<double>(spec.height - 1);
  const auto m = static_cast<double>(margin);
  double need = 0.0;
  for (const double x : {-m, w + m}) {
    for (const double y : {-m, h + m}) {
      const Point p = inverse(x, y);
      need = std::max({need, -p.x, p.x - w, -p.y, p.y - h});
    }
  }
  return static_cast<int64_t>(std::ceil(need)) + 4;
}

// `from` resampled onto canvas `to`: an output point q shows the source point inverse(q).
// Integer translations copy; anything else is 2D Catmull-Rom, zero outside the source canvas.
LayerCanvas warp(const LayerCanvas& from, const Canvas& to, const Pose& pose) {
  LayerCanvas out;
  out.canvas = to;
  const int64_t k = from.planes.size(0);
  const int64_t hs = from.canvas.height();
  const int64_t ws = from.canvas.width();
  const int64_t ho = to.height();
  const int64_t wo = to.width();
  out.planes = torch::zeros({k, ho, wo}, torch::kFloat32);
  out.box = Box{0, -1, 0, -1};
  if (from.box.empty()) {
    out.alpha = out.planes[k - 1].clone();
    return out;
  }
  const auto ms = static_cast<double>(from.canvas.margin);
  const auto mo = static_cast<double>(to.margin);
  // The output box: the source box's corners moved, plus the taps.
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const int64_t i : {from.box.i0, from.box.i1}) {
    for (const int64_t j : {from.box.j0, from.box.j1}) {
      const Point q = pose.forward(static_cast<double>(j) - ms, static_cast<double>(i) - ms);
      x0 = std::min(x0, q.x);
      x1 = std::max(x1, q.x);
      y0 = std::min(y0, q.y);
      y1 = std::max(y1, q.y);
    }
  }
  Box& box = out.box;
  box.i0 = std::max<int64_t>(0, static_cast<int64_t>(std::floor(y0 + mo)) - 3);
  box.i1 = std::min<int64_t>(ho - 1, static_cast<int64_t>(std::ceil(y1 + mo)) + 3);
  box.j0 = std::max<int64_t>(0, static_cast<int64_t>(std::floor(x0 + mo)) - 3);
  box.j1 = std::min<int64_t>(wo - 1, static_cast<int64_t>(std::ceil(x1 + mo)) + 3);
  if (box.empty()) {
    out.alpha = out.planes[k - 1].clone();
    return out;
  }
  const float* src = from.planes.data_ptr<float>();
  float* dst = out.planes.data_ptr<float>();
  const Affine& inv = pose.inverse;
  if (inv.integer_shift()) {
    // Output canvas (i, j) reads source canvas (i + di, j + dj).
    const auto di = static_cast<int64_t>(inv.by + ms - mo);
    const auto dj = static_cast<int64_t>(inv.bx + ms - mo);
    const int64_t i0 = std::max(box.i0, -di);
    const int64_t i1 = std::min(box.i1, hs - 1 - di);
    const int64_t j0 = std::max(box.j0, -dj);
    const int64_t j1 = std::min(box.j1, ws - 1 - dj);
    if (i0 <= i1 && j0 <= j1) {
      out.planes.slice(1, i0, i1 + 1)
          .slice(2, j0, j1 + 1)
          .copy_(from.planes.slice(1, i0 + di, i1 + di + 1).slice(2, j0 + dj, j1 + dj + 1));
    }
  } else {
    const int64_t bw = box.j1 - box.j0 + 1;
    detail::parallel_items(box.i1 - box.i0 + 1, 40 * k * bw, [&](int64_t b, int64_t e) {
      for (int64_t r = b; r < e; ++r) {
        const int64_t i = box.i0 + r;
        for (int64_t j = box.j0; j <= box.j1; ++j) {
          const Point p = inv(static_cast<double>(j) - mo, static_cast<double>(i) - mo);
          const double px = p.x + ms;
          const double py = p.y + ms;
          const double fx = std::floor(px);
          const double fy = std::floor(py);
          if (fx < -2.0 || fy < -2.0 || fx > static_cast<double>(ws) ||
              fy > static_cast<double>(hs)) {
            continue;
          }
          const auto ix = static_cast<int64_t>(fx);
          const auto iy = static_cast<int64_t>(fy);
          const auto wx = keys_weights(px - fx);
          const auto wy = keys_weights(py - fy);
          for (int64_t c = 0; c < k; ++c) {
            const float* plane = src + c * hs * ws;
            float acc = 0.0f;
            for (int64_t dy = 0; dy < 4; ++dy) {
              const int64_t y = iy - 1 + dy;
              if (y < 0 || y >= hs) continue;
              const float* row = plane + y * ws;
              float racc = 0.0f;
              for (int64_t dx = 0; dx < 4; ++dx) {
                const int64_t x = ix - 1 + dx;
                if (x >= 0 && x < ws) racc += wx[dx] * row[x];
              }
              acc += wy[dy] * racc;
            }
            dst[(c * ho + i) * wo + j] = acc;
          }
        }
      }
    });
  }
  out.alpha = out.planes[k - 1].clone();
  return out;
}

}  // namespace

RenderResult render_scene(const SceneSpec& spec, const RenderOptions& options) {
  spec.validate();
  Grid grid{spec.rows, spec.cols, (spec.rows - 1) / 2.0, (spec.cols - 1) / 2.0};
  const int64_t channels = spec.color ? 3 : 1;
  auto out =
      torch::zeros({channels, spec.rows, spec.cols, spec.height, spec.width}, torch::kFloat32);
  Target target{out.data_ptr<float>(), channels, grid, spec.height, spec.width};

  RenderResult result;
  result.effects_run = effects_of(spec, false);
  torch::Tensor disparity;
  for (size_t li = 0; li < spec.layers.size(); ++li) {
    const Plane plane = layer_plane(spec.layers[li], spec);
    const double sigma = defocus_sigma(spec, spec.layers[li].disparity);
    LayerCanvas lc =
        rasterise(spec, li, layer_margin(plane, spec, grid, blur_radius(sigma)), options);
    defocus(lc, sigma);
    composite_layer(spec, li, plane, lc, target, disparity);
  }
  if (spec.vignetting) apply_vignetting(*spec.vignetting, target);
  out.clamp_(0.0, 1.0);

  result.light_field = LightField(out);
  result.disparity = disparity;
  return result;
}

SequenceResult render_sequence(const SceneSpec& spec, int64_t frames,
                               const RenderOptions& options) {
  LFNET_CHECK_AS(ConfigError, frames >= 1 && frames <= kMaxFrames, "frames must lie in [1, ",
                 kMaxFrames, "], got ", frames);
  spec.validate();
  SequenceResult result;
  if (frames == 1 || !spec.moves()) {
    // Still: one render, filmed T times.
    const RenderResult still = render_scene(spec, options);
    const auto& lf = still.light_field.data();
    std::vector<int64_t> shape{frames};
    shape.insert(shape.end(), lf.sizes().begin(), lf.sizes().end());
    result.light_fields = LightFieldSequence(lf.unsqueeze(0).expand(shape));
    result.disparity =
        still.disparity.unsqueeze(0).expand({frames, spec.height, spec.width}).contiguous();
    result.effects_run = still.effects_run;
    return result;
  }

  // Each sub-frame's pose of every moving layer, checked against the scene's limits.
  const size_t n = spec.layers.size();
  std::vector<std::vector<Pose>> poses(n);
  std::vector<SceneSpec> posed(static_cast<size_t>(frames), spec);
  for (int64_t t = 0; t < frames; ++t) {
    const double tau = static_cast<double>(t) - (static_cast<double>(frames) - 1.0) / 2.0;
    SceneSpec& s = posed[t];
    for (size_t li = 0; li < n; ++li) {
      const LayerSpec& layer = spec.layers[li];
      if (!layer.moves()) continue;
      const std::string path = "$.layers[" + std::to_string(li) + "].motion";
      const double k = std::pow(layer.motion->scale, tau);
      LFNET_CHECK_AS(ConfigError, k >= 0.25 && k <= 4.0, path, ".scale: scales the layer by ", k,
                     " in sub-frame ", t, " of ", frames, "; the limit is 4 either way");
      LFNET_CHECK_AS(ConfigError,
                     std::abs(tau * layer.motion->shift.x) <= 1024.0 &&
                         std::abs(tau * layer.motion->shift.y) <= 1024.0,
                     path, ".shift: moves the layer more than 1024 px by sub-frame ", t, " of ",
                     frames);
      poses[li].push_back(layer_pose(layer, spec, tau));
      s.layers[li].disparity = poses[li].back().disparity;
      s.layers[li].disparity_gradient = poses[li].back().gradient;
    }
    try {
      s.validate();
    } catch (const ConfigError& e) {
      throw ConfigError("sub-frame " + std::to_string(t) + " of " + std::to_string(frames) + ": " +
                        e.what());
    }
  }

  Grid grid{spec.rows, spec.cols, (spec.rows - 1) / 2.0, (spec.cols - 1) / 2.0};
  const int64_t channels = spec.color ? 3 : 1;
  // Still layers once, on the canvas render_scene gives them; moving ones once at their spec
  // pose on a canvas that every sub-frame's canvas maps into.
  std::vector<LayerCanvas> canvases(n);
  std::vector<std::vector<int64_t>> margins(n);
  for (size_t li = 0; li < n; ++li) {
    const LayerSpec& layer = spec.layers[li];
    if (!layer.moves()) {
      const Plane plane = layer_plane(layer, spec);
      const double sigma = defocus_sigma(spec, layer.disparity);
      canvases[li] =
          rasterise(spec, li, layer_margin(plane, spec, grid, blur_radius(sigma)), options);
      defocus(canvases[li], sigma);
      continue;
    }
    int64_t source = 0;
    for (int64_t t = 0; t < frames; ++t) {
      const SceneSpec& s = posed[t];
      const Plane plane = layer_plane(s.layers[li], s);
      const int64_t margin =
          layer_margin(plane, s, grid, blur_radius(defocus_sigma(s, s.layers[li].disparity)));
      margins[li].push_back(margin);
      source = std::max(source, source_margin(poses[li][t].inverse, spec, margin));
    }
    canvases[li] = rasterise(spec, li, source, options);
  }

  // The still layers behind every moving one, composited once.
  size_t first_moving = 0;
  while (!spec.layers[first_moving].moves()) ++first_moving;
  auto base =
      torch::zeros({channels, spec.rows, spec.cols, spec.height, spec.width}, torch::kFloat32);
  auto base_disparity = torch::empty({spec.height, spec.width}, torch::kFloat32);
  {
    Target target{base.data_ptr<float>(), channels, grid, spec.height, spec.width};
    for (size_t li = 0; li < first_moving; ++li) {
      composite_layer(spec, li, layer_plane(spec.layers[li], spec), canvases[li], target,
                      base_disparity);
    }
  }

  auto out = torch::empty({frames, channels, spec.rows, spec.cols, spec.height, spec.width},
                          torch::kFloat32);
  auto disparity = torch::empty({frames, spec.height, spec.width}, torch::kFloat32);
  for (int64_t t = 0; t < frames; ++t) {
    const SceneSpec& s = posed[t];
    auto frame = out[t];
    frame.copy_(base);
    torch::Tensor frame_disparity = disparity[t];
    frame_disparity.copy_(base_disparity);
    Target target{frame.data_ptr<float>(), channels, grid, spec.height, spec.width};
    for (size_t li = first_moving; li < n; ++li) {
      const Plane plane = layer_plane(s.layers[li], s);
      if (!spec.layers[li].moves()) {
        composite_layer(s, li, plane, canvases[li], target, frame_disparity);
        continue;
      }
      const Canvas canvas{spec.height, spec.width, margins[li][t]};
      LayerCanvas lc = warp(canvases[li], canvas, poses[li][t]);
      defocus(lc, defocus_sigma(s, s.layers[li].disparity));
      composite_layer(s, li, plane, lc, target, frame_disparity);
    }
    if (spec.vignetting) apply_vignetting(*spec.vignetting, target);
    frame.clamp_(0.0, 1.0);
  }
  result.light_fields = LightFieldSequence(out);
  result.disparity = disparity;
  result.effects_run = effects_of(spec, true);
  return result;
}

}  // namespace lfnet::scene

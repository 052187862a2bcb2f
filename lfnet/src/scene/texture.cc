// Textures as functions of centre-view pixel coordinates: value noise, 1/f^beta fractal noise,
// anti-aliased stripes and checkers, gradients and images.
#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <vector>

#include "lfnet/core/constants.h"
#include "lfnet/core/error.h"
#include "raster.h"
#include "rng.h"

namespace lfnet::scene::detail {
namespace {

// Mean over positions of the sum of squared cubic B-spline weights, 1D: the integral of B^2.
constexpr double kBsplineEnergy1d = 151.0 / 315.0;
constexpr double kBsplineEnergy2d = kBsplineEnergy1d * kBsplineEnergy1d;

std::array<float, 4> bspline_weights(double t) {
  const double t2 = t * t;
  const double t3 = t2 * t;
  return {static_cast<float>((1.0 - t) * (1.0 - t) * (1.0 - t) / 6.0),
          static_cast<float>((3.0 * t3 - 6.0 * t2 + 4.0) / 6.0),
          static_cast<float>((-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0),
          static_cast<float>(t3 / 6.0)};
}

// Lattice index (the cell's left node) and B-spline weights for each of `n` canvas positions.
struct Axis {
  std::vector<int64_t> index;
  std::vector<std::array<float, 4>> weights;
  int64_t lo = 0;  // first lattice node needed
  int64_t hi = 0;  // last lattice node needed
};

Axis lattice_axis(int64_t n, int64_t origin, double spacing, double offset) {
  Axis a;
  a.index.resize(n);
  a.weights.resize(n);
  for (int64_t k = 0; k < n; ++k) {
    const double g = static_cast<double>(k - origin) / spacing + offset;
    const double f = std::floor(g);
    a.index[k] = static_cast<int64_t>(f);
    a.weights[k] = bspline_weights(g - f);
  }
  a.lo = a.index.front() - 1;
  a.hi = a.index.back() + 2;
  return a;
}

// Standard normal CDF.
inline float normal_cdf(float z) { return 0.5f * (1.0f + std::erf(z * 0.70710678f)); }

// Maps a field of unit-variance values through Phi(contrast * z) into [0, 1].
void to_uniform(torch::Tensor& field, double contrast) {
  float* f = field.data_ptr<float>();
  const auto c = static_cast<float>(contrast);
  parallel_items(field.numel(), 20, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) f[i] = normal_cdf(c * f[i]);
  });
}

// Integral of a square wave that is 1 on [0, duty) of each unit period.
inline double square_integral(double s, double duty) {
  const double fl = std::floor(s);
  return fl * duty + std::min(s - fl, duty);
}

// A square wave box-filtered over a footprint of `h` periods: the exact pixel coverage along
// the wave's normal.
inline double square_coverage(double s, double duty, double h) {
  return (square_integral(s + 0.5 * h, duty) - square_integral(s - 0.5 * h, duty)) / h;
}

// Fills t(y, x) over the canvas from a function of image coordinates.
template <typename Fn>
torch::Tensor field_from(const Canvas& canvas, Fn fn) {
  auto field = torch::empty({canvas.height(), canvas.width()}, torch::kFloat32);
  float* f = field.data_ptr<float>();
  const int64_t w = canvas.width();
  const auto my = static_cast<double>(canvas.origin_y());
  const auto mx = static_cast<double>(canvas.origin_x());
  parallel_items(canvas.height(), 20 * w, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const double y = static_cast<double>(i) - my;
      for (int64_t j = 0; j < w; ++j) {
        f[i * w + j] = static_cast<float>(fn(static_cast<double>(j) - mx, y));
      }
    }
  });
  return field;
}

// Maps t in [0, 1] through the colour ramp: (C, Hc, Wc).
torch::Tensor apply_palette(const torch::Tensor& t, const std::vector<Rgb>& colors, bool color) {
  const int64_t channels = color ? 3 : 1;
  std::vector<std::array<float, 3>> ramp;
  for (const auto& c : colors) {
    if (color) {
      ramp.push_back(
          {static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])});
    } else {
      const auto y = static_cast<float>(luma(c));
      ramp.push_back({y, y, y});
    }
  }
  const int64_t n = t.numel();
  auto out = torch::empty({channels, t.size(0), t.size(1)}, torch::kFloat32);
  const float* tp = t.data_ptr<float>();
  float* op = out.data_ptr<float>();
  const auto segments = static_cast<int64_t>(ramp.size()) - 1;
  parallel_items(n, 4 * channels, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      if (segments == 0) {
        for (int64_t c = 0; c < channels; ++c) op[c * n + i] = ramp[0][c];
        continue;
      }
      const float pos = std::clamp(tp[i], 0.0f, 1.0f) * static_cast<float>(segments);
      const int64_t k = std::min<int64_t>(static_cast<int64_t>(pos), segments - 1);
      const float f = pos - static_cast<float>(k);
      for (int64_t c = 0; c < channels; ++c) {
        op[c * n + i] = (1.0f - f) * ramp[k][c] + f * ramp[k + 1][c];
      }
    }
  });
  return out;
}

torch::Tensor noise_field(const TextureSpec& t, const Canvas& canvas, uint64_t seed) {
  auto field = torch::zeros({canvas.height(), canvas.width()}, torch::kFloat32);
  Rng rng(derive_seed(seed, 0x6e6f697365ULL));
  if (t.kind == TextureKind::kNoise) {
    add_value_noise(field, canvas, t.scale, rng.uniform(), rng.uniform(), rng.next(),
                    1.0 / std::sqrt(kBsplineEnergy2d));
  } else {
    // Octaves at halving spacings with amplitude spacing^((beta - 2) / 2): the low-frequency
    // density of an octave is amplitude^2 spacing^2, so the sum has power ~ 1 / f^beta.
    std::vector<double> spacings;
    for (int k = 0;; ++k) {
      const double s = std::ldexp(t.scale, -k);  // t.scale / 2^k: halving is exact
      if (!(s >= 1.0)) break;
      spacings.push_back(s);
    }
    if (spacings.empty()) spacings.push_back(t.scale);
    double energy = 0.0;
    for (double s : spacings) energy += std::pow(s, t.beta - 2.0);
    const double norm = 1.0 / std::sqrt(energy * kBsplineEnergy2d);
    for (double s : spacings) {
      add_value_noise(field, canvas, s, rng.uniform(), rng.uniform(), rng.next(),
                      std::pow(s, 0.5 * (t.beta - 2.0)) * norm);
    }
  }
  to_uniform(field, t.contrast);
  return field;
}

torch::Tensor stripes_field(const TextureSpec& t, const Canvas& canvas) {
  const double ca = std::cos(t.angle * kPi / 180.0);
  const double sa = std::sin(t.angle * kPi / 180.0);
  const double h = 1.0 / t.period;
  const bool sine = t.profile == "sine";
  return field_from(canvas, [&](double x, double y) {
    const double s = (x * ca + y * sa) / t.period + t.phase;
    if (sine) return 0.5 + 0.5 * std::sin(2.0 * kPi * s);
    return square_coverage(s, t.duty, h);
  });
}

torch::Tensor checker_field(const TextureSpec& t, const Canvas& canvas) {
  const double ca = std::cos(t.angle * kPi / 180.0);
  const double sa = std::sin(t.angle * kPi / 180.0);
  const double period = 2.0 * t.size;
  const double h = 1.0 / period;
  return field_from(canvas, [&](double x, double y) {
    const double q1 = 2.0 * square_coverage((x * ca + y * sa) / period, 0.5, h) - 1.0;
    const double q2 = 2.0 * square_coverage((-x * sa + y * ca) / period, 0.5, h) - 1.0;
    return 0.5 - 0.5 * q1 * q2;
  });
}

torch::Tensor gradient_field(const TextureSpec& t, const Canvas& canvas) {
  const double w = static_cast<double>(canvas.image_width - 1);
  const double hgt = static_cast<double>(canvas.image_height - 1);
  const Point c = t.center.value_or(Point{w / 2.0, hgt / 2.0});
  if (t.profile == "radial") {
    const double radius = t.length.value_or(std::max(1.0, 0.5 * std::hypot(w, hgt)));
    return field_from(canvas, [&](double x, double y) {
      return std::min(1.0, std::hypot(x - c.x, y - c.y) / radius);
    });
  }
  const double ca = std::cos(t.angle * kPi / 180.0);
  const double sa = std::sin(t.angle * kPi / 180.0);
  const double length = t.length.value_or(std::max(1.0, std::abs(w * ca) + std::abs(hgt * sa)));
  return field_from(canvas, [&](double x, double y) {
    return std::clamp(0.5 + ((x - c.x) * ca + (y - c.y) * sa) / length, 0.0, 1.0);
  });
}

// Reflects a sample coordinate into [0, n - 1] (mirror about the border pixels' centres).
inline double reflect(double s, int64_t n) {
  if (n == 1) return 0.0;
  const double period = 2.0 * static_cast<double>(n - 1);
  s = std::fmod(std::abs(s), period);
  return s > static_cast<double>(n - 1) ? period - s : s;
}

torch::Tensor image_texture(const TextureSpec& t, const Canvas& canvas, bool color,
                            const RenderOptions& options) {
  if (!options.image_loader) {
    throw ConfigError("image texture '" + t.path +
                      "' needs an image loader (lfnet render supplies one; library callers set "
                      "RenderOptions::image_loader)");
  }
  std::filesystem::path file(t.path);
  if (file.is_relative() && !options.base_dir.empty())
    file = std::filesystem::path(options.base_dir) / file;
  torch::Tensor img = options.image_loader(file.string());
  LFNET_CHECK_AS(
      ConfigError, img.defined() && img.dim() == 3 && img.size(0) >= 1 && img.size(0) <= 4,
      "image texture ", file.string(), ": the loader must give (C, H, W) with C in 1..4");
  img = img.to(torch::kFloat32).clamp(0.0, 1.0);
  if (img.size(0) == 2 || img.size(0) == 4) img = img.slice(0, 0, img.size(0) - 1);  // drop alpha
  if (color && img.size(0) == 1) img = img.expand({3, img.size(1), img.size(2)});
  if (!color && img.size(0) == 3) {
    img = (img[0] * 0.299 + img[1] * 0.587 + img[2] * 0.114).unsqueeze(0);
  }
  const double out_w = static_cast<double>(canvas.image_width);
  const double out_h = static_cast<double>(canvas.image_height);
  // Shrinking: average integer blocks first, so that bilinear sampling does not alias.
  const double shrink =
      std::min(static_cast<double>(img.size(2)) / out_w, static_cast<double>(img.size(1)) / out_h) /
      t.zoom;
  const auto pool = static_cast<int64_t>(std::floor(shrink));
  if (pool >= 2) img = torch::avg_pool2d(img.unsqueeze(0), pool).squeeze(0);
  img = img.contiguous();
  const int64_t channels = img.size(0);
  const int64_t ih = img.size(1);
  const int64_t iw = img.size(2);
  double sx = static_cast<double>(iw) / out_w;  // source px per image px
  double sy = static_cast<double>(ih) / out_h;
  if (t.fit == "cover") sx = sy = std::min(sx, sy);
  sx /= t.zoom;
  sy /= t.zoom;
  // The source point under the image centre: the middle, moved by `offset` across the part of
  // the source that does not show.
  const double cx = iw / 2.0 + t.offset.x * std::max(0.0, iw - out_w * sx) / 2.0;
  const double cy = ih / 2.0 + t.offset.y * std::max(0.0, ih - out_h * sy) / 2.0;
  auto out = torch::empty({channels, canvas.height(), canvas.width()}, torch::kFloat32);
  const float* src = img.data_ptr<float>();
  float* dst = out.data_ptr<float>();
  const int64_t hc = canvas.height();
  const int64_t wc = canvas.width();
  const auto my = static_cast<double>(canvas.origin_y());
  const auto mx = static_cast<double>(canvas.origin_x());
  parallel_items(hc, 20 * wc * channels, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const double y = static_cast<double>(i) - my;
      const double py = reflect((y + 0.5 - out_h / 2.0) * sy + cy - 0.5, ih);
      const auto y0 = std::min<int64_t>(static_cast<int64_t>(py), ih - 1);
      const int64_t y1 = std::min<int64_t>(y0 + 1, ih - 1);
      const auto fy = static_cast<float>(py - static_cast<double>(y0));
      for (int64_t j = 0; j < wc; ++j) {
        const double x = static_cast<double>(j) - mx;
        const double px = reflect((x + 0.5 - out_w / 2.0) * sx + cx - 0.5, iw);
        const auto x0 = std::min<int64_t>(static_cast<int64_t>(px), iw - 1);
        const int64_t x1 = std::min<int64_t>(x0 + 1, iw - 1);
        const auto fx = static_cast<float>(px - static_cast<double>(x0));
        for (int64_t c = 0; c < channels; ++c) {
          const float* p = src + c * ih * iw;
          const float top = (1 - fx) * p[y0 * iw + x0] + fx * p[y0 * iw + x1];
          const float bot = (1 - fx) * p[y1 * iw + x0] + fx * p[y1 * iw + x1];
          dst[(c * hc + i) * wc + j] = (1 - fy) * top + fy * bot;
        }
      }
    }
  });
  return out;
}

}  // namespace

void add_value_noise(torch::Tensor& field, const Canvas& canvas, double spacing, double offset_x,
                     double offset_y, uint64_t seed, double amplitude) {
  const int64_t hc = canvas.height();
  const int64_t wc = canvas.width();
  const Axis ax = lattice_axis(wc, canvas.origin_x(), spacing, offset_x);
  const Axis ay = lattice_axis(hc, canvas.origin_y(), spacing, offset_y);
  const int64_t lw = ax.hi - ax.lo + 1;
  const int64_t lh = ay.hi - ay.lo + 1;
  // Lattice values, uniform with unit variance, hashed from the node's integer coordinates so
  // that they do not depend on the canvas.
  std::vector<float> lattice(static_cast<size_t>(lh * lw));
  parallel_items(lh, 20 * lw, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const uint64_t row_seed = derive_seed(seed, static_cast<uint64_t>(ay.lo + r));
      for (int64_t c = 0; c < lw; ++c) {
        const double u = unit_double(mix64(row_seed ^ mix64(static_cast<uint64_t>(ax.lo + c))));
        lattice[r * lw + c] = static_cast<float>((2.0 * u - 1.0) * 1.7320508075688772);
      }
    }
  });
  // Along x for every lattice row, then along y.
  std::vector<float> rows(static_cast<size_t>(lh * wc));
  parallel_items(lh, 8 * wc, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const float* g = lattice.data() + r * lw;
      float* o = rows.data() + r * wc;
      for (int64_t j = 0; j < wc; ++j) {
        const int64_t k = ax.index[j] - 1 - ax.lo;
        const auto& w = ax.weights[j];
        o[j] = w[0] * g[k] + w[1] * g[k + 1] + w[2] * g[k + 2] + w[3] * g[k + 3];
      }
    }
  });
  float* f = field.data_ptr<float>();
  const auto amp = static_cast<float>(amplitude);
  parallel_items(hc, 8 * wc, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const int64_t k = ay.index[i] - 1 - ay.lo;
      const auto& w = ay.weights[i];
      const float* r0 = rows.data() + k * wc;
      const float* r1 = r0 + wc;
      const float* r2 = r1 + wc;
      const float* r3 = r2 + wc;
      float* o = f + i * wc;
      for (int64_t j = 0; j < wc; ++j) {
        o[j] += amp * (w[0] * r0[j] + w[1] * r1[j] + w[2] * r2[j] + w[3] * r3[j]);
      }
    }
  });
}

torch::Tensor render_texture(const TextureSpec& texture, const Canvas& canvas, bool color,
                             uint64_t seed, const RenderOptions& options) {
  const uint64_t s = texture.seed.value_or(seed);
  switch (texture.kind) {
    case TextureKind::kConstant:
      return apply_palette(torch::zeros({canvas.height(), canvas.width()}), texture.colors, color);
    case TextureKind::kNoise:
    case TextureKind::kFractal:
      return apply_palette(noise_field(texture, canvas, s), texture.colors, color);
    case TextureKind::kStripes:
      return apply_palette(stripes_field(texture, canvas), texture.colors, color);
    case TextureKind::kChecker:
      return apply_palette(checker_field(texture, canvas), texture.colors, color);
    case TextureKind::kGradient:
      return apply_palette(gradient_field(texture, canvas), texture.colors, color);
    case TextureKind::kImage:
      return image_texture(texture, canvas, color, options);
  }
  throw Error("unknown texture kind");
}

}  // namespace lfnet::scene::detail

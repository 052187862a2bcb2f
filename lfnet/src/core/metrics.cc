#include "lfnet/core/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet {

namespace {
void check_same(const torch::Tensor& a, const torch::Tensor& b) {
  LFNET_CHECK(a.sizes() == b.sizes(), "metric inputs differ in shape: ", a.sizes(), " vs ",
              b.sizes());
}

void check_same_shape(const LightFieldViews& a, const LightFieldViews& b) {
  LFNET_CHECK(a.shape_string() == b.shape_string(),
              "metric inputs differ in shape: ", a.shape_string(), " vs ", b.shape_string());
}

double psnr_from_mse(double mse) {
  if (mse <= 0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(mse);
}

// Separable Gaussian filter of a batch of images (B, H, W), float64, over the pixels whose
// window lies inside the image: (B, H - 2 r, W - 2 r). There it equals what
// scipy.ndimage.gaussian_filter computes (its border mode never reaches them). Each pass is a
// sum of 2 r + 1 shifted, weighted copies: a convolution of so few taps would go through
// im2col and a float64 GEMM, several times slower.
torch::Tensor gaussian_filter_valid(const torch::Tensor& images, double sigma, int64_t radius) {
  std::vector<double> kernel;
  double total = 0;
  for (int64_t i = -radius; i <= radius; ++i) {
    kernel.push_back(std::exp(-0.5 * static_cast<double>(i * i) / (sigma * sigma)));
    total += kernel.back();
  }
  for (auto& k : kernel) k /= total;
  auto pass = [&](const torch::Tensor& x, int64_t dim) {
    const int64_t n = x.size(dim) - 2 * radius;
    auto out = x.narrow(dim, 0, n) * kernel[0];
    for (size_t i = 1; i < kernel.size(); ++i) {
      out.add_(x.narrow(dim, static_cast<int64_t>(i), n), kernel[i]);
    }
    return out;
  };
  return pass(pass(images, 1), 2);
}
}  // namespace

double psnr(const torch::Tensor& estimate, const torch::Tensor& truth) {
  check_same(estimate, truth);
  auto diff = estimate.to(torch::kFloat64) - truth.to(torch::kFloat64);
  return psnr_from_mse(diff.pow(2).mean().item<double>());
}

namespace {
// Rows of a view scored at a time: the float64 copies stay a band high (a 12-megapixel view is
// 48 MB in float32, 96 MB per float64 copy).
constexpr int64_t kScoreBand = 128;
// SSIM's bands are lower, so that its five float64 maps of a band stay near a core's cache:
// the SSIM of 5 x 5 views of 593 x 840 takes 0.47 s in bands of 48 rows, 0.85 s in 128.
constexpr int64_t kSsimBand = 48;

// The mean squared error of each view (U, V) in float64, a band of rows at a time.
torch::Tensor per_view_mse(const LightFieldViews& estimate, const LightFieldViews& truth) {
  check_same_shape(estimate, truth);
  auto mse = torch::empty({truth.rows(), truth.cols()}, torch::kFloat64);
  auto out = mse.accessor<double, 2>();
  const int64_t h = truth.height();
  const auto count = static_cast<double>(truth.channels() * h * truth.width());
  for (int64_t u = 0; u < truth.rows(); ++u) {
    for (int64_t v = 0; v < truth.cols(); ++v) {
      double sum = 0;
      for (int64_t y0 = 0; y0 < h; y0 += kScoreBand) {
        const int64_t y1 = std::min(h, y0 + kScoreBand);
        auto diff = estimate.view_rows(u, v, y0, y1).to(torch::kFloat64) -
                    truth.view_rows(u, v, y0, y1).to(torch::kFloat64);
        sum += diff.pow_(2).sum().item<double>();
      }
      out[u][v] = sum / count;
    }
  }
  return mse;
}
}  // namespace

double psnr(const LightFieldViews& estimate, const LightFieldViews& truth) {
  // Every view has as many pixels, so the mean of the views' errors is the light field's.
  return psnr_from_mse(per_view_mse(estimate, truth).mean().item<double>());
}

torch::Tensor per_view_psnr(const LightFieldViews& estimate, const LightFieldViews& truth) {
  // A view that matches exactly has infinite PSNR, as the whole-field PSNR does.
  return -10.0 * torch::log10(per_view_mse(estimate, truth));
}

namespace {
// SSIM's constants for `options`, and the sum of a band's SSIM map per channel.
struct SsimWindow {
  explicit SsimWindow(const SsimOptions& o) : options(o) {
    radius = std::lround(o.truncate * o.sigma);
    const int64_t win = 2 * radius + 1;
    const double np = static_cast<double>(win * win);
    cov_norm = o.sample_covariance ? np / (np - 1.0) : 1.0;
    c1 = std::pow(o.k1 * o.data_range, 2);
    c2 = std::pow(o.k2 * o.data_range, 2);
  }

  void check(int64_t h, int64_t w) const {
    const int64_t win = 2 * radius + 1;
    LFNET_CHECK(h >= win && w >= win, "SSIM needs images of at least ", win, "x", win,
                " pixels, got ", h, "x", w);
  }

  // The sum over the SSIM map of the rows whose windows the band (C, rows + 2 radius, W) holds
  // whole, per channel (C) float64.
  torch::Tensor band_sum(const torch::Tensor& x, const torch::Tensor& y) const {
    const int64_t c = x.size(0);
    auto xb = x.to(torch::kFloat64);
    auto yb = y.to(torch::kFloat64);
    auto stack = torch::cat({xb, yb, xb * xb, yb * yb, xb * yb}, 0);  // (5C, rows + 2r, W)
    auto f = gaussian_filter_valid(stack, options.sigma, radius).split(c, 0);
    const auto &ux = f[0], &uy = f[1];
    auto vx = cov_norm * (f[2] - ux * ux);
    auto vy = cov_norm * (f[3] - uy * uy);
    auto vxy = cov_norm * (f[4] - ux * uy);
    auto s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
    return s.sum({1, 2});
  }

  // Mean per channel over the interior pixels, then over channels, as scikit-image does.
  double mean(const torch::Tensor& total, int64_t h, int64_t w) const {
    const auto interior = static_cast<double>((h - 2 * radius) * (w - 2 * radius));
    return (total / interior).mean().item<double>();
  }

  SsimOptions options;
  int64_t radius = 0;
  double cov_norm = 1, c1 = 0, c2 = 0;
};
}  // namespace

double ssim_image(const torch::Tensor& a, const torch::Tensor& b, const SsimOptions& options) {
  check_same(a, b);
  LFNET_CHECK(a.dim() == 2 || a.dim() == 3, "SSIM takes (H, W) or (C, H, W) images");
  const auto x = a.dim() == 2 ? a.unsqueeze(0) : a;
  const auto y = b.dim() == 2 ? b.unsqueeze(0) : b;
  const SsimWindow window(options);
  const int64_t c = x.size(0), h = x.size(1), w = x.size(2), r = window.radius;
  window.check(h, w);
  // Scikit-image averages the SSIM map over the pixels at least `radius` from the border, so
  // only windows inside the image count: rows are taken a band at a time (with the radius
  // above and below), which keeps the float64 maps a band high.
  auto total = torch::zeros({c}, torch::kFloat64);
  for (int64_t y0 = r; y0 < h - r; y0 += kSsimBand) {
    const int64_t rows = std::min(kSsimBand, h - r - y0);
    total += window.band_sum(x.narrow(1, y0 - r, rows + 2 * r), y.narrow(1, y0 - r, rows + 2 * r));
  }
  return window.mean(total, h, w);
}

double ssim(const LightFieldViews& estimate, const LightFieldViews& truth,
            const SsimOptions& options) {
  check_same_shape(estimate, truth);
  const SsimWindow window(options);
  const int64_t h = truth.height(), w = truth.width(), r = window.radius;
  window.check(h, w);
  // As ssim_image, each view a band of rows at a time (no view is decoded whole).
  double total = 0;
  for (int64_t u = 0; u < truth.rows(); ++u) {
    for (int64_t v = 0; v < truth.cols(); ++v) {
      auto sum = torch::zeros({truth.channels()}, torch::kFloat64);
      for (int64_t y0 = r; y0 < h - r; y0 += kSsimBand) {
        const int64_t y1 = std::min(h - r, y0 + kSsimBand);
        sum += window.band_sum(estimate.view_rows(u, v, y0 - r, y1 + r),
                               truth.view_rows(u, v, y0 - r, y1 + r));
      }
      total += window.mean(sum, h, w);
    }
  }
  return total / static_cast<double>(truth.rows() * truth.cols());
}

}  // namespace lfnet

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
// The mean squared error of each view (U, V) in float64, one view at a time: float64 copies of a
// whole light field would take four times its memory.
torch::Tensor per_view_mse(const LightField& estimate, const LightField& truth) {
  check_same(estimate.data(), truth.data());
  auto mse = torch::empty({truth.rows(), truth.cols()}, torch::kFloat64);
  auto out = mse.accessor<double, 2>();
  for (int64_t u = 0; u < truth.rows(); ++u) {
    for (int64_t v = 0; v < truth.cols(); ++v) {
      auto diff = estimate.view(u, v).to(torch::kFloat64) - truth.view(u, v).to(torch::kFloat64);
      out[u][v] = diff.pow_(2).mean().item<double>();
    }
  }
  return mse;
}
}  // namespace

double psnr(const LightField& estimate, const LightField& truth) {
  // Every view has as many pixels, so the mean of the views' errors is the light field's.
  return psnr_from_mse(per_view_mse(estimate, truth).mean().item<double>());
}

torch::Tensor per_view_psnr(const LightField& estimate, const LightField& truth) {
  // A view that matches exactly has infinite PSNR, as the whole-field PSNR does.
  return -10.0 * torch::log10(per_view_mse(estimate, truth));
}

double ssim_image(const torch::Tensor& a, const torch::Tensor& b, const SsimOptions& options) {
  check_same(a, b);
  LFNET_CHECK(a.dim() == 2 || a.dim() == 3, "SSIM takes (H, W) or (C, H, W) images");
  const auto x = a.dim() == 2 ? a.unsqueeze(0) : a;
  const auto y = b.dim() == 2 ? b.unsqueeze(0) : b;
  const int64_t radius = std::lround(options.truncate * options.sigma);
  const int64_t win = 2 * radius + 1;
  LFNET_CHECK(x.size(1) >= win && x.size(2) >= win, "SSIM needs images of at least ", win, "x", win,
              " pixels, got ", x.size(1), "x", x.size(2));
  const double np = static_cast<double>(win * win);
  const double cov_norm = options.sample_covariance ? np / (np - 1.0) : 1.0;
  const double c1 = std::pow(options.k1 * options.data_range, 2);
  const double c2 = std::pow(options.k2 * options.data_range, 2);

  // Scikit-image averages the SSIM map over the pixels at least `radius` from the border, so
  // only windows inside the image count: rows are taken a band at a time (with the radius
  // above and below), which keeps the float64 maps a band high.
  const int64_t c = x.size(0), h = x.size(1), w = x.size(2);
  constexpr int64_t kBand = 128;
  auto total = torch::zeros({c}, torch::kFloat64);
  for (int64_t y0 = radius; y0 < h - radius; y0 += kBand) {
    const int64_t rows = std::min(kBand, h - radius - y0);
    auto xb = x.narrow(1, y0 - radius, rows + 2 * radius).to(torch::kFloat64);
    auto yb = y.narrow(1, y0 - radius, rows + 2 * radius).to(torch::kFloat64);
    auto stack = torch::cat({xb, yb, xb * xb, yb * yb, xb * yb}, 0);  // (5C, rows + 2r, W)
    auto f = gaussian_filter_valid(stack, options.sigma, radius).split(c, 0);
    const auto &ux = f[0], &uy = f[1];
    auto vx = cov_norm * (f[2] - ux * ux);
    auto vy = cov_norm * (f[3] - uy * uy);
    auto vxy = cov_norm * (f[4] - ux * uy);
    auto s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
    total += s.sum({1, 2});
  }
  // Mean per channel, then over channels, as scikit-image does with channel_axis.
  const auto interior = static_cast<double>((h - 2 * radius) * (w - 2 * radius));
  return (total / interior).mean().item<double>();
}

double ssim(const LightField& estimate, const LightField& truth, const SsimOptions& options) {
  check_same(estimate.data(), truth.data());
  double total = 0;
  for (int64_t u = 0; u < truth.rows(); ++u) {
    for (int64_t v = 0; v < truth.cols(); ++v) {
      total += ssim_image(estimate.view(u, v), truth.view(u, v), options);
    }
  }
  return total / static_cast<double>(truth.rows() * truth.cols());
}

}  // namespace lfnet

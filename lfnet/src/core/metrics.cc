#include "lfnet/core/metrics.h"

#include <cmath>
#include <limits>

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

// Indices of a symmetric ("reflect" in scipy.ndimage) extension of n samples by r each side.
torch::Tensor symmetric_indices(int64_t n, int64_t r) {
  std::vector<int64_t> idx;
  idx.reserve(n + 2 * r);
  for (int64_t i = -r; i < n + r; ++i) {
    int64_t m = ((i % (2 * n)) + 2 * n) % (2 * n);
    idx.push_back(m < n ? m : 2 * n - 1 - m);
  }
  return torch::tensor(idx);
}

// Separable Gaussian filter of a batch of images (B, H, W), float64, as
// scipy.ndimage.gaussian_filter(mode="reflect") computes it.
torch::Tensor gaussian_filter(const torch::Tensor& images, double sigma, int64_t radius) {
  auto x = torch::arange(-radius, radius + 1, torch::kFloat64);
  auto kernel = torch::exp(-0.5 * x * x / (sigma * sigma));
  kernel = kernel / kernel.sum();
  const int64_t k = 2 * radius + 1;
  auto img = images.unsqueeze(1);  // (B, 1, H, W)
  img = img.index_select(2, symmetric_indices(images.size(1), radius));
  img = torch::conv2d(img, kernel.view({1, 1, k, 1}));
  img = img.index_select(3, symmetric_indices(images.size(2), radius));
  img = torch::conv2d(img, kernel.view({1, 1, 1, k}));
  return img.squeeze(1);
}
}  // namespace

double psnr(const torch::Tensor& estimate, const torch::Tensor& truth) {
  check_same(estimate, truth);
  auto diff = estimate.to(torch::kFloat64) - truth.to(torch::kFloat64);
  return psnr_from_mse(diff.pow(2).mean().item<double>());
}

double psnr(const LightField& estimate, const LightField& truth) {
  return psnr(estimate.data(), truth.data());
}

torch::Tensor per_view_psnr(const LightField& estimate, const LightField& truth) {
  check_same(estimate.data(), truth.data());
  auto diff = estimate.data().to(torch::kFloat64) - truth.data().to(torch::kFloat64);
  auto mse = diff.pow(2).mean({axis::kC, axis::kH, axis::kW});
  // A view that matches exactly has infinite PSNR, as the whole-field PSNR does.
  return -10.0 * torch::log10(mse);
}

double ssim_image(const torch::Tensor& a, const torch::Tensor& b, const SsimOptions& options) {
  check_same(a, b);
  LFNET_CHECK(a.dim() == 2 || a.dim() == 3, "SSIM takes (H, W) or (C, H, W) images");
  auto x = (a.dim() == 2 ? a.unsqueeze(0) : a).to(torch::kFloat64);
  auto y = (b.dim() == 2 ? b.unsqueeze(0) : b).to(torch::kFloat64);
  const auto radius = static_cast<int64_t>(options.truncate * options.sigma + 0.5);
  const int64_t win = 2 * radius + 1;
  LFNET_CHECK(x.size(1) >= win && x.size(2) >= win, "SSIM needs images of at least ", win, "x", win,
              " pixels, got ", x.size(1), "x", x.size(2));
  const double np = static_cast<double>(win * win);
  const double cov_norm = options.sample_covariance ? np / (np - 1.0) : 1.0;
  const double c1 = std::pow(options.k1 * options.data_range, 2);
  const double c2 = std::pow(options.k2 * options.data_range, 2);

  const int64_t c = x.size(0);
  auto stack = torch::cat({x, y, x * x, y * y, x * y}, 0);  // (5C, H, W)
  auto f = gaussian_filter(stack, options.sigma, radius).split(c, 0);
  const auto &ux = f[0], &uy = f[1];
  auto vx = cov_norm * (f[2] - ux * ux);
  auto vy = cov_norm * (f[3] - uy * uy);
  auto vxy = cov_norm * (f[4] - ux * uy);
  auto s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
  auto cropped = s.slice(1, radius, s.size(1) - radius).slice(2, radius, s.size(2) - radius);
  // Mean per channel, then over channels, as scikit-image does with channel_axis.
  return cropped.mean({1, 2}).mean().item<double>();
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

#include "lfnet/cv/opencv.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <opencv2/core.hpp>
#include <opencv2/photo.hpp>

#include <cmath>
#include <mutex>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/recon/denoise.h"

namespace lfnet::cv {

void OpenCvNlmOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, h > 0 && std::isfinite(h), "h: must be > 0, got ", h);
  LFNET_CHECK_AS(ConfigError, patch >= 1 && patch <= 35 && patch % 2 == 1,
                 "patch: must be odd, 1..35, got ", patch);
  LFNET_CHECK_AS(ConfigError, search >= 1 && search <= 101 && search % 2 == 1,
                 "search: must be odd, 1..101, got ", search);
}

torch::Tensor opencv_nlm(const torch::Tensor& views, double sigma, const OpenCvNlmOptions& o) {
  LFNET_CHECK_AS(ConfigError, views.dim() == 3, "opencv-nlm: expected views (C, H, W), got ",
                 views.sizes());
  LFNET_CHECK_AS(ConfigError, sigma >= 0 && std::isfinite(sigma),
                 "opencv-nlm: sigma must be finite and >= 0, got ", sigma);
  o.validate();
  if (sigma == 0) return views;
  torch::NoGradGuard no_grad;
  ::cv::setNumThreads(at::get_num_threads());
  // 16-bit views: OpenCV's non-local means takes 8- or 16-bit images; 16 bits keep the
  // quantisation (1 / 65535) far below any noise it is asked to remove.
  const auto quantised =
      (views.to(torch::kFloat32).clamp(0.0, 1.0) * 65535.0).round().to(torch::kInt32).contiguous();
  const int64_t c = views.size(0);
  const int rows = static_cast<int>(views.size(1)), cols = static_cast<int>(views.size(2));
  auto out = torch::empty({c, views.size(1), views.size(2)}, torch::kFloat32);
  const std::vector<float> h = {static_cast<float>(o.h * sigma * 65535.0)};
  for (int64_t i = 0; i < c; ++i) {
    const auto view = quantised[i];  // a row of a contiguous tensor: contiguous
    ::cv::Mat src(rows, cols, CV_16U);
    const int32_t* in = view.data_ptr<int32_t>();
    for (int64_t k = 0; k < static_cast<int64_t>(rows) * cols; ++k) {
      src.ptr<uint16_t>()[k] = static_cast<uint16_t>(in[k]);
    }
    ::cv::Mat dst;
    ::cv::fastNlMeansDenoising(src, dst, h, static_cast<int>(o.patch), static_cast<int>(o.search),
                               ::cv::NORM_L1);
    float* result = out[i].data_ptr<float>();
    for (int64_t k = 0; k < static_cast<int64_t>(rows) * cols; ++k) {
      result[k] = static_cast<float>(dst.ptr<uint16_t>()[k]) / 65535.0F;
    }
  }
  return out.to(views.scalar_type());
}

namespace {

class OpenCvNlmDenoiser : public recon::DenoiserWithOptions<OpenCvNlmOptions> {
 public:
  std::string name() const override { return "opencv-nlm"; }
  std::string summary() const override {
    return "OpenCV's non-local means (fastNlMeansDenoising), one 16-bit view at a time, "
           "strength h times the views' noise sigma";
  }

 protected:
  torch::Tensor run(const torch::Tensor& views, double sigma,
                    const OpenCvNlmOptions& options) const override {
    return opencv_nlm(views, sigma, options);
  }
};

}  // namespace

void register_opencv() {
  static std::once_flag once;
  std::call_once(once, [] { recon::register_denoiser(std::make_unique<OpenCvNlmDenoiser>()); });
}

}  // namespace lfnet::cv

// optics::demosaic against OpenCV's bilinear Bayer demosaicing (an independent implementation).
#include <catch2/catch.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <torch/torch.h>

#include "lfnet/optics/cfa.h"

TEST_CASE("bilinear demosaicing is OpenCV's inside the image", "[cv][cfa]") {
  // OpenCV names a Bayer pattern by the colours of the second row's second and third pixels.
  const std::pair<const char*, int> patterns[] = {{"RGGB", cv::COLOR_BayerBG2RGB},
                                                  {"BGGR", cv::COLOR_BayerRG2RGB},
                                                  {"GRBG", cv::COLOR_BayerGB2RGB},
                                                  {"GBRG", cv::COLOR_BayerGR2RGB}};
  torch::manual_seed(11);
  const int64_t h = 24, w = 30;
  const auto raw = torch::randint(0, 65536, {h, w}, torch::kInt32).contiguous();
  for (const auto& [name, code] : patterns) {
    INFO(name);
    cv::Mat bayer;
    cv::Mat(static_cast<int>(h), static_cast<int>(w), CV_32SC1, raw.data_ptr())
        .convertTo(bayer, CV_16U);
    cv::Mat rgb, rgb64;
    cv::demosaicing(bayer, rgb, code);
    REQUIRE(rgb.type() == CV_16UC3);
    rgb.convertTo(rgb64, CV_64F);
    const auto reference =
        torch::from_blob(rgb64.data, {h, w, 3}, torch::kFloat64).permute({2, 0, 1}).clone();
    const auto ours = lfnet::optics::demosaic(raw.to(torch::kFloat64),
                                              lfnet::optics::ColourFilterArray::bayer(name));
    // OpenCV rounds to integers; its borders are its own.
    const auto inner = [](const torch::Tensor& t) { return t.slice(1, 1, -1).slice(2, 1, -1); };
    CHECK((inner(ours) - inner(reference)).abs().max().item<double>() <= 1.0);
  }
}

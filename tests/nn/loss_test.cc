#include "lfnet/nn/loss.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::nn::LossOptions;
using lfnet::nn::ReconstructionLoss;

TEST_CASE("view weights reproduce the paper's 5 x 5 table", "[nn][loss]") {
  const double r2 = std::sqrt(2.0), r3 = std::sqrt(3.0), r5 = std::sqrt(5.0);
  auto paper = torch::tensor({r5,  2.0, r3,  2.0, r5,   //
                              2.0, r3,  r2,  r3,  2.0,  //
                              r3,  r2,  1.0, r2,  r3,   //
                              2.0, r3,  r2,  r3,  2.0,  //
                              r5,  2.0, r3,  2.0, r5},
                             torch::kFloat64)
                   .view({5, 5});
  auto w = lfnet::nn::view_weights(5, 5);
  REQUIRE(w.scalar_type() == torch::kFloat32);
  CHECK(torch::equal(w, paper.to(torch::kFloat32)));
}

TEST_CASE("view weights generalise to other angular sizes", "[nn][loss]") {
  auto w3 = lfnet::nn::view_weights(3, 3);
  CHECK(w3[1][1].item<double>() == 1.0);
  CHECK(w3[0][1].item<double>() == Approx(std::sqrt(2.0)));
  CHECK(w3[0][0].item<double>() == Approx(std::sqrt(3.0)));
  // Even sizes: the four central views weigh 1, the corners sqrt(1 + 2 + 2).
  auto w6 = lfnet::nn::view_weights(6, 6);
  CHECK(w6[2][3].item<double>() == 1.0);
  CHECK(w6[0][0].item<double>() == Approx(std::sqrt(5.0)));
  CHECK(w6[0][5].item<double>() == Approx(std::sqrt(5.0)));
  auto w17 = lfnet::nn::view_weights(1, 7);
  CHECK(w17[0][3].item<double>() == 1.0);
  CHECK(w17[0][0].item<double>() == Approx(2.0));
}

TEST_CASE("weighted L2 of a one-hot error is W(u, v)", "[nn][loss]") {
  LossOptions sum_options;
  sum_options.reduction = lfnet::nn::LossReduction::kSum;
  ReconstructionLoss sum_loss(sum_options, 5, 5);
  ReconstructionLoss mean_loss(LossOptions{}, 5, 5);
  auto weights = lfnet::nn::view_weights(5, 5);
  auto target = torch::rand({1, 1, 5, 5, 9, 9});
  for (auto uv : std::vector<std::pair<int, int>>{{0, 0}, {2, 2}, {1, 2}, {4, 3}, {3, 3}}) {
    INFO(uv.first << ", " << uv.second);
    auto pred = target.clone();
    pred[0][0][uv.first][uv.second][4][7] += 1.0;
    const double w = weights[uv.first][uv.second].item<double>();
    CHECK(sum_loss(pred, target).item<double>() == Approx(w).epsilon(1e-6));
    CHECK(mean_loss(pred, target).item<double>() == Approx(w / 2025).epsilon(1e-6));
    // An error of 0.5 counts 0.25 W.
    pred[0][0][uv.first][uv.second][4][7] -= 0.5;
    CHECK(sum_loss(pred, target).item<double>() == Approx(0.25 * w).epsilon(1e-5));
  }
}

TEST_CASE("plain L2 and L1 match hand computation", "[nn][loss]") {
  auto target = torch::zeros({2, 1, 3, 3, 2, 2});
  auto pred = target.clone();
  pred[0][0][0][0][0][0] = 0.5;  // corner view: the weight must not apply
  pred[1][0][1][2][1][1] = -2.0;
  LossOptions l2;
  l2.name = lfnet::nn::LossKind::kL2;
  LossOptions l1;
  l1.name = lfnet::nn::LossKind::kL1;
  LossOptions l1_sum = l1;
  l1_sum.reduction = lfnet::nn::LossReduction::kSum;
  const double n = 2 * 9 * 4;
  CHECK(ReconstructionLoss(l2, 3, 3)(pred, target).item<double>() == Approx((0.25 + 4.0) / n));
  CHECK(ReconstructionLoss(l1, 3, 3)(pred, target).item<double>() == Approx(2.5 / n));
  CHECK(ReconstructionLoss(l1_sum, 3, 3)(pred, target).item<double>() == Approx(2.5 / 2));
  // Weighted L2 on the same error: 0.25 sqrt3 (corner) + 4 sqrt2 (edge centre), per element.
  CHECK(ReconstructionLoss(LossOptions{}, 3, 3)(pred, target).item<double>() ==
        Approx((0.25 * std::sqrt(3.0) + 4.0 * std::sqrt(2.0)) / n));
}

TEST_CASE("the weighted loss has the gradient 2 W (l_hat - l) / n", "[nn][loss]") {
  auto target = torch::rand({2, 1, 5, 5, 3, 3});
  auto pred = torch::rand({2, 1, 5, 5, 3, 3}).requires_grad_(true);
  ReconstructionLoss loss(LossOptions{}, 5, 5);
  loss(pred, target).backward();
  auto want = 2 * lfnet::nn::view_weights(5, 5).view({5, 5, 1, 1}) * (pred.detach() - target) /
              static_cast<double>(pred.numel());
  lfnet::test::require_close(pred.grad(), want, 1e-7, 1e-5);
}

TEST_CASE("loss options are strict and name the bad field", "[nn][loss]") {
  CHECK(LossOptions::from_json(nlohmann::json::parse(R"({"name": "l1"})")).name ==
        lfnet::nn::LossKind::kL1);
  CHECK_THROWS_WITH(
      LossOptions::from_json(nlohmann::json::parse(R"({"name": "ssim"})"), "$.train.loss"),
      Catch::Contains("$.train.loss.name") && Catch::Contains("weighted_l2, l2, l1"));
  CHECK_THROWS_WITH(LossOptions::from_json(nlohmann::json::parse(R"({"reduce": "sum"})")),
                    Catch::Contains("$.reduce"));
  ReconstructionLoss loss(LossOptions{}, 5, 5);
  CHECK_THROWS_WITH(loss(torch::zeros({1, 1, 3, 3, 9, 9}), torch::zeros({1, 1, 3, 3, 9, 9})),
                    Catch::Contains("5, 5"));
}

TEST_CASE("noise_scale weighs each patch by s / (s + sigma)", "[nn][loss]") {
  auto target = torch::zeros({2, 1, 3, 3, 2, 2});
  auto pred = target.clone();
  pred[0][0][1][1][0][0] = 1.0;  // patch 0: one unit error
  pred[1][0][1][1][1][1] = 2.0;  // patch 1: an error of 4 when squared
  const auto sigma = torch::tensor({0.0f, 0.3f});
  LossOptions plain;
  plain.name = lfnet::nn::LossKind::kL2;
  LossOptions weighted = plain;
  weighted.noise_scale = 0.1;
  const double n = 2 * 9 * 4;
  // Without a noise_scale, the sigmas change nothing.
  CHECK(ReconstructionLoss(plain, 3, 3)(pred, target, sigma).item<double>() == Approx(5.0 / n));
  // With it, the noiseless patch keeps its weight 1 and the sigma 0.3 patch weighs 0.25.
  CHECK(ReconstructionLoss(weighted, 3, 3)(pred, target, sigma).item<double>() ==
        Approx((1.0 + 4.0 * 0.25) / n));
  // Batches that carry no sigmas (no noise_range) are not weighted.
  CHECK(ReconstructionLoss(weighted, 3, 3)(pred, target).item<double>() == Approx(5.0 / n));
  CHECK_THROWS_WITH(ReconstructionLoss(weighted, 3, 3)(pred, target, torch::zeros({3})),
                    Catch::Contains("3 noise sigmas"));
  CHECK_THROWS_WITH(
      LossOptions::from_json(nlohmann::json::parse(R"({"noise_scale": -1})"), "$.loss"),
      Catch::Contains("$.loss.noise_scale"));
}

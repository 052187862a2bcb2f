#include "lfnet/core/light_field.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::LightField;

TEST_CASE("grey conversion uses Rec. 601 luma", "[core]") {
  auto data = torch::rand({3, 2, 2, 4, 5});
  LightField lf(data);
  auto grey = lf.grey();
  REQUIRE(grey.channels() == 1);
  auto want = 0.299 * data[0] + 0.587 * data[1] + 0.114 * data[2];
  lfnet::test::require_close(grey.data()[0], want, 1e-6);
  // A grey light field stays as it is.
  lfnet::test::require_close(grey.grey().data(), grey.data(), 0.0);
}

TEST_CASE("central windows follow the paper's protocol", "[core]") {
  CHECK(lfnet::central_start(9, 5) == 2);   // views 3..7 (1-based)
  CHECK(lfnet::central_start(8, 5) == 1);   // views 2..6
  CHECK(lfnet::central_start(7, 5) == 1);   // views 2..6
  CHECK(lfnet::central_start(14, 5) == 5);  // views 6..10
  CHECK(lfnet::central_start(5, 5) == 0);

  auto data = torch::arange(9 * 9, torch::kFloat32).view({1, 9, 9, 1, 1}).expand({1, 9, 9, 2, 2});
  LightField lf(data.clone());
  auto c = lf.central(5);
  REQUIRE(c.rows() == 5);
  REQUIRE(c.cols() == 5);
  CHECK(c.data()[0][0][0][0][0].item<float>() == 2 * 9 + 2);
  CHECK(c.data()[0][4][4][1][1].item<float>() == 6 * 9 + 6);
  CHECK_THROWS_AS(lf.window({0, 10}, {0, 5}), lfnet::Error);
}

TEST_CASE("views are parsed as 1-based inclusive ranges", "[core]") {
  auto [u, v] = lfnet::parse_views("3:7,2:6");
  CHECK(u.begin == 2);
  CHECK(u.end == 7);
  CHECK(v.begin == 1);
  CHECK(v.end == 6);
  CHECK_THROWS_AS(lfnet::parse_views("3-7,2:6"), lfnet::ConfigError);
  CHECK_THROWS_AS(lfnet::parse_views("0:4,1:5"), lfnet::ConfigError);
  CHECK_THROWS_AS(lfnet::parse_views("5:4,1:5"), lfnet::ConfigError);
}

TEST_CASE("angular mean is the same in every view", "[core]") {
  LightField lf(torch::rand({1, 3, 3, 4, 4}));
  auto m = lf.angular_mean();
  lfnet::test::require_close(m.view(0, 0), lf.data().mean({1, 2})[0].unsqueeze(0), 1e-6);
  lfnet::test::require_close(m.view(2, 1), m.view(0, 0), 0.0);
}

TEST_CASE("a light field rejects tensors of the wrong rank or channels", "[core]") {
  CHECK_THROWS_AS(LightField(torch::rand({3, 4, 4})), lfnet::Error);
  CHECK_THROWS_AS(LightField(torch::rand({2, 5, 5, 4, 4})), lfnet::Error);
}

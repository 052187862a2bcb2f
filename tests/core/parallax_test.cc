#include "lfnet/core/parallax.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::AngularOrientation;
using lfnet::ParallaxVerdict;

TEST_CASE("the parallax check tells a consistent light field from one with a reversed axis",
          "[core][parallax]") {
  // Disparities of both signs, as in a scene focused in its middle.
  const auto lf = lfnet::test::parallax_light_field(5, 5, 96, 128, 2, -1);
  const auto ok = lfnet::check_parallax(lf);
  INFO(ok.summary());
  CHECK(ok.verdict == ParallaxVerdict::kAgree);
  CHECK(ok.blocks >= 8);
  CHECK(ok.agreement > 0.95);
  CHECK(ok.correlation > 0.9);
  // Reversing either angular axis makes the two parallaxes disagree; reversing both does not.
  for (const char* flip : {"flip-u", "flip-v"}) {
    const auto bad = lfnet::check_parallax(reorient(lf, AngularOrientation::parse(flip, "test")));
    INFO(flip << ": " << bad.summary());
    CHECK(bad.verdict == ParallaxVerdict::kDisagree);
    CHECK(bad.agreement < 0.05);
    CHECK(bad.correlation < -0.9);
  }
  const auto both =
      lfnet::check_parallax(reorient(lf, AngularOrientation::parse("flip-u,flip-v", "t")));
  CHECK(both.verdict == ParallaxVerdict::kAgree);
}

TEST_CASE("the parallax check does not guess without texture or parallax", "[core][parallax]") {
  // No parallax: every view the same.
  const auto still = lfnet::test::parallax_light_field(5, 5, 64, 64, 0, 0);
  CHECK(lfnet::check_parallax(still).verdict == ParallaxVerdict::kUndetermined);
  // No texture.
  lfnet::LightField flat(torch::full({1, 5, 5, 64, 64}, 0.5));
  const auto f = lfnet::check_parallax(flat);
  CHECK(f.verdict == ParallaxVerdict::kUndetermined);
  CHECK(f.blocks == 0);
  // One row of views, or views smaller than a block plus the search margin.
  CHECK(lfnet::check_parallax(lfnet::LightField(torch::rand({1, 1, 5, 64, 64}))).verdict ==
        ParallaxVerdict::kUndetermined);
  CHECK(lfnet::check_parallax(lfnet::LightField(torch::rand({1, 5, 5, 12, 12}))).verdict ==
        ParallaxVerdict::kUndetermined);
}

TEST_CASE("angular reorientations parse, print and move views", "[core][parallax]") {
  const auto o = AngularOrientation::parse("flip-v,transpose", "--orient");
  CHECK(o.transpose);
  CHECK(o.flip_v);
  CHECK_FALSE(o.flip_u);
  CHECK(o.to_string() == "transpose,flip-v");
  CHECK(AngularOrientation::parse("", "x").identity());
  CHECK(AngularOrientation::parse("none", "x").identity());
  CHECK_THROWS_AS(AngularOrientation::parse("flip-x", "--orient"), lfnet::ConfigError);
  CHECK_THROWS_WITH(AngularOrientation::parse("flip-u,", "--orient"), Catch::Contains("--orient"));

  auto data = torch::arange(2 * 3 * 4, torch::kFloat32).view({1, 2, 3, 2, 2});
  lfnet::LightField lf(data);
  // Swap u and v (a 2 x 3 grid becomes 3 x 2), then reverse the new v.
  const auto r = reorient(lf, o);
  REQUIRE(r.rows() == 3);
  REQUIRE(r.cols() == 2);
  for (int64_t u = 0; u < 3; ++u) {
    for (int64_t v = 0; v < 2; ++v) {
      // transpose: t(u, v) = lf(v, u); flip-v on the 3 x 2 grid: r(u, v) = t(u, 1 - v).
      lfnet::test::require_close(r.view(u, v), lf.view(1 - v, u), 0.0);
    }
  }
}

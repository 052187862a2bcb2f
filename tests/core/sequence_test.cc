// LightFieldSequence: frames, the stacked layout of time-coded Phis, and per-frame helpers.
#include "lfnet/core/sequence.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"

using lfnet::LightField;
using lfnet::LightFieldSequence;

TEST_CASE("a sequence stacks its frames along the angular rows and back", "[core][sequence]") {
  torch::manual_seed(1);
  auto data = torch::rand({3, 1, 5, 4, 6, 7});
  LightFieldSequence seq(data);
  CHECK(seq.shape_string() == "3x1x5x4x6x7");
  auto stacked = seq.stacked();
  REQUIRE(stacked.rows() == 15);
  // Row t U + u of the stacked light field is view u of frame t.
  CHECK(torch::equal(stacked.view(2 * 5 + 3, 1), seq.frame(2).view(3, 1)));
  CHECK(torch::equal(stacked.view(0 * 5 + 4, 3), seq.frame(0).view(4, 3)));
  CHECK(torch::equal(LightFieldSequence::unstack(stacked, 3).data(), data));
  CHECK_THROWS(LightFieldSequence::unstack(stacked, 4));
}

TEST_CASE("a sequence is built from frames of one shape", "[core][sequence]") {
  LightField a(torch::rand({3, 9, 9, 8, 8})), b(torch::rand({3, 9, 9, 8, 8}));
  LightFieldSequence seq(std::vector<LightField>{a, b});
  CHECK(seq.frames() == 2);
  CHECK(torch::equal(seq.frame(1).data(), b.data()));
  CHECK(torch::equal(seq.grey().frame(0).data(), a.grey().data()));
  CHECK(torch::equal(seq.central(5).frame(1).data(), b.central(5).data()));
  CHECK(torch::allclose(seq.time_mean().data(), (a.data() + b.data()) / 2));
  LightField c(torch::rand({3, 9, 9, 8, 7}));
  CHECK_THROWS_AS(LightFieldSequence(std::vector<LightField>{a, c}), lfnet::ConfigError);
  CHECK_THROWS_AS(LightFieldSequence(std::vector<LightField>{}), lfnet::ConfigError);
}

TEST_CASE("synthetic motion shifts a still light field whole or walks its views",
          "[core][sequence]") {
  torch::manual_seed(4);
  LightField lf(torch::rand({1, 5, 9, 20, 30}));
  const auto pan = lfnet::synthetic_motion(lf, 4, {2, -1, 0});
  REQUIRE(pan.shape_string() == "4x1x5x9x17x24");
  // Content moves right by 2 and up by 1 per sub-frame: pixel (y, x) of frame t is pixel
  // (y + 1, x - 2) of frame t + 1.
  for (int64_t t = 0; t + 1 < 4; ++t) {
    const auto a = pan.frame(t).data().narrow(3, 1, 16).narrow(4, 0, 22);
    const auto b = pan.frame(t + 1).data().narrow(3, 0, 16).narrow(4, 2, 22);
    CHECK(torch::equal(a, b));
  }
  CHECK_FALSE(torch::equal(pan.frame(0).data(), pan.frame(1).data()));
  // Walking one view a sub-frame: frame t's view column v is the source's column v + t.
  const auto walk = lfnet::synthetic_motion(lf, 3, {0, 0, 1});
  REQUIRE(walk.cols() == 7);
  CHECK(torch::equal(walk.frame(2).view(1, 0), lf.view(1, 2)));
  CHECK(torch::equal(walk.frame(0).view(4, 6), lf.view(4, 6)));
  // Standing still repeats the light field.
  CHECK(torch::equal(lfnet::synthetic_motion(lf, 2, {}).frame(1).data(), lf.data()));
  CHECK_THROWS_AS(lfnet::synthetic_motion(lf, 4, {0, 0, 3}), lfnet::ConfigError);
  CHECK_THROWS_AS(lfnet::synthetic_motion(lf, 4, {11, 0, 0}), lfnet::ConfigError);
}

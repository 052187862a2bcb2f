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

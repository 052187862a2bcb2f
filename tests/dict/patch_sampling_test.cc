#include "lfnet/dict/patch_sampling.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::LightField;
using lfnet::dict::PatchSamplingOptions;
using lfnet::dict::PatchSamplingStats;

namespace {

// A 7 x 7-view light field whose left half is flat and whose right half has a texture that
// makes every patch position distinct.
LightField half_flat(int64_t h, int64_t w) {
  auto data = torch::full({1, 7, 7, h, w}, 0.5f);
  auto right = torch::rand({1, 7, 7, h, w / 2});
  data.narrow(4, w - w / 2, w / 2).copy_(right);
  return LightField(data);
}

// Whether `patch` (flattened (u, v, y, x)) is the central 5 x 5 views of `lf` at some origin.
bool is_patch_of(const torch::Tensor& patch, const LightField& lf, int64_t p) {
  auto c = lf.central(5).data()[0];
  for (int64_t y = 0; y + p <= lf.height(); ++y) {
    for (int64_t x = 0; x + p <= lf.width(); ++x) {
      if (torch::equal(c.narrow(2, y, p).narrow(3, x, p).reshape({-1}), patch)) return true;
    }
  }
  return false;
}

}  // namespace

TEST_CASE("Patch sampling draws real patches and drops flat ones", "[dict][sampling]") {
  torch::manual_seed(73);
  const LightField lf = half_flat(20, 32);
  PatchSamplingOptions o;
  o.count = 40;
  o.seed = 5;
  PatchSamplingStats stats;
  auto patches = lfnet::dict::sample_patches({lf}, o, &stats);
  REQUIRE(patches.sizes() == torch::IntArrayRef({40, 2025}));
  CHECK(patches.scalar_type() == torch::kFloat32);
  CHECK(patches.var(1, /*unbiased=*/false).ge(o.min_variance).all().item<bool>());
  // Half of the positions see only the flat half: many draws were dropped.
  CHECK(stats.dropped > 5);
  CHECK(stats.drawn == 40 + stats.dropped);
  for (int64_t i = 0; i < 5; ++i) CHECK(is_patch_of(patches[i], lf, 9));
  // The same seed gives the same patches; another seed others.
  CHECK(torch::equal(lfnet::dict::sample_patches({lf}, o), patches));
  o.seed = 6;
  CHECK(!torch::equal(lfnet::dict::sample_patches({lf}, o), patches));
  // Without the threshold, flat patches come back too.
  o.min_variance = 0.0;
  o.count = 200;
  auto all = lfnet::dict::sample_patches({lf}, o, &stats);
  CHECK(stats.dropped == 0);
  CHECK(all.var(1, false).lt(1e-12).any().item<bool>());
}

TEST_CASE("Patch sampling covers several light fields, grey or colour", "[dict][sampling]") {
  torch::manual_seed(79);
  const LightField small(torch::rand({3, 5, 5, 9, 9}));    // one patch position
  const LightField large(torch::rand({3, 9, 9, 40, 40}));  // 1024 positions
  PatchSamplingOptions o;
  o.count = 300;
  o.min_variance = 0.0;
  auto grey = lfnet::dict::sample_patches({small, large}, o);
  const auto small_patch = small.grey().data().reshape({-1});
  int64_t from_small = 0;
  for (int64_t i = 0; i < o.count; ++i) from_small += torch::equal(grey[i], small_patch);
  CHECK(from_small <= 5);  // chosen in proportion to positions: about 0.3 expected
  o.color = true;
  auto color = lfnet::dict::sample_patches({small}, o);
  // Each draw is one of the three channels of the one position.
  for (int64_t i = 0; i < 10; ++i) {
    bool found = false;
    for (int64_t c = 0; c < 3; ++c) {
      found |= torch::equal(color[i], small.data()[c].reshape({-1}));
    }
    CHECK(found);
  }
}

TEST_CASE("Patch sampling reports what it cannot do", "[dict][sampling]") {
  PatchSamplingOptions o;
  o.count = 10;
  CHECK_THROWS_WITH(lfnet::dict::sample_patches({}, o), Catch::Contains("no light fields"));
  CHECK_THROWS_WITH(lfnet::dict::sample_patches({LightField(torch::rand({1, 5, 5, 8, 20}))}, o),
                    Catch::Contains("smaller than a 9x9 patch"));
  CHECK_THROWS_WITH(lfnet::dict::sample_patches({LightField(torch::rand({1, 3, 3, 20, 20}))}, o),
                    Catch::Contains("fewer than 5x5"));
  o.max_draws = 3;
  CHECK_THROWS_WITH(
      lfnet::dict::sample_patches({LightField(torch::full({1, 5, 5, 20, 20}, 0.3f))}, o),
      Catch::Contains("min_variance"));
  CHECK_THROWS_WITH(PatchSamplingOptions::from_json({{"count", 5}, {"size", 9}}, "$.sampling"),
                    Catch::Contains("$.sampling.size"));
  CHECK_THROWS_AS(PatchSamplingOptions::from_json({{"min_variance", -1.0}}), lfnet::ConfigError);
  auto back = PatchSamplingOptions::from_json(o.to_json());
  CHECK(back.to_json() == o.to_json());
}

#include "lfnet/core/patches.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/core/light_field.h"
#include "support/test_support.h"

using lfnet::encode_codes;
using lfnet::file_backed;
using lfnet::PatchGrid;
using lfnet::Stitcher;
namespace test = lfnet::test;

TEST_CASE("patch origins cover every pixel and end flush with the border", "[core][patches]") {
  CHECK(lfnet::patch_origins(20, 9, 9) == std::vector<int64_t>{0, 9, 11});
  CHECK(lfnet::patch_origins(18, 9, 9) == std::vector<int64_t>{0, 9});
  CHECK(lfnet::patch_origins(9, 9, 5) == std::vector<int64_t>{0});
  CHECK(lfnet::patch_origins(12, 9, 5) == std::vector<int64_t>{0, 3});
  CHECK(lfnet::patch_origins(11, 9, 1) == std::vector<int64_t>{0, 1, 2});
  CHECK_THROWS_AS(lfnet::patch_origins(8, 9, 5), lfnet::Error);
  CHECK_THROWS_AS(lfnet::patch_origins(20, 9, 0), lfnet::Error);
}

TEST_CASE("extract then stitch reproduces the light field exactly", "[core][patches]") {
  for (int64_t p : {4, 5, 8, 9}) {
    for (int64_t stride = 1; stride <= p; ++stride) {
      // Sizes from one patch to a few, odd and even, with ragged borders.
      for (auto hw : {std::pair<int64_t, int64_t>{p, p}, {p + 3, 2 * p + 1}, {2 * p - 1, p + 2}}) {
        auto data = torch::rand({2, 3, 2, hw.first, hw.second});
        PatchGrid grid(hw.first, hw.second, p, p, stride);
        auto patches = grid.extract(data);
        REQUIRE(patches.size(0) == 2 * grid.size());
        Stitcher stitcher(grid, 2, 3, 2);
        stitcher.add(patches, 0, grid.rows());
        auto back = stitcher.result();
        INFO("patch " << p << " stride " << stride << " size " << hw.first << "x" << hw.second);
        REQUIRE(torch::equal(back, data));
      }
    }
  }
}

TEST_CASE("patches hold the pixels at their origins", "[core][patches]") {
  auto data = torch::rand({1, 5, 5, 20, 23});
  PatchGrid grid(20, 23, 9, 9, 5);
  auto patches = grid.extract(data);
  // Patch (row 1, col 2): origin (5, 10).
  REQUIRE(grid.ys()[1] == 5);
  REQUIRE(grid.xs()[2] == 10);
  auto p = patches[1 * grid.cols() + 2];
  lfnet::test::require_close(p, data[0].slice(2, 5, 14).slice(3, 10, 19), 0.0);
}

TEST_CASE("stitching in bands equals stitching at once", "[core][patches]") {
  auto data = torch::rand({1, 2, 2, 31, 17});
  PatchGrid grid(31, 17, 9, 9, 2);
  auto estimates = grid.extract(data) + 0.1 * torch::randn({grid.size(), 2, 2, 9, 9});
  Stitcher whole(grid, 1, 2, 2);
  whole.add(estimates, 0, grid.rows());
  Stitcher bands(grid, 1, 2, 2);
  for (int64_t r = 0; r < grid.rows(); r += 3) {
    const int64_t e = std::min(grid.rows(), r + 3);
    bands.add(grid.extract(data, r, e) + estimates.slice(0, r * grid.cols(), e * grid.cols()) -
                  grid.extract(data, r, e),
              r, e);
  }
  lfnet::test::require_close(bands.result(), whole.result(), 1e-6);
  // Averaging noisy estimates moves values, so the result differs from the truth.
  CHECK_FALSE(torch::allclose(whole.result(), data, 0, 1e-4));
}

TEST_CASE("stitching averages every estimate of a pixel, weighted", "[core][patches]") {
  torch::manual_seed(5);
  // Ragged borders, so origins are evenly spaced and then flush with the edge.
  for (int64_t stride : {1, 3, 4, 7}) {
    PatchGrid grid(23, 19, 9, 7, stride);
    const auto estimates = torch::rand({2 * grid.size(), 2, 1, 9, 7}, torch::kFloat64);
    const auto window = torch::rand({9, 7}, torch::kFloat64) + 0.5;
    // The weighted mean, pixel by pixel.
    auto sum = torch::zeros({2, 2, 1, 23, 19}, torch::kFloat64);
    auto count = torch::zeros({23, 19}, torch::kFloat64);
    for (int64_t c = 0; c < 2; ++c) {
      for (int64_t i = 0; i < grid.rows(); ++i) {
        for (int64_t j = 0; j < grid.cols(); ++j) {
          const int64_t y = grid.ys()[i], x = grid.xs()[j];
          const auto e = estimates[(c * grid.rows() + i) * grid.cols() + j];
          sum[c].slice(2, y, y + 9).slice(3, x, x + 7) += e * window;
          if (c == 0) count.slice(0, y, y + 9).slice(1, x, x + 7) += window;
        }
      }
    }
    Stitcher s(grid, 2, 2, 1, window);
    s.add(estimates.to(torch::kFloat32), 0, grid.rows());
    INFO("stride " << stride);
    test::require_close(s.result(), (sum / count).to(torch::kFloat32), 1e-6);
  }
}

TEST_CASE("stitching takes patch rows in order and refuses rows left without estimates",
          "[core][patches]") {
  auto data = torch::rand({1, 1, 1, 31, 17});
  PatchGrid grid(31, 17, 9, 9, 2);  // 12 patch rows
  Stitcher s(grid, 1, 1, 1);
  s.add(grid.extract(data, 0, 4), 0, 4);
  s.add(grid.extract(data, 4, 8), 4, 8);
  CHECK_THROWS_WITH(s.add(grid.extract(data, 0, 4), 0, 4), Catch::Contains("in order"));
  // Starting at patch row 4 leaves image rows 0..7 without an estimate.
  Stitcher late(grid, 1, 1, 1);
  CHECK_THROWS_WITH(late.add(grid.extract(data, 4, 8), 4, 8),
                    Catch::Contains("without any estimate"));
  Stitcher top(grid, 1, 1, 1);
  top.add(grid.extract(data, 0, 6), 0, 6);
  CHECK_THROWS_WITH(top.result(), Catch::Contains("without any estimate"));  // the bottom rows
  Stitcher all(grid, 1, 1, 1);
  for (int64_t r = 0; r < grid.rows(); ++r) all.add(grid.extract(data, r, r + 1), r, r + 1);
  CHECK(torch::equal(all.result(), data));
}

TEST_CASE("a stitching window weights the estimates", "[core][patches]") {
  auto data = torch::rand({1, 1, 1, 12, 12});
  PatchGrid grid(12, 12, 9, 9, 3);
  auto window = torch::rand({9, 9}) + 0.5;
  Stitcher s(grid, 1, 1, 1, window);
  s.add(grid.extract(data), 0, grid.rows());
  // Identical estimates average to themselves whatever the weights.
  lfnet::test::require_close(s.result(), data, 1e-6);
}

TEST_CASE("stitching into 16-bit codes encodes each finished row", "[core][patches]") {
  torch::manual_seed(2);
  auto data = torch::rand({1, 2, 2, 31, 17});
  PatchGrid grid(31, 17, 9, 9, 2);
  auto estimates = grid.extract(data) + 0.2 * torch::randn({grid.size(), 2, 2, 9, 9});
  Stitcher plain(grid, 1, 2, 2);
  Stitcher coded(grid, 1, 2, 2, {}, /*coded=*/true);
  for (int64_t r = 0; r < grid.rows(); r += 3) {
    const int64_t e = std::min(grid.rows(), r + 3);
    const auto part = estimates.slice(0, r * grid.cols(), e * grid.cols());
    plain.add(part, r, e);
    coded.add(part, r, e);
  }
  const auto codes = coded.result();
  REQUIRE(codes.scalar_type() == torch::kInt16);
  // The noise puts some averages outside [0, 1]: the codes clamp them.
  const auto values = plain.result();
  REQUIRE(((values < 0) | (values > 1)).any().item<bool>());
  CHECK(torch::equal(codes, encode_codes(values)));

  // File-backed, as a large light field's, each finished row out of memory: the same codes.
  const test::FileBackedEverything everything;
  Stitcher held(grid, 1, 2, 2, {}, /*coded=*/true);
  for (int64_t r = 0; r < grid.rows(); r += 3) {
    const int64_t e = std::min(grid.rows(), r + 3);
    held.add(estimates.slice(0, r * grid.cols(), e * grid.cols()), r, e);
  }
  const auto held_codes = held.result();
  CHECK(file_backed(held_codes) == test::FileBackedEverything::available());
  CHECK(torch::equal(held_codes, codes));
}

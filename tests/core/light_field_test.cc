#include "lfnet/core/light_field.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::decode_codes;
using lfnet::encode_codes;
using lfnet::LightField;
using lfnet::LightFieldViews;

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

TEST_CASE("16-bit codes hold every 16-bit value exactly, clamped to [0, 1]", "[core]") {
  const auto k = torch::arange(0, 65536, torch::kFloat64);
  // What an image reader makes of 16-bit values: k times float32(1 / 65535).
  const auto values = k.to(torch::kFloat32) * (1.0F / 65535.0F);
  REQUIRE((values != (k / 65535.0).to(torch::kFloat32)).any().item<bool>());  // not k / 65535
  const auto codes = encode_codes(values);
  REQUIRE(codes.scalar_type() == torch::kInt16);
  // Each value is coded as k - 32768 and decodes to the same float32.
  CHECK(torch::equal(codes.to(torch::kFloat64) + 32768.0, k));
  CHECK(torch::equal(decode_codes(codes), values));
  CHECK(torch::equal(encode_codes((k / 65535.0).to(torch::kFloat32)), codes));
  // Out of range values are clamped; halfway values round up, as 16-bit image writers do.
  // (2.5 / 65535 and 200.5 / 65535 in float32 times 65535 are 2.5 and 200.5 exactly.)
  const auto edge = encode_codes(torch::tensor({-0.5f, 1.5f, 2.5f / 65535.0f, 200.5f / 65535.0f}));
  REQUIRE((torch::tensor({2.5f / 65535.0f, 200.5f / 65535.0f}) * 65535.0f)
              .equal(torch::tensor({2.5f, 200.5f})));
  CHECK(edge[0].item<int64_t>() == -32768);
  CHECK(edge[1].item<int64_t>() == 32767);
  CHECK(edge[2].item<int64_t>() == 3 - 32768);
  CHECK(edge[3].item<int64_t>() == 201 - 32768);
  CHECK_THROWS(decode_codes(values));
}

TEST_CASE("light-field views read float32 and 16-bit codes alike", "[core]") {
  torch::manual_seed(3);
  const LightField lf(torch::rand({1, 2, 3, 5, 7}));
  const LightFieldViews plain(lf);
  const LightFieldViews coded(encode_codes(lf.data()));
  CHECK_FALSE(plain.coded());
  CHECK(coded.coded());
  CHECK(coded.shape_string() == lf.shape_string());
  for (int64_t u = 0; u < 2; ++u) {
    for (int64_t v = 0; v < 3; ++v) {
      CHECK(torch::equal(plain.view(u, v), lf.view(u, v)));
      // Within half a step of 1 / 65535 of the float32 values.
      CHECK((coded.view(u, v) - lf.view(u, v)).abs().max().item<double>() <= 0.5 / 65535 + 1e-7);
      // view_bits: the unsigned values k in int16's bits.
      const auto k = coded.view_bits(u, v).to(torch::kInt32).remainder(65536);
      CHECK(torch::equal(k, (lf.view(u, v) * 65535 + 0.5).floor().to(torch::kInt32)));
    }
  }
  CHECK(torch::equal(coded.decode().data(), decode_codes(encode_codes(lf.data()))));
  CHECK_THROWS_WITH(plain.view_bits(0, 0), Catch::Contains("not 16-bit codes"));
  CHECK_THROWS_WITH(coded.view(2, 0), Catch::Contains("outside"));
  CHECK_THROWS(LightFieldViews(torch::zeros({1, 2, 3, 4, 4}, torch::kInt32)));
}

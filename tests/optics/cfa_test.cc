// Colour filter arrays (optics/cfa.h): the Bayer tiles, mosaicking and bilinear demosaicing.
#include "lfnet/optics/cfa.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"

namespace optics = lfnet::optics;
using lfnet::optics::ColourFilterArray;
using lfnet::optics::Demosaic;
using lfnet::optics::demosaic;
using lfnet::optics::mosaic;

TEST_CASE("Bayer patterns put each colour where their name says", "[optics][cfa]") {
  const auto rggb = ColourFilterArray::bayer("RGGB");
  CHECK(rggb.period() == 2);
  CHECK(rggb.one_colour_per_pixel());
  CHECK(rggb.response()[0][0][0].item<float>() == 1.0f);  // red at (0, 0)
  CHECK(rggb.response()[1][0][1].item<float>() == 1.0f);  // green at (0, 1) and (1, 0)
  CHECK(rggb.response()[1][1][0].item<float>() == 1.0f);
  CHECK(rggb.response()[2][1][1].item<float>() == 1.0f);  // blue at (1, 1)
  CHECK(rggb.response().sum().item<float>() == 4.0f);
  const auto gbrg = ColourFilterArray::parse("GBRG");
  CHECK(gbrg.response()[2][0][1].item<float>() == 1.0f);
  CHECK(gbrg.to_json() == nlohmann::json{{"pattern", "GBRG"}});
  CHECK_THROWS_WITH(ColourFilterArray::bayer("RGBG"), Catch::Contains("RGGB, BGGR"));
  CHECK_THROWS_WITH(ColourFilterArray::parse("/nonexistent.json"), Catch::Contains("--cfa"));
}

TEST_CASE("mosaicking keeps each pixel's own colour of every measurement", "[optics][cfa]") {
  torch::manual_seed(5);
  const auto colour = torch::rand({3, 2, 6, 7});  // (3 colours, N = 2, H, W)
  const auto cfa = ColourFilterArray::bayer("BGGR");
  const auto y = mosaic(colour, cfa);
  REQUIRE(y.sizes() == torch::IntArrayRef({1, 2, 6, 7}));
  CHECK(torch::equal(y[0].select(1, 0).select(1, 0), colour[2].select(1, 0).select(1, 0)));  // B
  CHECK(torch::equal(y[0].select(1, 1).select(1, 1), colour[0].select(1, 1).select(1, 1)));  // R
  CHECK(torch::equal(y[0].select(1, 4).select(1, 3), colour[1].select(1, 4).select(1, 3)));  // G
  CHECK_THROWS_AS(mosaic(torch::rand({2, 2, 6, 7}), cfa), lfnet::ConfigError);
}

TEST_CASE("bilinear demosaicing is exact for flat colours and linear ramps", "[optics][cfa]") {
  for (const auto* name : {"RGGB", "BGGR", "GRBG", "GBRG"}) {
    INFO(name);
    const auto cfa = ColourFilterArray::bayer(name);
    const int64_t h = 9, w = 12;
    const auto yy = torch::arange(h, torch::kFloat64).view({h, 1}).expand({h, w});
    const auto xx = torch::arange(w, torch::kFloat64).view({1, w}).expand({h, w});
    // Three linear images, one per colour, for two views.
    auto colour = torch::stack({0.1 + 0.02 * yy + 0.01 * xx, 0.5 - 0.01 * xx, 0.3 + 0.03 * yy});
    colour = torch::stack({colour, colour * 0.5}, 1);  // (3, 2, H, W)
    const auto raw = (colour * cfa.response_image(h, w).to(torch::kFloat64).unsqueeze(1)).sum(0);
    const auto rgb = demosaic(raw, cfa);  // (3, 2, H, W)
    REQUIRE(rgb.sizes() == colour.sizes());
    // The interior is exact; at the edges, mirroring keeps flat colours exact.
    const auto inner = [](const torch::Tensor& t) { return t.slice(-2, 1, -1).slice(-1, 1, -1); };
    CHECK((inner(rgb) - inner(colour)).abs().max().item<double>() < 1e-12);
    const auto flat = torch::tensor({0.2, 0.6, 0.9}, torch::kFloat64).view({3, 1, 1});
    const auto flat_raw = (flat * cfa.response_image(h, w).to(torch::kFloat64)).sum(0);
    CHECK((demosaic(flat_raw, cfa) - flat).abs().max().item<double>() < 1e-12);
  }
}

namespace {

// Malvar, He and Cutler's interpolation written out pixel by pixel from the paper's formulas
// (the edges mirrored), against which demosaic(..., kMalvar) is checked: (3, H, W).
torch::Tensor malvar_by_pixel(const torch::Tensor& raw, const ColourFilterArray& cfa) {
  const int64_t h = raw.size(0), w = raw.size(1);
  const auto a = raw.accessor<double, 2>();
  const auto colour_at = [&](int64_t y, int64_t x) {
    return cfa.response()[0][y % 2][x % 2].item<float>() > 0   ? 0
           : cfa.response()[1][y % 2][x % 2].item<float>() > 0 ? 1
                                                               : 2;
  };
  const auto m = [&](int64_t y, int64_t x) {
    y = y < 0 ? -y : y >= h ? 2 * (h - 1) - y : y;
    x = x < 0 ? -x : x >= w ? 2 * (w - 1) - x : x;
    return a[y][x];
  };
  auto out = torch::zeros({3, h, w}, torch::kFloat64);
  for (int64_t y = 0; y < h; ++y) {
    for (int64_t x = 0; x < w; ++x) {
      const double c = m(y, x);
      const double cross = m(y - 1, x) + m(y + 1, x) + m(y, x - 1) + m(y, x + 1);
      const double far = m(y - 2, x) + m(y + 2, x) + m(y, x - 2) + m(y, x + 2);
      const double diagonal = m(y - 1, x - 1) + m(y - 1, x + 1) + m(y + 1, x - 1) + m(y + 1, x + 1);
      const double row = m(y, x - 1) + m(y, x + 1), column = m(y - 1, x) + m(y + 1, x);
      const double far_row = m(y, x - 2) + m(y, x + 2), far_column = m(y - 2, x) + m(y + 2, x);
      // At a green pixel, the colour of its row's other pixels and the other colour.
      const double along_row = (5 * c + 4 * row - far_row - diagonal + 0.5 * far_column) / 8;
      const double along_column = (5 * c + 4 * column - far_column - diagonal + 0.5 * far_row) / 8;
      const int own = colour_at(y, x);
      out[own][y][x] = c;
      if (own == 1) {
        const int in_row = colour_at(y, x + 1);
        out[in_row][y][x] = along_row;
        out[2 - in_row][y][x] = along_column;
      } else {
        out[1][y][x] = (4 * c + 2 * cross - far) / 8;
        out[2 - own][y][x] = (6 * c + 2 * diagonal - 1.5 * far) / 8;
      }
    }
  }
  return out;
}

}  // namespace

TEST_CASE("malvar demosaicing follows the paper's formulas and is exact for linear ramps",
          "[optics][cfa]") {
  for (const auto* name : {"RGGB", "BGGR", "GRBG", "GBRG"}) {
    INFO(name);
    const auto cfa = ColourFilterArray::bayer(name);
    const int64_t h = 8, w = 11;
    const auto raw = torch::rand({h, w}, torch::kFloat64);
    const auto rgb = demosaic(raw, cfa, Demosaic::kMalvar);
    REQUIRE(rgb.sizes() == torch::IntArrayRef({3, h, w}));
    CHECK((rgb - malvar_by_pixel(raw, cfa)).abs().max().item<double>() < 1e-12);
    // Linear images, one per colour, in two views: exact two pixels from the edges, where the
    // 5 x 5 filters see no mirrored pixel; flat colours are exact everywhere.
    const auto yy = torch::arange(h, torch::kFloat64).view({h, 1}).expand({h, w});
    const auto xx = torch::arange(w, torch::kFloat64).view({1, w}).expand({h, w});
    auto colour = torch::stack({0.1 + 0.02 * yy + 0.01 * xx, 0.5 - 0.01 * xx, 0.3 + 0.03 * yy});
    colour = torch::stack({colour, colour * 0.5}, 1);  // (3, 2, H, W)
    const auto ramps = (colour * cfa.response_image(h, w).to(torch::kFloat64).unsqueeze(1)).sum(0);
    const auto inner = [](const torch::Tensor& t) { return t.slice(-2, 2, -2).slice(-1, 2, -2); };
    CHECK((inner(demosaic(ramps, cfa, Demosaic::kMalvar)) - inner(colour))
              .abs()
              .max()
              .item<double>() < 1e-12);
    const auto flat = torch::tensor({0.2, 0.6, 0.9}, torch::kFloat64).view({3, 1, 1});
    const auto flat_raw = (flat * cfa.response_image(h, w).to(torch::kFloat64)).sum(0);
    CHECK((demosaic(flat_raw, cfa, Demosaic::kMalvar) - flat).abs().max().item<double>() < 1e-12);
  }
  // A dark column at the image's edge, as some decoded Lytro views have: its missing colours
  // follow its own colour down, where bilinear interpolation takes its neighbours' brightness.
  const auto cfa = ColourFilterArray::bayer("RGGB");
  auto grey = torch::full({3, 8, 10}, 0.9, torch::kFloat64);
  grey.select(2, 9).zero_();
  const auto raw = (grey * cfa.response_image(8, 10).to(torch::kFloat64)).sum(0);
  const auto error = [&](Demosaic method) {
    return (demosaic(raw, cfa, method) - grey).select(2, 9).abs().mean().item<double>();
  };
  CHECK(error(Demosaic::kMalvar) < 0.7 * error(Demosaic::kBilinear));
  CHECK(optics::to_string(Demosaic::kMalvar) == "malvar");
  CHECK_THROWS_WITH(optics::from_string("vng", Demosaic{}), Catch::Contains("bilinear, malvar"));
  CHECK_THROWS_WITH(demosaic(torch::rand({2, 6}), cfa, Demosaic::kMalvar),
                    Catch::Contains("too small"));
  const auto custom = ColourFilterArray::from_json(
      nlohmann::json::parse(R"({"response": [[[1, 0, 0], [0, 1, 0]], [[0, 1, 0], [0, 0, 1]]]})"));
  CHECK_THROWS_WITH(demosaic(torch::rand({6, 6}), custom, Demosaic::kMalvar),
                    Catch::Contains("Bayer"));
}

TEST_CASE("a custom colour response comes from JSON and is checked", "[optics][cfa]") {
  // A 2 x 2 tile of filters that pass half of one colour each.
  const auto j = nlohmann::json::parse(
      R"({"response": [[[0.5, 0, 0], [0, 0.5, 0]], [[0, 0.5, 0], [0, 0, 0.5]]]})");
  const auto cfa = ColourFilterArray::from_json(j);
  CHECK(cfa.pattern() == "custom");
  CHECK(cfa.to_json() == j);
  const auto flat = torch::tensor({0.2f, 0.6f, 0.9f}).view({3, 1, 1});
  const auto raw = (flat * cfa.response_image(6, 6)).sum(0);
  CHECK((demosaic(raw, cfa) - flat).abs().max().item<float>() < 1e-6f);
  // A pixel that sees two colours cannot be demosaiced; bad tiles are refused with their path.
  const auto mixed =
      ColourFilterArray::from_json(nlohmann::json::parse(R"({"response": [[[0.5, 0.5, 0]]]})"));
  CHECK_FALSE(mixed.one_colour_per_pixel());
  CHECK_THROWS_WITH(demosaic(torch::rand({4, 4}), mixed), Catch::Contains("one colour"));
  CHECK_THROWS_WITH(
      ColourFilterArray::from_json(nlohmann::json::parse(R"({"response": [[[0, 0, 0]]]})")),
      Catch::Contains("$.response[0][0]"));
  // A weight a float cannot hold (it became NaN in the patch rows) is refused by its domain.
  CHECK_THROWS_WITH(
      ColourFilterArray::from_json(nlohmann::json::parse(R"({"response": [[[1e300, 0, 0]]]})")),
      Catch::Contains("$.response[0][0][0]: a weight must lie in [0, 100]"));
  CHECK_THROWS_WITH(
      ColourFilterArray::from_json(nlohmann::json::parse(R"({"pattern": "RGGB", "x": 1})")),
      Catch::Contains("x"));
  // Red pixels only every third column: some pixels have no red neighbour.
  const auto sparse = ColourFilterArray::from_json(nlohmann::json::parse(
      R"({"response": [[[1, 0, 0], [0, 1, 0], [0, 1, 0]], [[0, 1, 0], [0, 0, 1], [0, 0, 1]], [[0, 1, 0], [0, 0, 1], [0, 0, 1]]]})"));
  CHECK_THROWS_WITH(demosaic(torch::rand({9, 9}), sparse), Catch::Contains("no R pixel"));
}

#include "lfnet/core/colour_map.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "support/test_support.h"

TEST_CASE("viridis runs from dark purple to yellow and clamps", "[core][colour]") {
  const auto rgb = lfnet::viridis(torch::tensor({-1.0f, 0.0f, 0.5f, 1.0f, 2.0f, NAN}));
  REQUIRE(rgb.sizes() == torch::IntArrayRef({3, 6}));
  auto at = [&](int64_t i, int64_t c) { return rgb[c][i].item<float>() * 255.0f; };
  CHECK(at(1, 0) == Approx(68));
  CHECK(at(1, 2) == Approx(84));
  CHECK(at(3, 0) == Approx(253));
  CHECK(at(3, 1) == Approx(231));
  for (int c = 0; c < 3; ++c) {
    CHECK(at(0, c) == Approx(at(1, c)));  // below 0: the first colour
    CHECK(at(4, c) == Approx(at(3, c)));  // above 1: the last
    CHECK(at(5, c) == Approx(at(1, c)));  // NaN: the first
  }
  // Its luminance grows with the value (viridis is perceptually ordered).
  const auto levels = lfnet::viridis(torch::linspace(0, 1, 64));
  const auto luma = 0.299 * levels[0] + 0.587 * levels[1] + 0.114 * levels[2];
  CHECK((luma.slice(0, 1) - luma.slice(0, 0, -1)).min().item<float>() > 0);
  // A shape is kept: (2, 3) values give (3, 2, 3) colours.
  CHECK(lfnet::viridis(torch::rand({2, 3})).sizes() == torch::IntArrayRef({3, 2, 3}));
}

TEST_CASE("viridis matches matplotlib's within 3 / 255", "[core][colour][reference]") {
  const std::string py = lfnet::test::python_with("matplotlib");
  if (py.empty()) {
    LFNET_SKIP("python3-matplotlib is not installed: no viridis to compare with");
  }
  std::string out;
  REQUIRE(
      lfnet::test::run_command(py + " -c \"import json; from matplotlib import cm; "
                                    "print(json.dumps([[round(255 * x) for x in cm.viridis(i)[:3]] "
                                    "for i in range(256)]))\"",
                               out) == 0);
  const auto reference = nlohmann::json::parse(out);
  const auto table = lfnet::viridis_table(256);
  REQUIRE(reference.size() == table.size());
  int worst = 0;
  for (size_t i = 0; i < table.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      worst = std::max(worst, std::abs(table[i][c] - reference[i][c].get<int>()));
    }
  }
  CHECK(worst <= 3);
}

// Every scene shipped in configs/scenes parses, renders in [0, 1] and round-trips.
#include <catch2/catch.hpp>

#include <filesystem>

#include "lfnet/core/json.h"
#include "lfnet/scene/render.h"
#include "support/test_support.h"

namespace fs = std::filesystem;

TEST_CASE("every shipped scene parses and renders with values in [0, 1]", "[scene][shipped]") {
  const fs::path dir = fs::path(LFNET_SOURCE_DIR) / "configs" / "scenes";
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() == ".json") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  REQUIRE(files.size() >= 7);
  bool heldout = false;
  for (const auto& file : files) {
    INFO(file.string());
    const auto spec = lfnet::scene::load_scene(file.string());
    CHECK(lfnet::scene::SceneSpec::from_json(spec.to_json()).to_json() == spec.to_json());
    CHECK_FALSE(spec.name.empty());
    CHECK_FALSE(spec.description.empty());
    heldout = heldout || file.filename().string().rfind("heldout_", 0) == 0;
    const auto result = lfnet::scene::render_scene(spec);
    const auto& data = result.light_field.data();
    CHECK(result.light_field.height() == spec.height);
    CHECK(result.light_field.width() == spec.width);
    CHECK(data.isfinite().all().item<bool>());
    CHECK(data.min().item<double>() >= 0.0);
    CHECK(data.max().item<double>() <= 1.0);
    CHECK(data.std().item<double>() > 0.02);  // not blank
    CHECK(result.disparity.isfinite().all().item<bool>());
    CHECK(result.disparity.abs().max().item<double>() <= spec.max_abs_disparity() + 1e-4);
  }
  CHECK(heldout);
}

TEST_CASE("every number in a shipped scene has a domain", "[scene][shipped][domains]") {
  // Each numeric value of each shipped scene in turn at 1e300 and -1e300: refused, naming it.
  const fs::path dir = fs::path(LFNET_SOURCE_DIR) / "configs" / "scenes";
  int files = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() != ".json") continue;
    ++files;
    const auto found = lfnet::test::absurd_values_unrefused(
        lfnet::read_json_file(entry.path().string()),
        [](const nlohmann::json& j) { (void)lfnet::scene::SceneSpec::from_json(j); });
    std::string all;
    for (const auto& line : found) all += line + "\n";
    INFO(entry.path().string() << "\n" << all);
    CHECK(found.empty());
  }
  CHECK(files >= 7);
}

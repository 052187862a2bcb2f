// The random scene generator: deterministic, varied, and covering the requested disparities.
#include "lfnet/scene/random_scene.h"

#include <catch2/catch.hpp>

#include <map>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/scene/render.h"
#include "support/test_support.h"

using lfnet::scene::random_scene;
using lfnet::scene::RandomSceneOptions;
using lfnet::scene::SceneSpec;

TEST_CASE("random scenes are a pure function of the seed and options", "[scene][random]") {
  RandomSceneOptions o;
  o.height = 40;
  o.width = 56;
  CHECK(random_scene(5, o).to_json() == random_scene(5, o).to_json());
  CHECK(random_scene(5, o).to_json() != random_scene(6, o).to_json());
  // The spec survives a trip through JSON unchanged, so a saved scene re-renders identically.
  const SceneSpec spec = random_scene(9, o);
  const SceneSpec again = SceneSpec::from_json(spec.to_json());
  CHECK(again.to_json() == spec.to_json());
  CHECK(torch::equal(lfnet::scene::render_scene(spec).light_field.data(),
                     lfnet::scene::render_scene(again).light_field.data()));
  CHECK(spec.height == 40);
  CHECK(spec.width == 56);
}

TEST_CASE("random scenes cover the disparity range and vary in content", "[scene][random]") {
  RandomSceneOptions o;
  o.height = 48;
  o.width = 48;
  o.color = false;
  o.min_disparity = -2.0;
  o.max_disparity = 1.5;
  const int scenes = 80;
  const int bins = 7;
  std::vector<int64_t> histogram(bins, 0);
  int64_t pixels = 0;
  double lowest = 1e9, highest = -1e9;
  int occluded = 0, slanted = 0, thin = 0, with_effects = 0;
  std::set<std::string> textures, shapes;
  std::vector<double> contrasts;
  for (int seed = 0; seed < scenes; ++seed) {
    const SceneSpec spec = random_scene(static_cast<uint64_t>(seed), o);
    REQUIRE(spec.layers.size() >= 3);
    REQUIRE(spec.layers.size() <= 10);
    for (size_t i = 1; i < spec.layers.size(); ++i) {
      // Back to front: nearer layers (larger disparity) later.
      CHECK(spec.layers[i].disparity >= spec.layers[i - 1].disparity - 1e-9);
    }
    for (const auto& layer : spec.layers) {
      textures.insert(lfnet::scene::to_string(layer.texture.kind));
      shapes.insert(lfnet::scene::to_string(layer.shape.kind));
      if (layer.slanted()) ++slanted;
      if (layer.name.rfind("occluder", 0) == 0) ++thin;
    }
    if (spec.specular || spec.vignetting || spec.defocus) ++with_effects;
    const auto result = lfnet::scene::render_scene(spec);
    const auto& d = result.disparity;
    lowest = std::min(lowest, d.min().item<double>());
    highest = std::max(highest, d.max().item<double>());
    if (d.max().item<double>() - d.min().item<double>() > 0.1) ++occluded;
    auto idx = ((d - o.min_disparity) / (o.max_disparity - o.min_disparity) * bins)
                   .floor()
                   .clamp(0, bins - 1)
                   .to(torch::kLong)
                   .flatten();
    auto counts = torch::bincount(idx, {}, bins);
    for (int b = 0; b < bins; ++b) histogram[b] += counts[b].item<int64_t>();
    pixels += d.numel();
    contrasts.push_back(result.light_field.view(2, 2).std().item<double>());
    REQUIRE(result.light_field.data().min().item<double>() >= 0.0);
    REQUIRE(result.light_field.data().max().item<double>() <= 1.0);
  }
  // Every disparity lies in the range, and the range is reached at both ends.
  CHECK(lowest >= o.min_disparity - 1e-3);
  CHECK(highest <= o.max_disparity + 1e-3);
  CHECK(lowest < o.min_disparity + 0.1);
  CHECK(highest > o.max_disparity - 0.1);
  // Pixels spread over the whole range: no seventh of it is left nearly empty.
  for (int b = 0; b < bins; ++b) {
    INFO("bin " << b << " holds " << histogram[b] << " of " << pixels << " pixels");
    CHECK(histogram[b] > pixels / (bins * 4));
  }
  CHECK(occluded > scenes * 3 / 4);
  CHECK(slanted > 0);
  CHECK(thin > 0);
  CHECK(with_effects > 0);
  CHECK(textures ==
        std::set<std::string>{"checker", "constant", "fractal", "gradient", "noise", "stripes"});
  CHECK(shapes == std::set<std::string>{"bars", "disk", "full", "polygon", "rectangle"});
  // Contrast varies widely: from nearly flat scenes to busy ones.
  std::sort(contrasts.begin(), contrasts.end());
  CHECK(contrasts.front() < 0.05);
  CHECK(contrasts.back() > 0.2);
}

TEST_CASE("random scene options are validated and parsed strictly", "[scene][random]") {
  RandomSceneOptions o;
  o.min_disparity = 2;
  o.max_disparity = 1;
  CHECK_THROWS_WITH(random_scene(1, o), Catch::Contains("max_disparity"));
  o = RandomSceneOptions{};
  o.defocus_probability = 1.5;
  CHECK_THROWS_WITH(o.validate("$"), Catch::StartsWith("$.defocus_probability"));
  const auto doc = nlohmann::json::parse(R"({"height": 64, "max_disparity": 2, "depth": 1})");
  lfnet::JsonReader reader(doc, "$");
  CHECK_THROWS_WITH(RandomSceneOptions::from_json(reader), Catch::Contains("$.depth"));
  const auto good = nlohmann::json::parse(R"({"height": 64, "max_disparity": 2})");
  lfnet::JsonReader ok(good, "$");
  const auto parsed = RandomSceneOptions::from_json(ok);
  CHECK(parsed.height == 64);
  CHECK(parsed.max_disparity == 2.0);
  CHECK(parsed.to_json()["width"] == 256);
  // Every probability at 1: all effects and a slanted background, every time.
  o = RandomSceneOptions{};
  o.height = o.width = 32;
  o.slanted_probability = o.specular_probability = o.vignetting_probability =
      o.defocus_probability = o.thin_occluder_probability = 1.0;
  const auto spec = random_scene(3, o);
  CHECK(spec.specular);
  CHECK(spec.vignetting);
  CHECK(spec.defocus);
  CHECK(spec.layers[0].slanted());
  CHECK(spec.layers.back().name.rfind("occluder", 0) == 0);
}

// The random scene generator: deterministic, varied, and covering the requested disparities.
#include "lfnet/scene/random_scene.h"

#include <catch2/catch.hpp>

#include <cmath>
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
    CHECK(histogram[b] > pixels / (int64_t{bins} * 4));
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

TEST_CASE("random scenes draw man-made frames in front when asked", "[scene][random]") {
  RandomSceneOptions plain;
  plain.height = 96;
  plain.width = 128;
  plain.color = false;
  RandomSceneOptions framed = plain;
  framed.frame_probability = 1.0;
  auto starts = [](const std::string& name, const char* prefix) {
    return name.rfind(prefix, 0) == 0;
  };
  const int scenes = 40;
  int flat = 0, walls = 0, visible = 0;
  for (int seed = 0; seed < scenes; ++seed) {
    INFO("seed " << seed);
    const SceneSpec spec = random_scene(static_cast<uint64_t>(seed), framed);
    const lfnet::scene::LayerSpec* posts = nullptr;
    const lfnet::scene::LayerSpec* rails = nullptr;
    std::vector<nlohmann::json> others;
    for (size_t i = 0; i < spec.layers.size(); ++i) {
      const auto& layer = spec.layers[i];
      if (i > 0) CHECK(layer.disparity >= spec.layers[i - 1].disparity - 1e-9);
      if (starts(layer.name, "frame-posts")) {
        posts = &layer;
      } else if (starts(layer.name, "frame-rails")) {
        rails = &layer;
      } else if (starts(layer.name, "wall")) {
        ++walls;
        CHECK(layer.shape.invert);
        CHECK(layer.disparity >= spec.layers[0].disparity);
      } else {
        others.push_back({layer.shape.to_json(), layer.disparity});
      }
    }
    REQUIRE(posts != nullptr);
    REQUIRE(rails != nullptr);
    // One frame: the same depth, texture and crossing point, bars at right angles.
    CHECK(posts->disparity == rails->disparity);
    CHECK(posts->disparity >= spec.layers[0].disparity);
    CHECK(posts->disparity <= framed.max_disparity);
    CHECK(posts->texture.to_json() == rails->texture.to_json());
    CHECK(rails->shape.angle - posts->shape.angle ==
          Approx(90.0).margin(0.01));  // specs keep 5 digits
    CHECK(posts->shape.center->x == rails->shape.center->x);
    if (posts->texture.kind == lfnet::scene::TextureKind::kConstant) ++flat;
    // The frame is drawn after everything else: the rest of the scene is the plain one.
    std::vector<nlohmann::json> plain_layers;
    for (const auto& layer : random_scene(static_cast<uint64_t>(seed), plain).layers) {
      plain_layers.push_back({layer.shape.to_json(), layer.disparity});
    }
    CHECK(others == plain_layers);
    // Where the bars cross, the frame is seen unless something nearer hides it.
    const auto rendered = lfnet::scene::render_scene(spec);
    const auto c = *posts->shape.center;
    const double d = rendered
                         .disparity[static_cast<int64_t>(std::lround(c.y))]
                                   [static_cast<int64_t>(std::lround(c.x))]
                         .item<double>();
    if (std::abs(d - posts->disparity) < 1e-3) ++visible;
  }
  CHECK(flat > scenes / 4);
  CHECK(flat < scenes);
  CHECK(walls > scenes / 4);
  CHECK(walls < scenes);
  CHECK(visible > scenes / 2);
  framed.frame_probability = 1.5;
  CHECK_THROWS_WITH(framed.validate("$"), Catch::StartsWith("$.frame_probability"));
}

TEST_CASE("random scenes draw vivid palettes, contrast in chroma, when asked", "[scene][random]") {
  RandomSceneOptions o;
  o.height = o.width = 48;
  // Per palette: the smallest saturation, the largest hue gap and brightness gap between colours.
  struct Stats {
    double saturation = 0, hue_gap = 0, value_gap = 0;
    int palettes = 0;
  };
  auto stats = [](const RandomSceneOptions& options) {
    Stats st;
    for (uint64_t seed = 0; seed < 30; ++seed) {
      for (const auto& layer : random_scene(seed, options).layers) {
        const auto& colors = layer.texture.colors;
        if (colors.size() < 2) continue;
        double min_sat = 1, max_gap = 0, max_value_gap = 0;
        std::vector<double> hues, values;
        for (const auto& c : colors) {
          const double hi = std::max({c[0], c[1], c[2]}), lo = std::min({c[0], c[1], c[2]});
          min_sat = std::min(min_sat, hi > 0 ? (hi - lo) / hi : 0.0);
          hues.push_back(std::atan2(std::sqrt(3.0) * (c[1] - c[2]), 2 * c[0] - c[1] - c[2]));
          values.push_back(hi);
        }
        for (size_t i = 0; i < hues.size(); ++i) {
          for (size_t j = 0; j < i; ++j) {
            const double d = std::abs(std::remainder(hues[i] - hues[j], 2 * M_PI));
            max_gap = std::max(max_gap, d);
            max_value_gap = std::max(max_value_gap, std::abs(values[i] - values[j]));
          }
        }
        st.saturation += min_sat;
        st.hue_gap += max_gap;
        st.value_gap += max_value_gap;
        ++st.palettes;
      }
    }
    st.saturation /= st.palettes;
    st.hue_gap /= st.palettes;
    st.value_gap /= st.palettes;
    return st;
  };
  const auto before = random_scene(4, o).to_json();
  const Stats muted = stats(o);
  o.vivid_probability = 0.0;
  CHECK(random_scene(4, o).to_json() == before);  // 0 draws nothing: scenes stay as they were
  o.vivid_probability = 1.0;
  const Stats vivid = stats(o);
  CHECK(random_scene(4, o).to_json() != before);
  REQUIRE(vivid.palettes > 50);
  // Every vivid colour is at least half saturated and the hues lie at least 72 degrees apart.
  CHECK(vivid.saturation >= 0.5 - 1e-9);
  CHECK(vivid.hue_gap >= 72.0 * M_PI / 180.0 - 1e-6);
  INFO("saturation " << muted.saturation << " / " << vivid.saturation << ", hue gap "
                     << muted.hue_gap << " / " << vivid.hue_gap);
  CHECK(muted.saturation < 0.3);
  // (A near-grey colour's hue is noise: the natural palettes' gaps are not zero.)
  CHECK(vivid.hue_gap > 2.0 * muted.hue_gap);
  // Brightness varies less than in the natural palettes: the contrast is in chroma.
  CHECK(vivid.value_gap < muted.value_gap);
  o.vivid_probability = -0.1;
  CHECK_THROWS_WITH(o.validate("$"), Catch::StartsWith("$.vivid_probability"));
}

TEST_CASE("random scenes take regions of natural images as textures when asked",
          "[scene][random]") {
  lfnet::test::TempDir tmp;
  // Two "photographs" (only their names matter to the generator) and a stray file.
  for (const char* name : {"b.png", "a.jpg", "notes.txt"})
    lfnet::test::write_bytes(tmp / name, "x");
  RandomSceneOptions o;
  o.height = 48;
  o.width = 48;
  const auto before = random_scene(11, o).to_json();
  o.texture_images = {tmp.path().string()};
  // Listing images changes nothing until a probability asks for them.
  CHECK(random_scene(11, o).to_json() == before);
  const std::vector<std::string> sorted = {tmp / "a.jpg", tmp / "b.png"};
  CHECK(lfnet::scene::texture_image_files(o.texture_images) == sorted);
  o.image_probability = 1.0;
  const SceneSpec spec = random_scene(11, o);
  CHECK(spec.to_json() == random_scene(11, o).to_json());
  std::set<std::string> paths;
  std::set<double> zooms;
  for (const auto& layer : spec.layers) {
    REQUIRE(layer.texture.kind == lfnet::scene::TextureKind::kImage);
    paths.insert(layer.texture.path);
    zooms.insert(layer.texture.zoom);
    CHECK(layer.texture.zoom >= 1.0);
    CHECK(layer.texture.zoom <= 4.0);
  }
  CHECK(zooms.size() == spec.layers.size());
  // Rendering reads them through the loader: a gradient image, so zoom and offset show.
  int loads = 0;
  lfnet::scene::RenderOptions render;
  render.image_loader = [&](const std::string& path) {
    ++loads;
    CHECK(paths.count(path) == 1);
    return torch::linspace(0, 1, 200).view({1, 1, 200}).expand({1, 150, 200}).contiguous();
  };
  const auto lf = lfnet::scene::render_scene(spec, render).light_field;
  CHECK(loads >= 1);
  CHECK(torch::isfinite(lf.data()).all().item<bool>());
  CHECK(lf.data().std().item<double>() > 0.01);
  // Bad options are named.
  o.texture_images = {tmp / "notes.txt"};
  CHECK_THROWS_WITH(random_scene(1, o), Catch::Contains("notes.txt"));
  o.texture_images.clear();
  CHECK_THROWS_WITH(o.validate("$.random_options"), Catch::Contains("texture_images"));
}

TEST_CASE("an image texture's zoom and offset choose the region it shows", "[scene][render]") {
  // A 1 x 100 ramp fitted to a 20-pixel-wide scene: zoom 2 shows half of it, offset -1 / +1
  // its left / right half.
  auto scene_json = [](double zoom, double offset) {
    return nlohmann::json{{"height", 20},
                          {"width", 20},
                          {"rows", 1},
                          {"cols", 1},
                          {"color", false},
                          {"layers",
                           {{{"texture",
                              {{"kind", "image"},
                               {"path", "ramp.png"},
                               {"fit", "stretch"},
                               {"zoom", zoom},
                               {"offset", {offset, 0.0}}}}}}}};
  };
  lfnet::scene::RenderOptions render;
  render.image_loader = [](const std::string&) {
    return torch::linspace(0, 1, 100).view({1, 1, 100}).expand({1, 100, 100}).contiguous();
  };
  auto row = [&](double zoom, double offset) {
    const auto spec = SceneSpec::from_json(scene_json(zoom, offset));
    return lfnet::scene::render_scene(spec, render).light_field.data()[0][0][0][10];
  };
  const auto whole = row(1, 0), left = row(2, -1), right = row(2, 1);
  CHECK(whole.min().item<double>() < 0.05);
  CHECK(whole.max().item<double>() > 0.95);
  CHECK(left.max().item<double>() < 0.55);
  CHECK(right.min().item<double>() > 0.45);
  CHECK_THROWS_AS(SceneSpec::from_json(scene_json(0.5, 0)), lfnet::ConfigError);
  CHECK_THROWS_AS(SceneSpec::from_json(scene_json(2, 1.5)), lfnet::ConfigError);
}

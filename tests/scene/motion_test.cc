// Moving layers and render_sequence: still scenes film bit-identically, shifts move content by
// exactly their pixels, motion in depth moves the disparity map, rotations turn shapes, and the
// motion spec reads and writes strictly.
#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/core/runtime.h"
#include "lfnet/scene/scene.h"
#include "support/test_support.h"

using lfnet::scene::render_scene;
using lfnet::scene::render_sequence;
using lfnet::scene::SceneSpec;
using nlohmann::json;

namespace {

constexpr double kMotionPi = 3.14159265358979323846;

SceneSpec motion_scene(const std::string& text) { return SceneSpec::from_json(json::parse(text)); }

// A fractal background at -1 and a textured disk at disparity 1 in front, 64 x 48, 5 x 5 views.
json motion_disk_scene() {
  return json::parse(R"({"height": 48, "width": 64, "color": false, "seed": 5, "layers": [
    {"texture": {"kind": "fractal", "scale": 16}, "disparity": -1},
    {"texture": {"kind": "noise", "scale": 3}, "disparity": 1,
     "shape": {"kind": "disk", "center": [30, 24], "radius": 9}}]})");
}

// Parses `doc` and returns the ConfigError's message ("" if it parsed).
std::string motion_parse_error(const json& doc) {
  try {
    SceneSpec::from_json(doc);
  } catch (const lfnet::ConfigError& e) {
    return e.what();
  }
  return "";
}

torch::Tensor motion_interior(const torch::Tensor& view, int64_t m) {
  return view.slice(-2, m, view.size(-2) - m).slice(-1, m, view.size(-1) - m);
}

}  // namespace

TEST_CASE("a still scene renders every sub-frame bit-identically to render_scene",
          "[scene][motion][render]") {
  // Every effect, a slanted layer and an occluder: nothing may differ from a still render.
  const auto spec = motion_scene(R"({"height": 40, "width": 52, "rows": 3, "cols": 5, "seed": 9,
    "layers": [
      {"texture": {"kind": "fractal", "scale": 32}, "disparity": -1.5,
       "disparity_gradient": [0.01, 0.02]},
      {"texture": {"kind": "stripes", "period": 5}, "disparity": 0.7, "gloss": 0.8,
       "shape": {"kind": "rectangle", "center": [20, 18], "size": [18, 12], "angle": 20}},
      {"texture": {"kind": "constant", "colors": [[0.9, 0.2, 0.1]]}, "disparity": 1.6,
       "shape": {"kind": "bars", "width": 2, "period": 11}, "motion": {"shift": [0, 0]}}],
    "effects": {"defocus": {"focus_disparity": 0.5}, "specular": {}, "vignetting": {}}})");
  REQUIRE_FALSE(spec.moves());  // a zero motion is no motion
  const auto still = render_scene(spec);
  for (const int64_t frames : {1, 4}) {
    INFO(frames << " frames");
    const auto seq = render_sequence(spec, frames);
    REQUIRE(seq.light_fields.frames() == frames);
    REQUIRE(seq.disparity.sizes() == torch::IntArrayRef({frames, 40, 52}));
    for (int64_t t = 0; t < frames; ++t) {
      CHECK(torch::equal(seq.light_fields.frame(t).data(), still.light_field.data()));
      CHECK(torch::equal(seq.disparity[t], still.disparity));
    }
    CHECK(seq.effects_run == still.effects_run);
  }

  // A moving scene filmed in one sub-frame is its spec pose: render_scene exactly.
  json moving = motion_disk_scene();
  moving["layers"][1]["motion"] = {{"shift", {1.5, -0.5}}, {"rotation", 7}, {"disparity", 0.2}};
  const auto spec2 = SceneSpec::from_json(moving);
  REQUIRE(spec2.moves());
  const auto one = render_sequence(spec2, 1);
  CHECK(torch::equal(one.light_fields.frame(0).data(), render_scene(spec2).light_field.data()));
  CHECK(one.effects_run == std::vector<std::string>{"occlusion"});
  const std::vector<std::string> expected_effects = {"occlusion", "motion"};
  CHECK(render_sequence(spec2, 3).effects_run == expected_effects);
}

TEST_CASE("a layer shifting 2 px per sub-frame moves its content by exactly 2 px",
          "[scene][motion][render]") {
  json doc = motion_disk_scene();
  doc["layers"][1]["motion"] = {{"shift", {2, 0}}};
  const auto spec = SceneSpec::from_json(doc);
  const auto seq = render_sequence(spec, 3);
  const auto& lf = seq.light_fields;
  // The middle sub-frame is the spec's pose.
  const auto still = render_scene(spec);
  CHECK(torch::equal(lf.frame(1).data(), still.light_field.data()));
  CHECK(torch::equal(seq.disparity[1], still.disparity));
  // The disk spans x 21..39 around y 24 at tau = 0; at tau = -1 and 1 it sits 2 px left, right.
  // Inside it (radius 9, parallax up to 2 px, moving 2 px) the views are exact shifts.
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) {
      INFO("view " << u << ", " << v);
      const int64_t y = 24 + (u - 2);
      const int64_t x = 30 + (v - 2);
      const auto region = [&](int64_t t, int64_t dx) {
        return lf.frame(t).view(u, v).slice(1, y - 3, y + 4).slice(2, x + dx - 3, x + dx + 4);
      };
      REQUIRE(torch::equal(region(0, -2), region(1, 0)));
      REQUIRE(torch::equal(region(2, 2), region(1, 0)));
      // The region did change where it was: the disk's texture is not flat.
      CHECK_FALSE(torch::equal(region(0, 0), region(1, 0)));
    }
  }
  // The disparity map's disk moves with it; the background far from it stays.
  const auto disk = [&](int64_t t) { return seq.disparity[t] > 0.0f; };
  CHECK(torch::equal(disk(2).slice(1, 4, 64), disk(0).slice(1, 0, 60)));
  CHECK(disk(0)[24][20].item<bool>());
  CHECK_FALSE(disk(2)[24][20].item<bool>());
  CHECK(torch::equal(lf.frame(0).data().slice(-1, 50, 64), lf.frame(2).data().slice(-1, 50, 64)));

  // A full layer moving by whole pixels: every view of the next sub-frame is that view moved.
  json full = json::parse(R"({"height": 32, "width": 40, "color": true, "seed": 2, "layers": [
    {"texture": {"kind": "fractal", "scale": 12}, "disparity": 1,
     "motion": {"shift": [2, -2]}}]})");
  const auto seq2 = render_sequence(SceneSpec::from_json(full), 4);
  for (int64_t t = 0; t + 1 < 4; ++t) {
    const auto a = seq2.light_fields.frame(t).data();
    const auto b = seq2.light_fields.frame(t + 1).data();
    REQUIRE(
        torch::equal(motion_interior(torch::roll(a, {-2, 2}, {-2, -1}), 3), motion_interior(b, 3)));
  }
}

TEST_CASE("motion in depth changes the disparity map and the parallax per sub-frame",
          "[scene][motion][render]") {
  json doc = motion_disk_scene();
  doc["layers"][1]["motion"] = {{"disparity", 1}};
  const auto seq = render_sequence(SceneSpec::from_json(doc), 3);
  for (int64_t t = 0; t < 3; ++t) {
    INFO("sub-frame " << t);
    const double d = static_cast<double>(t);  // 1 + (t - 1) * 1
    CHECK(seq.disparity[t][24][30].item<double>() == d);
    CHECK(seq.disparity[t][2][2].item<double>() == -1.0);  // the background stays
    // Inside the disk, view (2, 4) is the centre view moved 2 d px to the right.
    const auto& lf = seq.light_fields.frame(t);
    const auto shifted = lf.view(2, 4).slice(1, 21, 28).slice(2, 27 + 2 * t, 34 + 2 * t);
    CHECK(torch::equal(shifted, lf.view(2, 2).slice(1, 21, 28).slice(2, 27, 34)));
  }
  CHECK_FALSE(
      torch::equal(seq.light_fields.frame(0).view(2, 4), seq.light_fields.frame(2).view(2, 4)));

  // Coming nearer with a scale: the disk grows by the factor per sub-frame.
  doc["layers"][1]["motion"] = {{"disparity", 0.5}, {"scale", 1.25}};
  const auto grown = render_sequence(SceneSpec::from_json(doc), 3);
  const auto area = [&](int64_t t) { return (grown.disparity[t] > -1.0f).sum().item<double>(); };
  CHECK(area(1) == Approx(kMotionPi * 81.0).epsilon(0.05));
  CHECK(area(2) == Approx(kMotionPi * 81.0 * 1.25 * 1.25).epsilon(0.05));
  CHECK(area(0) == Approx(kMotionPi * 81.0 / (1.25 * 1.25)).epsilon(0.05));
}

TEST_CASE("a rotating layer turns about its shape's centre", "[scene][motion][render]") {
  // A 20 x 6 bar turning 90 degrees per sub-frame is, one sub-frame on, a 6 x 20 bar (a flat
  // colour, so the texture's turn does not show). Its edges lie half-way between pixel centres.
  const char* text = R"({"height": 48, "width": 64, "rows": 3, "cols": 3, "color": false,
    "layers": [{"texture": {"kind": "constant", "colors": [0.2]}},
               {"texture": {"kind": "constant", "colors": [0.9]}, "disparity": 1,
                "shape": {"kind": "rectangle", "center": [31.5, 23.5], "size": [20, 6]},
                "motion": {"rotation": 90}}]})";
  const auto seq = render_sequence(motion_scene(text), 3);
  json upright = json::parse(text);
  upright["layers"][1]["shape"]["size"] = {6, 20};
  upright["layers"][1].erase("motion");
  const auto want = render_scene(SceneSpec::from_json(upright));
  for (const int64_t t : {0, 2}) {
    INFO("sub-frame " << t);
    lfnet::test::require_close(seq.light_fields.frame(t).data(), want.light_field.data(), 1e-4);
    CHECK(torch::equal(seq.disparity[t], want.disparity));
  }
  CHECK_FALSE(torch::allclose(seq.light_fields.frame(1).data(), want.light_field.data(), 0.0, 0.1));

  // A textured layer turning a few degrees: every sub-frame differs, the middle one is the spec's.
  json tex = json::parse(text);
  tex["layers"][1]["texture"] = {{"kind", "stripes"}, {"period", 4}};
  tex["layers"][1]["motion"]["rotation"] = 3;
  const auto spec = SceneSpec::from_json(tex);
  const auto turning = render_sequence(spec, 3);
  CHECK(torch::equal(turning.light_fields.frame(1).data(), render_scene(spec).light_field.data()));
  for (const int64_t t : {0, 2}) {
    const double diff =
        (turning.light_fields.frame(t).data() - turning.light_fields.frame(1).data())
            .abs()
            .max()
            .item<double>();
    CHECK(diff > 0.2);
  }
}

TEST_CASE("sequences do not depend on the thread count", "[scene][motion][render]") {
  json doc = motion_disk_scene();
  doc["layers"][1]["motion"] = {{"shift", {0.7, 1.3}}, {"rotation", 4}, {"scale", 1.1}};
  doc["layers"][0]["motion"] = {{"shift", {-0.5, 0}}};
  doc["effects"] = {{"defocus", json::object()}};
  const auto spec = SceneSpec::from_json(doc);
  const int threads = lfnet::thread_count();
  lfnet::configure_threads(1);
  const auto one = render_sequence(spec, 2);
  lfnet::configure_threads(2);
  const auto two = render_sequence(spec, 2);
  lfnet::configure_threads(threads);
  CHECK(torch::equal(one.light_fields.data(), two.light_fields.data()));
  CHECK(torch::equal(one.disparity, two.disparity));
  CHECK_FALSE(torch::equal(one.light_fields.frame(0).data(), one.light_fields.frame(1).data()));
}

TEST_CASE("a motion spec round-trips through JSON and is read strictly", "[scene][motion][spec]") {
  json doc = motion_disk_scene();
  doc["layers"][1]["motion"] =
      json::parse(R"({"shift": [1.5, -2], "disparity": 0.25, "rotation": -3, "scale": 1.05})");
  const auto spec = SceneSpec::from_json(doc);
  REQUIRE(spec.layers[1].motion);
  CHECK(spec.layers[1].motion->shift.y == -2.0);
  CHECK(spec.layers[1].motion->scale == 1.05);
  CHECK_FALSE(spec.layers[0].motion);
  const json once = spec.to_json();
  CHECK(once["layers"][1]["motion"] == doc["layers"][1]["motion"]);
  CHECK_FALSE(once["layers"][0].contains("motion"));
  CHECK(SceneSpec::from_json(once).to_json() == once);

  // Defaults fill what a motion leaves out.
  doc["layers"][1]["motion"] = {{"rotation", 2}};
  const auto partial = SceneSpec::from_json(doc).layers[1].motion.value();
  CHECK(partial.shift.x == 0.0);
  CHECK(partial.disparity == 0.0);
  CHECK(partial.scale == 1.0);

  const std::vector<std::pair<json, std::string>> bad = {
      {{{"speed", 2}}, "$.layers[1].motion.speed"},
      {{{"shift", 2}}, "$.layers[1].motion.shift"},
      {{{"scale", 3}}, "$.layers[1].motion.scale"},
      {{{"rotation", "fast"}}, "$.layers[1].motion.rotation"},
      {json::array(), "$.layers[1].motion"}};
  for (const auto& [motion, path] : bad) {
    INFO(motion.dump());
    doc["layers"][1]["motion"] = motion;
    CHECK_THAT(motion_parse_error(doc), Catch::StartsWith(path + ":"));
  }
}

TEST_CASE("render_sequence refuses bad frame counts and motion beyond the scene's limits",
          "[scene][motion][render]") {
  json doc = motion_disk_scene();
  doc["layers"][1]["motion"] = {{"scale", 1.5}};
  const auto spec = SceneSpec::from_json(doc);
  CHECK_THROWS_AS(render_sequence(spec, 0), lfnet::ConfigError);
  CHECK_THROWS_WITH(render_sequence(spec, 65), Catch::Contains("[1, 64]"));
  // 1.5^4.5 is more than 4.
  CHECK_THROWS_WITH(render_sequence(spec, 10), Catch::Contains("$.layers[1].motion.scale"));
  CHECK_NOTHROW(render_sequence(spec, 3));
  doc["layers"][1]["motion"] = {{"disparity", 40}};
  CHECK_THROWS_WITH(render_sequence(SceneSpec::from_json(doc), 64),
                    Catch::Contains("sub-frame 0 of 64") && Catch::Contains("$.layers"));
}

TEST_CASE("random scenes move only when their options ask", "[scene][motion][random]") {
  lfnet::scene::RandomSceneOptions still;
  still.height = 40;
  still.width = 48;
  lfnet::scene::RandomSceneOptions moving = still;
  moving.max_speed = 2.0;
  moving.max_disparity_speed = 0.1;
  moving.max_rotation = 5.0;
  moving.motion_probability = 1.0;
  int64_t moved = 0;
  for (uint64_t seed = 0; seed < 8; ++seed) {
    INFO("seed " << seed);
    const auto a = lfnet::scene::random_scene(seed, still);
    CHECK_FALSE(a.moves());
    CHECK(a.to_json().dump().find("motion") == std::string::npos);
    auto b = lfnet::scene::random_scene(seed, moving);
    REQUIRE(b.layers.size() == a.layers.size());
    for (auto& layer : b.layers) {
      if (!layer.motion) continue;
      ++moved;
      CHECK(std::hypot(layer.motion->shift.x, layer.motion->shift.y) <= 2.0 + 1e-4);
      CHECK(std::abs(layer.motion->disparity) <= 0.1);
      CHECK(std::abs(layer.motion->rotation) <= 5.0);
      layer.motion.reset();
    }
    // Motion is drawn from a stream of its own: the still scene underneath is the same.
    CHECK(b.to_json() == a.to_json());
  }
  CHECK(moved > 20);
  // The options round-trip, and a bad speed names its key.
  const auto j = moving.to_json();
  CHECK(j["max_speed"] == 2.0);
  lfnet::JsonReader reader(j, "$");
  CHECK(lfnet::scene::RandomSceneOptions::from_json(reader).to_json() == j);
  moving.max_speed = -1.0;
  CHECK_THROWS_WITH(moving.validate("opts"), Catch::StartsWith("opts.max_speed"));
}

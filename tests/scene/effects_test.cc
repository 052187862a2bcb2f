// Effects run only when a scene names them, and change the light field when they do.
#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/scene/render.h"
#include "support/test_support.h"

using lfnet::scene::render_scene;
using lfnet::scene::RenderResult;
using lfnet::scene::SceneSpec;
using nlohmann::json;

namespace {

// A textured background at disparity -1 and a checkered disk in front at 1.5.
json base_scene() {
  return json::parse(R"({"height": 48, "width": 64, "seed": 5, "layers": [
      {"texture": {"kind": "fractal", "scale": 32, "colors": [0.2, 0.7]}, "disparity": -1},
      {"texture": {"kind": "checker", "size": 3, "colors": [0.1, 0.9]},
       "shape": {"kind": "disk", "radius": 12, "center": [32, 24]}, "disparity": 1.5}]})");
}

RenderResult render(const json& doc) { return render_scene(SceneSpec::from_json(doc)); }

json with_effect(const std::string& name, const json& value) {
  json doc = base_scene();
  doc["effects"][name] = value;
  return doc;
}

}  // namespace

TEST_CASE("a scene that does not name an effect does not run it", "[scene][effects]") {
  const auto base = render(base_scene());
  CHECK(base.effects_run == std::vector<std::string>{"occlusion"});
  // Each effect named at zero strength runs (the record says so) and changes nothing: the plain
  // composite is all the unnamed scene computes.
  const std::vector<std::pair<std::string, json>> idle = {
      {"specular", {{"strength", 0.0}}},
      {"vignetting", {{"strength", 0.0}, {"angular", 0.0}}},
      {"defocus", {{"blur", 0.0}}}};
  for (const auto& [name, value] : idle) {
    INFO(name);
    const auto result = render(with_effect(name, value));
    CHECK(result.effects_run == std::vector<std::string>{"occlusion", name});
    CHECK(torch::equal(result.light_field.data(), base.light_field.data()));
  }
  // The sensor block is for the simulator: kept, not run.
  json doc = base_scene();
  doc["sensor"] = {{"gaussian", {{"sigma", 0.1}}}};
  const auto sensed = render(doc);
  CHECK(sensed.effects_run == std::vector<std::string>{"occlusion"});
  CHECK(torch::equal(sensed.light_field.data(), base.light_field.data()));
  // One layer: not even occlusion.
  doc = base_scene();
  doc["layers"].erase(1);
  CHECK(render(doc).effects_run.empty());
}

TEST_CASE("specular highlights add light that depends on the view", "[scene][effects]") {
  const auto base = render(base_scene());
  const auto lit =
      render(with_effect("specular", {{"count", 3}, {"strength", 0.8}, {"lobe", 1.0}}));
  CHECK(lit.effects_run == std::vector<std::string>{"occlusion", "specular"});
  const auto diff = lit.light_field.data() - base.light_field.data();
  CHECK(diff.min().item<double>() >= 0.0);
  CHECK(diff.max().item<double>() > 0.1);
  // Brightness varies across views (a narrow lobe), unlike a Lambertian surface.
  const auto per_view = diff.sum({0, 3, 4});
  CHECK(per_view.max().item<double>() > 3.0 * per_view.min().item<double>() + 1e-3);
}

TEST_CASE("specular highlights move with their own disparity", "[scene][effects]") {
  // A flat surface at disparity -1 with many small highlights at offset -1: they move with -2 px
  // per view step, not with the surface's -1.
  const json doc = json::parse(R"({"height": 64, "width": 96, "color": false, "seed": 2,
      "layers": [{"texture": {"kind": "constant", "colors": [0.3]}, "disparity": -1}],
      "effects": {"specular": {"count": 25, "sigma": 1.5, "lobe": 100, "strength": 0.5,
                               "disparity_offset": -1}}})");
  const auto lf = render(doc).light_field;
  const auto a = lf.view(2, 0)[0] - 0.3;
  const auto b = lf.view(2, 4)[0] - 0.3;
  // The horizontal shift that best maps view (2, 0)'s highlights onto view (2, 4)'s.
  int64_t best = 0;
  double best_score = -1.0;
  for (int64_t s = -12; s <= 12; ++s) {
    const double score = (torch::roll(a, {s}, {1}) * b).slice(1, 12, 84).sum().item<double>();
    if (score > best_score) {
      best_score = score;
      best = s;
    }
  }
  CHECK(best == -8);  // (d + offset) * (4 - 0) = -2 * 4
}

TEST_CASE("vignetting darkens the image corners and the outer views as specified",
          "[scene][effects]") {
  const auto base = render(base_scene());
  const double strength = 0.5, angular = 0.3, shift = 0.2;
  const auto dark = render(with_effect(
      "vignetting",
      {{"strength", strength}, {"power", 2.0}, {"angular", angular}, {"shift", shift}}));
  CHECK(dark.effects_run == std::vector<std::string>{"occlusion", "vignetting"});
  // The documented factor, computed here independently.
  const double h = 48, w = 64;
  auto xs = torch::arange(64, torch::kFloat64).view({1, 64});
  auto ys = torch::arange(48, torch::kFloat64).view({48, 1});
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) {
      const double nu = (u - 2) / 2.0, nv = (v - 2) / 2.0;
      const double cx = (w - 1) / 2 + shift * nv * w / 2, cy = (h - 1) / 2 + shift * nu * h / 2;
      const auto r = ((xs - cx).pow(2) + (ys - cy).pow(2)).sqrt() / std::hypot(w / 2, h / 2);
      const auto factor = (1.0 - angular * 0.5 * (nu * nu + nv * nv)) * (1.0 - strength * r.pow(2));
      const auto before = base.light_field.view(u, v).to(torch::kFloat64);
      const auto after = dark.light_field.view(u, v).to(torch::kFloat64);
      // Where the plain render was clipped (cubic overshoot at sharp edges), the vignetted one
      // is clipped after the factor: compare the rest.
      const auto unclipped = (before > 0.0) & (before < 1.0);
      CHECK(unclipped.to(torch::kFloat64).mean().item<double>() > 0.95);
      INFO("view (" << u << ", " << v << ")");
      lfnet::test::require_close(after.masked_select(unclipped),
                                 (before * factor).masked_select(unclipped), 1e-6);
    }
  }
  // Corner views are darker than the centre view overall.
  const auto mean = [&](int64_t u, int64_t v) {
    return dark.light_field.view(u, v).mean().item<double>();
  };
  CHECK(mean(0, 0) < 0.85 * mean(2, 2));
}

TEST_CASE("defocus blurs layers by their distance from the focal plane", "[scene][effects]") {
  const auto base = render(base_scene());
  // Focus on the background: it stays sharp, the disk (2.5 px of disparity away) blurs.
  const auto blurred = render(with_effect("defocus", {{"focus_disparity", -1.0}, {"blur", 0.6}}));
  CHECK(blurred.effects_run == std::vector<std::string>{"occlusion", "defocus"});
  const auto a = base.light_field.view(2, 2);
  const auto b = blurred.light_field.view(2, 2);
  // Far from the disk (radius 12 + blur reach 3 * 1.5 px), the background is untouched.
  CHECK(torch::equal(a.slice(1, 0, 4), b.slice(1, 0, 4)));
  // Inside the disk, the checker's fine detail is smoothed.
  auto detail = [](const torch::Tensor& img) {
    const auto c = img.slice(1, 18, 30).slice(2, 26, 38);
    return (c.slice(2, 1) - c.slice(2, 0, -1)).abs().mean().item<double>();
  };
  CHECK(detail(b) < 0.5 * detail(a));
  // The true disparity is geometry: defocus does not change it.
  CHECK(torch::equal(blurred.disparity, base.disparity));
}

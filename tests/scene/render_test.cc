// The renderer's geometry: exact integer shifts, band-limited fractional shifts, slanted planes,
// occlusion with the right parallax, shapes, textures, determinism.
#include "lfnet/scene/render.h"

#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/core/runtime.h"
#include "support/test_support.h"

using lfnet::scene::render_scene;
using lfnet::scene::SceneSpec;
using nlohmann::json;

namespace {

constexpr double kPi = 3.14159265358979323846;

SceneSpec scene(const std::string& text) { return SceneSpec::from_json(json::parse(text)); }

// A one-layer scene of a full-frame texture at disparity d.
SceneSpec one_layer(const std::string& texture, double d, bool color = false, int64_t h = 48,
                    int64_t w = 64) {
  json j = {{"height", h},
            {"width", w},
            {"color", color},
            {"seed", 3},
            {"layers", {{{"texture", json::parse(texture)}, {"disparity", d}}}}};
  return SceneSpec::from_json(j);
}

}  // namespace

TEST_CASE("integer disparity gives views that are exact shifts of the centre view",
          "[scene][render]") {
  for (const bool color : {false, true}) {
    for (const int64_t d : {2, -1, 3}) {
      INFO("colour " << color << ", disparity " << d);
      const auto spec = one_layer(R"({"kind": "fractal", "scale": 16, "beta": 2})", d, color);
      const auto result = render_scene(spec);
      const auto& lf = result.light_field;
      REQUIRE(lf.channels() == (color ? 3 : 1));
      REQUIRE(lf.rows() == 5);
      REQUIRE(lf.cols() == 5);
      const auto centre = lf.view(2, 2);
      const int64_t m = 2 * std::abs(d);  // the largest shift: views at +-2 steps
      for (int64_t u = 0; u < 5; ++u) {
        for (int64_t v = 0; v < 5; ++v) {
          const int64_t du = d * (u - 2);
          const int64_t dv = d * (v - 2);
          // View (u, v) shows the centre's content moved by (du, dv): compare on the interior,
          // where torch::roll's wrap-around does not reach.
          const auto want = torch::roll(centre, {du, dv}, {1, 2})
                                .slice(1, m, lf.height() - m)
                                .slice(2, m, lf.width() - m);
          const auto got = lf.view(u, v).slice(1, m, lf.height() - m).slice(2, m, lf.width() - m);
          REQUIRE(torch::equal(got, want));
        }
      }
      // The view's border shows texture from beyond the centre view's frame, not a fill.
      const auto edge = lf.view(0, 0).select(1, 0);
      CHECK(edge.std().item<double>() > 0.01);
      CHECK(torch::allclose(result.disparity, torch::full({48, 64}, static_cast<float>(d))));
    }
  }
}

TEST_CASE("fractional disparity shifts a sine grating by the right amount", "[scene][render]") {
  // t = 0.5 + 0.5 sin(2 pi x / P) through the ramp [0.2, 0.8]: 0.5 + 0.3 sin(2 pi x / P).
  const double period = 16.0;
  const auto spec = one_layer(
      R"({"kind": "stripes", "profile": "sine", "period": 16, "colors": [0.2, 0.8]})", 0.5);
  const auto lf = render_scene(spec).light_field;
  const int64_t w = lf.width();
  auto x = torch::arange(w, torch::kFloat64);
  for (int64_t v = 0; v < 5; ++v) {
    const double shift = 0.5 * static_cast<double>(v - 2);
    const auto want = 0.5 + 0.3 * torch::sin(2.0 * kPi * (x - shift) / period);
    for (int64_t u : {0, 2, 4}) {
      INFO("view (" << u << ", " << v << "), horizontal shift " << shift);
      const auto row = lf.view(u, v)[0][10].to(torch::kFloat64);
      // Catmull-Rom's error on a 16 px period is about 1e-3 at half a pixel.
      lfnet::test::require_close(row, want, 2.5e-3);
    }
  }
  // Half-pixel views are not copies of their neighbours: the shift is real.
  CHECK((lf.view(2, 3) - lf.view(2, 2)).abs().max().item<double>() > 0.05);
  // Values stay in the grating's range (cubic overshoot is tiny on smooth content).
  CHECK(lf.data().min().item<double>() > 0.2 - 2e-3);
  CHECK(lf.data().max().item<double>() < 0.8 + 2e-3);
}

TEST_CASE("a slanted plane shows the parallax of its local disparity", "[scene][render]") {
  // Disparity grows downwards: d(y) = 0.5 + 0.02 (y - cy).
  const double period = 12.0;
  const double d0 = 0.5;
  const double gy = 0.02;
  SceneSpec spec = scene(R"({"height": 48, "width": 64, "color": false, "layers": [
      {"texture": {"kind": "stripes", "profile": "sine", "period": 12, "colors": [0.2, 0.8]},
       "disparity": 0.5, "disparity_gradient": [0, 0.02]}]})");
  auto result = render_scene(spec);
  const double cy = (48 - 1) / 2.0;
  auto x = torch::arange(64, torch::kFloat64);
  // Horizontal parallax: view (2, v) row y is the grating moved by d(y) (v - 2).
  for (int64_t y : {5, 24, 40}) {
    const double d = d0 + gy * (y - cy);
    for (int64_t v : {0, 1, 4}) {
      INFO("row " << y << ", view column " << v);
      const auto want = 0.5 + 0.3 * torch::sin(2.0 * kPi * (x - d * (v - 2)) / period);
      lfnet::test::require_close(result.light_field.view(2, v)[0][y].to(torch::kFloat64), want,
                                 4e-3);
    }
  }
  // The true disparity is the plane.
  auto ys = torch::arange(48, torch::kFloat32).view({48, 1}).expand({48, 64});
  lfnet::test::require_close(result.disparity, d0 + gy * (ys - cy), 1e-5);

  // Vertical parallax of horizontal stripes: view (u, 2) at row q shows the plane point p with
  // p + d(p) s = q, s = u - 2, so p = cy + (q - cy - d0 s) / (1 + gy s).
  spec.layers[0].texture.angle = 90.0;
  result = render_scene(spec);
  for (int64_t u : {0, 3, 4}) {
    const double s = static_cast<double>(u - 2);
    auto q = torch::arange(48, torch::kFloat64);
    auto p = cy + (q - cy - d0 * s) / (1.0 + gy * s);
    const auto want = 0.5 + 0.3 * torch::sin(2.0 * kPi * p / period);
    INFO("view row " << u);
    lfnet::test::require_close(result.light_field.view(u, 2).select(2, 30)[0].to(torch::kFloat64),
                               want, 4e-3);
  }
}

TEST_CASE("a near layer occludes a far one with the parallax of its own edge", "[scene][render]") {
  // Far: textured, disparity -1. Near: a flat 0.9 rectangle over pixels x 31..50, y 25..40 of the
  // centre view, disparity +2, edges hard.
  const std::string far = R"({"texture": {"kind": "fractal", "scale": 8}, "disparity": -1})";
  const std::string near = R"({"texture": {"kind": "constant", "colors": [0.9]},
      "shape": {"kind": "rectangle", "center": [40.5, 32.5], "size": [20, 16], "softness": 0.05},
      "disparity": 2})";
  const auto both = render_scene(scene(R"({"height": 64, "width": 80, "color": false, "seed": 1,
                                           "layers": [)" +
                                       far + "," + near + "]}"));
  const auto back = render_scene(scene(R"({"height": 64, "width": 80, "color": false, "seed": 1,
                                           "layers": [)" +
                                       far + "]}"));
  CHECK(both.effects_run == std::vector<std::string>{"occlusion"});
  CHECK(back.effects_run.empty());
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) {
      INFO("view (" << u << ", " << v << ")");
      const int64_t du = 2 * (u - 2);
      const int64_t dv = 2 * (v - 2);
      auto inside = torch::zeros({64, 80}, torch::kBool);
      inside.slice(0, 25 + du, 41 + du).slice(1, 31 + dv, 51 + dv).fill_(true);
      const auto view = both.light_field.view(u, v)[0];
      // The rectangle, moved by its own disparity, hides the far layer completely...
      CHECK(view.masked_select(inside).eq(0.9f).all().item<bool>());
      // ...and everywhere else the far layer shows exactly as it does alone, moved by -1 per
      // view: its edge pixels just outside the rectangle included.
      const auto alone = back.light_field.view(u, v)[0];
      CHECK(torch::equal(view.masked_select(~inside), alone.masked_select(~inside)));
    }
  }
  // The far layer's content really moves the other way: its views differ from the centre's.
  CHECK_FALSE(torch::equal(back.light_field.view(2, 0), back.light_field.view(2, 2)));
  // Disparity map: 2 on the rectangle, -1 elsewhere.
  auto want = torch::full({64, 80}, -1.0f);
  want.slice(0, 25, 41).slice(1, 31, 51).fill_(2.0f);
  CHECK(torch::equal(both.disparity, want));
}

TEST_CASE("shapes cover the area they should, with soft edges", "[scene][render]") {
  auto coverage = [](const std::string& shape) {
    const auto spec = scene(R"({"height": 100, "width": 120, "rows": 1, "cols": 1, "color": false,
        "layers": [{"texture": {"kind": "constant", "colors": [1]}, "shape": )" +
                            shape + "}]}");
    return render_scene(spec).light_field.data().sum().item<double>();
  };
  CHECK(coverage(R"({"kind": "disk", "radius": 30, "center": [60, 50]})") ==
        Approx(kPi * 900.0).epsilon(0.002));
  CHECK(
      coverage(R"({"kind": "rectangle", "size": [40, 30], "center": [60.3, 50.1], "angle": 30})") ==
      Approx(1200.0).epsilon(0.002));
  CHECK(coverage(R"({"kind": "polygon", "points": [[20, 20], [80, 20], [20, 70]]})") ==
        Approx(0.5 * 60 * 50).epsilon(0.005));
  // Bars of width 3 every 12 px cover a quarter of the frame; three bars cover 3 * 3 * 100.
  CHECK(coverage(R"({"kind": "bars", "width": 3, "period": 12})") ==
        Approx(0.25 * 100 * 120).epsilon(0.01));
  CHECK(coverage(R"({"kind": "bars", "width": 3, "period": 12, "count": 3})") ==
        Approx(900.0).epsilon(0.002));
  CHECK(coverage(R"({"kind": "disk", "radius": 30, "invert": true})") ==
        Approx(12000.0 - kPi * 900.0).epsilon(0.002));

  // A square as a polygon and as a rectangle give the same alpha.
  auto alpha = [](const std::string& shape) {
    const auto spec = scene(R"({"height": 40, "width": 40, "rows": 1, "cols": 1, "color": false,
        "layers": [{"texture": {"kind": "constant", "colors": [1]}, "shape": )" +
                            shape + "}]}");
    return render_scene(spec).light_field.data();
  };
  lfnet::test::require_close(
      alpha(
          R"({"kind": "polygon", "points": [[10.2, 10.7], [30.2, 10.7], [30.2, 25.7], [10.2, 25.7]]})"),
      alpha(R"({"kind": "rectangle", "center": [20.2, 18.2], "size": [20, 15]})"), 1e-6);
  // The edge ramp: a pixel centre on the boundary is half covered, `softness` / 2 inside is full.
  const auto soft =
      alpha(R"({"kind": "rectangle", "center": [20, 20], "size": [20, 20], "softness": 4})");
  CHECK(soft[0][0][0][20][10].item<double>() == Approx(0.5));
  CHECK(soft[0][0][0][20][12].item<double>() == Approx(1.0));
  CHECK(soft[0][0][0][20][9].item<double>() == Approx(0.25));
}

TEST_CASE("fractal textures have a 1/f^beta power spectrum", "[scene][render]") {
  for (const double beta : {2.0, 3.0}) {
    INFO("beta " << beta);
    // A low contrast keeps Phi(contrast z) nearly linear, so t has z's spectrum.
    json texture = {{"kind", "fractal"}, {"scale", 256}, {"beta", beta}, {"contrast", 0.25}};
    const auto spec = one_layer(texture.dump(), 0.0, false, 256, 256);
    auto img = render_scene(spec).light_field.view(2, 2)[0].to(torch::kFloat64);
    img = img - img.mean();
    const auto power = torch::fft::fft2(img).abs().pow(2);
    auto f = torch::fft::fftfreq(256, 1.0, torch::kFloat64);
    const auto radius = (f.view({256, 1}).pow(2) + f.view({1, 256}).pow(2)).sqrt();
    // Mean power in log-spaced rings from 1/64 to 1/4 cycles per pixel; least-squares slope.
    std::vector<double> lx;
    std::vector<double> ly;
    for (double lo = 1.0 / 64; lo < 0.25; lo *= 1.25) {
      const auto ring = (radius >= lo) & (radius < lo * 1.25);
      lx.push_back(std::log(lo * 1.118));
      ly.push_back(std::log(power.masked_select(ring).mean().item<double>()));
    }
    const auto n = static_cast<double>(lx.size());
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (size_t i = 0; i < lx.size(); ++i) {
      sx += lx[i];
      sy += ly[i];
      sxx += lx[i] * lx[i];
      sxy += lx[i] * ly[i];
    }
    const double slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    CHECK(slope == Approx(-beta).margin(0.4));
  }
}

TEST_CASE("image textures come through the loader hook", "[scene][render]") {
  // A 40 x 60 image, stretched onto a 40 x 60 view at disparity 0: the centre view is the image.
  auto image = torch::rand({3, 40, 60}, torch::TensorOptions().dtype(torch::kFloat32));
  std::string asked;
  lfnet::scene::RenderOptions options;
  options.base_dir = "/data/scenes";
  options.image_loader = [&](const std::string& path) {
    asked = path;
    return image;
  };
  const auto spec = scene(R"({"height": 40, "width": 60, "layers": [
      {"texture": {"kind": "image", "path": "textures/wall.png", "fit": "stretch"}}]})");
  const auto lf = render_scene(spec, options).light_field;
  CHECK(asked == "/data/scenes/textures/wall.png");
  lfnet::test::require_close(lf.view(2, 2), image, 1e-6);
  // "cover" keeps the aspect ratio: a 20 x 60 image on a 40 x 60 view is scaled by 2 and cropped.
  image = torch::rand({1, 20, 60});
  const auto covered = render_scene(scene(R"({"height": 40, "width": 60, "color": false,
      "layers": [{"texture": {"kind": "image", "path": "/abs.png"}}]})"),
                                    options)
                           .light_field;
  CHECK(asked == "/abs.png");
  // View pixel (x, y) samples the image at ((x + 0.5) / 2 - 0.5 + 15, (y + 0.5) / 2 - 0.5):
  // pixel (2, 1) at (15.75, 0.25), bilinearly.
  const auto im = image[0].to(torch::kFloat64);
  const double want = 0.75 * (0.25 * im[0][15] + 0.75 * im[0][16]).item<double>() +
                      0.25 * (0.25 * im[1][15] + 0.75 * im[1][16]).item<double>();
  CHECK(covered.view(2, 2)[0][1][2].item<double>() == Approx(want).margin(1e-5));
  // Without a loader the renderer says what is missing.
  CHECK_THROWS_AS(render_scene(spec), lfnet::ConfigError);
  CHECK_THROWS_WITH(render_scene(spec), Catch::Contains("image loader"));
}

TEST_CASE("the same spec renders bit-identically, whatever the thread count", "[scene][render]") {
  const auto spec = scene(R"({"height": 50, "width": 70, "seed": 11, "layers": [
      {"texture": {"kind": "fractal"}, "disparity": -0.7, "disparity_gradient": [0.01, 0.005]},
      {"texture": {"kind": "noise", "scale": 3}, "shape": {"kind": "disk", "radius": 12},
       "disparity": 1.3}],
      "effects": {"specular": {}, "defocus": {}, "vignetting": {}}})");
  const int threads = lfnet::thread_count();
  lfnet::configure_threads(1);
  const auto one = render_scene(spec);
  lfnet::configure_threads(2);
  const auto two = render_scene(spec);
  const auto again = render_scene(spec);
  lfnet::configure_threads(threads);
  CHECK(torch::equal(one.light_field.data(), two.light_field.data()));
  CHECK(torch::equal(two.light_field.data(), again.light_field.data()));
  CHECK(torch::equal(one.disparity, two.disparity));
  // Another seed gives another texture.
  auto other = spec;
  other.seed = 12;
  CHECK_FALSE(torch::equal(render_scene(other).light_field.data(), one.light_field.data()));
}

TEST_CASE("textures do not change when the canvas does", "[scene][render]") {
  // The same texture at disparity 0 and 3: the larger canvas must not alter the centre view.
  for (const std::string texture :
       {R"({"kind": "fractal", "scale": 40})", R"({"kind": "noise", "scale": 2.5})",
        R"({"kind": "checker", "size": 3, "angle": 20})"}) {
    INFO(texture);
    const auto a = render_scene(one_layer(texture, 0.0)).light_field.view(2, 2);
    const auto b = render_scene(one_layer(texture, 3.0)).light_field.view(2, 2);
    CHECK(torch::equal(a, b));
  }
}

TEST_CASE("a grey scene is the luma of the colour scene", "[scene][render]") {
  auto spec = scene(R"({"height": 40, "width": 56, "seed": 8, "layers": [
      {"texture": {"kind": "fractal", "colors": [[0.9, 0.1, 0.2], [0.1, 0.8, 0.3]]},
       "disparity": -0.6, "disparity_gradient": [0.004, 0]},
      {"texture": {"kind": "stripes", "period": 7, "colors": [[0.2, 0.3, 0.8], [0.9, 0.85, 0.1]]},
       "shape": {"kind": "disk", "radius": 11}, "disparity": 1.3}],
      "effects": {"vignetting": {}}})");
  const auto colour = render_scene(spec).light_field;
  spec.color = false;
  const auto grey = render_scene(spec).light_field;
  REQUIRE(grey.channels() == 1);
  // Rendering is linear in colour: equal up to float rounding (the colours keep every value
  // inside [0, 1], so the final clip does not act).
  lfnet::test::require_close(grey.data(), colour.grey().data(), 1e-5);
}

// Scene specs: JSON round trips and strict parsing that names the JSON path of every mistake.
#include "lfnet/scene/scene_spec.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::scene::SceneSpec;
using nlohmann::json;

namespace {

// A scene that uses every texture, shape and effect.
json full_scene() {
  return json::parse(R"({
    "name": "everything", "description": "all keys",
    "height": 40, "width": 50, "rows": 3, "cols": 5, "color": true, "seed": 7,
    "layers": [
      {"name": "back", "texture": {"kind": "fractal", "beta": 2.5, "scale": 32, "contrast": 1.5,
        "colors": [[0.1, 0.2, 0.3], 0.5, [0.9, 0.8, 0.7]], "seed": 99},
       "disparity": -1.5, "disparity_gradient": [0.01, -0.02]},
      {"texture": {"kind": "noise", "scale": 2}, "shape": {"kind": "disk", "center": [10, 12],
        "radius": 6, "softness": 2}, "disparity": 0.5, "opacity": 0.8, "gloss": 0.3},
      {"texture": {"kind": "stripes", "period": 6, "duty": 0.3, "profile": "sine", "phase": 0.25,
        "angle": 30}, "shape": {"kind": "rectangle", "center": [25, 20], "size": [10, 5],
        "angle": 15, "invert": true}, "disparity": 1},
      {"texture": {"kind": "checker", "size": 3, "angle": 45}, "shape": {"kind": "polygon",
        "points": [[0, 0], [10, 0], [5, 8]]}, "disparity": 1.25},
      {"texture": {"kind": "gradient", "profile": "radial", "center": [3, 4], "length": 20},
       "shape": {"kind": "bars", "width": 2, "period": 9, "angle": 80, "count": 3}, "disparity": 2},
      {"texture": {"kind": "constant", "colors": [[1, 0, 0]]}, "shape": {"kind": "full"},
       "disparity": 2.5},
      {"texture": {"kind": "image", "path": "tex.png", "fit": "stretch"}, "disparity": 0,
       "shape": {"kind": "disk", "radius": 3}}
    ],
    "effects": {"specular": {"count": 2, "strength": 0.5, "sigma": 3, "lobe": 1, "disparity_offset": -0.5,
                             "color": [1, 0.9, 0.8], "seed": 3},
                "vignetting": {"strength": 0.2, "power": 3, "angular": 0.1, "shift": -0.1},
                "defocus": {"focus_disparity": 0.5, "blur": 0.25, "max_sigma": 4}},
    "sensor": {"shot": {"photons": 1000}, "read": {"electrons": 2.5}, "anything": [1, "two"]}
  })");
}

// Parses `doc` and returns the ConfigError's message ("" if it parsed).
std::string parse_error(const json& doc) {
  try {
    SceneSpec::from_json(doc);
  } catch (const lfnet::ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("a scene spec round-trips through JSON", "[scene][spec]") {
  const SceneSpec spec = SceneSpec::from_json(full_scene());
  REQUIRE(spec.layers.size() == 7);
  CHECK(spec.rows == 3);
  CHECK(spec.cols == 5);
  CHECK(spec.seed == 7);
  CHECK(spec.layers[0].texture.kind == lfnet::scene::TextureKind::kFractal);
  CHECK(spec.layers[0].texture.colors[1] == lfnet::scene::Rgb{0.5, 0.5, 0.5});
  CHECK(spec.layers[0].texture.seed.value() == 99);
  CHECK(spec.layers[0].disparity_gradient.y == -0.02);
  CHECK(spec.layers[2].shape.invert);
  CHECK(spec.layers[4].shape.count == 3);
  CHECK(spec.specular->color[2] == 0.8);
  CHECK(spec.defocus->max_sigma == 4.0);
  // The sensor block is kept verbatim, uninterpreted.
  CHECK(*spec.sensor == full_scene()["sensor"]);

  const json once = spec.to_json();
  const SceneSpec again = SceneSpec::from_json(once);
  CHECK(again.to_json() == once);
  CHECK(once["layers"][1]["shape"]["radius"] == 6.0);
  CHECK(once["effects"]["vignetting"]["power"] == 3.0);
}

TEST_CASE("defaults fill what a scene leaves out", "[scene][spec]") {
  const SceneSpec spec = SceneSpec::from_json(
      json::parse(R"({"height": 8, "width": 9, "layers": [{"texture": {"kind": "noise"}}]})"));
  CHECK(spec.rows == 5);
  CHECK(spec.cols == 5);
  CHECK(spec.color);
  CHECK(spec.seed == 0);
  CHECK(spec.layers[0].shape.kind == lfnet::scene::ShapeKind::kFull);
  CHECK(spec.layers[0].disparity == 0.0);
  CHECK(spec.layers[0].texture.scale == 4.0);
  CHECK_FALSE(spec.specular);
  CHECK_FALSE(spec.vignetting);
  CHECK_FALSE(spec.defocus);
  CHECK_FALSE(spec.sensor);
  CHECK_FALSE(spec.to_json().contains("effects"));
  CHECK(lfnet::scene::TextureSpec::defaults(lfnet::scene::TextureKind::kFractal).scale == 128.0);
}

TEST_CASE("strict parsing names the JSON path of the mistake", "[scene][spec]") {
  struct Case {
    std::string what;
    std::function<void(json&)> edit;
    std::string path;
  };
  const std::vector<Case> cases = {
      {"unknown texture key", [](json& j) { j["layers"][2]["texture"]["wood"] = 1; },
       "$.layers[2].texture.wood"},
      {"unknown texture kind", [](json& j) { j["layers"][2]["texture"]["kind"] = "wood"; },
       "$.layers[2].texture.kind"},
      {"a key of another kind", [](json& j) { j["layers"][1]["texture"]["duty"] = 0.5; },
       "$.layers[1].texture.duty"},
      {"unknown shape kind", [](json& j) { j["layers"][3]["shape"]["kind"] = "star"; },
       "$.layers[3].shape.kind"},
      {"negative radius", [](json& j) { j["layers"][1]["shape"]["radius"] = -2; },
       "$.layers[1].shape.radius"},
      {"missing radius", [](json& j) { j["layers"][1]["shape"].erase("radius"); },
       "$.layers[1].shape.radius"},
      {"polygon of two points",
       [](json& j) { j["layers"][3]["shape"]["points"] = json::parse("[[0,0],[1,1]]"); },
       "$.layers[3].shape.points"},
      {"bad point", [](json& j) { j["layers"][1]["shape"]["center"] = json::parse("[1]"); },
       "$.layers[1].shape.center"},
      {"missing height", [](json& j) { j.erase("height"); }, "$.height"},
      {"fractional rows", [](json& j) { j["rows"] = 2.5; }, "$.rows"},
      {"string as bool", [](json& j) { j["color"] = "yes"; }, "$.color"},
      {"negative seed", [](json& j) { j["seed"] = -1; }, "$.seed"},
      {"colour out of range",
       [](json& j) { j["layers"][0]["texture"]["colors"][1] = json::parse("[0, 2, 0]"); },
       "$.layers[0].texture.colors[1]"},
      {"unknown layer key", [](json& j) { j["layers"][4]["depth"] = 3; }, "$.layers[4].depth"},
      {"unknown effect", [](json& j) { j["effects"]["glare"] = json::object(); },
       "$.effects.glare"},
      {"effect value", [](json& j) { j["effects"]["vignetting"]["strength"] = 2; },
       "$.effects.vignetting.strength"},
      {"unknown effect key", [](json& j) { j["effects"]["defocus"]["aperture"] = 2; },
       "$.effects.defocus.aperture"},
      {"sensor not an object", [](json& j) { j["sensor"] = 3; }, "$.sensor"},
      {"too steep a slant",
       [](json& j) { j["layers"][0]["disparity_gradient"] = json::parse("[0.3, 0]"); },
       "$.layers[0].disparity_gradient"},
      {"unknown top-level key", [](json& j) { j["colour"] = true; }, "$.colour"},
      {"no layers", [](json& j) { j["layers"] = json::array(); }, "$.layers"},
      {"opacity above 1", [](json& j) { j["layers"][1]["opacity"] = 1.5; }, "$.layers[1].opacity"},
      {"bars wider than their period", [](json& j) { j["layers"][4]["shape"]["width"] = 10; },
       "$.layers[4].shape.width"},
      {"unknown image fit", [](json& j) { j["layers"][6]["texture"]["fit"] = "tile"; },
       "$.layers[6].texture.fit"},
  };
  CHECK(parse_error(full_scene()).empty());
  for (const auto& c : cases) {
    INFO(c.what);
    json doc = full_scene();
    c.edit(doc);
    const std::string message = parse_error(doc);
    CHECK_THAT(message, Catch::StartsWith(c.path + ":"));
  }
}

TEST_CASE("a render record beside the spec is ignored on reading", "[scene][spec]") {
  json doc = full_scene();
  doc["rendered"] = {{"effects_run", {"occlusion"}}, {"seconds", 0.1}};
  const SceneSpec spec = SceneSpec::from_json(doc);
  CHECK(spec.to_json() == SceneSpec::from_json(full_scene()).to_json());
}

TEST_CASE("load_scene reports the file and the path", "[scene][spec]") {
  lfnet::test::TempDir tmp;
  json doc = full_scene();
  doc["layers"][2]["texture"]["kind"] = "wood";
  lfnet::write_json_file(tmp / "bad.json", doc);
  CHECK_THROWS_WITH(lfnet::scene::load_scene(tmp / "bad.json"),
                    Catch::Contains("$.layers[2].texture.kind") && Catch::Contains("wood"));
  CHECK_THROWS_AS(lfnet::scene::load_scene(tmp / "missing.json"), lfnet::IoError);
}

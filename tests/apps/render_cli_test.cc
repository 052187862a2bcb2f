// lfnet render: the light field folder, disparity map, previews and resolved spec it writes.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>

#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/scene/scene.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;
namespace fs = std::filesystem;

namespace {

const char* kScene = R"({"name": "cli", "height": 24, "width": 32, "rows": 3, "cols": 5, "seed": 4,
  "layers": [{"texture": {"kind": "fractal", "scale": 16}, "disparity": -1},
             {"texture": {"kind": "image", "path": "tex.png", "fit": "stretch"},
              "shape": {"kind": "rectangle", "center": [16, 12], "size": [12, 8]}, "disparity": 1.5}],
  "effects": {"vignetting": {}}, "sensor": {"gaussian": {"sigma": 0.01}}})";

}  // namespace

TEST_CASE("lfnet render writes the light field, disparity, previews and resolved spec",
          "[app][scene]") {
  lfnet::test::TempDir tmp;
  // The image texture is loaded by the program, relative to the scene file.
  const auto texture = torch::rand({3, 10, 14});
  lfnet::io::write_image(tmp / "tex.png", texture, 16);
  lfnet::write_json_file(tmp / "scene.json", nlohmann::json::parse(kScene));
  std::string out;
  const std::string cmd = lfnet_binary() + " --threads 1 render --scene " + (tmp / "scene.json") +
                          " --out " + (tmp / "out");
  REQUIRE(run_command(cmd, out) == 0);
  CHECK(out.find("rendered cli") != std::string::npos);
  for (const char* name : {"lf_1_1.png", "lf_3_5.png", "disparity.pfm", "grid.png", "epi_h.png",
                           "epi_v.png", "preview.png", "scene.json"}) {
    INFO(name);
    CHECK(fs::exists(tmp / "out/" + std::string(name)));
  }

  // The files hold what the library renders (16-bit PNG quantisation aside).
  lfnet::scene::RenderOptions options;
  options.base_dir = tmp.path().string();
  options.image_loader = [](const std::string& path) { return lfnet::io::read_image(path); };
  const auto spec = lfnet::scene::load_scene(tmp / "scene.json");
  const auto want = lfnet::scene::render_scene(spec, options);
  const auto lf = lfnet::io::read_light_field(tmp / "out", 1);
  REQUIRE(lf.shape_string() == "3x3x5x24x32");
  lfnet::test::require_close(lf.data(), want.light_field.data(), 1.0 / 65535.0);
  const auto disparity = lfnet::io::read_pfm(tmp / "out/disparity.pfm");
  lfnet::test::require_close(disparity[0], want.disparity, 0.0);

  // scene.json is the resolved spec plus a record of the run; it renders the same scene again.
  const auto record = lfnet::read_json_file(tmp / "out/scene.json");
  CHECK(record["rendered"]["effects_run"] == nlohmann::json({"occlusion", "vignetting"}));
  CHECK(record["sensor"] == nlohmann::json::parse(R"({"gaussian": {"sigma": 0.01}})"));
  CHECK(record["effects"]["vignetting"]["strength"] == 0.35);
  CHECK(lfnet::scene::SceneSpec::from_json(record).to_json() == spec.to_json());
}

TEST_CASE("lfnet render refuses a non-empty folder unless forced, then replaces it",
          "[app][scene]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "out");
  { std::ofstream(tmp / "out/notes.txt") << "keep me"; }
  const std::string base =
      lfnet_binary() + " --threads 1 render --random 3 --size 16x20 --out " + (tmp / "out");
  std::string out;
  CHECK(run_command(base, out) != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find("--force") != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  REQUIRE(run_command(base + " --force", out) == 0);
  REQUIRE(run_command(base + " --force --views 3x3", out) == 0);  // replaces a 5 x 5 render
  CHECK_FALSE(fs::exists(tmp / "out/notes.txt"));  // the folder is replaced whole, not mixed
  CHECK(lfnet::io::read_light_field(tmp / "out", 1).shape_string() == "3x3x3x16x20");

  // The random scene is the library's random_scene(3) with the options given.
  lfnet::scene::RandomSceneOptions options;
  options.height = 16;
  options.width = 20;
  options.rows = options.cols = 3;
  const auto record = lfnet::read_json_file(tmp / "out/scene.json");
  CHECK(lfnet::scene::SceneSpec::from_json(record).to_json() ==
        lfnet::scene::random_scene(3, options).to_json());
  CHECK(record["rendered"]["source"] == "random 3");
}

TEST_CASE("lfnet render reports bad scenes with their path", "[app][scene]") {
  lfnet::test::TempDir tmp;
  auto doc = nlohmann::json::parse(kScene);
  doc["layers"][1]["texture"]["kind"] = "wood";
  lfnet::write_json_file(tmp / "bad.json", doc);
  std::string out;
  CHECK(run_command(
            lfnet_binary() + " render --scene " + (tmp / "bad.json") + " --out " + (tmp / "out"),
            out) != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find("bad.json") != std::string::npos);
  CHECK(out.find("$.layers[1].texture.kind") != std::string::npos);
  CHECK(run_command(lfnet_binary() + " render --out " + (tmp / "o"), out) != 0);
  CHECK(out.find("exactly one of --scene") != std::string::npos);
  CHECK(run_command(lfnet_binary() + " render --random 1 --size 10by10 --out " + (tmp / "o"),
                    out) != 0);
  CHECK(out.find("--size") != std::string::npos);
}

TEST_CASE("lfnet render takes a random scene's options inline or from a file", "[app][scene]") {
  lfnet::test::TempDir tmp;
  lfnet::scene::RandomSceneOptions options;
  options.height = 24;
  options.width = 32;
  options.frame_probability = 1.0;
  const auto expected = lfnet::scene::random_scene(2, options).to_json();
  lfnet::write_json_file(tmp / "options.json", options.to_json());
  const std::string base = lfnet_binary() + " --threads 1 render --random 2 --out ";
  std::string out;
  REQUIRE(run_command(base + (tmp / "a") + " --random-options " + (tmp / "options.json"), out) ==
          0);
  REQUIRE(
      run_command(base + (tmp / "b") +
                      R"( --random-options '{"height": 24, "width": 32, "frame_probability": 1}')",
                  out) == 0);
  for (const char* name : {"a", "b"}) {
    INFO(name);
    const auto record = lfnet::read_json_file(tmp / (std::string(name) + "/scene.json"));
    CHECK(lfnet::scene::SceneSpec::from_json(record).to_json() == expected);
  }
  // Bad options: one error line naming the option and the key, nothing written.
  CHECK(run_command(base + (tmp / "c") + R"( --random-options '{"frames": 1}')", out) != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK(out.find("--random-options:$.frames") != std::string::npos);
  CHECK(run_command(base + (tmp / "c") + R"( --random-options '{"height": ')", out) != 0);
  CHECK(out.find("--random-options: malformed JSON") != std::string::npos);
  CHECK(run_command(base + (tmp / "c") + " --random-options " + (tmp / "none.json"), out) != 0);
  CHECK(out.find("--random-options " + (tmp / "none.json")) != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "c"));
}

TEST_CASE("lfnet render --frames writes frame_0 .. frame_{T-1} of a moving scene",
          "[app][scene][motion]") {
  lfnet::test::TempDir tmp;
  const std::string base = lfnet_binary() + " --threads 1 render --size 24x32 --views 3x3 ";
  std::string out;
  REQUIRE(run_command(base + "--random 3 --frames 3 --out " + (tmp / "seq"), out) == 0);
  CHECK(out.find("3x3x3x3x24x32") != std::string::npos);
  for (int t = 0; t < 3; ++t) {
    const std::string frame = tmp / ("seq/frame_" + std::to_string(t));
    for (const char* name : {"lf_1_1.png", "lf_3_3.png", "disparity.pfm", "grid.png", "epi_h.png",
                             "epi_v.png", "preview.png"}) {
      INFO(frame << "/" << name);
      CHECK(fs::exists(frame + "/" + name));
    }
    CHECK_FALSE(fs::exists(frame + "/scene.json"));
  }
  CHECK_FALSE(fs::exists(tmp / "seq/frame_3"));
  CHECK_FALSE(fs::exists(tmp / "seq/lf_1_1.png"));

  // The random scene moves by default (up to 2 px per sub-frame), and the files hold what the
  // library renders for the resolved spec at the top.
  const auto record = lfnet::read_json_file(tmp / "seq/scene.json");
  CHECK(record["rendered"]["frames"] == 3);
  CHECK(record["rendered"]["random_options"]["max_speed"] == 2.0);
  CHECK(record["rendered"]["effects_run"][1] == "motion");
  const auto spec = lfnet::scene::SceneSpec::from_json(record);
  REQUIRE(spec.moves());
  const auto want = lfnet::scene::render_sequence(spec, 3);
  for (int t = 0; t < 3; ++t) {
    const std::string frame = tmp / ("seq/frame_" + std::to_string(t));
    lfnet::test::require_close(lfnet::io::read_light_field(frame, 1).data(),
                               want.light_fields.frame(t).data(), 1.0 / 65535.0);
    lfnet::test::require_close(lfnet::io::read_pfm(frame + "/disparity.pfm")[0], want.disparity[t],
                               0.0);
  }
  CHECK_FALSE(torch::allclose(want.light_fields.frame(0).data(), want.light_fields.frame(2).data(),
                              0.0, 0.01));

  // Motion turned off: a still scene filmed, every frame the same.
  REQUIRE(run_command(base + R"(--random 3 --frames 2 --random-options '{"max_speed": 0}' --out )" +
                          (tmp / "still"),
                      out) == 0);
  CHECK(torch::equal(lfnet::io::read_light_field(tmp / "still/frame_0", 1).data(),
                     lfnet::io::read_light_field(tmp / "still/frame_1", 1).data()));
  CHECK(lfnet::read_json_file(tmp / "still/scene.json")["rendered"]["effects_run"] ==
        nlohmann::json({"occlusion"}));
}

TEST_CASE("lfnet render --frames 1 writes what a still render writes; bad counts are refused",
          "[app][scene][motion]") {
  lfnet::test::TempDir tmp;
  auto doc = nlohmann::json::parse(R"({"height": 20, "width": 24, "rows": 3, "cols": 3, "layers": [
    {"texture": {"kind": "fractal", "scale": 8}, "disparity": -1},
    {"texture": {"kind": "checker", "size": 3}, "disparity": 1,
     "shape": {"kind": "disk", "radius": 5}, "motion": {"shift": [1, 0]}}]})");
  lfnet::write_json_file(tmp / "scene.json", doc);
  const std::string base =
      lfnet_binary() + " --threads 1 render --scene " + (tmp / "scene.json") + " --out ";
  std::string out;
  REQUIRE(run_command(base + (tmp / "plain"), out) == 0);
  REQUIRE(run_command(base + (tmp / "one") + " --frames 1", out) == 0);
  CHECK_FALSE(fs::exists(tmp / "one/frame_0"));
  CHECK_FALSE(lfnet::read_json_file(tmp / "one/scene.json")["rendered"].contains("frames"));
  for (const char* name : {"lf_1_1.png", "lf_3_3.png", "disparity.pfm", "preview.png"}) {
    INFO(name);
    std::ifstream a(tmp / ("plain/" + std::string(name)), std::ios::binary);
    std::ifstream b(tmp / ("one/" + std::string(name)), std::ios::binary);
    const std::string bytes_a((std::istreambuf_iterator<char>(a)), {});
    const std::string bytes_b((std::istreambuf_iterator<char>(b)), {});
    CHECK(!bytes_a.empty());
    CHECK(bytes_a == bytes_b);
  }
  // A scene file's motion, filmed: the disk moves 1 px per sub-frame.
  REQUIRE(run_command(base + (tmp / "two") + " --frames 2", out) == 0);
  const auto d0 = lfnet::io::read_pfm(tmp / "two/frame_0/disparity.pfm")[0];
  const auto d1 = lfnet::io::read_pfm(tmp / "two/frame_1/disparity.pfm")[0];
  CHECK(torch::equal(d1.slice(1, 1, 24), d0.slice(1, 0, 23)));
  CHECK_FALSE(torch::equal(d0, d1));

  for (const char* frames : {"0", "65", "x"}) {
    INFO(frames);
    CHECK(run_command(base + (tmp / "bad") + " --frames " + frames, out) != 0);
    CHECK(out.rfind("lfnet: error: ", 0) == 0);
    CHECK(out.find("--frames") != std::string::npos);
    CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  }
  CHECK_FALSE(fs::exists(tmp / "bad"));
  // Motion that leaves the scene's limits within the exposure names the scene and the key.
  doc["layers"][1]["motion"] = {{"scale", 2}};
  lfnet::write_json_file(tmp / "scene.json", doc);
  CHECK(run_command(base + (tmp / "bad") + " --frames 8", out) != 0);
  CHECK(out.find("scene.json") != std::string::npos);
  CHECK(out.find("$.layers[1].motion.scale") != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
}

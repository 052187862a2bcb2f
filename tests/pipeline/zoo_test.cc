// The model zoo (pipeline/zoo.h, models/zoo.json): every card names a file that exists, its
// measured block is what scripts/zoo.py makes of the records, and a zoo name stands for its file.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/nn/auto_precision.h"
#include "lfnet/pipeline/catalog.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/zoo.h"
#include "lfnet/train/checkpoint.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using namespace lfnet;

namespace {
const std::string kModels = (fs::path(LFNET_SOURCE_DIR) / "models").string();
}

TEST_CASE("every zoo card names a shipped file, one card per name, one default per camera",
          "[zoo]") {
  const auto zoo = pipeline::read_zoo(kModels);
  REQUIRE(zoo.models.size() >= 8);
  CHECK(zoo.models.size() <= 16);
  std::set<std::string> defaults;
  for (const auto& m : zoo.models) {
    INFO(m.name);
    CHECK(fs::exists(fs::path(kModels) / m.file));
    for (const char* key : {"use", "camera", "colour", "noise", "architecture", "recipe"}) {
      CHECK(m.card.contains(key));
    }
    if (m.card.value("default", false)) {
      const auto camera = m.card.value("camera", "") + " " + m.card.value("colour", "");
      CHECK(defaults.insert(camera).second);
    }
  }
  CHECK(defaults.count("asp:2 grey") == 1);
  CHECK(defaults.count("asp:2 RGGB") == 1);
  const auto table = pipeline::zoo_table(zoo);
  for (const auto& m : zoo.models) CHECK_THAT(table, Catch::Contains(m.name));
  // Every camera spec whole (aperture:2 is no learned code); learned codes and the dictionary
  // in one word.
  CHECK_THAT(table, Catch::Contains("aperture:2"));
  CHECK_THAT(table, Catch::Contains("learned"));
  CHECK_THAT(pipeline::zoo_card(zoo, "lfnet-asp-n2"), Catch::Contains("\"parameters\""));
  CHECK_THROWS_WITH(pipeline::zoo_card(zoo, "lfnet-asp-n3"),
                    Catch::Contains("no model 'lfnet-asp-n3' in the zoo"));
}

TEST_CASE("a zoo name stands for its file; paths and unknown names stay as given", "[zoo]") {
  ::setenv("LFNET_MODELS", kModels.c_str(), 1);
  CHECK(pipeline::resolve_model_name("lfnet-asp-n2") ==
        (fs::path(kModels) / "lfnet-asp-n2.ckpt").string());
  CHECK(pipeline::resolve_model_name("lfnet-asp-n2-auto") ==
        (fs::path(kModels) / "lfnet-asp-n2-auto.json").string());
  CHECK(pipeline::resolve_model_name("no-such-model") == "no-such-model");
  CHECK(pipeline::resolve_model_name("x/lfnet-asp-n2") == "x/lfnet-asp-n2");
  test::TempDir tmp;
  ::setenv("LFNET_MODELS", tmp.path().c_str(), 1);  // no zoo there: names stay names
  CHECK(pipeline::resolve_model_name("lfnet-asp-n2") == "lfnet-asp-n2");
  CHECK_THROWS_AS(pipeline::read_zoo(tmp.path().string()), IoError);
  ::unsetenv("LFNET_MODELS");
}

TEST_CASE("the cards' measured blocks are what scripts/zoo.py makes of the records", "[zoo]") {
  std::string out;
  const int rc = test::run_command(
      std::string(LFNET_TEST_PYTHON) + " " + LFNET_SOURCE_DIR + "/scripts/zoo.py --check", out);
  INFO(out);
  CHECK(rc == 0);
}

TEST_CASE("the zoo's default model for a sensor follows its camera and colour", "[zoo]") {
  ::setenv("LFNET_MODELS", kModels.c_str(), 1);
  test::TempDir tmp;
  // An acquisition folder says its camera (and colour filter array) in sensor.json.
  auto acquisition = [&](const std::string& name, const std::string& phi,
                         const nlohmann::json& cfa) {
    const auto dir = tmp.path() / name;
    fs::create_directories(dir);
    nlohmann::json meta = {{"phi", pipeline::phi_from_argument(phi).to_json()}};
    if (!cfa.is_null()) meta["cfa"] = cfa;
    test::write_bytes((dir / "sensor.json").string(), meta.dump());
    return dir.string();
  };
  auto grey = pipeline::zoo_default_model(acquisition("grey", "asp:2", nullptr), "");
  CHECK(grey.camera == "asp:2");
  CHECK(grey.colour == "grey");
  CHECK(grey.name == "lfnet-asp-n2-auto");
  CHECK(grey.path == (fs::path(kModels) / "lfnet-asp-n2-auto.json").string());
  const auto colour =
      pipeline::zoo_default_model(acquisition("colour", "asp:2", {{"pattern", "RGGB"}}), "");
  CHECK(colour.colour == "RGGB");
  CHECK(colour.name == "lfnet-asp-n2-bayer-hard-dark-blend");
  // Another pattern, or a camera without a default: no model.
  const auto grbg =
      pipeline::zoo_default_model(acquisition("grbg", "asp:2", {{"pattern", "GRBG"}}), "");
  CHECK(grbg.colour == "GRBG");
  CHECK(grbg.name.empty());
  CHECK(pipeline::zoo_default_model(acquisition("mask", "mask:2", nullptr), "").name ==
        "lfnet-mask-n2");
  const auto random = pipeline::zoo_default_model(acquisition("random", "random:2", nullptr), "");
  CHECK(random.camera == "random:2");
  CHECK(random.name.empty());
  CHECK(random.path.empty());
  // A plain sensor image's camera is its --phi; without one, or with an unreadable folder,
  // nothing is known.
  CHECK(pipeline::zoo_default_model(tmp / "image.png", "asp:15").name == "lfnet-asp-n15");
  // Its colour is its --cfa.
  const auto plain_colour = pipeline::zoo_default_model(tmp / "image.png", "asp:2", "RGGB");
  CHECK(plain_colour.colour == "RGGB");
  CHECK(plain_colour.name == "lfnet-asp-n2-bayer-hard-dark-blend");
  CHECK(pipeline::zoo_default_model(tmp / "image.png", "asp:2", "").name == "lfnet-asp-n2-auto");
  CHECK(pipeline::zoo_default_model(tmp / "image.png", "").camera.empty());
  fs::create_directories(tmp.path() / "empty");
  CHECK(pipeline::zoo_default_model(tmp / "empty", "").camera.empty());
  ::unsetenv("LFNET_MODELS");
}

TEST_CASE("the zoo's learned codes carry what it takes to make them", "[pipeline][zoo]") {
  // A shipped model trained on a code another model learned holds that code's physical
  // parameters itself: phi export writes them with no other file at hand.
  int learned = 0;
  for (const auto& path : test::zoo_checkpoints()) {
    const auto ck = train::load_checkpoint(path.string());
    const std::string source = ck.phi.value("params", nlohmann::json::object()).value("source", "");
    if (source.rfind("learned", 0) != 0) continue;
    INFO(path);
    ++learned;
    const auto code = pipeline::learned_code_of(path.string());
    REQUIRE(code.is_object());
    const std::string family = source.find("mask") != std::string::npos ? "mask" : "asp";
    CHECK(code["family"] == family);
    CHECK(code.contains(family == "mask" ? "transmittance" : "alpha"));
  }
  CHECK(learned >= 2);
}

TEST_CASE("precision auto judges a noise switch by its two members", "[zoo]") {
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "quiet.ckpt") << "quiet weights";
  std::ofstream(tmp / "noisy.ckpt") << "noisy weights";
  std::ofstream(tmp / "switch.json") << R"({"format": "lfnet-noise-switch", "version": 1,
    "quiet": "quiet.ckpt", "noisy": "noisy.ckpt", "switch_sigma": 0.01})";
  auto list = [&](bool noisy_verified) {
    std::ofstream(tmp / "bfloat16.json", std::ios::trunc) << nlohmann::json{
        {"models",
         {{"quiet.ckpt",
           {{"fingerprint", lfnet::nn::file_fingerprint(tmp / "quiet.ckpt")}, {"verified", true}}},
          {"noisy.ckpt",
           {{"fingerprint", lfnet::nn::file_fingerprint(tmp / "noisy.ckpt")},
            {"verified", noisy_verified}}}}}}.dump();
  };
  ::setenv("LFNET_NATIVE_BFLOAT16", "1", 1);
  using lfnet::nn::Precision;
  list(true);
  CHECK(lfnet::pipeline::choose_precision({tmp / "switch.json"}, "cpu") == Precision::kBFloat16);
  CHECK(lfnet::pipeline::choose_precision({tmp / "quiet.ckpt"}, "cpu") == Precision::kBFloat16);
  list(false);  // one member not verified: the switch runs in float32, as that member does
  CHECK(lfnet::pipeline::choose_precision({tmp / "switch.json"}, "cpu") == Precision::kFloat32);
  CHECK(lfnet::pipeline::choose_precision({tmp / "noisy.ckpt"}, "cpu") == Precision::kFloat32);
  ::unsetenv("LFNET_NATIVE_BFLOAT16");
}

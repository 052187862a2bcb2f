// A noise switch (models/lfnet-asp-n2-auto.json, docs/models.md "One model for any noise"): the
// sigma a sensor image is told, or the one estimated from it, picks one of two checkpoints.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;
namespace fs = std::filesystem;

namespace {

const std::string kModels = std::string(LFNET_SOURCE_DIR) + "/models/";
const std::string kScene = std::string(LFNET_SOURCE_DIR) + "/configs/scenes/probe_cross.json";

nlohmann::json read_json(const std::string& path) {
  return nlohmann::json::parse(std::ifstream(path));
}

// evaluate's record of `model` on the small probe scene at `sigma`, the noise estimated.
nlohmann::json evaluate(const std::string& model, const std::string& sigma,
                        const std::string& json) {
  std::string out;
  const std::string command = lfnet_binary() + " --threads 2 evaluate --model " + model +
                              " --scene " + kScene + " --method net --noise " + sigma +
                              " --estimate-noise --json " + json;
  INFO(out);
  REQUIRE(run_command(command, out) == 0);
  return read_json(json);
}

}  // namespace

TEST_CASE("a noise switch reconstructs with the quiet model below its sigma, the noisy above",
          "[app][slow]") {
  lfnet::test::TempDir tmp;
  const std::string automatic = kModels + "lfnet-asp-n2-auto.json";
  const auto file = read_json(automatic);
  const double from = file["switch_sigma"].get<double>();
  const auto quiet = evaluate(kModels + file["quiet"].get<std::string>(), "0", tmp / "quiet.json");
  const auto noisy = evaluate(kModels + "lfnet-asp-n2-noise.ckpt", "0.05", tmp / "noisy.json");
  const auto below = evaluate(automatic, "0", tmp / "below.json");
  const auto above = evaluate(automatic, "0.05", tmp / "above.json");
  CHECK(below["psnr_db"] == quiet["psnr_db"]);
  CHECK(above["psnr_db"] == noisy["psnr_db"]);
  CHECK(below["noise_sigma_estimated"].get<double>() < from);
  CHECK(above["noise_sigma_estimated"].get<double>() > from);
  CHECK(above["noise_switch"]["switch_sigma"] == from);
  // The record says which member ran; the added noise is white, all of it the sensor's.
  CHECK(below["noise_switch_choice"]["member"] == "quiet");
  CHECK(above["noise_switch_choice"]["member"] == "noisy");
  CHECK(above["noise_switch_choice"]["white_share"].get<double>() > 0.95);
  CHECK(above["noise_switch"]["noisy"] == kModels + "lfnet-asp-n2-noise.ckpt");
  CHECK(above["model"] == automatic);

  // reconstruct estimates the sigma of a sensor image that does not say it, and records it.
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 2 ";
  REQUIRE(run_command(lfnet + "simulate --scene " + kScene + " --phi " + automatic +
                          " --noise 0.05 --out " + (tmp / "acq"),
                      out) == 0);
  const auto meta = read_json(tmp / "acq/sensor.json");
  CHECK(meta["phi"]["name"] == "asp");
  auto sensor = meta;
  sensor.erase("noise_sigma");  // a camera that does not know its noise
  std::ofstream(tmp / "acq/sensor.json") << sensor.dump();
  REQUIRE(run_command(lfnet + "reconstruct --model " + automatic + " --sensor " + (tmp / "acq") +
                          " --out " + (tmp / "rec"),
                      out) == 0);
  const auto record = read_json(tmp / "rec/reconstruction.json");
  CHECK(record["noise_sigma"][0].get<double>() > from);
  CHECK(record["noise_switch"]["quiet"] == kModels + file["quiet"].get<std::string>());
  CHECK(record["noise_switch_choice"]["member"] == "noisy");
}

TEST_CASE("a noise switch that cannot work is one clear error", "[app]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 ";
  auto write = [&](const std::string& name, const nlohmann::json& j) {
    std::ofstream(tmp / name) << j.dump();
    return std::string(tmp / name);
  };
  const nlohmann::json good = {{"format", "lfnet-noise-switch"},
                               {"version", 1},
                               {"quiet", kModels + "lfnet-asp-n2.ckpt"},
                               {"noisy", kModels + "lfnet-asp-n2-noise.ckpt"},
                               {"switch_sigma", 0.01}};
  auto with = [&](const std::string& key, const nlohmann::json& value) {
    auto j = good;
    j[key] = value;
    return j;
  };
  const std::pair<nlohmann::json, std::string> bad[] = {
      {with("quiet", "missing.ckpt"), "missing.ckpt"},
      {with("quiet", kModels + "lfnet-asp-n15.ckpt"), "were trained for different Phis"},
      {with("noisy", kModels + "asp-n2.ckpt"), "not of a whole-image architecture"},
      {with("noisy", kModels + "lfnet-asp-n2-bayer-hard-dark-blend.ckpt"),
       "reconstruct different colours"},
      {with("switch_sigma", -1), "$.switch_sigma: must be a finite sigma > 0"},
      {with("exposure_target", 2), "$.exposure_target: must be an exposure in [0, 1]"},
      {with("version", 2), "$.version: this lfnet reads version 1"},
      {with("colour", true), "colour"},
  };
  std::string out;
  for (const auto& [json, message] : bad) {
    INFO(json.dump());
    const auto path = write("switch.json", json);
    std::string command = lfnet + "evaluate --model ";
    command += path;
    command += " --scene " + kScene;
    command += " --method net --json " + (tmp / "r.json");
    CHECK(run_command(command, out) != 0);
    CHECK(out.find(message) != std::string::npos);
    CHECK(out.find("lfnet: error:") != std::string::npos);
    CHECK_FALSE(fs::exists(tmp / "r.json"));
  }
  // Exporting one: export each of its checkpoints instead.
  const auto path = write("switch.json", good);
  CHECK(run_command(lfnet + "export --model " + path + " --out " + (tmp / "x.pt"), out) != 0);
  CHECK(out.find("export each of them") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "x.pt"));
}

TEST_CASE("a noise switch brightens a dim sensor image to its exposure target", "[app][slow]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 2 ";
  // A random scene at a third of its brightness, and the same switch without the target.
  std::ofstream(tmp / "set.json") << R"({"name": "dim", "role": "validation", "light_fields": [
      {"name": "dim", "description": "dim", "classes": ["dark-low-contrast"], "random": 5,
       "random_options": {"height": 96, "width": 96}, "gain": 0.3, "seed": 5}]})";
  REQUIRE(run_command(lfnet + "sets make " + (tmp / "set.json") + " --out " + (tmp / "sets"),
                      out) == 0);
  auto file = read_json(kModels + "lfnet-asp-n2-auto.json");
  const double target = file.value("exposure_target", 0.0);
  REQUIRE(target > 0);
  for (const char* key : {"quiet", "noisy"}) file[key] = kModels + file[key].get<std::string>();
  std::ofstream(tmp / "with.json") << file.dump();
  file.erase("exposure_target");
  std::ofstream(tmp / "without.json") << file.dump();
  auto score = [&](const std::string& model, const std::string& source) {
    const std::string json = tmp / "r.json";
    REQUIRE(run_command(lfnet + "evaluate --model " + model + " " + source +
                            " --method net --estimate-noise --force --json " + json,
                        out) == 0);
    return read_json(json);
  };
  const std::string lf = "--lf " + (tmp / "sets/dim");
  const auto dim = score(tmp / "with.json", lf);
  const auto plain = score(tmp / "without.json", lf);
  INFO(dim.dump());
  CHECK(dim["exposure_gain"].get<double>() > 1.5);
  CHECK(dim["noise_switch"]["exposure_target"] == target);
  CHECK_FALSE(plain.contains("exposure_gain"));
  CHECK(dim["psnr_db"] != plain["psnr_db"]);
  // A scene bright enough is reconstructed as it would be without the target.
  const auto bright = score(tmp / "with.json", "--scene " + kScene);
  CHECK(bright["exposure_gain"] == 1.0);
  CHECK(bright["psnr_db"] == score(tmp / "without.json", "--scene " + kScene)["psnr_db"]);
}

// The training and reconstruction commands end to end on a tiny config.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;
namespace fs = std::filesystem;

namespace {
const char* kTinyConfig = R"({
  "name": "tiny", "phi": "asp:2",
  "data": {"random_scenes": 2, "random_seed": 5, "random_options": {"height": 64, "width": 64}},
  "dataset": {"train_patches": 128, "validation_patches": 64, "seed": 2},
  "network": {"paper": {"residual": "pinv", "cnn": {"channels": 4}}},
  "training": {"epochs": 1, "batch_size": 32, "progress": false},
  "stages": ["cnn"],
  "evaluation": {"data": {"random_scenes": 1, "random_seed": 99,
                          "random_options": {"height": 40, "width": 40}},
                 "methods": ["net", "pinv", "no-parallax"], "strides": [9]}
})";

}  // namespace

TEST_CASE(
    "experiment trains, evaluates and writes its outputs, and evaluate and reconstruct use the "
    "model",
    "[app][slow]") {
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "tiny.json") << kTinyConfig;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  std::string out;
  REQUIRE(run_command(lfnet + "experiment " + (tmp / "tiny.json") + " --out " + (tmp / "run"),
                      out) == 0);
  CHECK(fs::exists(tmp / "run/config.json"));
  CHECK(fs::exists(tmp / "run/models/cnn.ckpt"));
  auto results = lfnet::test::read_json_lines(tmp / "run/results.jsonl");
  REQUIRE(results.size() == 3);
  for (const auto& r : results) {
    for (const char* key :
         {"psnr_db", "ssim", "seconds", "patches", "per_view_psnr_db", "method", "stride", "phi",
          "measurements", "noise_sigma", "mode", "threads", "device"}) {
      INFO(key);
      CHECK(r.contains(key));
    }
    CHECK(r["per_view_psnr_db"].size() == 5);
    CHECK(r["mode"] == "sensor");
  }
  // A second run into the same folder is refused without --force; the first one stays.
  CHECK(run_command(lfnet + "experiment " + (tmp / "tiny.json") + " --out " + (tmp / "run"), out) !=
        0);
  CHECK(out.find("lfnet: error:") != std::string::npos);
  CHECK(fs::exists(tmp / "run/models/cnn.ckpt"));

  // lfnet report RUN: the run's own report with its training and evaluation tables.
  REQUIRE(run_command(lfnet + "report " + (tmp / "run"), out) == 0);
  std::ifstream report_file(tmp / "run/report.md");
  const std::string report((std::istreambuf_iterator<char>(report_file)),
                           std::istreambuf_iterator<char>());
  CHECK(report.find("## Training") != std::string::npos);
  CHECK(report.find("| cnn | 1 |") != std::string::npos);  // one epoch of the cnn stage
  CHECK(report.find("over no-parallax") != std::string::npos);
  CHECK(report.find("| no-parallax |") != std::string::npos);
  CHECK(report.find("| pinv |") != std::string::npos);
  CHECK(fs::exists(tmp / "run/figures/pareto.png"));
  if (report.find("No training curves") == std::string::npos) {
    CHECK(fs::exists(tmp / "run/figures/training.png"));
    CHECK(fs::exists(tmp / "run/figures/training.svg"));
  }

  // evaluate --json with the model; a --phi that contradicts the model is an error.
  const std::string model = tmp / "run/models/cnn.ckpt";
  REQUIRE(run_command(lfnet + "render --random 7 --size 40x40 --out " + (tmp / "lf"), out) == 0);
  REQUIRE(run_command(lfnet + "evaluate --model " + model + " --lf " + (tmp / "lf") +
                          " --stride 9 --json " + (tmp / "eval.json"),
                      out) == 0);
  auto record = nlohmann::json::parse(std::ifstream(tmp / "eval.json"));
  CHECK(record["method"] == "net");
  CHECK(record["psnr_db"].get<double>() > 10.0);
  CHECK(run_command(lfnet + "evaluate --model " + model + " --lf " + (tmp / "lf") + " --phi mask:2",
                    out) != 0);
  CHECK(out.find("does not match") != std::string::npos);

  // reconstruct reads what simulate writes, and refuses another Phi's measurements.
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi asp:2 --out " + (tmp / "acq"),
                  out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --model " + model + " --sensor " + (tmp / "acq") +
                          " --out " + (tmp / "rec"),
                      out) == 0);
  CHECK(fs::exists(tmp / "rec/lf_3_3.png"));
  CHECK(fs::exists(tmp / "rec/grid.png"));
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi mask:2 --out " + (tmp / "acqm"),
                  out) == 0);
  CHECK(run_command(lfnet + "reconstruct --model " + model + " --sensor " + (tmp / "acqm") +
                        " --out " + (tmp / "recm"),
                    out) != 0);
  CHECK(out.find("trained for Phi") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "recm"));
}

TEST_CASE("train with $.distill learns from a teacher's self-ensemble and checks the teacher",
          "[app][slow]") {
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "student.json") << R"({
    "name": "student", "phi": "asp:2",
    "data": {"random_scenes": 2, "random_seed": 5, "random_options": {"height": 64, "width": 64}},
    "dataset": {"patch_h": 16, "patch_w": 16, "train_patches": 32, "validation_patches": 16,
                "validation_fraction": 0.3, "seed": 2},
    "network": {"architecture": "lfnet", "image": {"channels": 4, "levels": 2, "blocks": 1},
                "patch": {"height": 16, "width": 16}},
    "training": {"epochs": 1, "batch_size": 16, "progress": false},
    "stages": ["joint_scratch"]
  })";
  const std::string lfnet = lfnet_binary() + " --threads 2 ";
  const std::string models = std::string(LFNET_SOURCE_DIR) + "/models/";
  const std::string train = lfnet + "train " + (tmp / "student.json");
  std::string out;
  REQUIRE(run_command(train + " --set distill.teacher=" + models + "lfnet-asp-n2.ckpt" +
                          " --set distill.passes=2 --set distill.weight=0.5 --out " + (tmp / "run"),
                      out) == 0);
  CHECK(out.find("distillation: targets 0.5 x the self-ensemble of") != std::string::npos);
  CHECK(out.find("(2 passes)") != std::string::npos);
  // The checkpoint records what taught it.
  const auto config = nlohmann::json::parse(std::ifstream(tmp / "run/config.json"));
  CHECK(config["distill"]["passes"] == 2);
  // A colour net learns from a colour teacher's self-ensemble (its crops' mirror images read at
  // their phases of the pattern).
  REQUIRE(run_command(train + " --set network.cfa=RGGB --set distill.teacher=" + models +
                          "lfnet-asp-n2-bayer-hard-dark-blend.ckpt --out " + (tmp / "colour"),
                      out) == 0);
  CHECK(out.find("(4 passes)") != std::string::npos);

  // Teachers that cannot teach, and bad values, are one error each before any training.
  const std::pair<std::string, std::string> bad[] = {
      {"distill.teacher=" + models + "asp-n2.ckpt", "must be of a whole-image architecture"},
      {"distill.teacher=" + models + "lfnet-asp-n15.ckpt", "Phi"},
      {"distill.teacher=" + (tmp / "missing.ckpt"), "missing.ckpt: no such file"},
      // A colour net teaches colour nets of its pattern only.
      {"distill.teacher=" + models + "lfnet-asp-n2-bayer-hard-dark-blend.ckpt",
       "behind a Bayer RGGB filter, the net reconstructs grey sensor images"},
      {"distill.weight=1.5", "$.distill.weight: must lie in [0, 1]"},
      {"distill.passes=-1", "$.distill.passes: must lie in [0, 64], got -1"},
      {"distill.precision=half", "half"},
  };
  for (const auto& [set, message] : bad) {
    INFO(set);
    std::string command = train;
    command += " --set " + set;
    if (set.rfind("distill.teacher", 0) != 0) {
      command += " --set distill.teacher=" + models + "lfnet-asp-n2.ckpt";
    }
    CHECK(run_command(command + " --out " + (tmp / "bad"), out) != 0);
    CHECK(out.find(message) != std::string::npos);
    CHECK(out.find("lfnet: error:") != std::string::npos);
    CHECK_FALSE(fs::exists(tmp / "bad/models/joint_scratch.ckpt"));
  }
}

TEST_CASE("experiment with $.code learns a code, evaluates with it and exports it to print",
          "[app][slow]") {
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "code.json") << R"({
    "name": "code", "phi": {"name": "mask", "n": 2},
    "data": {"random_scenes": 2, "random_seed": 5, "random_options": {"height": 64, "width": 64}},
    "dataset": {"patch_h": 16, "patch_w": 16, "train_patches": 32, "validation_patches": 16,
                "validation_fraction": 0.3, "seed": 2},
    "network": {"architecture": "lfnet", "image": {"channels": 4, "levels": 2, "blocks": 1},
                "patch": {"height": 16, "width": 16}},
    "training": {"epochs": 2, "batch_size": 16, "progress": false},
    "code": {"family": "mask", "period": 3, "lr": 0.05, "freeze_epochs": 1, "binarise": true},
    "stages": ["joint_scratch"],
    "evaluation": {"data": {"random_scenes": 1, "random_seed": 99,
                            "random_options": {"height": 40, "width": 40}},
                   "methods": ["net", "pinv"]}
  })";
  const std::string lfnet = lfnet_binary() + " --threads 2 ";
  std::string out;
  REQUIRE(run_command(lfnet + "experiment " + (tmp / "code.json") + " --out " + (tmp / "run"),
                      out) == 0);
  CHECK(out.find("learning the code with the net: family mask, period 3") != std::string::npos);
  CHECK(out.find("the code was rounded to 0 or 1 before it") != std::string::npos);
  // Both methods reconstruct the sensor image of the learned camera.
  const auto results = lfnet::test::read_json_lines(tmp / "run/results.jsonl");
  REQUIRE(results.size() == 2);
  for (const auto& r : results) CHECK(r["phi"]["name"] == "calibrated");
  // The model's Phi is the rounded code, which phi export writes with the pattern to print.
  const std::string model = tmp / "run/models/joint_scratch.ckpt";
  REQUIRE(run_command(lfnet + "phi export --phi " + model + " --out " + (tmp / "code-phi"), out) ==
          0);
  CHECK(out.find("with its printable pattern") != std::string::npos);
  CHECK(fs::exists(tmp / "code-phi/mask_1.png"));
  CHECK(fs::exists(tmp / "code-phi/mask_2.png"));
  const auto sidecar = nlohmann::json::parse(std::ifstream(tmp / "code-phi/phi.json"));
  CHECK(sidecar["period"] == 3);
  CHECK(sidecar["exported_from"]["params"]["source"] == "learned mask, binarised");
  // And the code's physical parameters: one transmittance per measurement, view and pixel.
  CHECK(out.find("code.json") != std::string::npos);
  const auto code = nlohmann::json::parse(std::ifstream(tmp / "code-phi/code.json"));
  CHECK(code["family"] == "mask");
  CHECK(code["shape"] == nlohmann::json::array({2, 5, 5, 3, 3}));
  CHECK(code["transmittance"].size() == size_t{2} * 5 * 5 * 3 * 3);
  CHECK(code["options"]["period"] == 3);

  // A net trained on the learned code held fixed ($.phi names the model) carries the code of the
  // model that learned it, so it exports the code without that model at hand; a checkpoint of
  // the run that does not carry it (the stage's best.ckpt) says what is missing.
  {
    auto fixed = nlohmann::json::parse(std::ifstream(tmp / "code.json"));
    fixed.erase("code");
    fixed.erase("evaluation");
    fixed["phi"] = model;
    std::ofstream(tmp / "fixed.json") << fixed.dump();
  }
  REQUIRE(run_command(lfnet + "train " + (tmp / "fixed.json") + " --out " + (tmp / "fixed"), out) ==
          0);
  const std::string fixed_model = tmp / "fixed/models/joint_scratch.ckpt";
  REQUIRE(run_command(lfnet + "phi export --phi " + fixed_model + " --out " + (tmp / "fixed-phi"),
                      out) == 0);
  const auto learned_by = nlohmann::json::parse(std::ifstream(tmp / "fixed-phi/code.json"));
  CHECK(learned_by["learned_by"] == model);
  CHECK(learned_by["transmittance"] == code["transmittance"]);
  fs::rename(model, tmp / "elsewhere.ckpt");
  REQUIRE(run_command(lfnet + "phi export --phi " + fixed_model + " --out " + (tmp / "carried"),
                      out) == 0);
  const auto carried = nlohmann::json::parse(std::ifstream(tmp / "carried/code.json"));
  CHECK(carried["learned_by"] == model);
  CHECK(carried["transmittance"] == code["transmittance"]);
  const std::string stage_best = tmp / "fixed/models/joint_scratch/best.ckpt";
  REQUIRE(fs::exists(stage_best));
  REQUIRE(run_command(lfnet + "phi export --phi " + stage_best + " --out " + (tmp / "no-code"),
                      out) == 0);
  CHECK(out.find("but not its physical parameters") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "no-code/code.json"));
  fs::rename(tmp / "elsewhere.ckpt", model);

  // Another run's code starts from this model's ($.code.from), and its config records where.
  REQUIRE(run_command(lfnet + "train " + (tmp / "code.json") + " --set code.from=" + model +
                          " --out " + (tmp / "next"),
                      out) == 0);
  CHECK(out.find("the code starts from the learned code of " + model) != std::string::npos);
  const auto next = nlohmann::json::parse(std::ifstream(tmp / "next/config.json"));
  CHECK(next["code"]["from"] == model);

  // A code that cannot be trained is one error before any training.
  const std::pair<std::string, std::string> bad[] = {
      {"code.family=asp", "$.code.binarise: an ASP's response is a cosine"},
      {"code.colour=red", "$.code.colour"},
      {"code.freeze_epochs=5", "freeze_epochs"},
      {"code.family=lens", "lens"},
      {"code.from=" + (tmp / "missing.ckpt"), "$.code.from"},
  };
  for (const auto& [set, message] : bad) {
    INFO(set);
    std::string command = lfnet + "train " + (tmp / "code.json");
    command += " --set " + set;
    command += " --out " + (tmp / "bad");
    CHECK(run_command(command, out) != 0);
    CHECK(out.find(message) != std::string::npos);
    CHECK(out.find("lfnet: error:") != std::string::npos);
    CHECK_FALSE(fs::exists(tmp / "bad/models/joint_scratch.ckpt"));
  }
}

// --budget and bench --calibrate (docs/models.md, "A time budget"): through the command line,
// with a zoo of two small nets whose calibration the test writes or bench makes.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

#include "support/small_nets.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;
namespace fs = std::filesystem;

namespace {

const std::string kProbeScene = std::string(LFNET_SOURCE_DIR) + "/configs/scenes/probe_cross.json";

nlohmann::json read_record(const std::string& path) {
  return nlohmann::json::parse(std::ifstream(path));
}

}  // namespace

TEST_CASE("a budget runs the zoo model that fits and records its predicted and actual seconds",
          "[app]") {
  lfnet::test::TempDir tmp;
  const auto zoo = tmp / "zoo";
  fs::create_directories(zoo);
  // Two asp:2 nets: "wide" ranks first on validation, "narrow" second.
  lfnet::test::save_small_image_net("", 1, zoo + "/wide.ckpt", 12);
  lfnet::test::save_small_image_net("", 2, zoo + "/narrow.ckpt", 4);
  auto card = [](const std::string& name, double mean) {
    return nlohmann::json{{"name", name},
                          {"file", name + ".ckpt"},
                          {"camera", "asp:2"},
                          {"colour", "grey"},
                          {"measured", {{"validation", {{"mean_margin_over_pinv_db", mean}}}}}};
  };
  std::ofstream(zoo + "/zoo.json")
      << nlohmann::json{{"about", "test"}, {"models", {card("wide", 2.0), card("narrow", 1.0)}}}
             .dump();
  const std::string calibration = tmp / "calibration.json";
  const std::string env = "LFNET_MODELS=" + zoo + " LFNET_CALIBRATION=" + calibration + " ";
  const std::string lfnet = env + lfnet_binary() + " --threads 1 ";
  std::string out;

  // bench --calibrate times both and pinv.
  REQUIRE(run_command(lfnet + "bench --calibrate --height 64 --width 80", out) == 0);
  INFO(out);
  CHECK_THAT(out, Catch::Contains("wide") && Catch::Contains("narrow") && Catch::Contains("pinv") &&
                      Catch::Contains("wrote " + calibration));
  auto c = read_record(calibration);
  REQUIRE(c["entries"].size() == 3);
  for (const auto& e : c["entries"]) {
    CHECK(e["timings"][1]["pixels"] == 64 * 80);
    CHECK(e["timings"][0]["pixels"] == 32 * 40);
  }
  // --json is not what it writes.
  CHECK(run_command(lfnet + "bench --calibrate --json " + (tmp / "x.json"), out) != 0);
  CHECK_THAT(out, Catch::Contains("--calibrate writes the calibration file"));
  CHECK_FALSE(fs::exists(tmp / "x.json"));

  // bench --ladder times the camera's checkpoints in one run, most accurate first: in float32,
  // and in bfloat16 as well where bfloat16 is native, unless --precision names one.
  const std::string ladder = tmp / "ladder.json";
  const std::string bench = "bench --ladder --methods net --strides 5 --height 36 --width 45 " +
                            std::string("--skip-kernels --force --json ") + ladder;
  REQUIRE(run_command("LFNET_NATIVE_BFLOAT16=0 " + lfnet + bench, out) == 0);
  auto cases = read_record(ladder)["cases"];
  REQUIRE(cases.size() == 2);
  CHECK(cases[0]["model"] == zoo + "/wide.ckpt");
  CHECK(cases[1]["model"] == zoo + "/narrow.ckpt");
  CHECK(cases[1]["precision"] == "float32");
  REQUIRE(run_command("LFNET_NATIVE_BFLOAT16=1 " + lfnet + bench, out) == 0);
  cases = read_record(ladder)["cases"];
  REQUIRE(cases.size() == 4);
  for (size_t i = 0; i < 4; ++i) {
    CHECK(cases[i]["model"] == zoo + (i < 2 ? "/wide.ckpt" : "/narrow.ckpt"));
    CHECK(cases[i]["precision"] == (i % 2 == 0 ? "float32" : "bfloat16"));
  }
  CHECK_THAT(out, Catch::Contains("narrow.ckpt, bfloat16]"));
  REQUIRE(run_command("LFNET_NATIVE_BFLOAT16=1 " + lfnet + bench + " --precision float32", out) ==
          0);
  CHECK(read_record(ladder)["cases"].size() == 2);
  CHECK(run_command(lfnet + "bench --ladder --phi mask:2 --methods net", out) != 0);
  CHECK_THAT(out, Catch::Contains("no measured checkpoint for mask:2"));

  // Timings the test sets: wide 2 s, narrow 0.5 s, pinv 0.1 s per light field of any size.
  for (auto& e : c["entries"]) {
    const double s = e["model"] == "wide" ? 2.0 : e["model"] == "narrow" ? 0.5 : 0.1;
    e["fixed_seconds"] = s;
    e["seconds_per_megapixel"] = 0.0;
  }
  std::ofstream(calibration) << c.dump();

  REQUIRE(
      run_command(lfnet + "simulate --scene " + kProbeScene + " --phi asp:2 --out " + (tmp / "acq"),
                  out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --sensor " + (tmp / "acq") + " --budget 3 --out " +
                          (tmp / "wide"),
                      out) == 0);
  auto record = read_record(tmp / "wide/reconstruction.json");
  CHECK(record["model"] == zoo + "/wide.ckpt");
  CHECK(record["budget"]["model"] == "wide");
  CHECK(record["budget"]["seconds"] == 3.0);
  CHECK(record["budget"]["predicted_seconds"] == 2.0);
  CHECK(record["budget"]["actual_seconds"] == record["seconds"]);
  CHECK(record["budget"]["candidates"].size() == 2);
  REQUIRE(run_command(lfnet + "reconstruct --sensor " + (tmp / "acq") + " --budget 1 --out " +
                          (tmp / "narrow"),
                      out) == 0);
  CHECK(read_record(tmp / "narrow/reconstruction.json")["budget"]["model"] == "narrow");

  // None fits: one error line naming the fastest and pinv, no output.
  CHECK(run_command(lfnet + "reconstruct --sensor " + (tmp / "acq") + " --budget 0.2 --out " +
                        (tmp / "none"),
                    out) != 0);
  CHECK_THAT(out, Catch::Contains("the fastest, narrow, needs 0.50 s") &&
                      Catch::Contains("--method pinv needs 0.10 s"));
  CHECK_FALSE(fs::exists(tmp / "none"));
  // A model of one's own and a budget: refused.
  CHECK(run_command(lfnet + "reconstruct --sensor " + (tmp / "acq") + " --budget 1 --model " +
                        (zoo + "/wide.ckpt") + " --out " + (tmp / "both"),
                    out) != 0);
  CHECK_THAT(out, Catch::Contains("give --budget or --model, not both"));
  CHECK(run_command(lfnet + "reconstruct --sensor " + (tmp / "acq") + " --budget -1 --out " +
                        (tmp / "negative"),
                    out) != 0);

  // evaluate: the light field's camera is --phi.
  const std::string json = tmp / "eval.json";
  REQUIRE(run_command(
              lfnet + "evaluate --scene " + kProbeScene + " --phi asp:2 --budget 1 --json " + json,
              out) == 0);
  const auto evaluated = read_record(json);
  CHECK(evaluated["method"] == "net");
  CHECK(evaluated["budget"]["model"] == "narrow");
  CHECK(evaluated["model"] == zoo + "/narrow.ckpt");

  // batch: each item its choice.
  fs::create_directories(tmp / "in");
  fs::rename(tmp / "acq", tmp / "in/acq");
  REQUIRE(run_command(lfnet + "batch --in " + (tmp / "in") + " --budget 3 --out " + (tmp / "batch"),
                      out) == 0);
  const auto batched = read_record(tmp / "batch/records/acq__net.json");
  CHECK(batched["budget"]["model"] == "wide");
  CHECK(batched["status"] == "ok");
  CHECK(run_command(lfnet + "batch --in " + (tmp / "in") + " --budget 3 --methods pinv --out " +
                        (tmp / "batch-pinv"),
                    out) != 0);
  CHECK_THAT(out, Catch::Contains("leave out --method"));
}

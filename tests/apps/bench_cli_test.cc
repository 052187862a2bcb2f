// lfnet bench: the report's contract (docs/performance.md), on a small light field.
#include <catch2/catch.hpp>

#include <cmath>

#include "lfnet/core/json.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

TEST_CASE("lfnet bench reports every case with its own figures", "[app]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string json = tmp / "bench.json";
  REQUIRE(run_command(lfnet_binary() +
                          " --threads 1 bench --height 36 --width 45 --methods net,cnn,pinv,dict"
                          " --strides 9,4 --dict-atoms 40 --conv-batch 4 --reps 1 --json " +
                          json,
                      out) == 0);
  INFO(out);
  const auto report = lfnet::read_json_file(json);
  CHECK(report["gemm_gflops"].get<double>() > 0.1);
  REQUIRE(report["conv4d"].size() == 4);
  for (const auto& k : report["conv4d"]) CHECK(k["gflops"].get<double>() > 0);
  REQUIRE(report["cases"].size() == 8);
  for (const auto& c : report["cases"]) {
    INFO(c.dump());
    REQUIRE_FALSE(c.contains("error"));
    const int64_t stride = c["stride"].get<int64_t>();
    // 36 x 45 in 9 x 9 patches: 4 x 5 at stride 9, 8 x 10 at stride 4 (the last row and
    // column of patches are moved in to end at the border).
    CHECK(c["patches"].get<int64_t>() == (stride == 9 ? 20 : 80));
    CHECK(c["seconds"].get<double>() > 0);
    CHECK(c["patches_per_second"].get<double>() ==
          Approx(c["patches"].get<double>() / c["seconds"].get<double>()));
    CHECK(c["peak_rss_mb"].get<double>() >= c["rss_before_mb"].get<double>());
    CHECK(c["peak_rss_mb"].get<double>() > 10);
    CHECK(std::isfinite(c["psnr_db"].get<double>()));
    CHECK(c["gemm_fraction"].get<double>() > 0);
  }
  // The linear baseline recovers a smooth scene far better than an untrained net does.
  const auto& cases = report["cases"];
  CHECK(cases[2]["method"] == "pinv");
  CHECK(cases[2]["psnr_db"].get<double>() > cases[0]["psnr_db"].get<double>() + 3);
  CHECK(cases[2]["psnr_db"].get<double>() > 15);
  // net runs both branches, cnn one: more FLOPs per patch for net.
  CHECK(cases[0]["flops_per_patch"].get<double>() > cases[1]["flops_per_patch"].get<double>());
}

TEST_CASE("lfnet bench runs the CNN fully convolutionally on request", "[app]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string json = tmp / "bench.json";
  REQUIRE(
      run_command(lfnet_binary() +
                      " --threads 1 bench --height 30 --width 30 --methods cnn --strides 3"
                      " --skip-kernels --reps 1 --cnn-mode full --tile 16 --in-process --json " +
                      json,
                  out) == 0);
  INFO(out);
  const auto c = lfnet::read_json_file(json)["cases"][0];
  CHECK(c["cnn_mode"] == "full");
  CHECK(c["tile"] == 16);
  CHECK(std::isfinite(c["psnr_db"].get<double>()));
}

TEST_CASE("lfnet bench refuses a device it does not have", "[app]") {
  std::string out;
  CHECK(run_command(lfnet_binary() + " bench --device tpu --methods pinv", out) != 0);
  CHECK(out.find("unknown device 'tpu'") != std::string::npos);
  CHECK(run_command(lfnet_binary() + " bench --methods pinv --cnn-mode tiles", out) != 0);
  // Enum options name themselves and the known values (one name table per enum).
  CHECK(out.find("--cnn-mode: 'tiles' is unknown (known: patches, full)") != std::string::npos);
  CHECK(run_command(lfnet_binary() + " bench --methods net --architecture unet", out) != 0);
  CHECK(out.find("--architecture: 'unet' is unknown (known: paper, lfnet, unrolled)") !=
        std::string::npos);
}

TEST_CASE("lfnet bench --json - writes the JSON alone, and a bench with no case run fails",
          "[app]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string small =
      " --threads 1 bench --height 20 --width 20 --strides 9 --reps 1"
      " --skip-kernels";
  // Standard output is the report alone (progress and table on standard error).
  REQUIRE(run_command("(" + lfnet_binary() + small + " --methods pinv --json - 2>/dev/null)",
                      out) == 0);
  const auto report = nlohmann::json::parse(out);
  CHECK(report["cases"].size() == 1);
  // A --json file in folders not made yet: they are made.
  REQUIRE(run_command(lfnet_binary() + small + " --methods pinv --json " + (tmp / "new/r.json"),
                      out) == 0);
  CHECK(lfnet::read_json_file(tmp / "new/r.json")["cases"].size() == 1);
  // Every case failing (each in its child process: a JSON file is no dictionary): non-zero,
  // with the reason.
  lfnet::write_json_file(tmp / "json.json", {{"not", "a dictionary"}});
  CHECK(run_command(lfnet_binary() + small + " --methods dict --dictionary " + (tmp / "json.json"),
                    out) != 0);
  INFO(out);
  CHECK(out.find("every case failed (1 of 1)") != std::string::npos);
  // A --phi that contradicts the model is refused, as evaluate refuses it, before any case runs.
  const std::string model = std::string(LFNET_SOURCE_DIR) + "/models/lfnet-asp-n2.ckpt";
  CHECK(run_command(lfnet_binary() + small + " --methods net --model " + model + " --phi mask:2",
                    out) != 0);
  CHECK(out.find("--phi mask:2 does not match the model") != std::string::npos);
  CHECK(out.find("pinv stride") == std::string::npos);
}

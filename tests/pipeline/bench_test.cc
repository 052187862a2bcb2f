// pipeline/bench.h: the measurements of `lfnet bench`, without the program.
#include "lfnet/pipeline/bench.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <string>
#include <vector>

#include "lfnet/core/sequence.h"

using namespace lfnet;

TEST_CASE("bench_case reconstructs the bench light field and reports what it measured",
          "[pipeline][bench]") {
  pipeline::BenchOptions o;
  o.height = 40;
  o.width = 48;
  const auto r = pipeline::bench_case(o, "pinv", 5, 1e9);
  CHECK(r["method"] == "pinv");
  CHECK(r["stride"] == 5);
  // Origins every 5 px and one flush with the far edge: 8 rows (0..30, 31), 9 columns.
  CHECK(r["patches"].get<int64_t>() == int64_t{8} * 9);
  CHECK(r["seconds"].get<double>() > 0);
  // asp:2 is local: its pinv is per pixel, N = 2 multiply-adds per value of 25 x 81.
  CHECK(r["flops_per_patch"].get<double>() == 2.0 * 2 * 25 * 81);
  CHECK(r["gemm_fraction"].get<double>() > 0);
  CHECK(r["psnr_db"].get<double>() > 15);
  CHECK(r["phi"] == "asp:2");
  CHECK(pipeline::bench_light_field(o).data().sizes() == torch::IntArrayRef({1, 5, 5, 40, 48}));
}

TEST_CASE("bench times a time-coded camera on frames of a moving scene", "[pipeline][bench]") {
  pipeline::BenchOptions o;
  o.height = 40;
  o.width = 48;
  const auto lf = pipeline::bench_light_field(o, 4);
  REQUIRE(lf.data().sizes() == torch::IntArrayRef({1, 20, 5, 40, 48}));
  const auto frames = lfnet::LightFieldSequence::unstack(lf, 4);
  CHECK_FALSE(torch::equal(frames.frame(0).data(), frames.frame(3).data()));
  o.phi = "coded_exposure:2@4";
  const auto r = pipeline::bench_case(o, "pinv", 5, 1e9);
  CHECK(r["frames"] == 4);
  CHECK(r["max_speed_px_per_frame"] == 2.0);
  CHECK(r["psnr_db"].get<double>() > 5);
}

TEST_CASE("bench_report runs every stride and method through the given runner",
          "[pipeline][bench]") {
  pipeline::BenchOptions o;
  o.skip_kernels = true;
  o.reps = 1;
  o.methods = {"pinv", "adjoint"};
  o.strides = {9, 5};
  std::vector<std::string> asked;
  std::vector<std::string> lines;
  const auto report = pipeline::bench_report(
      o,
      [&](const pipeline::BenchOptions&, const std::string& method, int64_t stride, double gemm) {
        CHECK(gemm > 0);
        asked.push_back(method + ":" + std::to_string(stride));
        if (method == "adjoint")
          return nlohmann::json{
              {"method", method}, {"stride", stride}, {"error", "failed on purpose"}};
        return nlohmann::json{{"method", method},          {"stride", stride},   {"seconds", 1.0},
                              {"patches_per_second", 2.0}, {"peak_rss_mb", 3.0}, {"psnr_db", 4.0}};
      },
      [&](const std::string& line) { lines.push_back(line); });
  CHECK(asked == std::vector<std::string>{"pinv:9", "adjoint:9", "pinv:5", "adjoint:5"});
  REQUIRE(report["cases"].size() == 4);
  CHECK(report["cases"][1]["error"] == "failed on purpose");
  CHECK(report["gemm_gflops"].get<double>() > 0);
  CHECK_FALSE(report.contains("conv4d"));
  CHECK(report["paper_seconds"]["net"] == pipeline::kPaperNetSeconds);
  REQUIRE(lines.size() == 6);  // the machine, GEMM, and one line per case
  CHECK(lines[0].rfind("lfnet bench:", 0) == 0);
  CHECK(lines[3].find("failed on purpose") != std::string::npos);
}

TEST_CASE("bench_report times the network methods once per architecture, lfnet at one stride",
          "[pipeline][bench]") {
  pipeline::BenchOptions o;
  o.skip_kernels = true;
  o.reps = 1;
  o.methods = {"net", "pinv"};
  o.strides = {9, 5};
  o.architectures = {nn::kPaperArchitecture, nn::kLfnetArchitecture};
  std::vector<std::string> asked;
  pipeline::bench_report(
      o,
      [&](const pipeline::BenchOptions& n, const std::string& method, int64_t stride, double) {
        CHECK(n.architectures.size() == 1);
        asked.push_back(method + "/" + n.architectures.front() + ":" + std::to_string(stride));
        return nlohmann::json{{"method", method}, {"stride", stride}, {"error", "not run"}};
      },
      [](const std::string&) {});
  CHECK(asked == std::vector<std::string>{"net/paper:9", "net/lfnet:9", "pinv/paper:9",
                                          "net/paper:5", "pinv/paper:5"});
}

TEST_CASE("bench_case times an untrained lfnet network on the whole image", "[pipeline][bench]") {
  pipeline::BenchOptions o;
  o.height = 40;
  o.width = 52;
  o.architectures = {nn::kLfnetArchitecture};
  const auto r = pipeline::bench_case(o, "net", 5, 1e9);
  CHECK(r["architecture"] == "lfnet");
  CHECK(r["tile"] == 52);  // automatic: the whole image, its wider side
  {
    // A --scene is rendered at its own size (384 x 192), and the tile recorded is its own.
    pipeline::BenchOptions s = o;
    s.scene = std::string(LFNET_SOURCE_DIR) + "/configs/scenes/probe_cross.json";
    CHECK(pipeline::bench_case(s, "net", 5, 1e9)["tile"] == 384);
  }
  CHECK(r["gflops"].get<double>() > 0);
  // Untrained, the U-Net adds nothing: the result is the pseudo-inverse's.
  const auto pinv = pipeline::bench_case(o, "pinv", 5, 1e9);
  CHECK(r["psnr_db"].get<double>() == Approx(pinv["psnr_db"].get<double>()).margin(0.01));
  CHECK_FALSE(r.contains("self_ensemble_passes"));
  // The self-ensemble: four passes for asp:2, four times the work, the same pseudo-inverse.
  o.self_ensemble = true;
  const auto ensemble = pipeline::bench_case(o, "net", 5, 1e9);
  CHECK(ensemble["self_ensemble_passes"] == 4);
  CHECK(ensemble["gflops"].get<double>() * ensemble["seconds"].get<double>() ==
        Approx(4 * r["gflops"].get<double>() * r["seconds"].get<double>()).epsilon(1e-6));
  CHECK(ensemble["psnr_db"].get<double>() == Approx(r["psnr_db"].get<double>()).margin(0.01));
  // Two of them: twice the work.
  o.self_ensemble_passes = 2;
  const auto pair = pipeline::bench_case(o, "net", 5, 1e9);
  CHECK(pair["self_ensemble_passes"] == 2);
  CHECK(pair["gflops"].get<double>() * pair["seconds"].get<double>() ==
        Approx(2 * r["gflops"].get<double>() * r["seconds"].get<double>()).epsilon(1e-6));
}

TEST_CASE("bench_report runs a whole-image net once, and the other methods at every stride",
          "[pipeline][bench]") {
  pipeline::BenchOptions o;
  o.skip_kernels = true;
  o.reps = 1;
  o.methods = {"net", "pinv"};
  o.architectures = {"lfnet"};
  o.strides = {9, 5};
  std::vector<std::string> asked, lines;
  pipeline::bench_report(
      o,
      [&](const pipeline::BenchOptions&, const std::string& method, int64_t stride, double) {
        asked.push_back(method + ":" + std::to_string(stride));
        nlohmann::json r = {{"method", method},          {"seconds", 1.0},
                            {"peak_rss_mb", 3.0},        {"psnr_db", 4.0},
                            {"patches_per_second", 2.0}, {"megapixels_per_second", 0.5}};
        if (method == "net") r["whole_image"] = true;
        return r;
      },
      [&](const std::string& line) { lines.push_back(line); });
  CHECK(asked == std::vector<std::string>{"net:9", "pinv:9", "pinv:5"});
  REQUIRE(lines.size() == 5);
  CHECK(lines[2].find("whole image: 1.00 s, 0.50 Mpx/s") != std::string::npos);
  CHECK(lines[3].find("pinv stride 9: 1.00 s, 2 patches/s") != std::string::npos);
}

TEST_CASE("bench_table prints a line per case, its architecture and its error",
          "[pipeline][bench]") {
  nlohmann::json report;
  // A whole-image case has no stride and no patches; every case has its megapixels per second.
  report["cases"] = nlohmann::json::array(
      {{{"method", "net"},
        {"architecture", "lfnet"},
        {"whole_image", true},
        {"seconds", 1.5},
        {"megapixels_per_second", 0.33},
        {"peak_rss_mb", 812.0},
        {"gflops", 40.5},
        {"gemm_fraction", 0.2},
        {"cpu_utilisation", 0.97},
        {"psnr_db", 36.5}},
       {{"method", "pinv"},
        {"stride", 5},
        {"patches", 19824},
        {"seconds", 0.72},
        {"patches_per_second", 27556.9},
        {"megapixels_per_second", 0.69},
        {"peak_rss_mb", 563.0},
        {"gflops", 18.1},
        {"gemm_fraction", 0.13},
        {"cpu_utilisation", 0.95},
        {"psnr_db", 28.12}},
       {{"method", "dict"}, {"stride", 2}, {"error", "the child process failed (status 9)"}}});
  const auto table = pipeline::bench_table(report);
  INFO(table);
  const auto first = table.find('\n');
  REQUIRE(first != std::string::npos);
  CHECK(table.substr(0, first).find("PSNR dB") != std::string::npos);
  CHECK(table.substr(0, first).find("Mpx/s") != std::string::npos);
  CHECK(table.find("net/lfnet      image         -       1.50            -     0.33       812     "
                   "40.5     20.0%   0.97    36.50\n") != std::string::npos);
  CHECK(table.find("pinv           5         19824       0.72      27556.9     0.69       563     "
                   "18.1     13.0%   0.95    28.12\n") != std::string::npos);
  CHECK(table.find("dict           2       the child process failed (status 9)\n") !=
        std::string::npos);
  CHECK(std::count(table.begin(), table.end(), '\n') == 4);
  CHECK(table.find("model") == std::string::npos);  // no trained model, no model column

  // Cases of trained models end with the model and a precision other than float32.
  report["cases"][0]["model"] = "models/lfnet-asp-n2.ckpt";
  report["cases"][0]["precision"] = "bfloat16";
  const auto named = pipeline::bench_table(report);
  INFO(named);
  CHECK(named.substr(0, named.find('\n')).find("PSNR dB  model") != std::string::npos);
  CHECK(named.find("36.50  lfnet-asp-n2, bfloat16\n") != std::string::npos);
  CHECK(named.find("28.12\n") != std::string::npos);  // pinv names none
}

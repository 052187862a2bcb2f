// lfnet batch, lfnet report, the dict stage and reconstruct from a plain sensor image, end to end.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>

#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::read_bytes;
using lfnet::test::run_command;
namespace fs = std::filesystem;

namespace {

std::vector<std::string> lines_of(const std::string& path) {
  std::vector<std::string> lines;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// A small textured light field with parallax, written as a folder.
void write_test_light_field(const std::string& dir, int64_t h, int64_t w) {
  auto y = torch::arange(h, torch::kFloat32).view({1, 1, 1, h, 1});
  auto x = torch::arange(w, torch::kFloat32).view({1, 1, 1, 1, w});
  auto u = torch::arange(5, torch::kFloat32).view({1, 5, 1, 1, 1});
  auto v = torch::arange(5, torch::kFloat32).view({1, 1, 5, 1, 1});
  auto data = 0.5 + 0.3 * torch::sin(0.4 * (x + (v - 2)) + 0.25 * (y + (u - 2)));
  lfnet::io::write_light_field(lfnet::LightField(data), dir);
}

}  // namespace

TEST_CASE("batch reconstructs and evaluates every item, records bad ones and goes on", "[app]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  std::string out;
  write_test_light_field(tmp / "in/lf_a", 36, 45);
  REQUIRE(run_command(lfnet + "simulate --lf " + (tmp / "in/lf_a") + " --phi asp:2 --out " +
                          (tmp / "in/cam/shot1"),
                      out) == 0);
  fs::create_directories(tmp / "in/broken");
  std::ofstream(tmp / "in/broken/sensor.json") << "{ not json";
  const std::string cmd = lfnet + "batch --input " + (tmp / "in") + " --out " + (tmp / "out") +
                          " --phi asp:2 --methods pinv,no-parallax --stride 9";
  CHECK(run_command(cmd, out) != 0);  // one item failed ...
  CHECK(out.find("lfnet: error: 3 of 6") != std::string::npos);
  // ... and the others are done.
  const auto csv = lines_of(tmp / "out/summary.csv");
  REQUIRE(csv.size() == 7);  // header + broken x2 + cam/shot1 x2 + lf_a x2
  CHECK(csv[0].rfind("item,kind,method,status,psnr_db,ssim,seconds", 0) == 0);
  int ok = 0, failed = 0;
  for (size_t i = 1; i < csv.size(); ++i) {
    ok += csv[i].find(",ok,") != std::string::npos;
    failed += csv[i].find(",error,") != std::string::npos;
  }
  CHECK(ok == 3);
  CHECK(failed == 3);
  // no-parallax needs the truth: for the acquisition it is an error record, not a crash.
  CHECK(fs::exists(tmp / "out/cam/shot1/pinv/grid.png"));
  CHECK(fs::exists(tmp / "out/records/lf_a__pinv.json"));
  std::ifstream rec(tmp / "out/records/lf_a__pinv.json");
  const auto r = nlohmann::json::parse(rec);
  CHECK(r["status"] == "ok");
  CHECK(r["psnr_db"].get<double>() > 10.0);
  // The output folder is never reused without --force.
  CHECK(run_command(cmd, out) != 0);
  CHECK(out.find("not empty") != std::string::npos);
}

TEST_CASE("batch --resume does only the pairs without a record of success", "[app]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 1 ";
  std::string out;
  for (const char* name : {"a", "b", "c"})
    write_test_light_field(tmp / ("in/lf_" + std::string(name)), 27, 36);
  REQUIRE(run_command(lfnet + "simulate --lf " + (tmp / "in/lf_a") + " --phi asp:2 --out " +
                          (tmp / "in/shot"),
                      out) == 0);
  const std::string cmd = lfnet + "batch --input " + (tmp / "in") +
                          " --phi asp:2 --methods pinv,adjoint --stride 9 --out ";
  REQUIRE(run_command(cmd + (tmp / "whole"), out) == 0);
  REQUIRE(run_command(cmd + (tmp / "part"), out) == 0);
  const fs::path records = tmp / "part/records";
  // As if interrupted: lf_b's pinv never recorded, lf_c's a failure, shot's a torn file, and
  // shot/pinv's output left without its record.
  fs::remove(records / "lf_b__pinv.json");
  std::ofstream(records / "lf_c__adjoint.json") << R"({"status": "error", "method": "adjoint"})";
  std::ofstream(records / "shot__pinv.json") << R"({"status": "o)";
  fs::remove(tmp / "part/summary.csv");
  std::map<std::string, fs::file_time_type> before;
  for (const auto& e : fs::directory_iterator(records))
    before[e.path().filename()] = e.last_write_time();

  CHECK(run_command(cmd + (tmp / "part"), out) != 0);  // not empty: says that it can resume
  CHECK(out.find("holds a batch: --resume continues it") != std::string::npos);
  CHECK(run_command(cmd + (tmp / "part") + " --resume --noise 0.01", out) != 0);
  CHECK(out.find("--resume: the batch in " + (tmp / "part") +
                 " was run with noise = 0.0, this command gives 0.01") != std::string::npos);
  CHECK(run_command(cmd + (tmp / "part") + " --resume --force", out) != 0);
  CHECK(out.find("give one of them") != std::string::npos);
  CHECK(run_command(cmd + (tmp / "empty") + " --resume", out) != 0);
  CHECK(out.find("holds no batch to continue") != std::string::npos);

  REQUIRE(run_command(cmd + (tmp / "part") + " --resume", out) == 0);
  INFO(out);
  CHECK(out.find("5 of 8 item-method pair(s) done before, 3 item(s) to do") != std::string::npos);
  for (const auto& [name, time] : before) {
    const bool redone = name == "lf_c__adjoint.json" || name == "shot__pinv.json";
    INFO(name);
    CHECK((fs::last_write_time(records / name) != time) == redone);
  }
  CHECK(fs::exists(records / "lf_b__pinv.json"));
  // The summary is that of the uninterrupted batch but for the seconds (the 7th column) and
  // the output folder's name.
  auto without_seconds = [&](const std::string& path) {
    std::vector<std::string> rows;
    for (auto line : lines_of(path)) {
      for (auto at = line.find(tmp / "part"); at != std::string::npos; at = line.find(tmp / "part"))
        line.replace(at, (tmp / "part").size(), tmp / "whole");
      std::stringstream fields(line);
      std::string row, f;
      for (int i = 0; std::getline(fields, f, ','); ++i) row += i == 6 ? "," : f + ",";
      rows.push_back(row);
    }
    return rows;
  };
  CHECK(without_seconds(tmp / "part/summary.csv") == without_seconds(tmp / "whole/summary.csv"));
}

TEST_CASE("batch --resume refuses a model replaced under the same path", "[app]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 1 ";
  std::string out;
  for (const char* name : {"a", "b"})
    write_test_light_field(tmp / ("in/lf_" + std::string(name)), 27, 36);
  const fs::path models = fs::path(LFNET_SOURCE_DIR) / "models";
  fs::copy_file(models / "asp-n2.ckpt", tmp / "model.ckpt");
  const std::string cmd = lfnet + "batch --input " + (tmp / "in") + " --model " +
                          (tmp / "model.ckpt") + " --stride 9 --out " + (tmp / "run");
  REQUIRE(run_command(cmd, out) == 0);
  fs::remove(tmp / "run/records/lf_b__net.json");
  // Another network at the same path: resuming would mix two networks in one summary.
  fs::copy_file(models / "lfnet-asp-n2.ckpt", tmp / "model.ckpt",
                fs::copy_options::overwrite_existing);
  CHECK(run_command(cmd + " --resume", out) != 0);
  CHECK(out.find("is not the file the batch in " + (tmp / "run") + " began with") !=
        std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "run/records/lf_b__net.json"));
  // The same content again, under the same path: it resumes.
  fs::copy_file(models / "asp-n2.ckpt", tmp / "model.ckpt", fs::copy_options::overwrite_existing);
  REQUIRE(run_command(cmd + " --resume", out) == 0);
  CHECK(fs::exists(tmp / "run/records/lf_b__net.json"));
}

TEST_CASE("batch reads the model once for all its items", "[app]") {
  lfnet::test::TempDir tmp;
  write_test_light_field(tmp / "in/lf_a", 27, 27);
  write_test_light_field(tmp / "in/lf_b", 27, 36);
  const std::string model = std::string(LFNET_SOURCE_DIR) + "/models/asp-n2.ckpt";
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --threads 2 batch --input " + (tmp / "in") + " --out " +
                          (tmp / "out") + " --model " + model + " --methods net,ae,pinv --stride 9",
                      out) == 0);
  INFO(out);
  CHECK(lines_of(tmp / "out/summary.csv").size() == 7);
  CHECK(out.find("6 record(s), 0 failed") != std::string::npos);
  CHECK(out.find("1 model or dictionary file(s) read") != std::string::npos);
}

TEST_CASE("reconstruct takes a plain sensor image with --phi, and the post-filter", "[app]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  std::string out;
  write_test_light_field(tmp / "lf", 45, 45);
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi asp:2 --out " + (tmp / "acq"),
                  out) == 0);
  // The acquisition's sensor.tif on its own, as a camera would give it.
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq/sensor.tif") +
                          " --out " + (tmp / "plain"),
                      out) != 0);
  CHECK(out.find("--phi") != std::string::npos);
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --phi asp:2 --sensor " +
                          (tmp / "acq/sensor.tif") + " --out " + (tmp / "plain") + " --post-filter",
                      out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq") + " --out " +
                          (tmp / "folder"),
                      out) == 0);
  const auto a = lfnet::io::read_light_field(tmp / "plain");
  const auto b = lfnet::io::read_light_field(tmp / "folder");
  REQUIRE(a.data().sizes() == b.data().sizes());
  // The post-filter changes only the stride-periodic part: small against the signal.
  const double diff = (a.data() - b.data()).abs().mean().item<double>();
  CHECK(diff < 0.02);
  // A wrong channel count is an error naming the Phi.
  CHECK(run_command(lfnet + "reconstruct --method pinv --phi asp:3 --sensor " +
                        (tmp / "acq/sensor.tif") + " --out " + (tmp / "x"),
                    out) != 0);
  CHECK(out.find("N = 3") != std::string::npos);
}

TEST_CASE("the dict stage learns a dictionary that evaluate uses", "[app][slow]") {
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "dict.json") << R"({
    "name": "d", "phi": "asp:2",
    "data": {"random_scenes": 2, "random_seed": 3, "random_options": {"height": 48, "width": 48}},
    "stages": ["dict"],
    "dictionary": {"sampling": {"count": 400, "seed": 1},
                   "ksvd": {"atoms": 40, "sparsity": 4, "iterations": 2}}
  })";
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  std::string out;
  REQUIRE(run_command(lfnet + "train " + (tmp / "dict.json") + " --out " + (tmp / "run"), out) ==
          0);
  REQUIRE(fs::exists(tmp / "run/models/dict.ckpt"));
  write_test_light_field(tmp / "lf", 36, 36);
  REQUIRE(run_command(lfnet + "evaluate --lf " + (tmp / "lf") +
                          " --phi asp:2 --method dict --stride 9 --dictionary " +
                          (tmp / "run/models/dict.ckpt") + " --json " + (tmp / "r.json"),
                      out) == 0);
  std::ifstream in(tmp / "r.json");
  const auto r = nlohmann::json::parse(in);
  CHECK(r["method"] == "dict");
  CHECK(std::isfinite(r["psnr_db"].get<double>()));
  // A training option on the dict stage is refused with its JSON path.
  std::ofstream(tmp / "bad.json") << R"({"phi": "asp:2", "data": {"random_scenes": 1},
    "stages": [{"name": "dict", "training": {"epochs": 3}}]})";
  CHECK(run_command(lfnet + "train " + (tmp / "bad.json") + " --out " + (tmp / "bad"), out) != 0);
  CHECK(out.find("$.stages[0]") != std::string::npos);
}

TEST_CASE("report writes tables with the mode, margins, the paper's numbers and figures", "[app]") {
  // Records on the paper's scene (mit_dragons_bunnies_*) are judged against the paper's numbers,
  // per aperture; records elsewhere are not. The front page weighs the paper's scene at 5 cm.
  const std::string ap5 = "mit_dragons_bunnies_5x5_ap5", ap3 = "mit_dragons_bunnies_5x5_ap3";
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "results/a");
  std::ofstream(tmp / "results/a/section.json") << R"({"title": "Held out", "order": 1,
    "command": "scripts/x.sh", "heatmaps": ["net"], "margins": {"over": "pinv", "target": 1.5},
    "paper": [{"method": "net", "n": 2, "psnr_db": 26.77, "seconds": 242, "source": "Fig. 5"}],
    "gaps": [{"claim": "net beats pinv", "a": {"method": "net"}, "b": {"method": "pinv"}, "paper_db": [2, 3], "source": "s. 3"},
             {"claim": "net beats dict", "a": {"method": "net"}, "b": {"method": "dict"}, "paper_db": 0.55, "source": "s. 4"},
             {"claim": "net barely drops", "a": {"method": "pinv"}, "b": {"method": "dict"}, "paper_db": -0.1, "source": "s. 7"},
             {"claim": "pinv beats net", "a": {"method": "pinv"}, "b": {"method": "net"}, "paper_db": 1, "source": "s. 5"},
             {"claim": "missing", "a": {"method": "ae"}, "b": {"method": "net"}, "paper_db": 1, "source": "s. 6"}]})";
  std::ofstream rec(tmp / "results/a/records.jsonl");
  auto record = [&](const std::string& method, double psnr, double seconds,
                    const std::string& light_field = "") {
    nlohmann::json pv = nlohmann::json::array();
    for (int u = 0; u < 5; ++u) pv.push_back(std::vector<double>(5, psnr + u));
    return nlohmann::json{{"method", method},
                          {"psnr_db", psnr},
                          {"ssim", 0.9},
                          {"seconds", seconds},
                          {"stride", 5},
                          {"mode", "sensor"},
                          {"measurements", 2},
                          {"noise_sigma", 0.0},
                          {"phi", {{"name", "asp"}, {"n", 2}}},
                          {"light_field", light_field.empty() ? ap5 : light_field},
                          {"per_view_psnr_db", pv},
                          {"end_to_end_seconds", seconds + 2}}
        .dump();
  };
  rec << record("net", 30.0, 10.0) << "\n"
      << record("pinv", 29.0, 1.0) << "\n"
      << record("no-parallax", 28.5, 0.1) << "\n"
      << record("dict", 29.5, 100.0) << "\n";
  rec.close();
  // A section whose records say how long their model trained gets a "training s" column.
  fs::create_directories(tmp / "results/b");
  std::ofstream(tmp / "results/b/section.json") << R"({"title": "Switching", "order": 2,
    "heatmaps": [{"method": "net", "variant": "finetuned", "label": "fine tuned"}, {"method": "net", "variant": "none"}],
    "training": [{"log": ")" + (tmp / "b.training.jsonl") +
                                                       R"(", "label": "the finetuned net"}]})";
  std::ofstream(tmp / "b.training.jsonl")
      << R"({"stage": "ae", "record": {"epoch": 1, "train_loss": 0.02, "val_psnr_db": 25.0}})"
      << "\n"
      << R"({"stage": "ae", "record": {"epoch": 2, "train_loss": 0.01, "val_psnr_db": 26.0}})"
      << "\n";
  auto trained = nlohmann::json::parse(record("net", 27.0, 5.0, "x"));
  trained["training_seconds"] = 321.4;
  trained["variant"] = "finetuned";
  std::ofstream(tmp / "results/b/records.jsonl") << trained.dump() << "\n"
                                                 << record("no-parallax", 26.0, 0.1, "x") << "\n";
  // A sweep over N with the paper's numbers.
  fs::create_directories(tmp / "results/c");
  std::ofstream(tmp / "results/c/section.json") << R"({"title": "Compression", "order": 3,
    "sweep": {"x": "n", "label": "measurements per pixel N"},
    "paper": [{"method": "net", "n": 2, "psnr_db": 26.77}, {"method": "net", "n": 15, "psnr_db": 27.5}]})";
  {
    std::ofstream c(tmp / "results/c/records.jsonl");
    for (int n : {2, 15}) {
      for (const auto& [method, psnr] : {std::pair{"net", 29.0}, std::pair{"pinv", 28.0}}) {
        auto r = nlohmann::json::parse(record(method, psnr + (n == 15 ? 1 : 0), 1.0, ap3));
        r["measurements"] = n;
        // A stride that tells the methods apart but no method's records: not in the labels.
        if (std::string(method) == "pinv") r["stride"] = 9;
        c << r.dump() << "\n";
      }
    }
    // Another scene: no verdict against the paper's figure for N = 2.
    c << record("net", 20.0, 1.0, "x") << "\n";
  }
  // A whole-image reconstruction (the lfnet architecture) beside a stride sweep: no stride.
  fs::create_directories(tmp / "results/d");
  std::ofstream(tmp / "results/d/section.json")
      << R"({"title": "Strides", "order": 4, "sweep": {"x": "stride", "label": "stride"}})";
  {
    std::ofstream d(tmp / "results/d/records.jsonl");
    for (int stride : {2, 9}) {
      auto r = nlohmann::json::parse(record("net", 29.0 - stride * 0.1, 60.0 / stride));
      r["stride"] = stride;
      if (stride == 9) r.erase("end_to_end_seconds");  // listed, but not plotted end to end
      d << r.dump() << "\n";
    }
    auto whole = nlohmann::json::parse(record("net", 31.5, 20.0));
    whole["variant"] = "lfnet";
    whole["whole_image"] = true;
    d << whole.dump() << "\n";
    // A noise-blind record: the sigma its method was told, estimated from the sensor image.
    auto blind = nlohmann::json::parse(record("net", 30.5, 20.0, "x"));
    blind["variant"] = "lfnet, blind";
    blind["whole_image"] = true;
    blind["noise_sigma_estimated"] = 0.0987;
    d << blind.dump() << "\n";
  }
  // A margins chart over a section with noisy records draws the noiseless ones; an array of
  // charts draws each, the second over a baseline of its own, the third at a noise sigma of
  // its own.
  fs::create_directories(tmp / "results/e");
  std::ofstream(tmp / "results/e/section.json")
      << R"({"title": "Codes", "order": 5, "margins": [{"over": "pinv"},)"
      << R"( {"over": "no-parallax", "target": 1, "title": "Over the mean"},)"
      << R"( {"over": "pinv", "noise": 0.05, "stem": "e_noisy"}]})";
  {
    std::ofstream e(tmp / "results/e/records.jsonl");
    auto noisy = nlohmann::json::parse(record("net", 25.0, 1.0, "x"));
    noisy["noise_sigma"] = 0.05;
    auto noisy_pinv = nlohmann::json::parse(record("pinv", 21.0, 1.0, "x"));
    noisy_pinv["noise_sigma"] = 0.05;
    e << record("net", 30.0, 1.0, "x") << "\n"
      << record("pinv", 29.0, 1.0, "x") << "\n"
      << record("no-parallax", 27.0, 0.1, "x") << "\n"
      << noisy.dump() << "\n"
      << noisy_pinv.dump() << "\n";
  }
  // Another camera on the paper's scene: a front page plot of its own.
  fs::create_directories(tmp / "results/f");
  std::ofstream(tmp / "results/f/section.json") << R"({"title": "Fifteen", "order": 6})";
  {
    auto n15 = nlohmann::json::parse(record("pinv", 29.8, 0.5));
    n15["measurements"] = 15;
    n15["phi"]["n"] = 15;
    std::ofstream(tmp / "results/f/records.jsonl") << n15.dump() << "\n";
  }
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --log-level warn report " + (tmp / "results") + " --out " +
                          (tmp / "docs/RESULTS.md"),
                      out) == 0);
  std::ifstream md_in(tmp / "docs/RESULTS.md");
  std::stringstream md;
  md << md_in.rdbuf();
  const std::string text = md.str();
  CHECK(text.find("## Held out") != std::string::npos);
  CHECK(text.find("| method | mode |") != std::string::npos);
  CHECK(text.find("| net | sensor | 30.00 | 0.900 | 10.00 | 26.77 | 242 |") != std::string::npos);
  // Section c's record on another scene has no paper figure beside it.
  CHECK(text.find("| net | x | 2 | 5 | sensor | 20.00 | 0.900 | 1.00 | | |") != std::string::npos);
  CHECK(text.find("net - no-parallax = +1.50 dB") != std::string::npos);
  CHECK(text.find("net - dict = +0.50 dB") != std::string::npos);
  CHECK(text.find("time yes (24x faster)") != std::string::npos);
  // Differences: net - pinv = +1.00 against 2 to 3 dB; net - dict = +0.50 against 0.55 (within
  // 0.1 dB); pinv - dict = -0.50 against a drop of 0.1; pinv - net = -1.00 against +1; ae has no
  // record.
  CHECK(text.find("| Held out | aperture 5 cm | net beats pinv | +2.0 to +3.0 | +1.00 | direction "
                  "only (-1.00 dB) | s. 3 |") != std::string::npos);
  CHECK(text.find("| net beats dict | +0.6 | +0.50 | yes |") != std::string::npos);
  CHECK(text.find("| net barely drops | -0.1 | -0.50 | no (-0.40 dB) |") != std::string::npos);
  CHECK(text.find("| pinv beats net | +1.0 | -1.00 | no (-2.00 dB) |") != std::string::npos);
  CHECK(text.find("| method | variant | mode | PSNR dB | SSIM | seconds | training s |") !=
        std::string::npos);
  CHECK(text.find("| net | finetuned | sensor | 27.00 | 0.900 | 5.00 | 321 |") !=
        std::string::npos);
  // Section a's net at 5 cm and section c's two sweep points at 3 cm against the paper's numbers;
  // not section c's record on scene x.
  CHECK(text.find("| aperture 5 cm | method net, mode sensor | 26.77 | 30.00 | 242 | 10.00 | PSNR "
                  "yes; time yes (24x faster) |") != std::string::npos);
  CHECK(text.find("- aperture 3 cm: 2 of 2 PSNR figures, 0 of 0 times\n") != std::string::npos);
  CHECK(text.find("- aperture 5 cm: 1 of 1 PSNR figures, 1 of 1 times\n") != std::string::npos);
  CHECK(text.find("- x:") == std::string::npos);
  CHECK(text.find("- aperture 5 cm: 1 of 5 claims; 1 more in direction only\n") !=
        std::string::npos);
  CHECK(text.find("| missing | +1.0 |  | not measured (records missing) |") != std::string::npos);
  // The front page comes first: the paper's scene at 5 cm against end-to-end time. dict is
  // slower and worse than net: off the front; the stride-9 net has no end-to-end time: listed,
  // not plotted.
  const auto front = text.find("## What accuracy costs in time, on the paper's scene");
  REQUIRE(front != std::string::npos);
  CHECK(front < text.find("## Held out"));
  CHECK(text.find("| net |  | 2 | 5 | 30.00 | 0.900 | 10.00 | 12.00 | yes |") != std::string::npos);
  CHECK(text.find("| dict |  | 2 | 5 | 29.50 | 0.900 | 100.00 | 102.00 |  |") != std::string::npos);
  CHECK(text.find("| net |  | 2 | 9 | 28.10 | 0.900 | 6.67 |  |  |") != std::string::npos);
  CHECK(text.find("| net | lfnet | 2 | whole image | 31.50 | 0.900 | 20.00 | 22.00 | yes |") !=
        std::string::npos);
  // no-parallax sees no camera: one row, without N or stride.
  CHECK(text.find("| no-parallax |  |  |  | 28.50 | 0.900 | 0.10 | 2.10 | yes |") !=
        std::string::npos);
  // Records of other scenes and apertures stay off it.
  CHECK(text.find("| net | finetuned | 2 | 5 |") == std::string::npos);
  // Figures: a PNG and its SVG twin each, drawn from one spec file by scripts/figures.py.
  const fs::path figures = tmp.path() / "docs/images/results";
  for (const char* stem :
       {"pareto", "a_views", "a_margins", "b_views", "b_training_0", "c_sweep"}) {
    CHECK(fs::file_size(figures / (std::string(stem) + ".png")) > 1000);
    CHECK(fs::file_size(figures / (std::string(stem) + ".svg")) > 1000);
  }
  CHECK(text.find(
            "![per-view PSNR](images/results/b_views.png) ([SVG](images/results/b_views.svg))") !=
        std::string::npos);
  CHECK(text.find("the finetuned net:\n\n![training curves](images/results/b_training_0.png)") !=
        std::string::npos);
  const auto spec = nlohmann::json::parse(read_bytes((figures / "figures.json").string()));
  std::map<std::string, nlohmann::json> by_stem;
  for (const auto& f : spec["figures"])
    by_stem[fs::path(f["stem"].get<std::string>()).filename().string()] = f;
  // The margins chart gets the section's records and its baseline.
  REQUIRE(by_stem.count("a_margins"));
  CHECK(by_stem["a_margins"]["records"].size() == 4);
  CHECK(by_stem["a_margins"]["over"] == "pinv");
  CHECK(by_stem["a_margins"]["target"] == 1.5);
  // Of each record only what the chart reads: not the per-view PSNRs, not the Phi.
  for (const auto& r : by_stem["a_margins"]["records"]) {
    CHECK(r.size() == 3);
    CHECK(r.contains("light_field"));
    CHECK(r.contains("method"));
    CHECK(r.contains("psnr_db"));
  }
  REQUIRE(by_stem.count("e_margins"));
  REQUIRE(by_stem["e_margins"]["records"].size() == 3);
  for (const auto& r : by_stem["e_margins"]["records"])
    CHECK((r["psnr_db"] != 25.0 && r["psnr_db"] != 21.0));
  CHECK(fs::file_size(figures / "e_margins.png") > 1000);
  REQUIRE(by_stem.count("e_margins_1"));
  CHECK(by_stem["e_margins_1"]["over"] == "no-parallax");
  CHECK(by_stem["e_margins_1"]["target"] == 1);
  CHECK(by_stem["e_margins_1"]["title"] == "Over the mean");
  CHECK(by_stem["e_margins"]["title"] == "Codes");
  CHECK(fs::file_size(figures / "e_margins_1.png") > 1000);
  CHECK(text.find("![margins over no-parallax](images/results/e_margins_1.png)") !=
        std::string::npos);
  // The noisy chart reads the two records at sigma 0.05 and no other.
  REQUIRE(by_stem.count("e_noisy"));
  REQUIRE(by_stem["e_noisy"]["records"].size() == 2);
  for (const auto& r : by_stem["e_noisy"]["records"])
    CHECK((r["psnr_db"] == 25.0 || r["psnr_db"] == 21.0));
  CHECK(fs::file_size(figures / "e_noisy.png") > 1000);
  CHECK(text.find("![margins over pinv at noise sigma 0.05](images/results/e_noisy.png)") !=
        std::string::npos);
  // A heatmap chosen by a selector; one that matches no record adds no panel.
  REQUIRE(by_stem.count("b_views"));
  REQUIRE(by_stem["b_views"]["panels"].size() == 1);
  CHECK(by_stem["b_views"]["panels"][0]["label"] == "fine tuned");
  // The Pareto points carry method, camera and stride apart; dict is off the front, and so are
  // the stride sweep's nets (slower than the whole-image net and worse).
  REQUIRE(by_stem.count("pareto"));
  CHECK(by_stem["pareto"]["points"].size() == 6);
  CHECK(by_stem["pareto"]["xlabel"] == "end-to-end time of the command (s, log scale)");
  int whole_points = 0;
  for (const auto& p : by_stem["pareto"]["points"]) {
    CHECK(p["n"] == 2);
    if (p["whole_image"] == true) {
      ++whole_points;
      CHECK(p["variant"] == "lfnet");
      CHECK(p["front"] == true);
    } else if (p["stride"] == 5) {
      CHECK(p["front"] == (p["method"] != "dict"));
    } else {
      CHECK(p["front"] == false);
    }
  }
  CHECK(whole_points == 1);
  // N = 15 on a plot of its own, beside no-parallax, and on its own front.
  REQUIRE(by_stem.count("pareto-asp-15"));
  REQUIRE(by_stem["pareto-asp-15"]["points"].size() == 2);
  for (const auto& p : by_stem["pareto-asp-15"]["points"]) {
    CHECK((p["method"] == "no-parallax" || p["n"] == 15));
    CHECK(p["front"] == true);
  }
  CHECK_THAT(by_stem["pareto-asp-15"]["title"].get<std::string>(), Catch::Contains("ASP N = 15"));
  CHECK(text.find("![ASP N = 15: PSNR against seconds](images/results/pareto-asp-15.png)") !=
        std::string::npos);
  CHECK(text.find("| pinv |  | 15 | 5 | 29.80 | 0.900 | 0.50 | 2.50 | yes |") != std::string::npos);
  CHECK(text.find("| lfnet | whole image |") != std::string::npos);
  CHECK(text.find("| PSNR dB | SSIM | seconds | estimated sigma |") != std::string::npos);
  CHECK(text.find("| 30.50 | 0.900 | 20.00 | 0.0987 |") != std::string::npos);
  // The stride sweep plots the patch nets only: a whole-image record has no stride.
  REQUIRE(by_stem.count("d_sweep"));
  REQUIRE(by_stem["d_sweep"]["series"].size() == 1);
  CHECK(by_stem["d_sweep"]["series"][0]["x"] == nlohmann::json({2, 9}));
  // The sweep: net and the pinv baseline against N, and the paper's numbers as their own series.
  REQUIRE(by_stem.count("c_sweep"));
  std::map<std::string, nlohmann::json> series;
  for (const auto& s : by_stem["c_sweep"]["series"]) series[s["label"]] = s;
  // A series per scene, named by its aperture on the paper's scene.
  REQUIRE(series.count("net, aperture 3 cm"));
  CHECK(series["net, aperture 3 cm"]["x"] == nlohmann::json({2, 15}));
  CHECK(series["net, aperture 3 cm"]["y"] == nlohmann::json({29.0, 30.0}));
  CHECK(series["pinv, aperture 3 cm"]["kind"] == "baseline");
  CHECK(series["paper: net"]["kind"] == "paper");
  CHECK(series["paper: net"]["y"] == nlohmann::json({26.77, 27.5}));
  // Against the reconstruction time, the stride-9 net is plotted too.
  REQUIRE(run_command(lfnet_binary() + " --log-level warn report " + (tmp / "results") + " --out " +
                          (tmp / "recon/RESULTS.md") + " --pareto-time reconstruction",
                      out) == 0);
  const auto spec2 = nlohmann::json::parse(
      read_bytes((tmp.path() / "recon/images/results/figures.json").string()));
  for (const auto& f : spec2["figures"]) {
    if (f["kind"] != "pareto") continue;
    CHECK(f["points"].size() == (f["stem"] == "pareto" ? 7 : 2));
    CHECK(f["xlabel"] == "reconstruction time (s, log scale)");
  }
  CHECK(run_command(lfnet_binary() + " report " + (tmp / "results") + " --pareto-time wall", out) !=
        0);
  CHECK(out.find("--pareto-time") != std::string::npos);
  // A missing results folder is one clear error.
  CHECK(run_command(lfnet_binary() + " report " + (tmp / "nothing"), out) != 0);
  CHECK(out.find("lfnet: error:") != std::string::npos);
}

namespace {
// Whether the config at `path`, or a base it extends, names a file under out/ that is not there:
// a step of a long chain or a research model, checked once its recipe has made it
// (docs/models.md, "Recipes").
bool waits_for_out(const fs::path& path) {
  const auto j = lfnet::read_json_file(path.string());
  const std::function<bool(const nlohmann::json&)> missing = [&](const nlohmann::json& v) {
    if (v.is_string()) {
      const auto s = v.get<std::string>();
      return s.rfind("out/", 0) == 0 && !fs::exists(fs::path(LFNET_SOURCE_DIR) / s);
    }
    if (v.is_structured()) {
      for (const auto& x : v) {
        if (missing(x)) return true;
      }
    }
    return false;
  };
  if (missing(j)) return true;
  if (j.contains("extends") && j["extends"].is_string()) {
    return waits_for_out(path.parent_path() / j["extends"].get<std::string>());
  }
  return false;
}
}  // namespace

TEST_CASE("every shipped config is valid", "[app]") {
  std::string out;
  int checked = 0;
  for (const char* dir : {"configs", "configs/models", "configs/paper", "configs/recipes"}) {
    const fs::path root = fs::path(LFNET_SOURCE_DIR) / dir;
    for (const auto& entry : fs::recursive_directory_iterator(root)) {
      if (entry.path().extension() != ".json" ||
          entry.path().string().find("/scenes/") != std::string::npos)
        continue;
      if (std::string(dir) == "configs" && entry.path().parent_path() != root) continue;
      // The list of recipes is no config: scripts/models.py reads it (tests/pipeline).
      if (entry.path().filename() == "recipes.json") continue;
      const auto written = lfnet::read_json_file(entry.path().string());
      // A blend recipe's config names two models for `lfnet blend`, not a training:
      // scripts/models.py checks it (tests/pipeline).
      if (written.contains("blend")) continue;
      if (waits_for_out(entry.path())) continue;
      std::string stages[2];
      for (int k = 0; k < 2; ++k) {
        const char* scale = k == 0 ? "quick" : "paper";
        INFO(entry.path().string() << " " << scale);
        CHECK(run_command(
                  lfnet_binary() + " train " + entry.path().string() + " --check --scale " + scale,
                  out) == 0);
        INFO(out);
        CHECK(out.find("the config is valid") != std::string::npos);
        const auto at = out.find("stages ");
        if (at != std::string::npos) stages[k] = out.substr(at, out.find(';', at) - at);
        ++checked;
      }
      // A scale changes how long each stage trains, never which stages: the paper scale of
      // an ablation must stay that ablation.
      INFO(entry.path().string());
      CHECK(!stages[0].empty());
      CHECK(stages[0] == stages[1]);
    }
  }
  CHECK(checked >= 2 * 20);
}

namespace {
// `lfnet report` on a folder of sections, its markdown read back.
std::string report_of(const std::string& results, const std::string& markdown) {
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --log-level warn report " + results + " --out " + markdown,
                      out) == 0);
  std::ifstream in(markdown);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
// A no-parallax record of light field "lf" in sensor mode, as one JSONL line.
std::string no_parallax_line(double psnr, double ssim) {
  return nlohmann::json({{"method", "no-parallax"},
                         {"psnr_db", psnr},
                         {"ssim", ssim},
                         {"seconds", 0.1},
                         {"mode", "sensor"},
                         {"light_field", "lf"}})
             .dump() +
         "\n";
}
}  // namespace

TEST_CASE("report gives a camera error's cost against the nominal camera", "[app]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "results/c");
  std::ofstream(tmp / "results/c/section.json") << R"({"title": "Calibration", "order": 1})";
  auto record = [](const std::string& variant, double psnr, const nlohmann::json& error) {
    nlohmann::json r = {{"method", "net"},    {"variant", variant},
                        {"psnr_db", psnr},    {"ssim", 0.9},
                        {"seconds", 1.0},     {"stride", 5},
                        {"mode", "sensor"},   {"measurements", 2},
                        {"noise_sigma", 0.0}, {"phi", {{"name", "asp"}, {"n", 2}}},
                        {"light_field", "lf"}};
    if (!error.is_null()) r["camera_error"] = error;
    return r.dump() + "\n";
  };
  const nlohmann::json depth = {{"depth", -0.1}, {"vignetting", 0.0}};
  std::ofstream(tmp / "results/c/records.jsonl")
      << record("a", 30.0, nullptr) << record("a", 29.25, depth) << record("b", 28.0, nullptr)
      << record("b", 27.9, depth) << no_parallax_line(20.0, 0.5);
  // A self-calibrated record: its estimated shift in a column of its own.
  auto calibrated = nlohmann::json::parse(record("c", 29.8, {{"angular_shift_u", 0.25}}));
  calibrated["camera_error_estimated"] = {{"angular_shift_u", 0.2468}, {"angular_shift_v", 0.0}};
  std::ofstream(tmp / "results/c/records.jsonl", std::ios::app)
      << record("c", 30.1, nullptr) << calibrated.dump() << "\n";
  const std::string md = report_of(tmp / "results", tmp / "R.md");
  CHECK(md.find("| estimated shift |") != std::string::npos);
  CHECK(md.find("| 29.80 | 0.900 | 1.00 | 0.30 | U 0.247 |") != std::string::npos);
  CHECK(md.find("| camera error |") != std::string::npos);
  CHECK(md.find("cost dB |") != std::string::npos);
  // Each variant's cost is against its own nominal record; fields at 0 are not named.
  CHECK(md.find("| depth -0.1 |") != std::string::npos);
  CHECK(md.find("vignetting") == std::string::npos);
  CHECK(md.find("| 29.25 | 0.900 | 1.00 | 0.75 |  |") != std::string::npos);
  CHECK(md.find("| 27.90 | 0.900 | 1.00 | 0.10 |  |") != std::string::npos);
  CHECK(md.find("| none |") != std::string::npos);
}

TEST_CASE("report shows colour records' luma PSNR beside their colour PSNR", "[app]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "results/c");
  std::ofstream(tmp / "results/c/section.json") << R"({"title": "Colour", "order": 1})";
  std::ofstream(tmp / "results/c/records.jsonl") << nlohmann::json({{"method", "pinv"},
                                                                    {"psnr_db", 31.5},
                                                                    {"luma_psnr_db", 32.25},
                                                                    {"ssim", 0.9},
                                                                    {"seconds", 1.0},
                                                                    {"mode", "sensor"},
                                                                    {"cfa", {{"pattern", "RGGB"}}},
                                                                    {"light_field", "lf"}})
                                                        .dump()
                                                 << "\n"
                                                 << no_parallax_line(30.0, 0.8);
  const std::string md = report_of(tmp / "results", tmp / "R.md");
  CHECK(md.find("| luma PSNR dB |") != std::string::npos);
  CHECK(md.find("| 31.50 | 0.900 | 1.00 | 32.25 |") != std::string::npos);
  CHECK(md.find("| 30.00 | 0.800 | 0.10 |  |") != std::string::npos);
}

TEST_CASE("report shows a sequence's PSNR per frame", "[app]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "results/v");
  std::ofstream(tmp / "results/v/section.json") << R"({"title": "Video", "order": 1})";
  std::ofstream(tmp / "results/v/records.jsonl")
      << nlohmann::json({{"method", "pinv"},
                         {"psnr_db", 25.0},
                         {"per_frame_psnr_db", {24.5, 25.25, nullptr, 25.0}},
                         {"ssim", 0.9},
                         {"seconds", 1.0},
                         {"mode", "sensor"},
                         {"light_field", "lf"}})
             .dump()
      << "\n"
      << no_parallax_line(20.0, 0.8);
  const std::string md = report_of(tmp / "results", tmp / "R.md");
  CHECK(md.find("| per frame dB |") != std::string::npos);
  CHECK(md.find("| 24.50 / 25.25 / inf / 25.00 |") != std::string::npos);
}

TEST_CASE("a section's sweep can keep one light field", "[app]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "results/s");
  std::ofstream(tmp / "results/s/section.json")
      << R"({"title": "Noise", "order": 1, "sweep": {"x": "noise", "light_field": "a"}})";
  std::ofstream rec(tmp / "results/s/records.jsonl");
  for (const char* lf : {"a", "b"}) {
    for (double sigma : {0.0, 0.1}) {
      for (const char* method : {"pinv", "no-parallax"}) {
        rec << nlohmann::json({{"method", method},
                               {"psnr_db", 30.0 - 50 * sigma},
                               {"ssim", 0.9},
                               {"seconds", 1.0},
                               {"mode", "sensor"},
                               {"noise_sigma", sigma},
                               {"light_field", lf}})
                   .dump()
            << "\n";
      }
    }
  }
  rec.close();
  (void)report_of(tmp / "results", tmp / "R.md");
  const auto spec = lfnet::read_json_file(tmp / "images/results/figures.json");
  const nlohmann::json* sweep = nullptr;
  for (const auto& f : spec["figures"]) {
    if (f["kind"] == "sweep") sweep = &f;
  }
  REQUIRE(sweep != nullptr);
  CHECK((*sweep)["title"].get<std::string>().find(", a") != std::string::npos);
  REQUIRE((*sweep)["series"].size() == 2);  // pinv and no-parallax, of light field a alone
  for (const auto& series : (*sweep)["series"]) {
    CHECK(series["label"].get<std::string>().find(", b") == std::string::npos);
    CHECK(series["x"].size() == 2);
  }
}

TEST_CASE("a section's pivot and sweep count a scene's moving versions as one family", "[app]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp / "results/m");
  std::ofstream(tmp / "results/m/section.json") << R"({"title": "Motion", "order": 1,
    "pivot": {"x": "motion_speed", "label": "speed", "family": "-(s|pan)[0-9]+$"},
    "sweep": {"x": "motion_speed", "family": "-(s|pan)[0-9]+$", "light_field": "lf"}})";
  std::ofstream rec(tmp / "results/m/records.jsonl");
  // lf (still: no motion_speed), lf-pan2 and scene-s0, scene-s2 (1.9998 px: 2 to a thousandth
  // of a pixel): pinv loses 1 dB per px, and scene is 4 dB below lf.
  for (const auto& [name, speed] : std::vector<std::pair<std::string, double>>{
           {"lf", -1}, {"lf-pan2", 2}, {"scene-s0", 0}, {"scene-s2", 1.9998}}) {
    for (const char* method : {"pinv", "no-parallax"}) {
      const double base =
          (name.rfind("scene", 0) == 0 ? 26.0 : 30.0) - (std::string(method) == "pinv" ? 0.0 : 2.0);
      nlohmann::json r = {
          {"method", method}, {"psnr_db", base - std::max(speed, 0.0)},
          {"ssim", 0.9},      {"seconds", std::string(method) == "pinv" ? 3.0 : 1.0},
          {"mode", "sensor"}, {"light_field", name}};
      if (speed >= 0) r["motion_speed"] = speed;
      rec << r.dump() << "\n";
    }
  }
  rec.close();
  const std::string md = report_of(tmp / "results", tmp / "R.md");
  CHECK(md.find("Mean PSNR (dB) against speed, over lf, scene") != std::string::npos);
  CHECK(md.find("| method | 0 | 2 | seconds |") != std::string::npos);
  CHECK(md.find("| pinv | 28.00 | 26.00 | 3.00 |") != std::string::npos);
  CHECK(md.find("| no-parallax | 26.00 | 24.00 | 1.00 |") != std::string::npos);
  const auto spec = lfnet::read_json_file(tmp / "images/results/figures.json");
  const nlohmann::json* sweep = nullptr;
  for (const auto& f : spec["figures"]) {
    if (f["kind"] == "sweep") sweep = &f;
  }
  REQUIRE(sweep != nullptr);
  REQUIRE((*sweep)["series"].size() == 2);  // pinv and no-parallax of lf and lf-pan2
  for (const auto& series : (*sweep)["series"]) {
    CHECK(series["x"] == nlohmann::json({0.0, 2.0}));
  }
  // A family that is no regular expression is named.
  std::ofstream(tmp / "results/m/section.json")
      << R"({"title": "Motion", "order": 1, "pivot": {"x": "motion_speed", "family": "("}})";
  std::string out;
  CHECK(run_command(lfnet_binary() + " report " + (tmp / "results") + " --out " + (tmp / "R2.md"),
                    out) != 0);
  CHECK(out.find("no regular expression") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "R2.md"));
}

TEST_CASE("a front section is the front page: its records alone, its text, not repeated", "[app]") {
  lfnet::test::TempDir tmp;
  auto line = [](const std::string& method, const std::string& variant, double psnr,
                 double seconds) {
    return nlohmann::json({{"method", method},
                           {"variant", variant},
                           {"model", variant},
                           {"psnr_db", psnr},
                           {"ssim", 0.9},
                           {"seconds", seconds},
                           {"end_to_end_seconds", seconds + 1},
                           {"stride", 5},
                           {"mode", "sensor"},
                           {"measurements", 2},
                           {"noise_sigma", 0.0},
                           {"phi", {{"name", "asp"}, {"n", 2}}},
                           {"light_field", "mit_dragons_bunnies_5x5_ap5"}})
               .dump() +
           "\n";
  };
  // An older section on the same scene, and the front section measured in one run.
  fs::create_directories(tmp / "results/old");
  std::ofstream(tmp / "results/old/section.json") << R"({"title": "Older runs", "order": 1})";
  std::ofstream(tmp / "results/old/records.jsonl") << line("net", "old-model", 40.0, 0.5);
  fs::create_directories(tmp / "results/front");
  std::ofstream(tmp / "results/front/section.json")
      << R"({"title": "Front", "order": 0, "front": true, "text": "One run of the zoo.",
             "command": "scripts/results.sh front"})";
  std::ofstream(tmp / "results/front/records.jsonl")
      << line("net", "fast-rung", 31.0, 0.3) << line("net", "slow-rung", 33.0, 3.0)
      << line("pinv", "", 28.0, 0.6);
  const std::string md = report_of(tmp / "results", tmp / "R.md");
  const auto front = md.find("## What accuracy costs in time, on the paper's scene");
  REQUIRE(front != std::string::npos);
  CHECK(md.find("One run of the zoo.") > front);
  CHECK(md.find("    scripts/results.sh front\n") != std::string::npos);
  CHECK(md.find("| net | fast-rung | 2 |") != std::string::npos);
  CHECK(md.find("| net | slow-rung | 2 |") != std::string::npos);
  // pinv is slower and worse than the fast rung: off the front.
  CHECK(md.find("| pinv |  | 2 | 5 | 28.00 | 0.900 | 0.60 | 1.60 |  |") != std::string::npos);
  // The older section's record is in its own section, not on the front page; the front section
  // is not repeated below.
  const auto older = md.find("## Older runs");
  REQUIRE(older != std::string::npos);
  CHECK(md.find("old-model") > older);
  CHECK(md.find("## Front") == std::string::npos);
}

TEST_CASE("results.py narrowed to light fields replaces only their records", "[apps][report]") {
  std::string out;
  const int rc = lfnet::test::run_command(std::string(LFNET_TEST_PYTHON) + " " + LFNET_SOURCE_DIR +
                                              "/tests/apps/check_results_narrowing.py",
                                          out);
  INFO(out);
  CHECK(rc == 0);
  CHECK(out.find("ok") != std::string::npos);
}

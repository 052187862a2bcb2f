// The lfnet program's contract: --help, one-line errors, non-zero exits.
#include <catch2/catch.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "lfnet/io/light_field_io.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

TEST_CASE("lfnet --help lists the subcommands", "[app]") {
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --help", out) == 0);
  CHECK(out.find("info") != std::string::npos);
  REQUIRE(run_command(lfnet_binary() + " info --help", out) == 0);
  CHECK(out.find("--lf") != std::string::npos);
}

TEST_CASE("lfnet answers --version without loading LibTorch and runs lfnet-run for the rest",
          "[app]") {
  namespace fs = std::filesystem;
  const fs::path launcher = lfnet_binary();
  const fs::path program = launcher.parent_path() / "lfnet-run";
  REQUIRE(fs::exists(program));
  std::string quick;
  std::string full;
  REQUIRE(run_command(launcher.string() + " --version", quick) == 0);
  REQUIRE(run_command(program.string() + " --version", full) == 0);
  CHECK(quick.rfind("lfnet ", 0) == 0);
  CHECK(quick == full);
  // The launcher needs no LibTorch; the program holding the commands does.
  std::string needed;
  REQUIRE(run_command("readelf -d " + launcher.string(), needed) == 0);
  CHECK(needed.find("libtorch") == std::string::npos);
  REQUIRE(run_command("readelf -d " + program.string(), needed) == 0);
  CHECK(needed.find("libtorch") != std::string::npos);
  // Arguments and the exit status pass through it.
  std::string out;
  CHECK(run_command(launcher.string() + " info --lf /nonexistent/folder", out) == 1);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  // Without lfnet-run beside it, one line says what is missing.
  lfnet::test::TempDir tmp;
  fs::copy_file(launcher, tmp / "lfnet");
  CHECK(run_command((tmp / "lfnet") + " info", out) == 127);
  CHECK(out.find("cannot run " + (tmp / "lfnet-run")) != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  REQUIRE(run_command((tmp / "lfnet") + " --version", out) == 0);
  CHECK(out == quick);
}

TEST_CASE("lfnet info describes a light field folder", "[app]") {
  lfnet::test::TempDir tmp;
  lfnet::LightField lf(torch::full({1, 2, 3, 9, 10}, 0.25));
  lfnet::io::write_light_field(lf, tmp / "lf", {"png", 16});
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --threads 1 info --lf " + (tmp / "lf"), out) == 0);
  CHECK(out.find("2 x 3 views") != std::string::npos);
  CHECK(out.find("1x2x3x9x10") != std::string::npos);
  CHECK(out.find("lf_R_C") != std::string::npos);
}

TEST_CASE("errors are one line with a non-zero exit", "[app]") {
  std::string out;
  CHECK(run_command(lfnet_binary() + " info --lf /nonexistent/folder", out) != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find("/nonexistent/folder") != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK(run_command(lfnet_binary() + " nosuchcommand", out) != 0);
  CHECK(out.find("lfnet: error: ") != std::string::npos);
  CHECK(run_command(lfnet_binary() + " --threads -3 info --lf x", out) != 0);
}

TEST_CASE("every reconstructing command takes the shared flags with one meaning", "[app]") {
  const std::vector<std::string> shared = {
      "--model",  "--phi",           "--device",          "--precision",     "--tile",
      "--stride", "--self-ensemble", "--ensemble-passes", "--method-options"};
  for (const std::string command : {"evaluate", "reconstruct", "batch", "bench"}) {
    INFO(command);
    std::string out;
    // --threads is lfnet's own option; it may follow the command's name too.
    REQUIRE(run_command(lfnet_binary() + " " + command + " --threads 1 --help", out) == 0);
    for (const auto& flag : shared) {
      INFO(flag);
      const auto at = out.find("  " + flag + " ");
      REQUIRE(at != std::string::npos);
      const auto line = out.substr(at, out.find('\n', at) - at);
      // The help texts come from one binding: the device's is word for word the same.
      if (flag == "--device")
        CHECK(line.find("cpu or cuda[:K]: where the network runs") != std::string::npos);
      if (flag == "--precision") CHECK(line.find("bfloat16") != std::string::npos);
      // The methods with options come from the registry.
      if (flag == "--method-options") CHECK(line.find("(dict, pinv-nlm)") != std::string::npos);
    }
    // Every registered method is offered, pinv-nlm included.
    CHECK(out.find("pinv-nlm") != std::string::npos);
  }
  // bench's --stride is one stride of its sweep.
  std::string out;
  CHECK(run_command(lfnet_binary() + " bench --stride 0", out) != 0);
  CHECK(out.find("--stride") != std::string::npos);
  // The values are checked the same way in every command (the relative paths here are missing,
  // and a command reads its paths only once every value is checked).
  const std::vector<std::string> commands = {
      "evaluate", "reconstruct --sensor nonexistent --out nonexistent-out",
      "batch --input nonexistent --out nonexistent-out", "bench"};
  for (const auto& command : commands) {
    INFO(command);
    CHECK(run_command(lfnet_binary() + " " + command + " --precision half", out) != 0);
    CHECK(out.find("--precision: 'half' is unknown (known: auto, float32, bfloat16)") !=
          std::string::npos);
    CHECK(run_command(lfnet_binary() + " " + command + " --tile 0", out) != 0);
    CHECK(out.find("--tile") != std::string::npos);
    CHECK(run_command(lfnet_binary() + " " + command + " --method-options '{\"net\": {\"x\": 1}}'",
                      out) != 0);
    // Either "'net' takes no options" or "options for method 'net', which this command does not
    // run": evaluate and batch run pinv without a model.
    CHECK(out.find("--method-options") != std::string::npos);
    CHECK(out.find("'net'") != std::string::npos);
  }
}

TEST_CASE("reconstruct without --model runs the zoo's default for the camera and says so",
          "[app][zoo]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level info ";
  std::string out;
  REQUIRE(run_command(lfnet + "render --random 7 --size 45x38 --grey --out " + (tmp / "lf"), out) ==
          0);
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi asp:2 --out " + (tmp / "asp"),
                  out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --sensor " + (tmp / "asp") + " --out " + (tmp / "rec"),
                      out) == 0);
  INFO(out);
  CHECK(out.find("no --model: the zoo's default for asp:2 (grey) is lfnet-asp-n2-auto") !=
        std::string::npos);
  CHECK(out.find("with net") != std::string::npos);
  // A camera the zoo has no model for: pinv, said as such.
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi asp:4 --out " + (tmp / "asp4"),
                  out) == 0);
  REQUIRE(
      run_command(lfnet + "reconstruct --sensor " + (tmp / "asp4") + " --out " + (tmp / "rec-asp4"),
                  out) == 0);
  CHECK(out.find("the zoo has no default for asp:4 (grey): pinv") != std::string::npos);
  CHECK(out.find("with pinv") != std::string::npos);
  // --method says what runs: no zoo model is chosen for it.
  REQUIRE(run_command(lfnet + "reconstruct --method adjoint --sensor " + (tmp / "asp") + " --out " +
                          (tmp / "rec-adjoint"),
                      out) == 0);
  CHECK(out.find("zoo") == std::string::npos);
}

namespace {

// The options of `lfnet ARGS --help`: flag -> help text (CLI11 writes one line per option, or
// two when a "Needs:" clause pushes the text to the next).
std::map<std::string, std::string> help_texts(const std::string& args) {
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " " + args + " --help", out) == 0);
  std::map<std::string, std::string> texts;
  std::istringstream lines(out);
  std::string line, pending;
  while (std::getline(lines, line)) {
    if (!pending.empty()) {
      texts[pending] = line.substr(line.find_first_not_of(' '));
      pending.clear();
      continue;
    }
    if (line.rfind("  --", 0) != 0) continue;
    const auto end = line.find_first_of(" ", 2);
    const auto flag = line.substr(2, end - 2);
    const auto gap = line.find("  ", end);
    if (line.find("Needs:") != std::string::npos || gap == std::string::npos) {
      pending = flag;
    } else {
      texts[flag] = line.substr(line.find_first_not_of(' ', gap));
    }
  }
  return texts;
}

}  // namespace

TEST_CASE("a flag several commands take has one help text", "[app]") {
  // The flags whose meaning is the command's own: where its output goes, which model it
  // blends or exports, which methods it can run or time (reconstruct has no truth for
  // no-parallax), what it resumes or checks, render's view grid (RxC, not a window) and
  // simulate's per_patch stride.
  const std::set<std::string> own = {"--out",    "--model", "--method", "--methods",
                                     "--resume", "--check", "--views",  "--stride"};
  const std::vector<std::string> commands = {
      "info",        "render", "simulate",  "train",     "experiment", "evaluate",
      "reconstruct", "batch",  "report",    "export",    "launch",     "bench",
      "phi export",  "blend",  "sets make", "sets list", "models"};
  std::map<std::string, std::map<std::string, std::string>> by_flag;  // flag -> text -> command
  for (const auto& command : commands) {
    for (const auto& [flag, text] : help_texts(command)) by_flag[flag][text] = command;
  }
  int shared = 0;
  for (const auto& [flag, texts] : by_flag) {
    if (own.count(flag)) continue;
    std::string said;
    for (const auto& [text, command] : texts) said += "\n  " + command + ": " + text;
    INFO(flag << said);
    CHECK(texts.size() == 1);
    ++shared;
  }
  CHECK(shared > 40);
  // The shared groups are there: --force in every command that writes.
  for (const auto& command : {"render", "simulate", "train", "evaluate", "reconstruct", "batch",
                              "export", "bench", "phi export", "blend", "sets make"}) {
    INFO(command);
    CHECK(help_texts(command).count("--force") == 1);
  }
}

TEST_CASE("the commands reach the library through pipeline/ and core/ alone", "[app]") {
  // docs/architecture.md: a subcommand turns its flags into a pipeline request and makes one
  // call; the types its flags bind come through lfnet/pipeline/catalog.h.
  namespace fs = std::filesystem;
  int files = 0, includes = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(LFNET_SOURCE_DIR) / "apps" / "lfnet")) {
    const auto ext = entry.path().extension();
    if (ext != ".cc" && ext != ".h") continue;
    ++files;
    std::ifstream in(entry.path());
    for (std::string line; std::getline(in, line);) {
      const auto at = line.find("#include \"lfnet/");
      if (at == std::string::npos) continue;
      ++includes;
      const std::string area = line.substr(at + 16, line.find('/', at + 16) - at - 16);
      INFO(entry.path().filename().string() << ": " << line);
      CHECK((area == "pipeline" || area == "core"));
    }
  }
  CHECK(files > 20);
  CHECK(includes > 20);
}

// The README and the docs as a newcomer reads them: the README's "A first session" commands
// run in order and leave what it says they leave; the names the docs cite exist; both stay short.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "support/test_support.h"

namespace fs = std::filesystem;

namespace {

// The indented command lines of the README section titled `title`, up to the next section.
std::vector<std::string> section_commands(const std::string& readme, const std::string& title) {
  std::istringstream in(readme);
  std::string line;
  bool inside = false;
  std::vector<std::string> commands;
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) {
      if (inside) break;
      inside = line == "## " + title;
      continue;
    }
    const std::string prefix = "    build/apps/lfnet ";
    if (inside && line.rfind(prefix, 0) == 0) commands.push_back(line.substr(4));
  }
  return commands;
}

void replace_all(std::string& text, const std::string& from, const std::string& to) {
  for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
    text.replace(at, from.size(), to);
}

}  // namespace

TEST_CASE("the README's first session runs in order on the shipped models", "[apps][readme]") {
  const std::string data = lfnet::test::shared_data_dir();
  if (data.empty()) {
    LFNET_SKIP("../shared/data is not beside the checkout");
  }
  const auto commands = section_commands(lfnet::test::read_bytes("README.md"), "A first session");
  // The section names the steps it describes; a README edit that drops one fails here.
  REQUIRE(commands.size() >= 9);
  lfnet::test::TempDir tmp;
  const std::string tour = tmp / "tour";
  for (auto command : commands) {
    replace_all(command, "build/apps/lfnet ", lfnet::test::lfnet_program(""));
    replace_all(command, "out/tour", tour);
    replace_all(command, "../shared/data", data);
    INFO(command);
    std::string output;
    const int rc = lfnet::test::run_command(command, output);
    INFO(output);
    REQUIRE(rc == 0);
  }
  // What the README says the session leaves.
  CHECK(fs::exists(tour + "/acq/sensor.json"));
  CHECK(fs::exists(tour + "/rec/lf_3_3.png"));
  CHECK(fs::exists(tour + "/eval/evaluation.json"));
  CHECK(fs::exists(tour + "/pinv.json"));
  CHECK(fs::exists(tour + "/camera/phi.json"));
  CHECK(fs::exists(tour + "/finetuned/models/joint.ckpt"));
  CHECK(fs::exists(tour + "/finetuned/results.jsonl"));
  CHECK(fs::exists(tour + "/finetuned/report.md"));
  CHECK(fs::exists(tour + "/asp-n2.pt"));
  // The finetuned run recorded the camera itself, not the path to it.
  const auto config = lfnet::test::read_bytes(tour + "/finetuned/config.json");
  CHECK(config.find("\"calibrated\"") != std::string::npos);
  CHECK(config.find(tour + "/camera") == std::string::npos);
}

TEST_CASE("every name the docs cite in backticks exists in the tree", "[apps][readme]") {
  std::string out;
  const int rc = lfnet::test::run_command(
      std::string(LFNET_TEST_PYTHON) + " " + LFNET_SOURCE_DIR + "/scripts/check-doc-names.py", out);
  INFO(out);
  CHECK(rc == 0);
}

TEST_CASE("the README stays a front page and the hand-written docs stay short", "[apps][readme]") {
  const fs::path root = LFNET_SOURCE_DIR;
  const std::string readme = lfnet::test::read_bytes((root / "README.md").string());
  CHECK(std::count(readme.begin(), readme.end(), '\n') <= 120);
  // Words as wc -w counts them, in README.md and docs/*.md but the generated docs/RESULTS.md.
  auto words = [](const std::string& text) {
    size_t n = 0;
    bool in_word = false;
    for (const unsigned char c : text) {
      const bool space = std::isspace(c) != 0;
      if (!space && !in_word) ++n;
      in_word = !space;
    }
    return n;
  };
  size_t total = words(readme);
  for (const auto& entry : fs::directory_iterator(root / "docs")) {
    if (entry.path().extension() != ".md" || entry.path().filename() == "RESULTS.md") continue;
    total += words(lfnet::test::read_bytes(entry.path().string()));
  }
  INFO(total << " words");
  CHECK(total <= 25000);
}

TEST_CASE("the README's zoo table is what lfnet models prints", "[apps][readme]") {
  std::string table;
  REQUIRE(lfnet::test::run_command(lfnet::test::lfnet_binary() + " models", table) == 0);
  const std::string readme =
      lfnet::test::read_bytes((fs::path(LFNET_SOURCE_DIR) / "README.md").string());
  std::istringstream lines(table);
  std::string line;
  int rows = 0;
  while (std::getline(lines, line)) {
    while (!line.empty() && line.back() == ' ') line.pop_back();
    if (line.empty()) continue;
    INFO(line);
    CHECK(readme.find("    " + line + "\n") != std::string::npos);
    ++rows;
  }
  CHECK(rows >= 10);
}

// The README's "A first session" commands, run in order as a newcomer would: each must
// succeed and leave what the README says it leaves.
#include <catch2/catch.hpp>

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

// Every path flag of every command, found in the program's own help (paths.h declares them:
// PATH what a command reads, RUN a run folder it continues, DIR and FILE what it writes), gets
// the same careless inputs: a named pipe, a path that does not exist, and the same path as an
// output. A flag added later is covered without a new test.
#include <catch2/catch.hpp>

#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

namespace {

struct Flag {
  std::string name;  // --model, or a positional's name (config)
  std::string type;  // PATH, RUN, DIR or FILE
  bool positional = false;
};

std::string help_of(const std::string& command) {
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " " + command + " --help", out) == 0);
  return out;
}

// The names listed under "Subcommands:" in a help text.
std::vector<std::string> subcommands_in(const std::string& help) {
  std::vector<std::string> names;
  const auto at = help.find("Subcommands:");
  if (at == std::string::npos) return names;
  std::istringstream lines(help.substr(at));
  std::string line;
  std::getline(lines, line);
  const std::regex entry(R"(^  ([a-z][a-z-]*)\b.*)");
  while (std::getline(lines, line)) {
    std::smatch m;
    if (std::regex_match(line, m, entry)) names.push_back(m[1]);
  }
  return names;
}

// Every command line that runs a command: "evaluate", "phi export", ...
std::vector<std::string> commands() {
  std::vector<std::string> all;
  std::vector<std::string> todo = {""};
  while (!todo.empty()) {
    const std::string command = todo.back();
    todo.pop_back();
    const auto subs = subcommands_in(help_of(command));
    if (subs.empty() && !command.empty()) all.push_back(command);
    for (const auto& sub : subs) todo.push_back(command.empty() ? sub : command + " " + sub);
  }
  return all;
}

// The flags and positionals of a command whose type is a path, from its help:
// "  --model PATH:FILE  ...", "  config PATH:FILE REQUIRED ...".
std::vector<Flag> path_flags_of(const std::string& command) {
  std::vector<Flag> flags;
  std::istringstream lines(help_of(command));
  std::string line;
  const std::regex option(R"(^  (-\w,)?(--[a-z][a-z-]*)(,--[a-z-]+)? (PATH|RUN|DIR|FILE)\b.*)");
  const std::regex positional(R"(^  ([A-Za-z][A-Za-z_]*) (PATH|RUN)\b.*)");
  while (std::getline(lines, line)) {
    std::smatch m;
    if (std::regex_match(line, m, option)) flags.push_back({m[2], m[4]});
    if (std::regex_match(line, m, positional)) flags.push_back({m[1], m[2], true});
  }
  return flags;
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

TEST_CASE("every path flag refuses a pipe, a missing path and its own output", "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  REQUIRE(mkfifo((tmp / "fifo").c_str(), 0600) == 0);
  const auto all = commands();
  // Every command is found, nested ones too.
  CHECK(std::set<std::string>(all.begin(), all.end()).count("phi export") == 1);
  CHECK(all.size() >= 15);
  int inputs = 0;
  for (const auto& command : all) {
    const auto flags = path_flags_of(command);
    std::vector<Flag> outputs;
    for (const auto& f : flags) {
      if (f.type == "DIR" || f.type == "FILE") outputs.push_back(f);
    }
    for (const auto& f : flags) {
      if (f.type != "PATH" && f.type != "RUN") continue;
      ++inputs;
      INFO(command << " " << f.name);
      const std::string run = "timeout 60 " + lfnet_binary() + " " + command + " " +
                              (f.positional ? std::string() : f.name + " ");
      std::string out;
      // A named pipe is refused before it is opened, quickly, naming the flag.
      const auto start = std::chrono::steady_clock::now();
      const int status = run_command(run + (tmp / "fifo"), out);
      CHECK(status != 0);
      CHECK(status != 124);
      CHECK(std::chrono::steady_clock::now() - start < std::chrono::seconds(30));
      CHECK(out.find(f.name + " " + (tmp / "fifo") +
                     " is not a regular file or folder: it is a named pipe") != std::string::npos);
      // A path that does not exist names the flag.
      CHECK(run_command(run + (tmp / "no/such/file"), out) != 0);
      CHECK(out.find(f.name + " " + (tmp / "no/such/file") + ": no such file or folder") !=
            std::string::npos);
      if (f.type == "RUN") continue;
      // The same path as an output, or inside an output folder, with --force: refused, naming
      // both flags, and the input is untouched.
      for (const auto& o : outputs) {
        INFO(o.name);
        fs::create_directories(tmp / "keep");
        std::ofstream(tmp / "keep/input.json") << "{\"kept\": true}";
        const std::string input = tmp / "keep/input.json";
        const std::string target = o.type == "DIR" ? tmp / "keep" : input;
        CHECK(run_command(run + input + " " + o.name + " " + target + " --force", out) != 0);
        CHECK(out.find(o.name + " " + target) != std::string::npos);
        CHECK(out.find("the input " + f.name + " " + input + ": choose an output apart") !=
              std::string::npos);
        CHECK(read_text(input) == "{\"kept\": true}");
      }
    }
  }
  // Every command that reads a file declares it: at least the 40 flags of today.
  CHECK(inputs >= 40);
}

// The output policy at the program level (docs/robustness.md, "Outputs"): no command writes
// over what it reads, a failed start leaves nothing, --force replaces a run afresh, runs resume
// from their folder, --set overrides are validated and recorded, and batch goes on past
// unreadable entries.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "lfnet/core/json.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::read_bytes;
using lfnet::test::run_command;

namespace {

std::string program(const std::string& args) { return lfnet::test::lfnet_program(args); }

// A config of two quick stages.
nlohmann::json two_stage_config(double lr = 1e-3) {
  return {{"name", "two"},
          {"phi", "asp:2"},
          {"data",
           {{"random_scenes", 1},
            {"random_seed", 5},
            {"random_options", {{"height", 64}, {"width", 64}}}}},
          {"dataset", {{"train_patches", 64}, {"validation_patches", 32}, {"seed", 2}}},
          {"network",
           {{"ae", {{"hidden", {64, 32, 64, 32, 64}}}}, {"cnn", {{"depth", 2}, {"channels", 4}}}}},
          {"training", {{"epochs", 1}, {"batch_size", 32}, {"lr", lr}, {"progress", false}}},
          {"stages", {"ae", "cnn"}}};
}

// One lfnet: error line, naming `needle`.
void expect_one_error(const std::string& out, const std::string& needle) {
  INFO(out);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find(needle) != std::string::npos);
  CHECK(out.find(".cc:") == std::string::npos);  // no source locations
}

pid_t dead_pid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  waitpid(pid, nullptr, 0);
  return pid;
}

}  // namespace

TEST_CASE("no command writes over its inputs, even with --force", "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string lf = tmp / "lf";
  REQUIRE(run_command(program("render --random 1 --size 24x24 --grey --out " + lf), out) == 0);
  const std::string view = read_bytes(lf + "/lf_1_1.png");
  // evaluate --out into its own light field, or into a folder inside it.
  CHECK(run_command(
            program("evaluate --lf " + lf + " --phi asp:2 --method pinv --out " + lf + " --force"),
            out) != 0);
  expect_one_error(out, "is the input");
  CHECK(run_command(
            program("evaluate --lf " + lf + " --phi asp:2 --method pinv --out " + lf + "/rec"),
            out) != 0);
  expect_one_error(out, "lies inside the input");
  CHECK(read_bytes(lf + "/lf_1_1.png") == view);
  CHECK_FALSE(fs::exists(lf + "/rec"));
  // evaluate --out: an existing non-empty folder only with --force, and then replaced whole.
  fs::create_directories(tmp.path() / "ev");
  std::ofstream(tmp / "ev/old.txt") << "old";
  CHECK(run_command(
            program("evaluate --lf " + lf + " --phi asp:2 --method pinv --out " + (tmp / "ev")),
            out) != 0);
  expect_one_error(out, "--force");
  REQUIRE(run_command(program("evaluate --lf " + lf + " --phi asp:2 --method pinv --out " +
                              (tmp / "ev") + " --force"),
                      out) == 0);
  CHECK_FALSE(fs::exists(tmp.path() / "ev/old.txt"));
  CHECK(fs::exists(tmp.path() / "ev/evaluation.json"));
  // reconstruct --out its own acquisition keeps sensor.tif and sensor.json.
  const std::string acq = tmp / "acq";
  REQUIRE(run_command(program("simulate --lf " + lf + " --phi asp:2 --out " + acq), out) == 0);
  const std::string sidecar = read_bytes(acq + "/sensor.json");
  CHECK(run_command(
            program("reconstruct --sensor " + acq + " --method pinv --out " + acq + " --force"),
            out) != 0);
  expect_one_error(out, "is the input");
  CHECK(read_bytes(acq + "/sensor.json") == sidecar);
  CHECK(fs::exists(acq + "/sensor.tif"));
  // simulate into the light field it reads; export over its checkpoint.
  CHECK(run_command(program("simulate --lf " + lf + " --phi asp:2 --out " + lf + " --force"),
                    out) != 0);
  expect_one_error(out, "is the input");
  // A dead writer's half-written output is removed by the next writer of that output.
  const fs::path stale = tmp.path() / (".rec.tmp" + std::to_string(dead_pid()));
  fs::create_directories(stale);
  REQUIRE(
      run_command(program("reconstruct --sensor " + acq + " --method pinv --out " + (tmp / "rec")),
                  out) == 0);
  CHECK_FALSE(fs::exists(stale));
  CHECK(fs::exists(tmp.path() / "rec/reconstruction.json"));
}

TEST_CASE("a training run that fails before its first checkpoint leaves nothing behind",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  lfnet::write_json_file(tmp / "wild.json", two_stage_config(1e308));
  CHECK(run_command(program("train " + (tmp / "wild.json") + " --out " + (tmp / "run")), out) != 0);
  CHECK(out.find("lfnet: error: ") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp.path() / "run"));
  // The same command with a sane config then runs: nothing was left to refuse it.
  lfnet::write_json_file(tmp / "good.json", two_stage_config());
  REQUIRE(run_command(
              program("train " + (tmp / "good.json") + " --out " + (tmp / "run") + " --stage ae"),
              out) == 0);
  // --resume of something that does not exist fails before any data is loaded, and creates
  // nothing.
  CHECK(run_command(program("train " + (tmp / "good.json") + " --out " + (tmp / "new") +
                            " --resume " + (tmp / "nosuch")),
                    out) != 0);
  expect_one_error(out, "--resume");
  CHECK_FALSE(fs::exists(tmp.path() / "new"));
  // --force with a failing config keeps the old run as it was.
  const std::string ae = read_bytes(tmp / "run/models/ae.ckpt");
  CHECK(
      run_command(program("train " + (tmp / "wild.json") + " --out " + (tmp / "run") + " --force"),
                  out) != 0);
  CHECK(read_bytes(tmp / "run/models/ae.ckpt") == ae);
}

TEST_CASE(
    "train --resume RUN continues the remaining stages, --force starts afresh, --set is "
    "recorded",
    "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  lfnet::write_json_file(tmp / "two.json", two_stage_config());
  // Only the first stage, as an interrupted run would have done, with an override.
  REQUIRE(run_command(program("train " + (tmp / "two.json") + " --out " + (tmp / "run") +
                              " --stage ae --set training.epochs=2"),
                      out) == 0);
  const auto config = lfnet::read_json_file(tmp / "run/config.json");
  CHECK(config["training"]["epochs"] == 2);
  const std::string ae = read_bytes(tmp / "run/models/ae.ckpt");
  // Running the config again into it says how to continue, not only how to discard.
  CHECK(run_command(program("train " + (tmp / "two.json") + " --out " + (tmp / "run")), out) != 0);
  CHECK(out.find("holds a run (its config.json); continue it with --resume") != std::string::npos);
  CHECK(read_bytes(tmp / "run/models/ae.ckpt") == ae);
  // Resuming the folder keeps the finished stage and trains the other, with the run's config.
  REQUIRE(run_command(program("train --resume " + (tmp / "run")), out) == 0);
  CHECK(read_bytes(tmp / "run/models/ae.ckpt") == ae);
  REQUIRE(fs::exists(tmp.path() / "run/models/cnn.ckpt"));
  size_t cnn_epochs = 0;
  std::ifstream log(tmp / "run/training.jsonl");
  for (std::string line; std::getline(log, line);) {
    cnn_epochs += nlohmann::json::parse(line)["stage"] == "cnn";
  }
  CHECK(cnn_epochs == 2);  // the recorded override, not the file's 1
  // Nothing left to do: a second resume changes nothing.
  const std::string cnn = read_bytes(tmp / "run/models/cnn.ckpt");
  REQUIRE(run_command(program("train --resume " + (tmp / "run")), out) == 0);
  CHECK(read_bytes(tmp / "run/models/cnn.ckpt") == cnn);
  // --set values are validated like the file; --force and --resume exclude each other.
  CHECK(run_command(program("train " + (tmp / "two.json") + " --out " + (tmp / "x") +
                            " --set training.epochs=1.5"),
                    out) != 0);
  expect_one_error(out, "$.training.epochs");
  CHECK_FALSE(fs::exists(tmp.path() / "x"));
  CHECK(run_command(program("train --resume " + (tmp / "run") + " --force"), out) != 0);
  expect_one_error(out, "--force");
  // --force starts the run afresh: the old models and log are gone once it trains.
  REQUIRE(run_command(program("train " + (tmp / "two.json") + " --out " + (tmp / "run") +
                              " --stage ae --force"),
                      out) == 0);
  CHECK_FALSE(fs::exists(tmp.path() / "run/models/cnn.ckpt"));
  size_t lines = 0;
  std::ifstream fresh(tmp / "run/training.jsonl");
  for (std::string line; std::getline(fresh, line);) ++lines;
  CHECK(lines == 1);  // one ae epoch, not appended to the old log
}

TEST_CASE("a run snapshot carries an interrupted run to another folder, which resumes it alike",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  lfnet::write_json_file(tmp / "two.json", two_stage_config());
  REQUIRE(run_command(
              program("train " + (tmp / "two.json") + " --out " + (tmp / "run") + " --stage ae"),
              out) == 0);
  // An unfinished stage's state, as an interrupted run leaves it.
  fs::create_directories(tmp.path() / "run/models/cnn");
  lfnet::test::write_bytes(tmp / "run/models/cnn/last.ckpt", "state");
  const std::string script = std::string(LFNET_SOURCE_DIR) + "/scripts/run-snapshot.sh";
  REQUIRE(run_command(script + " save " + (tmp / "run") + " " + (tmp / "snap"), out) == 0);
  CHECK(fs::exists(tmp.path() / "snap/config.json"));
  CHECK(fs::exists(tmp.path() / "snap/training.jsonl"));
  CHECK(read_bytes(tmp / "snap/models/ae.ckpt") == read_bytes(tmp / "run/models/ae.ckpt"));
  CHECK_FALSE(fs::exists(tmp.path() / "snap/models/ae"));  // a finished stage needs its model only
  CHECK(read_bytes(tmp / "snap/models/cnn/last.ckpt") == "state");
  // Restoring never replaces a folder, and a folder that is no run folder is refused.
  CHECK(run_command(script + " restore " + (tmp / "snap") + " " + (tmp / "run"), out) != 0);
  CHECK(out.find("exists") != std::string::npos);
  CHECK(run_command(script + " save " + (tmp / "nothing") + " " + (tmp / "x"), out) != 0);
  CHECK_FALSE(fs::exists(tmp.path() / "x"));
  // The restored run continues exactly as the original one does.
  fs::remove_all(tmp.path() / "run/models/cnn");
  fs::remove_all(tmp.path() / "snap/models/cnn");
  REQUIRE(run_command(script + " restore " + (tmp / "snap") + " " + (tmp / "moved"), out) == 0);
  REQUIRE(run_command(program("train --resume " + (tmp / "run")), out) == 0);
  REQUIRE(run_command(program("train --resume " + (tmp / "moved")), out) == 0);
  auto cnn_losses = [](const std::string& log_path) {
    std::vector<double> losses;
    std::ifstream log(log_path);
    for (std::string line; std::getline(log, line);) {
      const auto j = nlohmann::json::parse(line);
      if (j["stage"] == "cnn") losses.push_back(j["record"]["val_loss"].get<double>());
    }
    return losses;
  };
  const auto original = cnn_losses(tmp / "run/training.jsonl");
  REQUIRE_FALSE(original.empty());
  CHECK(cnn_losses(tmp / "moved/training.jsonl") == original);
}

TEST_CASE("batch records unreadable entries as failed items and goes on", "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const fs::path in = tmp.path() / "in";
  fs::create_directories(in);
  REQUIRE(
      run_command(program("render --random 2 --size 24x24 --grey --out " + (in / "good").string()),
                  out) == 0);
  fs::create_symlink(in / "nowhere", in / "broken");
  fs::create_symlink(in, in / "loop");  // a link back to the root
  REQUIRE(run_command(program("batch --input " + in.string() +
                              " --phi asp:2 --methods pinv --out " + (tmp / "b")),
                      out) != 0);
  CHECK(out.find("2 of 3 item-method pair(s) failed") != std::string::npos);
  const auto summary = lfnet::read_json_file(tmp / "b/summary.json");
  REQUIRE(summary.size() == 3);
  std::map<std::string, std::string> status;
  for (const auto& r : summary)
    status[r["item"].get<std::string>()] = r["status"].get<std::string>();
  CHECK(status["good"] == "ok");
  CHECK(status["broken"] == "error");
  CHECK(status["loop"] == "error");
  // The output may not lie inside the input (the batch would find its own outputs).
  CHECK(run_command(
            program("batch --input " + in.string() + " --phi asp:2 --out " + (in / "out").string()),
            out) != 0);
  expect_one_error(out, "lies inside the input");
}

TEST_CASE("batch records a folder it may not read as a failed item and goes on",
          "[app][bad_input]") {
  // Permissions do not stop root: run lfnet as `nobody` (setpriv, util-linux) when the tests
  // run as root, else as the user running them.
  std::string out;
  std::string as_user;
  if (::geteuid() == 0) {
    if (run_command("command -v setpriv", out) != 0) {
      LFNET_SKIP("running as root without setpriv: permissions cannot be tested");
    }
    as_user = "setpriv --reuid=65534 --regid=65534 --clear-groups ";
  }
  lfnet::test::TempDir tmp;
  const fs::path in = tmp.path() / "in";
  fs::create_directories(in);
  REQUIRE(
      run_command(program("render --random 2 --size 24x24 --grey --out " + (in / "good").string()),
                  out) == 0);
  REQUIRE(run_command(
              program("render --random 3 --size 24x24 --grey --out " + (in / "secret").string()),
              out) == 0);
  fs::permissions(in / "secret", fs::perms::none);
  // nobody must reach the input and write the output.
  fs::permissions(tmp.path(), fs::perms::all);
  fs::permissions(in, fs::perms::all);
  for (const auto& e : fs::directory_iterator(in / "good")) {
    fs::permissions(e.path(),
                    fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
  }
  fs::permissions(in / "good", fs::perms::all);
  CHECK(run_command(as_user + program("batch --input " + in.string() +
                                      " --phi asp:2 --methods pinv --out " + (tmp / "b")),
                    out) != 0);
  INFO(out);
  CHECK(out.find("1 of 2 item-method pair(s) failed") != std::string::npos);
  const auto summary = lfnet::read_json_file(tmp / "b/summary.json");
  REQUIRE(summary.size() == 2);
  std::map<std::string, std::string> status;
  for (const auto& r : summary)
    status[r["item"].get<std::string>()] = r["status"].get<std::string>();
  CHECK(status["good"] == "ok");
  CHECK(status["secret"] == "error");
  fs::permissions(in / "secret", fs::perms::owner_all);  // so the folder can be removed
}

// The output policy at the program level (docs/robustness.md, "Outputs"): no command writes
// over what it reads, a failed start leaves nothing, --force replaces a run afresh, runs resume
// from their folder, --set overrides are validated and recorded, and batch goes on past
// unreadable entries.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "lfnet/core/json.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::read_bytes;
using lfnet::test::run_command;

namespace {

// A config of two quick stages.
nlohmann::json two_stage_config(double lr = 1e-3) {
  return {
      {"name", "two"},
      {"phi", "asp:2"},
      {"data",
       {{"random_scenes", 1},
        {"random_seed", 5},
        {"random_options", {{"height", 64}, {"width", 64}}}}},
      {"dataset", {{"train_patches", 64}, {"validation_patches", 32}, {"seed", 2}}},
      {"network",
       {{"paper",
         {{"ae", {{"hidden", {64, 32, 64, 32, 64}}}}, {"cnn", {{"depth", 2}, {"channels", 4}}}}}}},
      {"training", {{"epochs", 1}, {"batch_size", 32}, {"lr", lr}, {"progress", false}}},
      {"stages", {"ae", "cnn"}}};
}

// A run of two_stage_config() in tmp/run (its config in tmp/two.json) with only its first stage
// trained, as an interrupted run leaves it.
void train_first_stage(const lfnet::test::TempDir& tmp) {
  std::string out;
  lfnet::write_json_file(tmp / "two.json", two_stage_config());
  REQUIRE(run_command(lfnet::test::lfnet_program("train " + (tmp / "two.json") + " --out " +
                                                 (tmp / "run") + " --stage ae"),
                      out) == 0);
}

// One lfnet: error line, naming `needle`.
void expect_one_error(const std::string& out, const std::string& needle) {
  INFO(out);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find(needle) != std::string::npos);
  CHECK(out.find(".cc:") == std::string::npos);  // no source locations
}

// A small grey light field rendered into tmp/lf, its path.
std::string rendered_light_field(const lfnet::test::TempDir& tmp) {
  std::string out;
  std::string lf = tmp / "lf";
  REQUIRE(
      run_command(lfnet::test::lfnet_program("render --random 1 --size 24x24 --grey --out " + lf),
                  out) == 0);
  return lf;
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
  const std::string lf = rendered_light_field(tmp);
  const std::string view = read_bytes(lf + "/lf_1_1.png");
  // evaluate --out into its own light field, or into a folder inside it.
  CHECK(
      run_command(lfnet::test::lfnet_program("evaluate --lf " + lf +
                                             " --phi asp:2 --method pinv --out " + lf + " --force"),
                  out) != 0);
  expect_one_error(out, "is the input");
  CHECK(run_command(lfnet::test::lfnet_program("evaluate --lf " + lf +
                                               " --phi asp:2 --method pinv --out " + lf + "/rec"),
                    out) != 0);
  expect_one_error(out, "lies inside the input");
  CHECK(read_bytes(lf + "/lf_1_1.png") == view);
  CHECK_FALSE(fs::exists(lf + "/rec"));
  // evaluate --out: an existing non-empty folder only with --force, and then replaced whole.
  fs::create_directories(tmp.path() / "ev");
  std::ofstream(tmp / "ev/old.txt") << "old";
  CHECK(run_command(lfnet::test::lfnet_program("evaluate --lf " + lf +
                                               " --phi asp:2 --method pinv --out " + (tmp / "ev")),
                    out) != 0);
  expect_one_error(out, "--force");
  REQUIRE(run_command(lfnet::test::lfnet_program("evaluate --lf " + lf +
                                                 " --phi asp:2 --method pinv --out " +
                                                 (tmp / "ev") + " --force"),
                      out) == 0);
  CHECK_FALSE(fs::exists(tmp.path() / "ev/old.txt"));
  CHECK(fs::exists(tmp.path() / "ev/evaluation.json"));
  // reconstruct --out its own acquisition keeps sensor.tif and sensor.json.
  const std::string acq = tmp / "acq";
  REQUIRE(
      run_command(lfnet::test::lfnet_program("simulate --lf " + lf + " --phi asp:2 --out " + acq),
                  out) == 0);
  const std::string sidecar = read_bytes(acq + "/sensor.json");
  CHECK(run_command(lfnet::test::lfnet_program("reconstruct --sensor " + acq +
                                               " --method pinv --out " + acq + " --force"),
                    out) != 0);
  expect_one_error(out, "is the input");
  CHECK(read_bytes(acq + "/sensor.json") == sidecar);
  CHECK(fs::exists(acq + "/sensor.tif"));
  // simulate into the light field it reads; export over its checkpoint.
  CHECK(run_command(lfnet::test::lfnet_program("simulate --lf " + lf + " --phi asp:2 --out " + lf +
                                               " --force"),
                    out) != 0);
  expect_one_error(out, "is the input");
  // A dead writer's half-written output is removed by the next writer of that output.
  const fs::path stale = tmp.path() / (".rec.tmp" + std::to_string(dead_pid()));
  fs::create_directories(stale);
  REQUIRE(run_command(lfnet::test::lfnet_program("reconstruct --sensor " + acq +
                                                 " --method pinv --out " + (tmp / "rec")),
                      out) == 0);
  CHECK_FALSE(fs::exists(stale));
  CHECK(fs::exists(tmp.path() / "rec/reconstruction.json"));
}

TEST_CASE("files read through other files and JSON options are inputs too, even with --force",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string lf = rendered_light_field(tmp);
  // A noise switch in a folder of its own, beside its two members; the files of --method-options,
  // --cfa and --camera-error in another.
  const fs::path models = fs::path(LFNET_SOURCE_DIR) / "models";
  fs::create_directories(tmp.path() / "sw");
  const auto members = lfnet::read_json_file((models / "lfnet-asp-n2-auto.json").string());
  for (const std::string& f :
       {std::string("lfnet-asp-n2-auto.json"), members.at("quiet").get<std::string>(),
        members.at("noisy").get<std::string>()}) {
    fs::copy_file(models / f, tmp.path() / "sw" / f);
  }
  const std::string sw = tmp / "sw", opts = tmp / "opts";
  fs::create_directories(opts);
  lfnet::write_json_file(opts + "/options.json", {{"pinv", {{"lambda", 0.01}}}});
  lfnet::write_json_file(opts + "/cfa.json", {{"pattern", "RGGB"}});
  lfnet::write_json_file(opts + "/error.json", {{"depth", 0.05}});
  const std::string noisy = read_bytes(sw + "/lfnet-asp-n2-noise.ckpt");
  const std::string options = read_bytes(opts + "/options.json");
  const std::string model = " --model " + sw + "/lfnet-asp-n2-auto.json ";
  const std::string pinv = "evaluate --lf " + lf + " --phi asp:2 --method pinv ";
  // Each command, and what its one error line names.
  const std::pair<std::string, std::string> refused[] = {
      {"evaluate --lf " + lf + model + "--out " + sw + " --force", "contains the input"},
      {"evaluate --lf " + lf + model + "--json " + sw + "/lfnet-asp-n2-noise.ckpt --force",
       "lfnet-asp-n2-noise.ckpt"},
      {"phi export --phi " + sw + "/lfnet-asp-n2-auto.json --out " + sw + " --force",
       "contains the input"},
      {"batch --in " + lf + model + "--out " + sw + " --force", "contains the input"},
      {pinv + "--method-options " + opts + "/options.json --out " + opts + " --force",
       "contains the input"},
      {pinv + "--method-options " + opts + "/options.json --json " + opts + "/options.json --force",
       "options.json"},
      {"simulate --lf " + lf + " --phi asp:2 --cfa " + opts + "/cfa.json --out " + opts +
           " --force",
       "contains the input"},
      {"simulate --lf " + lf + " --phi asp:2 --camera-error " + opts + "/error.json --out " + opts +
           " --force",
       "contains the input"},
  };
  for (const auto& [args, needle] : refused) {
    INFO(args);
    CHECK(run_command(lfnet::test::lfnet_program(args), out) != 0);
    expect_one_error(out, needle);
  }
  CHECK(read_bytes(sw + "/lfnet-asp-n2-noise.ckpt") == noisy);
  CHECK(fs::exists(sw + "/" + members.at("quiet").get<std::string>()));
  CHECK(read_bytes(opts + "/options.json") == options);
  CHECK(fs::exists(opts + "/cfa.json"));
  CHECK(fs::exists(opts + "/error.json"));
  // A config's base ($.extends) is an input of the run too.
  fs::create_directories(tmp.path() / "base");
  lfnet::write_json_file(tmp / "base/base.json", two_stage_config());
  lfnet::write_json_file(tmp / "child.json", {{"extends", "base/base.json"}});
  CHECK(run_command(lfnet::test::lfnet_program("train " + (tmp / "child.json") + " --out " +
                                               (tmp / "base") + " --force"),
                    out) != 0);
  expect_one_error(out, "contains the input");
  CHECK(fs::exists(tmp.path() / "base/base.json"));
  // --json - is standard output, not a file named "-".
  REQUIRE(run_command("cd " + opts + " && " + lfnet::test::lfnet_program(pinv + "--json -"), out) ==
          0);
  CHECK(nlohmann::json::parse(out.substr(out.find('{')))["method"] == "pinv");
  CHECK_FALSE(fs::exists(opts + "/-"));
}

TEST_CASE("a training run that fails before its first checkpoint leaves nothing behind",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  lfnet::write_json_file(tmp / "wild.json", two_stage_config(1e308));
  CHECK(run_command(
            lfnet::test::lfnet_program("train " + (tmp / "wild.json") + " --out " + (tmp / "run")),
            out) != 0);
  CHECK(out.find("lfnet: error: ") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp.path() / "run"));
  // The same command with a sane config then runs: nothing was left to refuse it.
  lfnet::write_json_file(tmp / "good.json", two_stage_config());
  REQUIRE(run_command(lfnet::test::lfnet_program("train " + (tmp / "good.json") + " --out " +
                                                 (tmp / "run") + " --stage ae"),
                      out) == 0);
  // --resume of something that does not exist fails before any data is loaded, and creates
  // nothing.
  CHECK(run_command(lfnet::test::lfnet_program("train " + (tmp / "good.json") + " --out " +
                                               (tmp / "new") + " --resume " + (tmp / "nosuch")),
                    out) != 0);
  expect_one_error(out, "--resume");
  CHECK_FALSE(fs::exists(tmp.path() / "new"));
  // --force with a failing config keeps the old run as it was.
  const std::string ae = read_bytes(tmp / "run/models/ae.ckpt");
  CHECK(run_command(lfnet::test::lfnet_program("train " + (tmp / "wild.json") + " --out " +
                                               (tmp / "run") + " --force"),
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
  REQUIRE(
      run_command(lfnet::test::lfnet_program("train " + (tmp / "two.json") + " --out " +
                                             (tmp / "run") + " --stage ae --set training.epochs=2"),
                  out) == 0);
  const auto config = lfnet::read_json_file(tmp / "run/config.json");
  CHECK(config["training"]["epochs"] == 2);
  const std::string ae = read_bytes(tmp / "run/models/ae.ckpt");
  // Running the config again into it says how to continue, not only how to discard.
  CHECK(run_command(
            lfnet::test::lfnet_program("train " + (tmp / "two.json") + " --out " + (tmp / "run")),
            out) != 0);
  CHECK(out.find("holds a run (its config.json); continue it with --resume") != std::string::npos);
  CHECK(read_bytes(tmp / "run/models/ae.ckpt") == ae);
  // Resuming the folder keeps the finished stage and trains the other, with the run's config.
  REQUIRE(run_command(lfnet::test::lfnet_program("train --resume " + (tmp / "run")), out) == 0);
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
  REQUIRE(run_command(lfnet::test::lfnet_program("train --resume " + (tmp / "run")), out) == 0);
  CHECK(read_bytes(tmp / "run/models/cnn.ckpt") == cnn);
  // --set values are validated like the file; --force and --resume exclude each other.
  CHECK(run_command(lfnet::test::lfnet_program("train " + (tmp / "two.json") + " --out " +
                                               (tmp / "x") + " --set training.epochs=1.5"),
                    out) != 0);
  expect_one_error(out, "$.training.epochs");
  CHECK_FALSE(fs::exists(tmp.path() / "x"));
  CHECK(run_command(lfnet::test::lfnet_program("train --resume " + (tmp / "run") + " --force"),
                    out) != 0);
  expect_one_error(out, "--force");
  // --force starts the run afresh: the old models and log are gone once it trains.
  REQUIRE(run_command(lfnet::test::lfnet_program("train " + (tmp / "two.json") + " --out " +
                                                 (tmp / "run") + " --stage ae --force"),
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
  train_first_stage(tmp);
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
  REQUIRE(run_command(lfnet::test::lfnet_program("train --resume " + (tmp / "run")), out) == 0);
  REQUIRE(run_command(lfnet::test::lfnet_program("train --resume " + (tmp / "moved")), out) == 0);
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
  REQUIRE(run_command(lfnet::test::lfnet_program("render --random 2 --size 24x24 --grey --out " +
                                                 (in / "good").string()),
                      out) == 0);
  fs::create_symlink(in / "nowhere", in / "broken");
  fs::create_symlink(in, in / "loop");           // a link back to the root
  fs::create_symlink(in / "self", in / "self");  // a link to itself
  // Light fields that cannot be read are failed items, not folders to skip: a missing view, a
  // view that is a folder. macOS's "._" files beside the views are no views.
  fs::copy(in / "good", in / "gap");
  fs::remove(in / "gap/lf_3_3.png");
  fs::copy(in / "good", in / "viewdir");
  fs::remove(in / "viewdir/lf_2_2.png");
  fs::create_directories(in / "viewdir/lf_2_2.png");
  fs::copy(in / "good", in / "mac");
  for (const auto& e : fs::directory_iterator(in / "good")) {
    lfnet::test::write_bytes((in / "mac" / ("._" + e.path().filename().string())).string(), "x");
  }
  REQUIRE(
      run_command(lfnet::test::lfnet_program("batch --input " + in.string() +
                                             " --phi asp:2 --methods pinv --out " + (tmp / "b")),
                  out) != 0);
  CHECK(out.find("5 of 7 item-method pair(s) failed") != std::string::npos);
  const auto summary = lfnet::read_json_file(tmp / "b/summary.json");
  REQUIRE(summary.size() == 7);
  std::map<std::string, std::string> errors;
  for (const auto& r : summary) errors[r["item"].get<std::string>()] = r.value("error", "");
  CHECK(errors["gap"].find("lf_3_3.png is missing") != std::string::npos);
  CHECK(errors["viewdir"].find("lf_2_2.png is not a regular file") != std::string::npos);
  CHECK(errors["self"] == "a link that loops");
  CHECK(errors["viewdir"].find(".cc:") == std::string::npos);  // no source locations
  std::map<std::string, std::string> status;
  for (const auto& r : summary)
    status[r["item"].get<std::string>()] = r["status"].get<std::string>();
  CHECK(status["good"] == "ok");
  CHECK(status["mac"] == "ok");
  CHECK(status["broken"] == "error");
  CHECK(status["loop"] == "error");
  // The output may not lie inside the input (the batch would find its own outputs).
  CHECK(run_command(lfnet::test::lfnet_program("batch --input " + in.string() +
                                               " --phi asp:2 --out " + (in / "out").string()),
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
  REQUIRE(run_command(lfnet::test::lfnet_program("render --random 2 --size 24x24 --grey --out " +
                                                 (in / "good").string()),
                      out) == 0);
  REQUIRE(run_command(lfnet::test::lfnet_program("render --random 3 --size 24x24 --grey --out " +
                                                 (in / "secret").string()),
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
  CHECK(run_command(as_user + lfnet::test::lfnet_program("batch --input " + in.string() +
                                                         " --phi asp:2 --methods pinv --out " +
                                                         (tmp / "b")),
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

TEST_CASE("files named by --json and --plot-weights go through the output policy",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string lf = rendered_light_field(tmp);
  const std::string eval = "evaluate --lf " + lf + " --phi asp:2 --method pinv --json ";
  // An existing record is replaced only with --force; an empty file (mktemp's) is written.
  lfnet::test::write_bytes(tmp / "r.json", "{\"kept\": true}\n");
  CHECK(run_command(lfnet::test::lfnet_program(eval + (tmp / "r.json")), out) != 0);
  expect_one_error(out, "--json");
  CHECK(read_bytes(tmp / "r.json") == "{\"kept\": true}\n");
  lfnet::test::write_bytes(tmp / "empty.json", "");
  REQUIRE(run_command(lfnet::test::lfnet_program(eval + (tmp / "empty.json")), out) == 0);
  CHECK(lfnet::read_json_file(tmp / "empty.json")["method"] == "pinv");
  REQUIRE(run_command(lfnet::test::lfnet_program(eval + (tmp / "r.json") + " --force"), out) == 0);
  CHECK(lfnet::read_json_file(tmp / "r.json")["method"] == "pinv");
  CHECK(run_command(lfnet::test::lfnet_program(
                        "bench --phi asp:2 --methods pinv --reps 1 --strides 9 --height 24 "
                        "--width 24 --skip-kernels --json " +
                        (tmp / "r.json")),
                    out) != 0);
  expect_one_error(out, "--force");
  // --plot-weights: never into what the command reads, existing drawings only with --force,
  // several cameras side by side in one folder.
  CHECK(run_command(lfnet::test::lfnet_program("simulate --lf " + lf + " --phi asp:2 --out " +
                                               (tmp / "acq") + " --plot-weights " + lf),
                    out) != 0);
  expect_one_error(out, "--plot-weights");
  CHECK_FALSE(fs::exists(tmp / "acq"));
  fs::create_directories(tmp / "specs");
  lfnet::write_json_file(tmp / "specs/asp-n2.json", {{"name", "asp"}, {"n", 2}});
  const std::string spec = read_bytes(tmp / "specs/asp-n2.json");
  CHECK(run_command(lfnet::test::lfnet_program("simulate --phi " + (tmp / "specs/asp-n2.json") +
                                               " --plot-weights " + (tmp / "specs") + " --force"),
                    out) != 0);
  expect_one_error(out, "contains the input");
  CHECK(read_bytes(tmp / "specs/asp-n2.json") == spec);
  if (run_command("/usr/bin/python3 -c 'import matplotlib'", out) != 0) return;  // no plotter
  REQUIRE(
      run_command(lfnet::test::lfnet_program("simulate --phi asp:2 --plot-weights " + (tmp / "w")),
                  out) == 0);
  REQUIRE(
      run_command(lfnet::test::lfnet_program("simulate --phi mask:2 --plot-weights " + (tmp / "w")),
                  out) == 0);
  CHECK(fs::exists(tmp / "w/asp-n2.png"));
  CHECK(fs::exists(tmp / "w/mask-n2.svg"));
  CHECK(
      run_command(lfnet::test::lfnet_program("simulate --phi asp:2 --plot-weights " + (tmp / "w")),
                  out) != 0);
  expect_one_error(out, "--force");
  REQUIRE(run_command(lfnet::test::lfnet_program("simulate --phi asp:2 --plot-weights " +
                                                 (tmp / "w") + " --force"),
                      out) == 0);
  size_t files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(tmp / "w")) ++files;
  CHECK(files == 6);  // png, svg and json of each: no temporaries, no lock
}

TEST_CASE("train --force killed before its first checkpoint: the old run comes back",
          "[app][bad_input][slow]") {
  lfnet::test::TempDir tmp;
  std::string out;
  auto config = two_stage_config();
  config["stages"] = {"ae"};
  lfnet::write_json_file(tmp / "one.json", config);
  REQUIRE(run_command(
              lfnet::test::lfnet_program("train " + (tmp / "one.json") + " --out " + (tmp / "run")),
              out) == 0);
  const std::string ae = read_bytes(tmp / "run/models/ae.ckpt");
  // A replacement whose data take a while to make, killed while they are made (its old run is
  // aside, its new folder holds only config.json).
  config["data"]["random_scenes"] = 24;
  config["data"]["random_options"] = {{"height", 256}, {"width", 256}};
  lfnet::write_json_file(tmp / "slow.json", config);
  const pid_t pid = lfnet::test::spawn_command(lfnet::test::lfnet_program(
      "train " + (tmp / "slow.json") + " --out " + (tmp / "run") + " --force"));
  const fs::path aside = tmp.path() / (".run.tmp" + std::to_string(pid) + ".replaced");
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  bool caught = false;
  while (std::chrono::steady_clock::now() < deadline && !caught) {
    caught = fs::exists(aside) && fs::exists(tmp.path() / "run/config.json");
    if (waitpid(pid, nullptr, WNOHANG) == pid) FAIL("the replacement ended before it was killed");
    if (!caught) usleep(20000);
  }
  kill(pid, SIGKILL);
  waitpid(pid, nullptr, 0);
  REQUIRE(caught);
  CHECK_FALSE(fs::exists(tmp.path() / "run/models/ae.ckpt"));  // the new run's folder
  // Whoever opens the run next (here a resume) finds the old run, whole.
  REQUIRE(run_command(lfnet::test::lfnet_program("train --resume " + (tmp / "run")), out) == 0);
  CHECK(out.find("put back the run that an interrupted --force had replaced") != std::string::npos);
  CHECK(read_bytes(tmp / "run/models/ae.ckpt") == ae);
  CHECK(lfnet::read_json_file(tmp / "run/config.json")["data"]["random_scenes"] == 1);
  CHECK_FALSE(fs::exists(aside));
}

TEST_CASE("report: its plotter dies with it, and a failed report leaves the old one",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  std::string out;
  train_first_stage(tmp);
  // A plotter that records its pid and then takes its time.
  fs::create_directories(tmp / "slow");
  lfnet::test::write_bytes(tmp / "slow/figures.py",
                           "import os, sys, time\nopen('" + (tmp / "plotter.pid") +
                               "', 'w').write(str(os.getpid()))\ntime.sleep(60)\n");
  const pid_t pid =
      lfnet::test::spawn_command("env LFNET_SCRIPTS=" + (tmp / "slow") + " " +
                                 lfnet::test::lfnet_program("report " + (tmp / "run")));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline && !fs::exists(tmp / "plotter.pid")) {
    usleep(20000);
  }
  REQUIRE(fs::exists(tmp / "plotter.pid"));
  usleep(100000);  // the pid is written
  const pid_t plotter = std::stoi(read_bytes(tmp / "plotter.pid"));
  kill(pid, SIGKILL);
  waitpid(pid, nullptr, 0);
  // Gone, or a zombie waiting for init: not running, not writing.
  bool running = true;
  for (int i = 0; i < 100 && running; ++i) {
    const std::string stat = read_bytes("/proc/" + std::to_string(plotter) + "/stat");
    const size_t paren = stat.rfind(')');
    running = paren != std::string::npos && paren + 2 < stat.size() && stat[paren + 2] != 'Z' &&
              stat[paren + 2] != 'X';
    if (running) usleep(20000);
  }
  CHECK_FALSE(running);
  if (running) kill(plotter, SIGKILL);
  CHECK_FALSE(fs::exists(tmp / "run/report.md"));
  CHECK_FALSE(fs::exists(tmp / "run/figures"));
  // A report, then a damaged training log: the second report fails and the first stays.
  REQUIRE(run_command(lfnet::test::lfnet_program("report " + (tmp / "run")), out) == 0);
  const std::string report = read_bytes(tmp / "run/report.md");
  std::ofstream(tmp / "run/training.jsonl", std::ios::app) << "{not json\n";
  CHECK(run_command(lfnet::test::lfnet_program("report " + (tmp / "run")), out) != 0);
  expect_one_error(out, "training.jsonl");
  CHECK(read_bytes(tmp / "run/report.md") == report);
  size_t entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(tmp / "run")) ++entries;
  CHECK(entries == 5);  // config.json, training.jsonl, models, report.md, figures: no temporary
}

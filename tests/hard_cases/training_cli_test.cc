// Training and reproducibility at the program level (docs/robustness.md): a run killed while
// it writes a checkpoint leaves the previous one loadable and resumable; a diverging run stops
// with a clear message and keeps the last good checkpoint; the same seed and thread count give
// bit-identical outputs.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>

#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/train/checkpoint.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::read_bytes;
using lfnet::test::run_command;

namespace {

// The pieces of a command or a path, joined.
std::string cat(std::initializer_list<std::string_view> parts) {
  std::string out;
  for (const auto part : parts) out += part;
  return out;
}

// A tiny config; `ae_width` sets the autoencoder's widths (wide ones make checkpoint writes
// take long enough to be interrupted).
nlohmann::json tiny_config(int64_t epochs, int64_t ae_width, double lr = 1e-3) {
  return {{"name", "tiny"},
          {"phi", "asp:2"},
          {"data",
           {{"random_scenes", 1},
            {"random_seed", 5},
            {"random_options", {{"height", 64}, {"width", 64}}}}},
          {"dataset", {{"train_patches", 64}, {"validation_patches", 32}, {"seed", 2}}},
          {"network",
           {{"paper",
             {{"ae", {{"hidden", {ae_width, ae_width / 2, ae_width, ae_width / 2, ae_width}}}}}}}},
          {"training", {{"epochs", epochs}, {"batch_size", 32}, {"lr", lr}, {"progress", false}}},
          {"stages", {"ae"}}};
}

void write_config(const std::string& path, const nlohmann::json& config) {
  std::ofstream(path) << config.dump(2);
}

// A temporary `.<stem>.tmp<pid>.ckpt` in `dir`: a checkpoint being written.
bool writing_checkpoint(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const auto name = it->path().filename().string();
    if (name.rfind('.', 0) == 0 && name.find(".tmp") != std::string::npos && name.size() > 5 &&
        name.compare(name.size() - 5, 5, ".ckpt") == 0) {
      return true;
    }
  }
  return false;
}

// Starts `command` through the shell, replaced by the program itself: returns its pid.
}  // namespace

TEST_CASE("training killed while writing a checkpoint resumes from the previous one",
          "[app][bad_input][slow]") {
  lfnet::test::TempDir tmp;
  write_config(tmp / "long.json", tiny_config(400, 1024));
  const fs::path stage_dir = tmp.path() / "run/models/ae";
  const fs::path last = stage_dir / "last.ckpt";
  const pid_t pid = lfnet::test::spawn_command(
      lfnet::test::lfnet_program("train " + (tmp / "long.json") + " --out " + (tmp / "run")));
  REQUIRE(pid > 0);
  // Wait for a first complete checkpoint, then for the next write to start, and kill then.
  bool caught = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(90);
  while (std::chrono::steady_clock::now() < deadline) {
    if (fs::exists(last) && writing_checkpoint(stage_dir)) {
      caught = true;
      break;
    }
    if (waitpid(pid, nullptr, WNOHANG) == pid) FAIL("training ended before it could be killed");
  }
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  CHECK(WIFSIGNALED(status));
  if (!caught) WARN("no checkpoint write was caught in progress; killed between writes instead");
  REQUIRE(fs::exists(last));
  // The previous checkpoint is whole.
  lfnet::train::Checkpoint ckpt;
  REQUIRE_NOTHROW(ckpt = lfnet::train::load_checkpoint(last.string()));
  const int64_t epoch = ckpt.training.epoch;
  CHECK(epoch >= 1);
  // Resuming continues from it to one more epoch.
  write_config(tmp / "resume.json", tiny_config(epoch + 1, 1024));
  std::string out;
  REQUIRE(run_command(
              lfnet::test::lfnet_program("train " + (tmp / "resume.json") + " --out " +
                                         (tmp / "run") + " --stage ae --resume " + last.string()),
              out) == 0);
  CHECK(lfnet::train::load_checkpoint(last.string()).training.epoch == epoch + 1);
  CHECK(fs::exists(tmp.path() / "run/models/ae.ckpt"));
  // The killed writer's temporary file is gone: the next write of last.ckpt removed it.
  CHECK_FALSE(writing_checkpoint(stage_dir));
}

TEST_CASE("a checkpoint write removes temporaries of dead writers, not of live ones",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  write_config(tmp / "one.json", tiny_config(1, 64));
  std::string out;
  REQUIRE(run_command(
              lfnet::test::lfnet_program("train " + (tmp / "one.json") + " --out " + (tmp / "run")),
              out) == 0);
  const fs::path dir = tmp.path() / "run/models/ae";
  // A dead writer (a child that has exited and been reaped) and a live one (this process).
  const pid_t dead = fork();
  if (dead == 0) _exit(0);
  waitpid(dead, nullptr, 0);
  const fs::path stale = dir / (".last.tmp" + std::to_string(dead) + ".ckpt");
  const fs::path live = dir / (".last.tmp" + std::to_string(getpid()) + ".ckpt");
  const fs::path other = dir / "notes.tmp123";
  for (const auto& p : {stale, live, other}) std::ofstream(p) << "partial";
  write_config(tmp / "two.json", tiny_config(2, 64));
  REQUIRE(run_command(
              lfnet::test::lfnet_program("train " + (tmp / "two.json") + " --out " + (tmp / "run") +
                                         " --stage ae --resume " + (dir / "last.ckpt").string()),
              out) == 0);
  CHECK_FALSE(fs::exists(stale));
  CHECK(fs::exists(live));
  CHECK(fs::exists(other));
}

TEST_CASE(
    "a far too large learning rate stops with a clear message; the last good checkpoint resumes",
    "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  write_config(tmp / "good.json", tiny_config(1, 64));
  std::string out;
  REQUIRE(run_command(lfnet::test::lfnet_program("train " + (tmp / "good.json") + " --out " +
                                                 (tmp / "run")),
                      out) == 0);
  const std::string last = tmp / "run/models/ae/last.ckpt";
  const std::string good = read_bytes(last);
  // Three more epochs at a learning rate of 1e12: diverges, and says so on one line.
  write_config(tmp / "wild.json", tiny_config(4, 64, 1e12));
  const int rc =
      run_command(lfnet_binary() + " --threads 2 --log-level off train " + (tmp / "wild.json") +
                      " --out " + (tmp / "run") + " --stage ae --resume " + last,
                  out);
  INFO(out);
  CHECK(rc != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find("diverged") != std::string::npos);
  CHECK(out.find("last good checkpoint") != std::string::npos);
  // The last good checkpoint is intact, and resuming from it with a sane rate works.
  CHECK(read_bytes(last) == good);
  write_config(tmp / "sane.json", tiny_config(2, 64));
  REQUIRE(run_command(lfnet::test::lfnet_program("train " + (tmp / "sane.json") + " --out " +
                                                 (tmp / "run") + " --stage ae --resume " + last),
                      out) == 0);
  CHECK(lfnet::train::load_checkpoint(last).training.epoch == 2);
}

TEST_CASE("the same seed and thread count give bit-identical simulate, train and reconstruct",
          "[app][determinism]") {
  // Promises (docs/robustness.md, section 3): for one thread count, every output is
  // bit-identical run to run, on 1 and on 2 threads. Across thread counts only the noisy
  // sensor image is (its noise is addressed by pixel index); trained weights and
  // reconstructions go through BLAS, whose rounding follows the thread count and the CPU's
  // kernel, and agree to a stated tolerance.
  lfnet::test::TempDir tmp;
  write_config(tmp / "c.json", tiny_config(1, 64));
  std::string out;
  REQUIRE(run_command(
              lfnet::test::lfnet_program("render --random 4 --size 30x30 --out " + (tmp / "lf")),
              out) == 0);
  for (const char* threads : {"1", "2"}) {
    for (const char* run : {"a", "b"}) {
      const std::string dir = tmp / (std::string(run) + threads);
      const std::string lfnet = lfnet_binary() + " --threads " + threads + " --log-level warn ";
      REQUIRE(run_command(cat({lfnet, "simulate --lf ", tmp / "lf",
                               " --phi asp:2 --noise 0.05 --seed 9 --out ", dir, "/acq"}),
                          out) == 0);
      REQUIRE(run_command(cat({lfnet, "train ", tmp / "c.json", " --out ", dir, "/run"}), out) ==
              0);
      REQUIRE(run_command(cat({lfnet, "reconstruct --model ", dir, "/run/models/ae.ckpt --sensor ",
                               dir, "/acq --stride 3 --out ", dir, "/rec"}),
                          out) == 0);
    }
  }
  for (const char* threads : {"1", "2"}) {
    INFO(threads << " thread(s), run to run");
    const std::string a = tmp / (std::string("a") + threads),
                      b = tmp / (std::string("b") + threads);
    // TIFF headers carry the time of writing: compare the pixels.
    CHECK(torch::equal(lfnet::io::read_image_channels(a + "/acq/sensor.tif"),
                       lfnet::io::read_image_channels(b + "/acq/sensor.tif")));
    auto ca = lfnet::train::load_checkpoint(a + "/run/models/ae/last.ckpt");
    auto cb = lfnet::train::load_checkpoint(b + "/run/models/ae/last.ckpt");
    REQUIRE(ca.model.size() == cb.model.size());
    for (const auto& [name, tensor] : ca.model) {
      INFO(name);
      CHECK(torch::equal(tensor, cb.model.at(name)));
    }
    for (const auto& [name, tensor] : ca.optimizer) {
      INFO(name);
      CHECK(torch::equal(tensor, cb.optimizer.at(name)));
    }
    CHECK(ca.training.history[0]["train_loss"] == cb.training.history[0]["train_loss"]);
    for (const auto& e : fs::directory_iterator(a + "/rec")) {
      const auto name = e.path().filename().string();
      // The record and the viewer page that shows it hold the wall time.
      if (name == "reconstruction.json" || name == "index.html") continue;
      INFO(name);
      CHECK(read_bytes(e.path().string()) == read_bytes(cat({b, "/rec/", name})));
    }
  }
  // Across thread counts.
  const std::string one = tmp / "a1", two = tmp / "a2";
  CHECK(torch::equal(lfnet::io::read_image_channels(one + "/acq/sensor.tif"),
                     lfnet::io::read_image_channels(two + "/acq/sensor.tif")));
  auto c1 = lfnet::train::load_checkpoint(one + "/run/models/ae/last.ckpt");
  auto c2 = lfnet::train::load_checkpoint(two + "/run/models/ae/last.ckpt");
  for (const auto& [name, tensor] : c1.model) {
    INFO(name << ", 1 thread against 2");
    // One epoch from the same start: BLAS round-off (about 1e-7 relative per product) grows
    // through 2 Adam steps to well under 1e-4.
    lfnet::test::require_close(c2.model.at(name), tensor, 1e-5, 1e-4);
  }
  const auto rec1 = lfnet::io::read_light_field(one + "/rec", 1).data();
  const auto rec2 = lfnet::io::read_light_field(two + "/rec", 1).data();
  // 16-bit views: a rounding flip moves a value by one code.
  lfnet::test::require_close(rec2, rec1, 2.0 / 65535);
  // A different seed gives a different sensor image (the comparison can fail).
  REQUIRE(run_command(lfnet::test::lfnet_program("simulate --lf " + (tmp / "lf") +
                                                 " --phi asp:2 --noise 0.05 --seed 10 --out " +
                                                 (tmp / "c/acq")),
                      out) == 0);
  CHECK_FALSE(torch::equal(lfnet::io::read_image_channels(one + "/acq/sensor.tif"),
                           lfnet::io::read_image_channels(tmp / "c/acq/sensor.tif")));
}

// The output policy (core/output.h): atomic files and folders, inputs never overwritten,
// exclusive writers, stale temporaries removed, failed starts undone.
#include "lfnet/core/output.h"
#include "lfnet/core/zip_check.h"

#include <sys/wait.h>
#include <unistd.h>
#include <catch2/catch.hpp>
#include <csignal>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "lfnet/core/error.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::ConfigError;

namespace {
std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The pid of a process that has exited (a reaped child): a writer that died.
pid_t dead_pid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  waitpid(pid, nullptr, 0);
  return pid;
}

size_t entries(const fs::path& dir) {
  size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}
}  // namespace

TEST_CASE("an output that is, contains or lies inside an input is refused", "[core][output]") {
  lfnet::test::TempDir tmp;
  fs::create_directories(tmp.path() / "data/lf");
  const std::string lf = tmp / "data/lf";
  CHECK_THROWS_WITH(lfnet::check_output_apart(lf, {lf}), Catch::Contains("is the input"));
  CHECK_THROWS_WITH(lfnet::check_output_apart(lf + "/", {lf}), Catch::Contains("is the input"));
  CHECK_THROWS_WITH(lfnet::check_output_apart(lf + "/rec", {lf}),
                    Catch::Contains("lies inside the input"));
  CHECK_THROWS_WITH(lfnet::check_output_apart(tmp / "data", {lf}),
                    Catch::Contains("contains the input"));
  CHECK_THROWS_AS(lfnet::check_output_apart(tmp / "data/./lf/../lf", {lf}), ConfigError);
  // Siblings and name prefixes are apart: data/lf2 is not inside data/lf.
  CHECK_NOTHROW(lfnet::check_output_apart(tmp / "data/lf2", {lf, ""}));
  CHECK_NOTHROW(lfnet::check_output_apart(tmp / "out", {lf}));
}

TEST_CASE("write_folder refuses a non-empty folder without force and swaps with it",
          "[core][output]") {
  lfnet::test::TempDir tmp;
  const std::string out = tmp / "out";
  lfnet::OutputFolderPolicy policy;
  lfnet::write_folder(out, policy, [](const std::string& dir) {
    std::ofstream(fs::path(dir) / "a.txt") << "first";
  });
  CHECK(read_text(fs::path(out) / "a.txt") == "first");
  CHECK_THROWS_WITH(lfnet::write_folder(out, policy, [](const std::string&) {}),
                    Catch::Contains("--force"));
  // A failing writer with force leaves the old folder as it was and no temporary.
  policy.force = true;
  CHECK_THROWS_AS(lfnet::write_folder(out, policy,
                                      [](const std::string& dir) {
                                        std::ofstream(fs::path(dir) / "b.txt") << "half";
                                        throw lfnet::IoError("disk full");
                                      }),
                  lfnet::IoError);
  CHECK(read_text(fs::path(out) / "a.txt") == "first");
  CHECK_FALSE(fs::exists(fs::path(out) / "b.txt"));
  CHECK(entries(tmp.path()) == 1);  // out only: no temporary, no lock file
  // With force a complete new folder replaces the old one, nothing of the old one is mixed in.
  lfnet::write_folder(out, policy, [](const std::string& dir) {
    std::ofstream(fs::path(dir) / "b.txt") << "second";
  });
  CHECK_FALSE(fs::exists(fs::path(out) / "a.txt"));
  CHECK(read_text(fs::path(out) / "b.txt") == "second");
  CHECK(entries(tmp.path()) == 1);
}

TEST_CASE("a second writer of the same output is refused while the first holds it",
          "[core][output]") {
  lfnet::test::TempDir tmp;
  const std::string out = tmp / "out";
  {
    lfnet::OutputLock first(out);
    CHECK_THROWS_WITH(lfnet::OutputLock(out), Catch::Contains("another lfnet process"));
    CHECK_THROWS_WITH(lfnet::write_folder(out, {}, [](const std::string&) {}),
                      Catch::Contains("another lfnet process"));
    // Another output in the same folder is free.
    CHECK_NOTHROW(lfnet::OutputLock(tmp / "other"));
  }
  CHECK_NOTHROW(lfnet::OutputLock(out));
  CHECK_FALSE(fs::exists(tmp.path() / ".out.lock"));
}

TEST_CASE("temporaries of dead writers are removed, a live writer's are kept", "[core][output]") {
  lfnet::test::TempDir tmp;
  const fs::path target = tmp.path() / "model.ckpt";
  const pid_t dead = dead_pid();
  const fs::path stale_file = tmp.path() / (".model.tmp" + std::to_string(dead) + ".ckpt");
  // A live writer other than this process: the parent (this process writes its own name).
  const fs::path live_file = tmp.path() / (".model.tmp" + std::to_string(getppid()) + ".ckpt");
  const fs::path unrelated = tmp.path() / (".modelx.tmp" + std::to_string(dead) + ".ckpt");
  for (const auto& p : {stale_file, live_file, unrelated}) std::ofstream(p) << "partial";
  lfnet::write_text_file(target.string(), "whole");
  CHECK(read_text(target) == "whole");
  CHECK_FALSE(fs::exists(stale_file));
  CHECK(fs::exists(live_file));
  CHECK(fs::exists(unrelated));
  // Folders: a dead writer's half-built folder, and the folder it was replacing after the new
  // one took its place (the swap was complete: the old one goes).
  const fs::path half = tmp.path() / (".rec.tmp" + std::to_string(dead));
  const fs::path old = tmp.path() / (".rec.tmp" + std::to_string(dead) + ".old");
  fs::create_directories(half);
  fs::create_directories(old);
  std::ofstream(old / "old.txt") << "old";
  fs::create_directories(tmp.path() / "rec");
  std::ofstream(tmp.path() / "rec/new.txt") << "new";
  lfnet::OutputFolderPolicy force;
  force.force = true;
  lfnet::write_folder(tmp / "rec", force, [](const std::string& dir) {
    std::ofstream(fs::path(dir) / "a.txt") << "a";
  });
  CHECK_FALSE(fs::exists(half));
  CHECK_FALSE(fs::exists(old));
  CHECK(fs::exists(tmp.path() / "rec/a.txt"));
}

TEST_CASE("what an interrupted replacement moved aside comes back", "[core][output]") {
  lfnet::test::TempDir tmp;
  const pid_t dead = dead_pid();
  // A folder swap cut between its two renames: the old folder aside, no folder in its place.
  const fs::path old = tmp.path() / (".rec.tmp" + std::to_string(dead) + ".old");
  fs::create_directories(old);
  std::ofstream(old / "old.txt") << "old";
  CHECK(lfnet::remove_stale_temporaries(tmp.path() / "rec"));
  CHECK(read_text(tmp.path() / "rec/old.txt") == "old");
  CHECK_FALSE(fs::exists(old));
  // A run replaced by --force whose new run died before its first checkpoint: the new run goes,
  // the old one comes back, whoever opens the folder next (here a resume).
  const std::string run = tmp / "run";
  const fs::path replaced = tmp.path() / (".run.tmp" + std::to_string(dead) + ".replaced");
  fs::create_directories(replaced / "models");
  std::ofstream(replaced / "models/ae.ckpt") << "old run";
  fs::create_directories(run);
  std::ofstream(fs::path(run) / "config.json") << "{\"new\": true}";
  {
    lfnet::RunFolder resumed(run, {}, /*resume=*/true);
    CHECK(read_text(fs::path(run) / "models/ae.ckpt") == "old run");
    CHECK_FALSE(fs::exists(fs::path(run) / "config.json"));
  }
  CHECK(entries(tmp.path()) == 2);  // rec and run: nothing aside, no lock
  // A committed --force run leaves nothing to put back: its old run is gone for good.
  lfnet::OutputFolderPolicy force;
  force.force = true;
  {
    lfnet::RunFolder fresh(run, force);
    std::ofstream(fs::path(run) / "new.ckpt") << "new";
    fresh.commit();
  }
  CHECK_FALSE(lfnet::remove_stale_temporaries(run));
  CHECK(fs::exists(fs::path(run) / "new.ckpt"));
  CHECK_FALSE(fs::exists(fs::path(run) / "models"));
  CHECK(entries(tmp.path()) == 2);
}

TEST_CASE("an output that cannot be written names the output and the system's reason",
          "[core][output]") {
  lfnet::test::TempDir tmp;
  // A writer that fails with the temporary's name in its message: the message names the target.
  try {
    lfnet::write_file_atomically(tmp / "out.png", [](const std::string& temporary) {
      throw lfnet::IoError("cannot write " + temporary + ": some library failed");
    });
    FAIL("no error");
  } catch (const lfnet::IoError& e) {
    CHECK(std::string(e.what()) == "cannot write " + (tmp / "out.png") + ": some library failed");
  }
  CHECK(entries(tmp.path()) == 0);
  // The same inside a folder being written.
  try {
    lfnet::write_folder(tmp / "rec", {}, [](const std::string& dir) {
      throw lfnet::IoError("cannot write " + dir + "/index.html");
    });
    FAIL("no error");
  } catch (const lfnet::IoError& e) {
    CHECK(std::string(e.what()) == "cannot write " + (tmp / "rec") + "/index.html");
  }
  CHECK(entries(tmp.path()) == 0);
  // A folder the lock had to make goes again when the output never came.
  CHECK_THROWS(lfnet::write_folder(tmp / "a/b/rec", {},
                                   [](const std::string&) { throw lfnet::IoError("failed"); }));
  CHECK(entries(tmp.path()) == 0);
  // write_all reports the system's reason: a pipe with no reader.
  int fds[2];
  REQUIRE(pipe(fds) == 0);
  close(fds[0]);
  signal(SIGPIPE, SIG_IGN);
  CHECK_THROWS_WITH(lfnet::write_all(fds[1], "data", "the pipe"),
                    Catch::Contains("cannot write the pipe: Broken pipe"));
  close(fds[1]);
}

TEST_CASE("output files: refused when taken or a folder, replaced with force", "[core][output]") {
  lfnet::test::TempDir tmp;
  lfnet::OutputFolderPolicy policy;
  policy.option = "--json";
  policy.inputs = {tmp / "in.json"};
  CHECK_THROWS_WITH(lfnet::check_output_file(tmp / "in.json", policy), Catch::Contains("--json"));
  CHECK_THROWS_WITH(lfnet::check_output_file(tmp.path().string(), policy),
                    Catch::Contains("contains the input"));
  // An empty file (made by mktemp, say) holds nothing to lose; one with content needs --force.
  lfnet::write_text_file(tmp / "out.json", "");
  CHECK_NOTHROW(lfnet::check_output_file(tmp / "out.json", policy));
  lfnet::write_text_file(tmp / "out.json", "{}");
  CHECK_THROWS_WITH(lfnet::check_output_file(tmp / "out.json", policy), Catch::Contains("--force"));
  policy.force = true;
  CHECK_NOTHROW(lfnet::check_output_file(tmp / "out.json", policy));
  fs::create_directories(tmp.path() / "dir");
  CHECK_THROWS_WITH(lfnet::check_output_file(tmp / "dir", policy), Catch::Contains("is a folder"));
  CHECK(lfnet::split_paths("a.tif,,b.tif") == std::vector<std::string>{"a.tif", "b.tif"});
}

TEST_CASE("a run folder that fails before committing leaves nothing; force restores the old one",
          "[core][output]") {
  lfnet::test::TempDir tmp;
  const std::string run = tmp / "run";
  {
    lfnet::RunFolder folder(run, {});
    std::ofstream(fs::path(run) / "config.json") << "{}";
  }  // destroyed without commit: a failed start
  CHECK_FALSE(fs::exists(run));
  {
    lfnet::RunFolder folder(run, {});
    std::ofstream(fs::path(run) / "model.ckpt") << "old";
    folder.commit();
  }
  CHECK(fs::exists(fs::path(run) / "model.ckpt"));
  CHECK_THROWS_WITH(lfnet::RunFolder(run, {}), Catch::Contains("--force"));
  lfnet::OutputFolderPolicy force;
  force.force = true;
  {
    lfnet::RunFolder folder(run, force);
    CHECK_FALSE(fs::exists(fs::path(run) / "model.ckpt"));  // afresh
    std::ofstream(fs::path(run) / "config.json") << "{}";
  }  // failed before its first checkpoint: the old run comes back
  CHECK(read_text(fs::path(run) / "model.ckpt") == "old");
  CHECK_FALSE(fs::exists(fs::path(run) / "config.json"));
  {
    lfnet::RunFolder folder(run, force);
    std::ofstream(fs::path(run) / "new.ckpt") << "new";
    folder.commit();
  }
  CHECK_FALSE(fs::exists(fs::path(run) / "model.ckpt"));
  CHECK(fs::exists(fs::path(run) / "new.ckpt"));
  CHECK(entries(tmp.path()) == 1);
  {
    lfnet::RunFolder resumed(run, {}, /*resume=*/true);  // continues in place
    CHECK(fs::exists(fs::path(run) / "new.ckpt"));
  }
  CHECK(fs::exists(fs::path(run) / "new.ckpt"));  // resuming never removes the run
}

TEST_CASE("crc32 is the zip checksum", "[core][zip]") {
  const std::string check = "123456789";
  CHECK(lfnet::crc32(check.data(), check.size()) == 0xCBF43926u);  // the standard check value
  CHECK(lfnet::crc32(nullptr, 0) == 0u);
  // Continuing a running checksum gives the checksum of the whole.
  CHECK(lfnet::crc32(check.data() + 4, 5, lfnet::crc32(check.data(), 4)) == 0xCBF43926u);
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "short.zip") << "PK";
  CHECK_THROWS_WITH(lfnet::check_zip_integrity(tmp / "short.zip", "file X"),
                    Catch::Contains("file X is damaged or truncated"));
  std::ofstream(tmp / "text.zip") << std::string(100, 'x');
  CHECK_THROWS_WITH(lfnet::check_zip_integrity(tmp / "text.zip", "file X"),
                    Catch::Contains("no zip directory"));
}

TEST_CASE("a damaged deflated entry (TorchScript code) is caught before LibTorch reads it",
          "[core][zip]") {
  const std::string seed =
      std::string(LFNET_SOURCE_DIR) + "/tests/fuzz/corpus/checkpoint/tiny_net.pt";
  std::ifstream in(seed, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  REQUIRE(bytes.size() > 1000);
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "good.pt", std::ios::binary) << bytes;
  CHECK_NOTHROW(lfnet::check_zip_integrity(tmp / "good.pt", "model"));
  // The code file is deflated: flip one byte in the middle of its compressed data.
  const auto name = bytes.find("code/__torch__/lfnet.py");
  REQUIRE(name != std::string::npos);
  const size_t header = bytes.rfind("PK\x03\x04", name);
  const auto u16 = [&](size_t at) {
    return static_cast<size_t>(static_cast<uint8_t>(bytes[at]) | static_cast<uint8_t>(bytes[at + 1])
                                                                     << 8);
  };
  REQUIRE(u16(header + 8) == 8);  // deflate
  const size_t data = header + 30 + u16(header + 26) + u16(header + 28);
  bytes[data + 100] = static_cast<char>(bytes[data + 100] ^ 0x10);
  std::ofstream(tmp / "bad.pt", std::ios::binary) << bytes;
  if (lfnet::zip_checks_deflated()) {
    CHECK_THROWS_WITH(lfnet::check_zip_integrity(tmp / "bad.pt", "model"),
                      Catch::Contains("lfnet.py"));
  } else {
    WARN("built without zlib: deflated entries are not checked");
  }
}

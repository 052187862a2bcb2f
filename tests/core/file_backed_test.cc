#include "lfnet/core/file_backed.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "support/test_support.h"

#if defined(__linux__)
#include <linux/magic.h>
#include <sys/statfs.h>
#endif

namespace {

// A field of /proc/self/status in kB ("RssFile", "RssAnon"), or -1.
int64_t status_kb(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(field + ":", 0) == 0) return std::stoll(line.substr(field.size() + 1));
  }
  return -1;
}

// Lines of /proc/self/maps that name one of file_backed_empty's files.
int mapped_files() {
  std::ifstream in("/proc/self/maps");
  std::string line;
  int n = 0;
  while (std::getline(in, line)) n += line.find("/lfnet-") != std::string::npos ? 1 : 0;
  return n;
}

// Points TMPDIR at a fresh folder under the working directory for the test's life; false where
// that folder is not on a disk (then nothing can be file-backed there).
struct DiskTemporaryFolder {
  std::filesystem::path dir = std::filesystem::absolute("file-backed-test-tmp");
  std::string old;
  bool had_old = false;
  DiskTemporaryFolder() {
    std::filesystem::create_directories(dir);
    if (const char* env = std::getenv("TMPDIR")) {
      old = env;
      had_old = true;
    }
    setenv("TMPDIR", dir.c_str(), 1);
  }
  ~DiskTemporaryFolder() {
    if (had_old) {
      setenv("TMPDIR", old.c_str(), 1);
    } else {
      unsetenv("TMPDIR");
    }
    std::filesystem::remove_all(dir);
  }
  bool on_disk() const {
#if defined(__linux__)
    struct statfs fs {};
    return statfs(dir.c_str(), &fs) == 0 && fs.f_type != TMPFS_MAGIC && fs.f_type != RAMFS_MAGIC;
#else
    return false;
#endif
  }
};

}  // namespace

TEST_CASE("a file-backed tensor keeps its contents when its pages leave memory", "[core]") {
  DiskTemporaryFolder tmp;
  if (!tmp.on_disk()) LFNET_SKIP("the working directory is not on a disk: nothing to file-back");
  constexpr int64_t kBytes = int64_t{64} << 20;
  auto t = lfnet::file_backed_empty({kBytes / 2}, torch::kInt16, 0);
  REQUIRE(lfnet::file_backed(t));
  CHECK(t.is_contiguous());
  CHECK(t.scalar_type() == torch::kInt16);
  // The file is unlinked as soon as it is made: the folder stays empty.
  CHECK(std::filesystem::is_empty(tmp.dir));
  // Views share the storage, so they are file-backed too.
  CHECK(lfnet::file_backed(t.slice(0, 10, 20)));
  t.copy_(torch::arange(kBytes / 2, torch::kInt32).remainder(30011).to(torch::kInt16));
  const auto expected = t.clone();
  CHECK_FALSE(lfnet::file_backed(expected));

  const int64_t before = status_kb("RssFile");
  lfnet::page_out(t);
  const int64_t after = status_kb("RssFile");
  if (before >= 0) {
    // All 64 MB were resident after the writes, and leave the process's memory.
    CHECK(before - after >= (kBytes >> 10) * 9 / 10);
  }
  CHECK(torch::equal(t, expected));  // read back from the file
  if (before >= 0) CHECK(status_kb("RssFile") - after >= (kBytes >> 10) * 9 / 10);

  // The mapping goes with the last tensor that holds it.
  const int files = mapped_files();
  CHECK(files >= 1);
  t = torch::Tensor();
  CHECK(mapped_files() == files - 1);
}

TEST_CASE("small tensors and copies stay in ordinary memory", "[core]") {
  DiskTemporaryFolder tmp;
  auto small = lfnet::file_backed_empty({4, 5}, torch::kFloat32);
  CHECK_FALSE(lfnet::file_backed(small));
  CHECK(small.sizes() == torch::IntArrayRef({4, 5}));
  lfnet::page_out(small);  // nothing to do, nothing lost
  small.fill_(2.5F);
  lfnet::page_out(small);
  CHECK(small.eq(2.5F).all().item<bool>());
  CHECK_FALSE(lfnet::file_backed(torch::Tensor()));

  // A copy: the same values, contiguous, file-backed when over the size asked for.
  const auto source = torch::rand({3, 40, 50}).permute({2, 0, 1});
  REQUIRE_FALSE(source.is_contiguous());
  const auto same = lfnet::file_backed_copy(source, source.nbytes() + 1);
  CHECK(same.is_contiguous());
  CHECK_FALSE(lfnet::file_backed(same));
  CHECK(torch::equal(same, source));
  if (!tmp.on_disk()) return;
  const auto copy = lfnet::file_backed_copy(source, 0);
  CHECK(lfnet::file_backed(copy));
  CHECK(torch::equal(copy, source));
  // A file-backed contiguous tensor is not copied again.
  CHECK(lfnet::file_backed_copy(copy, 0).data_ptr() == copy.data_ptr());
}

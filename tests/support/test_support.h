// Helpers shared by lfnet's tests.
#pragma once

#include <torch/torch.h>
#include <nlohmann/json.hpp>

#include <sys/types.h>

#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "lfnet/core/file_backed.h"
#include "lfnet/core/light_field.h"

// Ends the running test case as skipped, with `reason` in its output: CTest reports it as
// "Skipped" (SKIP_REGULAR_EXPRESSION in tests/CMakeLists.txt), where a WARN would let it pass
// unseen. For a dependency the machine lacks; call it before the test's first assertion.
#define LFNET_SKIP(reason)                                 \
  do {                                                     \
    std::cout << "LFNET_SKIPPED: " << reason << std::endl; \
    return;                                                \
  } while (false)

namespace lfnet::test {

// For the object's life every tensor that may be file-backed is (core/file_backed.h's
// threshold 0), so that small light fields take the paths of large ones.
struct FileBackedEverything {
  size_t old = file_backed_threshold();
  FileBackedEverything() { set_file_backed_threshold(0); }
  ~FileBackedEverything() { set_file_backed_threshold(old); }
  FileBackedEverything(const FileBackedEverything&) = delete;
  FileBackedEverything& operator=(const FileBackedEverything&) = delete;
  // Whether a temporary folder on a disk can hold one here (else nothing is file-backed).
  static bool available() { return file_backed(file_backed_empty({1}, torch::kInt16, 0)); }
};

// Fails the current test with the first index where |got - want| > atol + rtol * |want|.
void require_close(const torch::Tensor& got, const torch::Tensor& want, double atol,
                   double rtol = 0.0);

// A fresh temporary folder, removed when the object goes out of scope.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

// ../shared/data beside the checkout (or $LFNET_SHARED_DATA), or "" when absent.
std::string shared_data_dir();

// Runs a shell command; returns its exit status and sets `output` to stdout and stderr.
int run_command(const std::string& command, std::string& output);

// Starts a shell command in the background, its output discarded; returns its pid (the shell
// execs the command, so the pid is the command's own) for waitpid and kill.
pid_t spawn_command(const std::string& command);

// Debian's python3 with the reference packages, or "" when a module is missing.
std::string python_with(const std::string& module);

// The lfnet program under test.
std::string lfnet_binary();

// The program with two threads and warnings only, followed by `args`: a command line.
std::string lfnet_program(const std::string& args);

// Each line of a JSON Lines file, parsed, as one array.
nlohmann::json read_json_lines(const std::string& path);

// A tensor's values as raw float64 (native byte order), for the Python reference scripts.
void write_f64(const std::string& path, const torch::Tensor& t);

// The columns of `d` scaled to unit L2 norm.
torch::Tensor unit_columns(const torch::Tensor& d);

// The whole content of a file, byte for byte ("" when it cannot be read).
std::string read_bytes(const std::string& path);

// Writes `bytes` to a file, replacing it.
void write_bytes(const std::string& path, const std::string& bytes);

// The network checkpoints of the model zoo (models/zoo.json's cards, the dictionary and noise
// switches left out), sorted by path. Models outside the zoo are research models that their
// recipes make again: the tests that cover every shipped model cover these.
std::vector<std::filesystem::path> zoo_checkpoints();

// A grey rows x cols x h x w light field of known parallax, in lfnet's orientation: a random
// texture whose left half moves by `left` and right half by `right` pixels per view step
// (integers, so every view is an exact shift: L(u, v)(y, x) = T(y - d du, x - d dv)).
LightField parallax_light_field(int64_t rows, int64_t cols, int64_t h, int64_t w, int64_t left,
                                int64_t right, uint64_t seed = 1);

// Sets each numeric leaf of `base` in turn (seeds aside: any value is one) to 1e300 and -1e300
// and runs `read` on the result: one line for each value it accepts, or refuses otherwise than
// with a ConfigError naming the leaf's key. Empty when every leaf has a domain.
// "" when `read(input)` throws a ConfigError naming `key`; else what it did instead (": accepted",
// ": refused without naming ...", ": not a ConfigError: ...").
std::string unrefused(const nlohmann::json& input, const std::string& key,
                      const std::function<void(const nlohmann::json&)>& read);

std::vector<std::string> absurd_values_unrefused(
    const nlohmann::json& base, const std::function<void(const nlohmann::json&)>& read);

}  // namespace lfnet::test

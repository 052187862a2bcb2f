#include "support/test_support.h"

#include <catch2/catch.hpp>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <sys/wait.h>

namespace lfnet::test {

void require_close(const torch::Tensor& got, const torch::Tensor& want, double atol, double rtol) {
  REQUIRE(got.sizes() == want.sizes());
  auto g = got.to(torch::kFloat64).contiguous().reshape({-1});
  auto w = want.to(torch::kFloat64).contiguous().reshape({-1});
  auto err = (g - w).abs();
  auto bound = atol + rtol * w.abs();
  auto bad = (err > bound).logical_or(err.isnan());
  if (bad.any().item<bool>()) {
    const int64_t i = bad.nonzero()[0][0].item<int64_t>();
    std::ostringstream msg;
    msg << "first mismatch at flat index " << i << " of shape " << got.sizes() << ": got "
        << g[i].item<double>() << ", want " << w[i].item<double>() << " (max abs error "
        << err.max().item<double>() << ", atol " << atol << ", rtol " << rtol << ")";
    FAIL(msg.str());
  }
}

TempDir::TempDir() {
  std::random_device rd;
  path_ = std::filesystem::temp_directory_path() /
          ("lfnet-test-" + std::to_string(rd()) + std::to_string(rd()));
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::string shared_data_dir() {
  const char* env = std::getenv("LFNET_SHARED_DATA");
  std::string dir = env ? env : LFNET_SHARED_DATA_DIR;
  return std::filesystem::is_directory(dir) ? dir : "";
}

int run_command(const std::string& command, std::string& output) {
  output.clear();
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  std::array<char, 4096> buf{};
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) output.append(buf.data(), n);
  int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string python_with(const std::string& module) {
  std::string out;
  const std::string py = LFNET_TEST_PYTHON;
  if (py.empty()) return "";
  return run_command(py + " -c 'import " + module + "'", out) == 0 ? py : "";
}

std::string lfnet_binary() { return LFNET_BINARY; }

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

}  // namespace lfnet::test

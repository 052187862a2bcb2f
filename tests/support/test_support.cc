#include "support/test_support.h"

#include "lfnet/core/error.h"

#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>

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

pid_t spawn_command(const std::string& command) {
  const pid_t pid = fork();
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", ("exec " + command + " >/dev/null 2>&1").c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
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

std::vector<std::filesystem::path> zoo_checkpoints() {
  const auto dir = std::filesystem::path(LFNET_SOURCE_DIR) / "models";
  std::ifstream in(dir / "zoo.json");
  std::vector<std::filesystem::path> files;
  if (!in) return files;
  const auto zoo = nlohmann::json::parse(in);
  for (const auto& card : zoo.at("models")) {
    const auto file = dir / card.at("file").get<std::string>();
    if (file.extension() == ".ckpt" && card.value("architecture", "") != "dictionary") {
      files.push_back(file);
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::string lfnet_program(const std::string& args) {
  return lfnet_binary() + " --threads 2 --log-level warn " + args;
}

nlohmann::json read_json_lines(const std::string& path) {
  nlohmann::json lines = nlohmann::json::array();
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

void write_f64(const std::string& path, const torch::Tensor& t) {
  auto d = t.to(torch::kFloat64).contiguous();
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(d.data_ptr<double>()),
            static_cast<std::streamsize>(d.numel() * sizeof(double)));
}

torch::Tensor unit_columns(const torch::Tensor& d) { return d / d.norm(2, 0, /*keepdim=*/true); }

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

LightField parallax_light_field(int64_t rows, int64_t cols, int64_t h, int64_t w, int64_t left,
                                int64_t right, uint64_t seed) {
  torch::manual_seed(seed);
  const int64_t pad = std::max(std::abs(left), std::abs(right)) * std::max(rows, cols);
  auto layer = [&] {
    // Blurred noise: texture at every scale a block matcher sees, values well inside [0, 1].
    auto t = torch::rand({1, 1, h + 2 * pad + 2, w + 2 * pad + 2});
    return torch::avg_pool2d(t, {3, 3}, {1, 1})[0][0];
  };
  const auto a = layer(), b = layer();
  auto out = torch::empty({1, rows, cols, h, w});
  const int64_t cu = rows / 2, cv = cols / 2;
  for (int64_t u = 0; u < rows; ++u) {
    for (int64_t v = 0; v < cols; ++v) {
      auto crop = [&](const torch::Tensor& t, int64_t d) {
        return t.narrow(0, pad - d * (u - cu), h).narrow(1, pad - d * (v - cv), w);
      };
      auto view = crop(a, left).clone();
      view.narrow(1, w / 2, w - w / 2).copy_(crop(b, right).narrow(1, w / 2, w - w / 2));
      out[0][u][v].copy_(view);
    }
  }
  return LightField(out);
}

namespace {
// The JSON pointers of the numeric leaves of `j` (their last key: `key`).
void numeric_leaves(const nlohmann::json& j, const std::string& pointer, const std::string& key,
                    std::vector<std::pair<std::string, std::string>>& out) {
  if (j.is_object()) {
    for (const auto& [k, v] : j.items()) {
      std::string child = pointer;
      child.append("/").append(k);
      numeric_leaves(v, child, k, out);
    }
  } else if (j.is_array()) {
    for (size_t i = 0; i < j.size(); ++i) {
      numeric_leaves(j[i], pointer + "/" + std::to_string(i), key, out);
    }
  } else if (j.is_number()) {
    out.emplace_back(pointer, key);
  }
}
}  // namespace

std::vector<std::string> absurd_values_unrefused(
    const nlohmann::json& base, const std::function<void(const nlohmann::json&)>& read) {
  std::vector<std::pair<std::string, std::string>> leaves;
  numeric_leaves(base, "", "", leaves);
  std::vector<std::string> found;
  for (const auto& [pointer, key] : leaves) {
    if (key == "seed") continue;
    for (const double value : {1e300, -1e300}) {
      auto input = base;
      input[nlohmann::json::json_pointer(pointer)] = value;
      const auto problem = unrefused(input, key, read);
      if (problem.empty()) continue;
      std::string line = pointer;
      line.append(" = ").append(nlohmann::json(value).dump()).append(problem);
      found.push_back(line);
    }
  }
  return found;
}

std::string unrefused(const nlohmann::json& input, const std::string& key,
                      const std::function<void(const nlohmann::json&)>& read) {
  try {
    read(input);
    return ": accepted";
  } catch (const ConfigError& e) {
    if (std::string(e.what()).find(key) != std::string::npos) return "";
    std::string problem = ": refused without naming '" + key + "': ";
    return problem + e.what();
  } catch (const std::exception& e) {
    return std::string(": not a ConfigError: ") + e.what();
  }
}

}  // namespace lfnet::test

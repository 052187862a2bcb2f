#include "lfnet/nn/auto_precision.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/hash.h"
#include "lfnet/core/json.h"
#include "lfnet/core/machine.h"
#include "lfnet/core/progress.h"

namespace fs = std::filesystem;

namespace lfnet::nn {

bool cpu_has_native_bfloat16() {
  if (const char* forced = std::getenv("LFNET_NATIVE_BFLOAT16")) {
    return std::string(forced) == "1";
  }
  std::istringstream flags(cpu_info("flags"));  // every core lists the same flags
  std::string flag;
  while (flags >> flag) {
    if (flag == "avx512_bf16" || flag == "amx_bf16") return true;
  }
  return false;
}

PrecisionSpeed precision_speed() {
  if (const char* forced = std::getenv("LFNET_NATIVE_BFLOAT16")) {
    return std::string(forced) == "1" ? PrecisionSpeed{1.0, 0.5} : PrecisionSpeed{1.0, 2.0};
  }
  static const PrecisionSpeed measured = [] {
    torch::NoGradGuard no_grad;
    auto gen = torch::make_generator<at::CPUGeneratorImpl>(1);
    const auto x = torch::rand({1, 48, 64, 64}, gen);
    const auto w = torch::rand({48, 48, 3, 3}, gen) - 0.5;
    auto best_ms = [](const torch::Tensor& input, const torch::Tensor& weight) {
      double best = INFINITY;
      for (int rep = 0; rep < 6; ++rep) {
        Stopwatch clock;
        torch::conv2d(input, weight, {}, 1, 1);
        if (rep > 0) best = std::min(best, clock.seconds() * 1000.0);  // the first warms up
      }
      return best;
    };
    return PrecisionSpeed{best_ms(x, w), best_ms(x.to(torch::kBFloat16), w.to(torch::kBFloat16))};
  }();
  return measured;
}

std::string file_fingerprint(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  LFNET_CHECK_AS(IoError, in.good(), "cannot read ", path);
  uint64_t hash = kFnv1aBasis;
  char buffer[1 << 16];
  while (in) {
    in.read(buffer, sizeof(buffer));
    hash = fnv1a(buffer, static_cast<size_t>(in.gcount()), hash);
  }
  char hex[17];
  std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(hash));
  return hex;
}

namespace {

// Why `model` may not run in bfloat16 ("" when it is verified): its folder's bfloat16.json
// must list its fingerprint as verified.
std::string unverified(const std::string& model) {
  const fs::path list = fs::path(model).parent_path() / "bfloat16.json";
  const std::string name = fs::path(model).filename().string();
  if (!fs::is_regular_file(list)) return name + " has no bfloat16.json beside it";
  const auto j = read_json_file(list.string());
  const std::string fingerprint = file_fingerprint(model);
  if (!j.contains("models") || !j["models"].is_object()) return list.string() + " lists no models";
  for (const auto& [listed, entry] : j["models"].items()) {
    if (!entry.is_object() || entry.value("fingerprint", "") != fingerprint) continue;
    if (entry.value("verified", false)) return "";
    std::string why = name + " loses more than the tolerance in bfloat16 (";
    why += list.string();
    why += ", ";
    why += listed;
    why += ")";
    return why;
  }
  return name + " is not verified in " + list.string();
}

}  // namespace

AutoPrecision choose_precision(const std::vector<std::string>& models, const std::string& device) {
  if (models.empty()) return {Precision::kFloat32, "no network"};
  if (device != "cpu") return {Precision::kFloat32, "bfloat16 is chosen on CPUs only"};
  if (!cpu_has_native_bfloat16()) {
    return {Precision::kFloat32, "this CPU has no native bfloat16 (AVX-512 BF16 or AMX)"};
  }
  for (const auto& model : models) {
    try {
      const auto why = unverified(model);
      if (!why.empty()) return {Precision::kFloat32, why};
    } catch (const std::exception& e) {
      return {Precision::kFloat32, e.what()};
    }
  }
  const auto speed = precision_speed();
  if (!speed.bfloat16_faster()) {
    char why[160];
    std::snprintf(why, sizeof(why),
                  "bfloat16 is not faster on this CPU (%.2f ms against %.2f ms in float32 for a "
                  "3 x 3 convolution)",
                  speed.bfloat16_ms, speed.float32_ms);
    return {Precision::kFloat32, why};
  }
  return {Precision::kBFloat16,
          "native bfloat16 measured faster, and every model verified in bfloat16.json"};
}

}  // namespace lfnet::nn

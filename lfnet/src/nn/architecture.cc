#include "lfnet/nn/architecture.h"

#include <mutex>

#include "lfnet/core/error.h"
#include "lfnet/nn/network.h"

namespace lfnet::nn {

// One factory per built-in architecture, each defined beside its class.
std::unique_ptr<NetworkArchitecture> make_paper_architecture();  // paper_architecture.cc
std::unique_ptr<NetworkArchitecture> make_lfnet_architecture();  // lfnet_architecture.cc

namespace {

struct Registry {
  std::mutex mutex;
  std::vector<std::unique_ptr<NetworkArchitecture>> architectures;  // registration order
};

Registry& registry() {
  static Registry r;
  return r;
}

void add(std::unique_ptr<NetworkArchitecture> architecture) {
  auto& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  for (auto& a : r.architectures) {
    if (a->name() == architecture->name()) {
      a = std::move(architecture);
      return;
    }
  }
  r.architectures.push_back(std::move(architecture));
}

// The built-in architectures, one line each.
void register_builtin_architectures() {
  add(make_paper_architecture());
  add(make_lfnet_architecture());
}

void ensure_builtins() {
  static std::once_flag once;
  std::call_once(once, [] { register_builtin_architectures(); });
}

}  // namespace

torch::Tensor NetworkArchitecture::forward_image(LightFieldNetImpl&, const torch::Tensor&, int64_t,
                                                 double) const {
  throw ConfigError("the " + name() +
                    " architecture reconstructs patches, not whole sensor images");
}

ImageTiling NetworkArchitecture::image_tiling(const NetworkOptions&) const {
  throw ConfigError("the " + name() +
                    " architecture reconstructs patches, not whole sensor images");
}

WarmStart NetworkArchitecture::warm_start(const LightFieldNetImpl&, const std::string&,
                                          const torch::Tensor& src, torch::Tensor& dst,
                                          const WarmStartSource&) const {
  if (src.sizes() != dst.sizes()) return WarmStart::kMismatch;
  dst.copy_(src);
  return WarmStart::kCopied;
}

void register_architecture(std::unique_ptr<NetworkArchitecture> architecture) {
  LFNET_CHECK(architecture != nullptr, "register_architecture: no architecture");
  ensure_builtins();
  add(std::move(architecture));
}

const NetworkArchitecture& find_architecture(const std::string& name) {
  ensure_builtins();
  auto& r = registry();
  {
    std::lock_guard<std::mutex> lock(r.mutex);
    for (const auto& a : r.architectures) {
      if (a->name() == name) return *a;
    }
  }
  throw ConfigError("'" + name + "' is unknown (known: " + architecture_list() + ")");
}

std::vector<std::string> registered_architectures() {
  ensure_builtins();
  auto& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  std::vector<std::string> names;
  names.reserve(r.architectures.size());
  for (const auto& a : r.architectures) names.push_back(a->name());
  return names;
}

std::string architecture_list() {
  std::string out;
  for (const auto& name : registered_architectures()) out += (out.empty() ? "" : ", ") + name;
  return out;
}

}  // namespace lfnet::nn

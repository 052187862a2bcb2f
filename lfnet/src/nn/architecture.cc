#include "lfnet/nn/architecture.h"

#include "lfnet/core/error.h"
#include "lfnet/core/registry.h"
#include "lfnet/nn/network.h"

namespace lfnet::nn {

// One factory per built-in architecture, each defined beside its class.
std::unique_ptr<NetworkArchitecture> make_paper_architecture();     // paper_architecture.cc
std::unique_ptr<NetworkArchitecture> make_lfnet_architecture();     // lfnet_architecture.cc
std::unique_ptr<NetworkArchitecture> make_unrolled_architecture();  // unrolled_architecture.cc

namespace {

// The built-in architectures, one line each.
NamedRegistry<NetworkArchitecture>& registry() {
  static NamedRegistry<NetworkArchitecture> r([](NamedRegistry<NetworkArchitecture>& builtins) {
    builtins.add(make_paper_architecture());
    builtins.add(make_lfnet_architecture());
    builtins.add(make_unrolled_architecture());
  });
  return r;
}

}  // namespace

torch::Tensor NetworkArchitecture::forward_image(LightFieldNetImpl&, const torch::Tensor&, int64_t,
                                                 double) const {
  throw ConfigError("the " + name() +
                    " architecture reconstructs patches, not whole sensor images");
}

void NetworkArchitecture::emulate_precision(LightFieldNetImpl&, torch::Dtype dtype) const {
  if (dtype == torch::kFloat32) return;
  throw ConfigError("training.precision: the " + name() +
                    " architecture trains in float32 only (lfnet and unrolled train for bfloat16)");
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
  registry().add(std::move(architecture));
}

const NetworkArchitecture& find_architecture(const std::string& name) {
  if (const NetworkArchitecture* a = registry().find(name)) return *a;
  throw ConfigError("'" + name + "' is unknown (known: " + architecture_list() + ")");
}

std::vector<std::string> registered_architectures() { return registry().names(); }

std::string architecture_list() { return registry().list(); }

}  // namespace lfnet::nn

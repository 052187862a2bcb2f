#include "lfnet/pipeline/catalog.h"

#include "lfnet/nn/architecture.h"
#include "lfnet/nn/auto_precision.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/methods.h"

namespace lfnet::pipeline {

std::string method_list(bool reconstruction) {
  return reconstruction ? recon::method_list(recon::MethodNeeds::kTruth) : recon::method_list();
}

std::string methods_with_options() { return recon::methods_with_options(); }

std::string architecture_list() { return nn::architecture_list(); }

void check_architecture(const std::string& name) { (void)nn::find_architecture(name); }

bool needs_network(const std::string& method) { return recon::needs_network(method); }

Precision parse_precision(const std::string& text) { return nn::parse_precision(text); }

Precision choose_precision(const std::vector<std::string>& models, const std::string& device) {
  // A noise switch runs its members: they decide, as if given themselves.
  std::vector<std::string> files;
  for (const auto& model : models) {
    auto read = model_input_files(model);
    if (read.size() > 1) read.erase(read.begin());
    files.insert(files.end(), read.begin(), read.end());
  }
  return nn::choose_precision(files, device).precision;
}

}  // namespace lfnet::pipeline

#include "lfnet/recon/method_registry.h"

#include <algorithm>

#include "lfnet/core/error.h"
#include "lfnet/core/registry.h"
#include "lfnet/dict/omp.h"
#include "lfnet/recon/builtin_methods.h"

namespace lfnet::recon {

namespace {

NamedRegistry<Method>& registry() {
  static NamedRegistry<Method> r([](NamedRegistry<Method>& builtins) {
    register_builtin_methods([&](std::unique_ptr<Method> m) { builtins.add(std::move(m)); });
  });
  return r;
}

}  // namespace

nlohmann::json Method::read_options(const nlohmann::json& given, const std::string& path) const {
  LFNET_CHECK_AS(ConfigError, given.is_object(), path, ": expected a JSON object, got ",
                 given.dump());
  LFNET_CHECK_AS(ConfigError, given.empty(), path, ": method '", name(),
                 "' takes no options (methods with options: ", methods_with_options(), ")");
  return nlohmann::json::object();
}

void register_method(std::unique_ptr<Method> method) {
  LFNET_CHECK(method != nullptr, "register_method: no method");
  registry().add(std::move(method));
}

const Method& find_method(const std::string& name) {
  if (const Method* m = registry().find(name)) return *m;
  throw ConfigError("unknown method '" + name + "' (known: " + method_list() + ")");
}

std::vector<std::string> registered_methods() { return registry().names(); }

bool is_baseline(const std::string& name) {
  const Method* m = registry().find(name);
  return m != nullptr && m->baseline();
}

std::string method_list(std::optional<MethodNeeds> excluded) {
  return registry().list([&](const Method& m) { return !excluded || m.needs() != *excluded; });
}

std::string methods_with_options() {
  return registry().list([](const Method& m) { return !m.default_options().empty(); });
}

nlohmann::json check_method_options(const std::string& name, const nlohmann::json& given,
                                    const std::string& path) {
  return find_method(name).read_options(given, path);
}

namespace {
const Method& checked_method(const std::string& name, const MethodResources& resources) {
  const Method& method = find_method(name);
  LFNET_CHECK(resources.phi != nullptr, "method '", name, "' without a Phi");
  switch (method.needs()) {
    case MethodNeeds::kNetwork:
      LFNET_CHECK_AS(ConfigError, resources.script || !resources.net.is_empty(), "method '", name,
                     "' needs a trained model: give --model");
      break;
    case MethodNeeds::kDictionary:
      LFNET_CHECK_AS(ConfigError, resources.dictionary != nullptr, "method '", name,
                     "' needs a dictionary: give --dictionary FILE (e.g. models/dictionary.ckpt)");
      break;
    case MethodNeeds::kTruth:
      throw ConfigError("method '" + name +
                        "' needs the true light field: it is a method of lfnet evaluate");
    case MethodNeeds::kNothing:
      break;
  }
  return method;
}
}  // namespace

PatchSolver make_solver(const std::string& name, const MethodResources& resources) {
  return checked_method(name, resources).solver(resources);
}

ImageSolver make_image_solver(const std::string& name, const MethodResources& resources) {
  return checked_method(name, resources).image_solver(resources);
}

// ---- the methods that need no more than their registry entry ------------------------------

bool needs_network(const std::string& method) {
  const auto names = registered_methods();
  if (std::find(names.begin(), names.end(), method) == names.end()) return false;
  return find_method(method).needs() == MethodNeeds::kNetwork;
}

}  // namespace lfnet::recon

#include "lfnet/recon/method_registry.h"

#include <algorithm>
#include <map>
#include <mutex>

#include "lfnet/core/error.h"
#include "lfnet/dict/omp.h"
#include "lfnet/recon/builtin_methods.h"

namespace lfnet::recon {

namespace {

struct Registry {
  std::mutex mutex;
  std::vector<std::unique_ptr<Method>> methods;  // registration order
};

Registry& registry() {
  static Registry r;
  return r;
}

void add(std::unique_ptr<Method> method) {
  auto& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  for (auto& m : r.methods) {
    if (m->name() == method->name()) {
      m = std::move(method);
      return;
    }
  }
  r.methods.push_back(std::move(method));
}

void ensure_builtins() {
  static std::once_flag once;
  std::call_once(once, [] { register_builtin_methods(add); });
}

}  // namespace

void register_method(std::unique_ptr<Method> method) {
  LFNET_CHECK(method != nullptr, "register_method: no method");
  ensure_builtins();
  add(std::move(method));
}

const Method& find_method(const std::string& name) {
  ensure_builtins();
  auto& r = registry();
  {
    std::lock_guard<std::mutex> lock(r.mutex);
    for (const auto& m : r.methods) {
      if (m->name() == name) return *m;
    }
  }
  throw ConfigError("unknown method '" + name + "' (known: " + method_list() + ")");
}

std::vector<std::string> registered_methods() {
  ensure_builtins();
  auto& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  std::vector<std::string> names;
  for (const auto& m : r.methods) names.push_back(m->name());
  return names;
}

bool is_baseline(const std::string& name) {
  for (const auto& known : registered_methods()) {
    if (known == name) return find_method(name).baseline();
  }
  return false;
}

std::string method_list(std::optional<MethodNeeds> excluded) {
  std::string out;
  for (const auto& name : registered_methods()) {
    if (excluded && find_method(name).needs() == *excluded) continue;
    out += (out.empty() ? "" : ", ") + name;
  }
  return out;
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

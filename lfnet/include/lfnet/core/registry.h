// One shape for lfnet's registries of named classes (reconstruction methods, network
// architectures, denoisers; docs/architecture.md "Registries"): entries are kept in
// registration order, the built-ins are added once before anything else, and an entry
// registered later replaces one of the same name (so a library outside the core can replace a
// built-in). Entries are never removed while the program runs.
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet {

// T has `std::string name() const`. The registry is meant to live in a function-local static
// of the .cc that owns the built-ins.
template <typename T>
class NamedRegistry {
 public:
  using Builtins = std::function<void(NamedRegistry&)>;

  explicit NamedRegistry(Builtins builtins) : builtins_(std::move(builtins)) {}

  // Adds `entry`, replacing one of the same name (in its place in the order).
  void add(std::unique_ptr<T> entry) {
    LFNET_CHECK(entry != nullptr, "registering no entry");
    ensure_builtins();
    std::lock_guard<std::mutex> lock(mutex_);
    insert(std::move(entry));
  }

  // The entry called `name`, or nullptr.
  const T* find(const std::string& name) {
    ensure_builtins();
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& e : entries_) {
      if (e->name() == name) return e.get();
    }
    return nullptr;
  }

  // Every entry's name, in registration order.
  std::vector<std::string> names() {
    ensure_builtins();
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::string> out;
    out.reserve(entries_.size());
    for (const auto& e : entries_) out.push_back(e->name());
    return out;
  }

  // "a, b, c": the names of the entries for which `keep` holds (all without one).
  std::string list(const std::function<bool(const T&)>& keep = {}) {
    std::string out;
    for (const auto& name : names()) {
      if (keep && !keep(*find(name))) continue;
      out += (out.empty() ? "" : ", ") + name;
    }
    return out;
  }

 private:
  void insert(std::unique_ptr<T> entry) {
    for (auto& e : entries_) {
      if (e->name() == entry->name()) {
        e = std::move(entry);
        return;
      }
    }
    entries_.push_back(std::move(entry));
  }

  void ensure_builtins() {
    std::call_once(once_, [this] {
      // The built-ins go in through a registry of their own so that `add` does not recurse.
      NamedRegistry staging{Builtins{}};
      staging.once_flag_done();
      if (builtins_) builtins_(staging);
      std::lock_guard<std::mutex> lock(mutex_);
      for (auto& e : staging.entries_) insert(std::move(e));
    });
  }

  void once_flag_done() {
    std::call_once(once_, [] {});
  }

  Builtins builtins_;
  std::once_flag once_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<T>> entries_;
};

}  // namespace lfnet

// The error of a scene spec's field: a ConfigError that names the JSON path. Reading itself is
// JsonReader's (kinds checked, unknown keys refused).
#pragma once

#include <string>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"

namespace lfnet::scene::detail {

[[noreturn]] inline void fail(const std::string& path, const std::string& message) {
  throw ConfigError(path + ": " + message);
}

}  // namespace lfnet::scene::detail

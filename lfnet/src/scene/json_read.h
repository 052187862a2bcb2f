// Typed JSON readers for scene specs: JsonReader::get converts loosely (true -> 1, 2.5 -> 2);
// these insist on the JSON type and name the path when it is wrong.
#pragma once

#include <nlohmann/json.hpp>

#include <string>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"

namespace lfnet::scene::detail {

using nlohmann::json;

[[noreturn]] inline void fail(const std::string& path, const std::string& message) {
  throw ConfigError(path + ": " + message);
}

inline bool read_raw(JsonReader& r, const std::string& key, json& out) { return r.get(key, out); }

inline bool read_double(JsonReader& r, const std::string& key, double& out) {
  json v;
  if (!read_raw(r, key, v)) return false;
  if (!v.is_number()) fail(r.path_of(key), "expected a number, got " + v.dump());
  out = v.get<double>();
  return true;
}

inline bool read_int(JsonReader& r, const std::string& key, int64_t& out) {
  json v;
  if (!read_raw(r, key, v)) return false;
  if (!v.is_number_integer()) fail(r.path_of(key), "expected an integer, got " + v.dump());
  out = v.get<int64_t>();
  return true;
}

inline bool read_seed(JsonReader& r, const std::string& key, uint64_t& out) {
  json v;
  if (!read_raw(r, key, v)) return false;
  if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<int64_t>() >= 0)) {
    fail(r.path_of(key), "expected a non-negative integer seed, got " + v.dump());
  }
  out = v.get<uint64_t>();
  return true;
}

inline bool read_bool(JsonReader& r, const std::string& key, bool& out) {
  json v;
  if (!read_raw(r, key, v)) return false;
  if (!v.is_boolean()) fail(r.path_of(key), "expected true or false, got " + v.dump());
  out = v.get<bool>();
  return true;
}

inline bool read_string(JsonReader& r, const std::string& key, std::string& out) {
  json v;
  if (!read_raw(r, key, v)) return false;
  if (!v.is_string()) fail(r.path_of(key), "expected a string, got " + v.dump());
  out = v.get<std::string>();
  return true;
}

}  // namespace lfnet::scene::detail

// Strict JSON reading for Options structs: unknown keys are errors that name the JSON path.
#pragma once

#include <nlohmann/json.hpp>

#include <limits>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet {

// Reads the fields of one JSON object. Every key read is remembered; `finish()` throws a
// ConfigError naming the first key nobody asked for, with its path, e.g. "$.train.lr".
class JsonReader {
 public:
  JsonReader(const nlohmann::json& object, std::string path);

  // Sets `out` from `key` if present; a value of the wrong kind is a ConfigError naming the
  // path: integers must be whole numbers that fit the field (2.5 is not 2, -1 is no count),
  // booleans true or false (not 1), numbers numbers, strings strings; lists element by element.
  template <typename T>
  bool get(const std::string& key, T& out) {
    seen_.insert(key);
    auto it = object_.find(key);
    if (it == object_.end()) return false;
    check_kind<T>(*it, path_of(key));
    try {
      out = it->template get<T>();
    } catch (const nlohmann::json::exception& e) {
      throw ConfigError(path_of(key) + ": " + type_hint(*it, out) + " (" + e.what() + ")");
    }
    return true;
  }

  // Like get(), but a missing key is a ConfigError.
  template <typename T>
  void require(const std::string& key, T& out) {
    if (!get(key, out)) throw ConfigError(path_of(key) + ": required key is missing");
  }

  bool has(const std::string& key) const { return object_.contains(key); }

  // A reader of the nested object at `key` (which must be an object).
  JsonReader child(const std::string& key);

  // The JSON path of `key`, e.g. "$.phi.n".
  std::string path_of(const std::string& key) const { return path_ + "." + key; }
  const std::string& path() const { return path_; }
  const nlohmann::json& object() const { return object_; }

  // Throws ConfigError for the first key that was never read.
  void finish() const;

 private:
  template <typename T>
  struct IsVector : std::false_type {};
  template <typename T, typename A>
  struct IsVector<std::vector<T, A>> : std::true_type {};

  // Throws ConfigError at `path` when `value` is not of T's kind (see get()).
  template <typename T>
  static void check_kind(const nlohmann::json& value, const std::string& path) {
    if constexpr (std::is_same_v<T, bool>) {
      if (!value.is_boolean())
        throw ConfigError(path + ": expected true or false, got " + value.dump());
    } else if constexpr (std::is_integral_v<T>) {
      check_integer(value, path, static_cast<long double>(std::numeric_limits<T>::min()),
                    static_cast<long double>(std::numeric_limits<T>::max()));
    } else if constexpr (std::is_floating_point_v<T>) {
      if (!value.is_number()) throw ConfigError(path + ": expected a number, got " + value.dump());
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (!value.is_string()) throw ConfigError(path + ": expected a string, got " + value.dump());
    } else if constexpr (IsVector<T>::value) {
      if (!value.is_array()) throw ConfigError(path + ": expected a list, got " + value.dump());
      for (size_t i = 0; i < value.size(); ++i) {
        check_kind<typename T::value_type>(value[i], path + "[" + std::to_string(i) + "]");
      }
    }
  }
  // A whole number in [lo, hi]; integral floats such as 1e3 count.
  static void check_integer(const nlohmann::json& value, const std::string& path, long double lo,
                            long double hi);

  template <typename T>
  static std::string type_hint(const nlohmann::json& value, const T&) {
    return "unexpected value " + value.dump();
  }

  const nlohmann::json& object_;
  std::string path_;
  std::set<std::string> seen_;
};

// JSON has no inf or NaN: a non-finite number is written as null.
nlohmann::json finite_or_null(double v);
// The number `j` holds, or `fallback` where it holds none (null, a string).
double number_or(const nlohmann::json& j, double fallback);

// Parses JSON text; a syntax error is a ConfigError naming `source` and the byte offset.
nlohmann::json parse_json(const std::string& text, const std::string& source);

// Reads and parses a JSON file.
nlohmann::json read_json_file(const std::string& path);

// A command-line option's JSON: the text itself when it holds a '{' (an inline object), else the
// file it names. Errors are ConfigErrors that start with `option`.
bool is_inline_json(const std::string& text);
nlohmann::json read_json_argument(const std::string& text, const std::string& option);
// The file such an option names, "" for inline JSON: an input its command must not overwrite.
std::string json_argument_file(const std::string& text);
// Where that JSON came from, for a JsonReader's path: "--opt" or "--opt FILE".
std::string json_argument_source(const std::string& text, const std::string& option);

// Writes `value` to `path` atomically (temporary file, then rename), pretty-printed.
void write_json_file(const std::string& path, const nlohmann::json& value);

// The fields in which two JSON documents differ, as "params.pair_alpha (A 90, B 0)" joined by
// "; " (`a_name`, `b_name` label the values); "" when equal.
std::string json_differences(const nlohmann::json& a, const nlohmann::json& b,
                             const std::string& a_name, const std::string& b_name);

// "name:n" of a Phi spec object (its "name" and "n" fields), for messages; "?" for parts missing.
std::string phi_label(const nlohmann::json& spec);

}  // namespace lfnet

// One field list per Options struct (docs/architecture.md, "Options"). A struct names its JSON
// fields once, in a member template
//
//   template <typename Fields>
//   void fields(Fields& f) {
//     f("name", name);
//     f("reduction", reduction);
//   }
//
// and read_fields / fields_to_json drive that list both ways. A numeric field names its domain
// as a third argument, f("lr", lr, Range::above(0, 1)): reading refuses a value outside it (each
// element of a list) with its JSON path; every numeric field of a JSON input has one
// (tests/pipeline/numeric_domains_test.cc). Reading and writing: reading is strict (JsonReader:
// kinds checked, unknown keys refused with their JSON path), nested Options structs (those
// with a fields() of their own) are read and written as nested objects, and a missing key
// keeps the field's default. An optional Options struct (std::optional<T>) is set when its key
// is present, however empty its object, and written only when set. An enum field (a closed set) is
// written by its name: its namespace provides `std::string to_string(E)` and `E from_string(const
// std::string&, E)` (found by argument-dependent lookup; the second argument only picks the
// overload), which throws ConfigError naming the known values. A list of enums is a list of
// names, and an unknown one is refused with its index, e.g. "$.evaluation.modes[1]: ...".
#pragma once

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "lfnet/core/json.h"

namespace lfnet {

// The values a numeric field may take: [lo, hi], or (lo, hi] when made by above().
struct Range {
  double lo = 0;
  double hi = 0;
  bool lo_open = false;

  static constexpr Range closed(double lo, double hi) { return {lo, hi, false}; }
  static constexpr Range above(double lo, double hi) { return {lo, hi, true}; }
  bool contains(double v) const { return (lo_open ? v > lo : v >= lo) && v <= hi; }
  // "[0, 1]", "(0, 10]"
  std::string text() const;
};

namespace detail {

// Throws ConfigError "PATH: must lie in [lo, hi], got V" unless `v` is in `range`.
void check_in_range(double v, const Range& range, const std::string& path);

struct FieldProbe {
  template <typename T>
  void operator()(const char*, T&) {}
  template <typename T>
  void operator()(const char*, T&, const Range&) {}
};

// True for types with a fields() member template: nested Options structs.
template <typename T, typename = void>
struct HasFields : std::false_type {};
template <typename T>
struct HasFields<T, std::void_t<decltype(std::declval<T&>().fields(std::declval<FieldProbe&>()))>>
    : std::true_type {};

template <typename T>
struct IsOptional : std::false_type {};
template <typename T>
struct IsOptional<std::optional<T>> : std::true_type {};

// True for lists of enums, read and written as lists of names.
template <typename T>
struct IsEnumVector : std::false_type {};
template <typename T, typename A>
struct IsEnumVector<std::vector<T, A>> : std::is_enum<T> {};

}  // namespace detail

template <typename T>
void read_fields(JsonReader& reader, T& options);

// Reads one field: a nested Options struct from its object, anything else with JsonReader::get.
struct FieldReader {
  JsonReader& reader;
  template <typename T>
  void operator()(const char* key, T& value) {
    if constexpr (detail::HasFields<T>::value) {
      if (!reader.has(key)) return;
      auto child = reader.child(key);
      read_fields(child, value);
      child.finish();
    } else if constexpr (detail::IsOptional<T>::value) {
      if (!reader.has(key)) return;
      auto child = reader.child(key);
      value.emplace();
      read_fields(child, *value);
      child.finish();
    } else if constexpr (std::is_enum_v<T>) {
      std::string name;
      if (!reader.get(key, name)) return;
      try {
        value = from_string(name, value);
      } catch (const ConfigError& e) {
        throw ConfigError(reader.path_of(key) + ": " + e.what());
      }
    } else if constexpr (detail::IsEnumVector<T>::value) {
      std::vector<std::string> names;
      if (!reader.get(key, names)) return;
      T values;
      for (size_t i = 0; i < names.size(); ++i) {
        try {
          values.push_back(from_string(names[i], typename T::value_type{}));
        } catch (const ConfigError& e) {
          throw ConfigError(reader.path_of(key) + "[" + std::to_string(i) + "]: " + e.what());
        }
      }
      value = std::move(values);
    } else {
      reader.get(key, value);
    }
  }
  // A numeric field (or a list of numbers) and its domain.
  template <typename T>
  void operator()(const char* key, T& value, const Range& range) {
    if (!reader.get(key, value)) return;
    if constexpr (std::is_arithmetic_v<T>) {
      detail::check_in_range(static_cast<double>(value), range, reader.path_of(key));
    } else {
      for (size_t i = 0; i < value.size(); ++i) {
        detail::check_in_range(static_cast<double>(value[i]), range,
                               reader.path_of(key) + "[" + std::to_string(i) + "]");
      }
    }
  }
};

// Every field of `options` present in the reader's object. Unknown keys are left to the
// caller's reader.finish(), so a struct can read more keys than its list.
template <typename T>
void read_fields(JsonReader& reader, T& options) {
  FieldReader f{reader};
  options.fields(f);
}

template <typename T>
nlohmann::json fields_to_json(const T& options);

// Writes one field: a nested Options struct as its object, anything else as nlohmann writes it.
struct FieldWriter {
  nlohmann::json& out;
  template <typename T>
  void operator()(const char* key, const T& value) {
    if constexpr (detail::HasFields<T>::value) {
      out[key] = fields_to_json(value);
    } else if constexpr (detail::IsOptional<T>::value) {
      if (value) out[key] = fields_to_json(*value);
    } else if constexpr (std::is_enum_v<T>) {
      out[key] = to_string(value);
    } else if constexpr (detail::IsEnumVector<T>::value) {
      auto names = nlohmann::json::array();
      for (const auto v : value) names.push_back(to_string(v));
      out[key] = std::move(names);
    } else {
      out[key] = value;
    }
  }
  template <typename T>
  void operator()(const char* key, const T& value, const Range&) {
    out[key] = value;
  }
};

// The field list written as a JSON object. fields() does not change the struct when the
// visitor only reads, so a const struct is visited through a copy-free const_cast.
template <typename T>
nlohmann::json fields_to_json(const T& options) {
  nlohmann::json out = nlohmann::json::object();
  FieldWriter f{out};
  const_cast<T&>(options).fields(f);  // NOLINT(cppcoreguidelines-pro-type-const-cast)
  return out;
}

// Runs `fn` (a validate()); a ConfigError it throws gets the reader's path in front, so
// "epochs: must be >= 1" reads "$.training.epochs: must be >= 1".
template <typename Fn>
void with_path(const JsonReader& reader, Fn&& fn) {
  try {
    fn();
  } catch (const ConfigError& e) {
    throw ConfigError(reader.path() + "." + e.what());
  }
}

namespace detail {
template <typename T, typename = void>
struct HasValidate : std::false_type {};
template <typename T>
struct HasValidate<T, std::void_t<decltype(std::declval<const T&>().validate())>> : std::true_type {
};
}  // namespace detail

// An Options struct read from `given` (a JSON object): its defaults, then every key of
// `given` (unknown keys and wrong kinds refused, with `path`, e.g. "--method-options.omp"),
// then its validate() when it has one.
template <typename Options>
Options options_from_json(const nlohmann::json& given, const std::string& path) {
  LFNET_CHECK_AS(ConfigError, given.is_object(), path, ": expected a JSON object, got ",
                 given.dump());
  Options options;
  JsonReader reader(given, path);
  read_fields(reader, options);
  reader.finish();
  if constexpr (detail::HasValidate<Options>::value) {
    with_path(reader, [&] { options.validate(); });
  }
  return options;
}

}  // namespace lfnet

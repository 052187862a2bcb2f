#include "lfnet/core/json.h"

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/output.h"

namespace lfnet {

JsonReader::JsonReader(const nlohmann::json& object, std::string path)
    : object_(object), path_(std::move(path)) {
  if (!object_.is_object())
    throw ConfigError(path_ + ": expected a JSON object, got " + object_.dump());
}

JsonReader JsonReader::child(const std::string& key) {
  seen_.insert(key);
  auto it = object_.find(key);
  if (it == object_.end()) throw ConfigError(path_of(key) + ": required object is missing");
  return JsonReader(*it, path_of(key));
}

void JsonReader::check_integer(const nlohmann::json& value, const std::string& path, long double lo,
                               long double hi) {
  long double v = 0;
  if (value.is_number_unsigned()) {
    v = static_cast<long double>(value.get<uint64_t>());
  } else if (value.is_number_integer()) {
    v = static_cast<long double>(value.get<int64_t>());
  } else if (value.is_number_float()) {
    v = static_cast<long double>(value.get<double>());
    if (!std::isfinite(v) || std::floor(v) != v) {
      throw ConfigError(path + ": expected a whole number, got " + value.dump());
    }
  } else {
    throw ConfigError(path + ": expected a whole number, got " + value.dump());
  }
  if (v < lo || v > hi) {
    std::ostringstream range;
    range << std::fixed << std::setprecision(0) << lo << " .. " << hi;
    throw ConfigError(path + ": " + value.dump() + " is outside the range " + range.str());
  }
}

void JsonReader::finish() const {
  for (auto it = object_.begin(); it != object_.end(); ++it) {
    if (!seen_.count(it.key())) {
      std::string known;
      for (const auto& k : seen_) known += (known.empty() ? "" : ", ") + k;
      throw ConfigError(path_of(it.key()) + ": unknown key (known keys here: " + known + ")");
    }
  }
}

nlohmann::json finite_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

double number_or(const nlohmann::json& j, double fallback) {
  return j.is_number() ? j.get<double>() : fallback;
}

nlohmann::json parse_json(const std::string& text, const std::string& source) {
  // A key that appears twice in one object is refused: the parser would keep the last and
  // drop the first without a word. Each frame is an open object or list; its name is the key
  // it was found under ("[]" inside a list).
  struct Frame {
    bool object = false;
    std::string name, key;
    std::set<std::string> keys;
  };
  std::vector<Frame> frames;
  std::string duplicate;
  using Event = nlohmann::json::parse_event_t;
  auto check = [&](int, Event event, nlohmann::json& parsed) {
    if (!duplicate.empty()) return true;
    if (event == Event::object_start || event == Event::array_start) {
      Frame f;
      f.object = event == Event::object_start;
      if (!frames.empty()) f.name = frames.back().object ? frames.back().key : "[]";
      frames.push_back(std::move(f));
    } else if (event == Event::object_end || event == Event::array_end) {
      if (!frames.empty()) frames.pop_back();
    } else if (event == Event::key && !frames.empty()) {
      auto& f = frames.back();
      f.key = parsed.get<std::string>();
      if (!f.keys.insert(f.key).second) {
        duplicate = "$";
        for (size_t i = 1; i < frames.size(); ++i) {
          duplicate += frames[i].name == "[]" ? "[]" : "." + frames[i].name;
        }
        duplicate += "." + f.key;
      }
    }
    return true;
  };
  try {
    auto j = nlohmann::json::parse(text, check);
    LFNET_CHECK_AS(ConfigError, duplicate.empty(), source, ": ", duplicate,
                   ": the key appears twice in one object (only one may be given)");
    return j;
  } catch (const nlohmann::json::parse_error& e) {
    throw ConfigError(source + ": malformed JSON at byte " + std::to_string(e.byte) + ": " +
                      e.what());
  } catch (const nlohmann::json::exception& e) {
    // Well-formed text the parser still refuses, e.g. a number too large for a double.
    throw ConfigError(source + ": malformed JSON: " + e.what());
  }
}

nlohmann::json read_json_file(const std::string& path) {
  check_regular_input(path);
  std::ifstream in(path);
  if (!in) throw IoError("cannot read " + path + ": no such file or not readable");
  std::stringstream buffer;
  buffer << in.rdbuf();
  return parse_json(buffer.str(), path);
}

bool is_inline_json(const std::string& text) {
  // An object anywhere, or an array: '[1,2]' is JSON given inline, not a file's name.
  return text.find('{') != std::string::npos || text.rfind('[', 0) == 0;
}

std::string json_argument_file(const std::string& text) {
  return is_inline_json(text) ? std::string() : text;
}

std::string json_argument_source(const std::string& text, const std::string& option) {
  return is_inline_json(text) ? option : option + " " + text;
}

nlohmann::json read_json_argument(const std::string& text, const std::string& option) {
  if (is_inline_json(text)) return parse_json(text, option);
  try {
    return read_json_file(text);
  } catch (const IoError& e) {
    throw ConfigError(option + " " + text + ": " + e.what());
  } catch (const ConfigError& e) {
    throw ConfigError(option + " " + e.what());
  }
}

void write_json_file(const std::string& path, const nlohmann::json& value) {
  write_text_file(path, value.dump(2) + "\n");
}

namespace {
// "WHERE (A_NAME A_VALUE, B_NAME B_VALUE)": one field that differs.
std::string difference_line(const std::string& where, const std::string& a_name,
                            const std::string& a_value, const std::string& b_name,
                            const std::string& b_value) {
  std::string line = where;
  line.append(" (").append(a_name).append(" ").append(a_value);
  line.append(", ").append(b_name).append(" ").append(b_value).append(")");
  return line;
}

void collect_differences(const nlohmann::json& a, const nlohmann::json& b, const std::string& path,
                         const std::string& a_name, const std::string& b_name,
                         std::vector<std::string>& out) {
  if (a.is_object() && b.is_object()) {
    std::set<std::string> keys;
    for (const auto& [k, v] : a.items()) keys.insert(k);
    for (const auto& [k, v] : b.items()) keys.insert(k);
    for (const auto& k : keys) {
      const std::string sub = path.empty() ? k : std::string(path).append(".").append(k);
      if (!a.contains(k)) {
        out.push_back(difference_line(sub, a_name, "none", b_name, b[k].dump()));
      } else if (!b.contains(k)) {
        out.push_back(difference_line(sub, a_name, a[k].dump(), b_name, "none"));
      } else {
        collect_differences(a[k], b[k], sub, a_name, b_name, out);
      }
    }
    return;
  }
  if (a == b) return;
  const std::string where = path.empty() ? "$" : path;
  // Long values (a calibrated camera's weights) are summarised, not printed.
  auto shown = [](const nlohmann::json& v) {
    std::string text = v.dump();
    if (text.size() <= 40) return text;
    return v.is_array() ? "a list of " + std::to_string(v.size()) + " values"
                        : text.substr(0, 37) + "...";
  };
  out.push_back(difference_line(where, a_name, shown(a), b_name, shown(b)));
}

// Model names that differ make every parameter differ: say only that.
void collect_top_differences(const nlohmann::json& a, const nlohmann::json& b,
                             const std::string& a_name, const std::string& b_name,
                             std::vector<std::string>& out) {
  if (a.is_object() && b.is_object() && a.contains("name") && b.contains("name") &&
      a["name"] != b["name"] && a.contains("params") && b.contains("params")) {
    auto a_rest = a, b_rest = b;
    a_rest.erase("params");
    b_rest.erase("params");
    collect_differences(a_rest, b_rest, "", a_name, b_name, out);
    out.push_back("params (another model's)");
    return;
  }
  collect_differences(a, b, "", a_name, b_name, out);
}
}  // namespace

std::string json_differences(const nlohmann::json& a, const nlohmann::json& b,
                             const std::string& a_name, const std::string& b_name) {
  std::vector<std::string> parts;
  collect_top_differences(a, b, a_name, b_name, parts);
  std::string out;
  for (const auto& p : parts) out += (out.empty() ? "" : "; ") + p;
  return out;
}

std::string phi_label(const nlohmann::json& spec) {
  const auto part = [&](const char* key) {
    if (!spec.is_object() || !spec.contains(key)) return std::string("?");
    const auto& v = spec[key];
    return v.is_string() ? v.get<std::string>() : v.dump();
  };
  return part("name") + ":" + part("n");
}

namespace {
std::string number_text(double v) {
  std::ostringstream out;
  out << std::setprecision(6) << v;
  return out.str();
}
}  // namespace

std::string Range::text() const {
  return std::string(lo_open ? "(" : "[") + number_text(lo) + ", " + number_text(hi) + "]";
}

void detail::check_in_range(double v, const Range& range, const std::string& path) {
  if (!range.contains(v)) {
    throw ConfigError(path + ": must lie in " + range.text() + ", got " + number_text(v));
  }
}

}  // namespace lfnet

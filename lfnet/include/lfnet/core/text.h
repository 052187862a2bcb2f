// printf-style formatting into a std::string, for tables and reports printed line by line.
#pragma once

#include <cstdio>
#include <string>
#include <vector>

namespace lfnet {

// The text std::printf(format, args...) would print, whatever its length.
template <typename... Args>
std::string format_text(const char* format, Args... args) {
  // The format is the caller's literal, passed through.
  const int size = std::snprintf(nullptr, 0, format, args...);  // NOLINT
  if (size <= 0) return {};
  std::string text(static_cast<size_t>(size) + 1, '\0');
  std::snprintf(text.data(), text.size(), format, args...);  // NOLINT
  text.pop_back();
  return text;
}

// The items with `separator` between them: join({"a", "b"}, ", ") is "a, b".
inline std::string join(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) out += (i ? separator : "") + items[i];
  return out;
}

// `text` with every `from` replaced by `to` (an error about a temporary names what it becomes).
inline std::string replace_all(std::string text, const std::string& from, const std::string& to) {
  if (from.empty()) return text;
  for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size())) {
    text.replace(at, from.size(), to);
  }
  return text;
}

// `message` without the source locations lfnet's checks append (" [lfnet/src/io/x.cc:12]",
// core/error.h): the text for a user, a record or a summary.
inline std::string without_source_locations(std::string message) {
  for (size_t open = message.find(" ["); open != std::string::npos;
       open = message.find(" [", open + 1)) {
    const size_t close = message.find(']', open);
    if (close == std::string::npos) break;
    const std::string inside = message.substr(open + 2, close - open - 2);
    const size_t colon = inside.rfind(':');
    const bool digits = colon != std::string::npos && colon + 1 < inside.size() &&
                        inside.find_first_not_of("0123456789", colon + 1) == std::string::npos;
    const std::string file = colon == std::string::npos ? "" : inside.substr(0, colon);
    bool source = false;
    for (const std::string ending : {".cc", ".h", ".cpp", ".hpp"}) {
      source = source || (file.size() > ending.size() &&
                          file.compare(file.size() - ending.size(), ending.size(), ending) == 0);
    }
    if (digits && source && file.find_first_of("[]") == std::string::npos) {
      message.erase(open, close - open + 1);
      open = open == 0 ? 0 : open - 1;
    }
  }
  return message;
}

}  // namespace lfnet

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

}  // namespace lfnet

// What a file that is neither a regular file nor a folder is, in words, for error messages.
#pragma once

#include <filesystem>

namespace lfnet {

// "a named pipe (FIFO)", "a socket" or "a device" (which reading would block on or stream);
// nullptr for a regular file, a folder, a missing path or anything else.
inline const char* special_file_kind(const std::filesystem::file_status& status) {
  switch (status.type()) {
    case std::filesystem::file_type::fifo:
      return "a named pipe (FIFO)";
    case std::filesystem::file_type::socket:
      return "a socket";
    case std::filesystem::file_type::block:
    case std::filesystem::file_type::character:
      return "a device";
    default:
      return nullptr;
  }
}

}  // namespace lfnet

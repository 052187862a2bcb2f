// FNV-1a 64: the checksum of checkpoint files and the content fingerprint of models.
#pragma once

#include <cstddef>
#include <cstdint>

namespace lfnet {

constexpr uint64_t kFnv1aBasis = 14695981039346656037ULL;

// FNV-1a 64 of `n` bytes, continuing from `hash` (the basis for a fresh hash), so that a file
// read in pieces hashes as one.
inline uint64_t fnv1a(const char* data, size_t n, uint64_t hash = kFnv1aBasis) {
  for (size_t i = 0; i < n; ++i) {
    hash ^= static_cast<unsigned char>(data[i]);
    hash *= 1099511628211ULL;
  }
  return hash;
}

}  // namespace lfnet

// A learned light-field dictionary and its file (`models/dictionary.ckpt`).
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <string>

namespace lfnet::dict {

// Version of the dictionary file format; bumped when the layout changes.
constexpr int64_t kDictionaryFormatVersion = 1;

// Atoms of light-field patches with how they were made.
struct Dictionary {
  torch::Tensor atoms;                                 // (d, K) float32, unit-norm columns
  std::array<int64_t, 4> patch_shape{5, 5, 9, 9};      // (U, V, h, w); d = U V h w, (u, v, y, x)
  nlohmann::json training = nlohmann::json::object();  // options, data, history (free form)

  int64_t dimension() const { return atoms.size(0); }
  int64_t size() const { return atoms.size(1); }
  // Throws Error when the atoms are not (U V h w, K) float32 and finite.
  void validate() const;
};

// Writes `dictionary` to `path` atomically (temporary file, then rename) as one LibTorch
// archive: the atoms and a JSON string with the format name, version, patch shape and
// training metadata. 2025 x K float32 atoms take 8.1 kB per atom (K = 1000: 8.1 MB).
void save_dictionary(const Dictionary& dictionary, const std::string& path);

// Reads a file written by save_dictionary. A missing file is an IoError; a truncated or
// foreign file, or another format version, is a CheckpointError that says which.
Dictionary load_dictionary(const std::string& path);

}  // namespace lfnet::dict

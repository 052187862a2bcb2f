// Fuzz target: reading model files. The input is written as a file and read as what lfnet
// takes it for (pipeline::model_file_kind): a checkpoint or exported network through
// pipeline::load_model (the network built and its Phi checked), a dictionary through
// dict::load_dictionary. The seeds are a tiny checkpoint and a tiny dictionary
// (tests/fuzz/corpus/checkpoint). Any lfnet::Error is a clean rejection; anything else is a
// finding.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include "lfnet/core/error.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/pipeline/models.h"

namespace fs = std::filesystem;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > (size_t{1} << 20)) return 0;
  static const fs::path path =
      fs::temp_directory_path() / ("lfnet-fuzz-checkpoint-" + std::to_string(::getpid()) + ".ckpt");
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  try {
    using lfnet::pipeline::ModelFileKind;
    const auto kind = lfnet::pipeline::model_file_kind(path.string());
    if (kind == ModelFileKind::kDictionary) {
      const auto d = lfnet::dict::load_dictionary(path.string());
      if (d.size() <= 0) std::abort();  // a loaded dictionary has atoms
    } else {
      (void)lfnet::pipeline::load_model(path.string(), /*network=*/true);
    }
  } catch (const lfnet::Error&) {
    // A clear rejection.
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_checkpoint: unexpected %s exception: %s\n", typeid(e).name(),
                 e.what());
    std::abort();
  }
  std::error_code ec;
  fs::remove(path, ec);  // nothing left behind in the temporary folder
  return 0;
}

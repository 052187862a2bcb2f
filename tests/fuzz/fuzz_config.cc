// Fuzz target: the experiment config parser (ExperimentConfig::load, the strict readers of
// every Options struct it calls, and the Phi it resolves). Any lfnet::Error is a clean
// rejection; any other exception, a crash, a leak or a hang is a finding.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include <unistd.h>

#include "lfnet/core/error.h"
#include "lfnet/pipeline/experiment.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 8192) return 0;  // configs are small; longer inputs only slow the search
  static const std::string path = "/tmp/lfnet-fuzz-config-" + std::to_string(::getpid()) + ".json";
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  try {
    auto config = lfnet::pipeline::ExperimentConfig::load(path);
    for (const auto& stage : config.stages) {
      (void)config.stage_options(stage);
      (void)config.stage_network(stage);
    }
  } catch (const lfnet::Error&) {
    // A clear rejection.
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_config: unexpected %s exception: %s\n", typeid(e).name(), e.what());
    std::abort();
  }
  std::remove(path.c_str());
  return 0;
}

// --precision auto (docs/performance.md, "Precision auto"): bfloat16 where it is both faster
// and harmless, float32 everywhere else.
#pragma once

#include <string>
#include <vector>

#include "lfnet/nn/network.h"

namespace lfnet::nn {

// True when this CPU computes bfloat16 natively: AVX-512 BF16 or AMX (the avx512_bf16 or
// amx_bf16 flag in /proc/cpuinfo). LFNET_NATIVE_BFLOAT16=1 or 0 overrides the detection.
bool cpu_has_native_bfloat16();

// How a 3 x 3 convolution of 48 channels over a 64 x 64 image, lfnet's U-Net's commonest layer,
// runs here in each precision at LibTorch's thread count: the best of five after a warm-up.
struct PrecisionSpeed {
  double float32_ms = 0, bfloat16_ms = 0;
  bool bfloat16_faster() const { return bfloat16_ms < 0.9 * float32_ms; }
};
// Measured once per process (about 30 ms). LFNET_NATIVE_BFLOAT16=1 or 0 stands for the
// measurement too: bfloat16 faster, or not.
PrecisionSpeed precision_speed();

// The content fingerprint that bfloat16.json lists models by (a renamed or copied file keeps
// it, a retrained one does not): FNV-1a 64 of the file's bytes, 16 hex digits. Throws IoError
// when the file cannot be read.
std::string file_fingerprint(const std::string& path);

// What auto chose, and why.
struct AutoPrecision {
  Precision precision = Precision::kFloat32;
  std::string reason;
};

// auto's choice for the model files `models` (none: a method without a network) on `device`:
// bfloat16 on a CPU with native bfloat16 when every model is verified in the bfloat16.json of
// its folder (its PSNR within 0.05 dB of float32 on every light field of the cross-scene
// benchmark, scripts/precision-check.sh) and bfloat16 is measured faster here
// (precision_speed), float32 otherwise. Never throws: a model that cannot
// be read gets float32, and the command that loads it reports why it cannot.
AutoPrecision choose_precision(const std::vector<std::string>& models, const std::string& device);

}  // namespace lfnet::nn

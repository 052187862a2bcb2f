// What `lfnet bench` measures (docs/performance.md): LibTorch's GEMM FLOP/s, Conv4d FLOP/s at
// the default channel counts, and whole-light-field reconstruction of a procedural light field
// (593 x 840 x 5 x 5, the paper's test size, by default) per method and stride.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "lfnet/core/light_field.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/recon/fully_convolutional.h"

namespace lfnet::pipeline {

// The paper's times on a Titan X (Table 3, ASP, dragons scene, 593 x 840 x 5 x 5).
inline constexpr double kPaperNetSeconds = 242.0;
inline constexpr double kPaperDictSeconds = 3786.0;

struct BenchOptions {
  std::vector<std::string> methods = {"net", "ae", "cnn", "dict", "pinv"};
  std::vector<int64_t> strides = {9, 5, 2};
  int64_t height = 593, width = 840;  // the random scene's size
  std::string phi = "asp:2";
  int64_t batch = 1024;  // patches per solver call
  // Trained checkpoints: the network methods are timed once with each (both architectures can
  // share one run). Empty: an untrained net of each of `architectures`.
  std::vector<std::string> models;
  std::string dictionary;       // dictionary file; default a small K-SVD dictionary
  std::string method_options;   // --method-options: JSON or file, keyed by method
  std::string save_dictionary;  // write the bench's K-SVD dictionary here
  std::string scene;            // scene spec file; default random_scene(seed) at height x width
  int64_t dict_atoms = 1000;
  uint64_t seed = 7;
  int64_t conv_batch = 256;  // patches per Conv4d timing
  int reps = 3;              // repetitions of the kernel timings (the best is kept)
  bool skip_kernels = false;
  std::string device = "cpu";
  recon::CnnMode cnn_mode = recon::CnnMode::kPatches;
  // Untrained nets without models: registered architectures (nn/architecture.h).
  std::vector<std::string> architectures = {nn::kPaperArchitecture};
  int64_t tile = 0;  // tile of cnn_mode full and of lfnet models (0: 128 and automatic)
  nn::Precision precision = nn::Precision::kFloat32;  // of the CNN branch's convolutions
  // Several precisions: every network case runs in each, one after another (empty: precision).
  std::vector<nn::Precision> precisions;
  bool self_ensemble = false;        // lfnet models: average over the Phi's mirror images
  int64_t self_ensemble_passes = 0;  // at most this many of them (0: all)
};

// The precisions `bench --ladder` times each rung in when no --precision is given: float32, and
// bfloat16 too on a CPU with native bfloat16 (nn::cpu_has_native_bfloat16) or a GPU.
std::vector<nn::Precision> ladder_precisions(const std::string& device);

// FLOP/s of a 2048^3 single-precision matrix product, the best of `reps` after a warm-up.
double bench_gemm_flops(int reps, const torch::Device& device);

// Conv4d layers of the default CNN branch and the whole branch, forward, in inference mode:
// one record per layer (seconds, GFLOP/s, share of `gemm`).
nlohmann::json bench_conv_kernels(const BenchOptions& options, double gemm);

// The light field the cases reconstruct (grey): --scene's, else a random scene. For a
// time-coded camera of `frames` sub-frames, that many frames of it stacked along the rows, the
// random scene's layers moving up to 2 px per sub-frame, --scene's as it declares.
LightField bench_light_field(const BenchOptions& options, int64_t frames = 1);

// The dictionary of the dict cases: options.dictionary, or a small K-SVD dictionary trained on
// another random scene (OMP's cost depends on its size, not on its training).
dict::Dictionary bench_dictionary(const BenchOptions& options, int64_t patch);

// One case in this process: reconstructs the bench light field with `method` at `stride`; the
// record has seconds, patches/s, peak memory, CPU use, GFLOP/s and its share of `gemm`, PSNR.
// Network methods use the first of `options.models`, else an untrained net of the first of
// `options.architectures`; the record names it ("model", "architecture").
nlohmann::json bench_case(const BenchOptions& options, const std::string& method, int64_t stride,
                          double gemm);

// The whole run: machine, GEMM, Conv4d kernels, then every stride and method through
// `run_case` (in this process, or a child process of the caller's for peak memory of its own);
// network methods once per model (or architecture), each case given options narrowed to that
// one. Nets of the lfnet architecture reconstruct whole images, so they run at the first
// stride only.
using BenchCaseRunner = std::function<nlohmann::json(
    const BenchOptions& narrowed, const std::string& method, int64_t stride, double gemm)>;
nlohmann::json bench_report(const BenchOptions& options, const BenchCaseRunner& run_case,
                            const std::function<void(const std::string&)>& print);

// One case in a child process of this program (`lfnet bench --case METHOD:STRIDE` with the
// options as flags), so that its peak resident memory is its own and not the high-water mark
// of the cases before it. The child prints kBenchCaseTag and its record's JSON on one line; a
// child that fails gives a record with "error".
inline constexpr const char* kBenchCaseTag = "LFNET_BENCH_CASE ";
nlohmann::json bench_case_in_child(const BenchOptions& options, const std::string& method,
                                   int64_t stride, double gemm);

// The report's cases as a table: a header line, then one line per case (method and
// architecture, stride, patches, seconds, patches/s, peak MB, GFLOP/s, share of GEMM, CPU use,
// PSNR), or its error.
std::string bench_table(const nlohmann::json& report);

}  // namespace lfnet::pipeline

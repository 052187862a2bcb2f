// Evaluating a method on a light field with known truth: simulate the sensor, reconstruct,
// score (docs/reconstruction.md).
#pragma once

#include <torch/torch.h>
#include <nlohmann/json.hpp>

#include <memory>
#include <optional>
#include <string>

#include "lfnet/eval/evaluate.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/sources.h"

namespace lfnet::pipeline {

// What a method needs besides the measurements.
struct MethodContext {
  const optics::Phi* phi = nullptr;
  nn::LightFieldNet net{nullptr};               // for net, ae, cnn
  std::shared_ptr<nn::ScriptedNetwork> script;  // or an exported net (used when set)
  std::string dictionary;                       // for dict: a dictionary file
  ModelCache* cache =
      nullptr;  // where to read it (and keep it) for many calls; none: read it each call
  std::string dict_method;   // for dict: omp or admm ("": dict_options', else the dictionary's)
  std::string dict_options;  // for dict: SparseCodingOptions JSON or file (pipeline/models.h)
};

// The evaluation options of the command line: simulation mode, Gaussian noise sigma (0: none),
// noise seed, patch stride, solver batch, window stitching, and the model's patch size when
// there is a model (else the default 9 x 9).
eval::EvalOptions make_eval_options(const std::string& mode, double noise, uint64_t seed,
                                    int64_t stride, int64_t batch, bool window,
                                    const std::optional<nn::PatchShape>& patch);

// Evaluates `method` on one grey light field; the record names the light field and method.
// `show_progress` draws a progress bar over the patches.
nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, eval::EvalOptions options,
                               torch::Tensor* estimate = nullptr, bool show_progress = true);

}  // namespace lfnet::pipeline

#include "lfnet/pipeline/evaluate.h"

#include <spdlog/spdlog.h>

#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/progress.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

eval::EvalOptions make_eval_options(const std::string& mode, double noise, uint64_t seed,
                                    int64_t stride, int64_t batch, bool window,
                                    const std::optional<nn::PatchShape>& patch) {
  eval::EvalOptions o;
  o.mode = optics::parse_simulation_mode(mode);
  if (noise > 0) o.effects.gaussian = optics::SensorOptions::Gaussian{noise};
  o.seed = seed;
  o.reconstruct.stride = stride;
  o.reconstruct.batch = batch;
  o.reconstruct.window = window;
  if (patch) {
    o.reconstruct.patch_h = patch->height;
    o.reconstruct.patch_w = patch->width;
  }
  return o;
}

nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, eval::EvalOptions options,
                               torch::Tensor* estimate, bool show_progress) {
  LFNET_CHECK(context.phi != nullptr, "evaluation without a Phi");
  const auto& phi = *context.phi;
  eval::EvalResult result;
  std::shared_ptr<recon::SolverReport> report;  // iterative methods: non-convergence
  const std::string label =
      method + " " + truth.name + " stride " + std::to_string(options.reconstruct.stride);
  const auto needs = recon::find_method(method).needs();
  if (needs == recon::MethodNeeds::kTruth) {
    result = eval::evaluate_no_parallax(truth.lf, phi, options);
  } else {
    recon::MethodResources resources;
    resources.phi = &phi;
    resources.patch_h = options.reconstruct.patch_h;
    resources.patch_w = options.reconstruct.patch_w;
    resources.net = context.net;
    resources.script = context.script.get();
    ModelCache local;
    if (needs == recon::MethodNeeds::kDictionary && !context.dictionary.empty()) {
      resources.dictionary =
          &(context.cache ? *context.cache : local).dictionary(context.dictionary);
      resources.coding =
          dict_coding(*resources.dictionary, context.dict_options, context.dict_method);
      report = std::make_shared<recon::SolverReport>();
      resources.report = report;
    }
    const recon::PatchSolver solver = recon::make_solver(method, resources);
    std::unique_ptr<ProgressBar> patches_bar;
    if (show_progress) {
      patches_bar = std::make_unique<ProgressBar>(
          label,
          PatchGrid(truth.lf.height(), truth.lf.width(), options.reconstruct.patch_h,
                    options.reconstruct.patch_w, options.reconstruct.stride)
              .size(),
          "patches");
    }
    int64_t shown = 0;
    result = eval::evaluate(truth.lf, phi, method, solver, options, [&](int64_t done, int64_t) {
      if (patches_bar) patches_bar->advance(done - shown);
      shown = done;
    });
  }
  result.record["light_field"] = truth.name;
  if (report) {
    result.record["unconverged_patches"] = report->unconverged.load();
    if (report->unconverged > 0) {
      spdlog::warn("{}: {} of {} patches did not converge (finite, best estimate kept)", label,
                   report->unconverged.load(), report->patches.load());
    }
  }
  if (estimate) *estimate = result.estimate;
  return result.record;
}

}  // namespace lfnet::pipeline

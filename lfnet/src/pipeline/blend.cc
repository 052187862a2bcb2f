#include "lfnet/pipeline/blend.h"

#include <torch/torch.h>

#include <cmath>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/core/output.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/train/checkpoint.h"

namespace lfnet::pipeline {

namespace {

// An exported file or a noise switch is refused by name; anything else but a checkpoint is
// refused by load_checkpoint with what is wrong with it.
void check_checkpoint_file(const std::string& path, const std::string& option) {
  const auto kind = model_file_kind(path);
  LFNET_CHECK_AS(ConfigError, kind != ModelFileKind::kExported, option, " ", path,
                 " is an exported file; blend takes checkpoints");
  LFNET_CHECK_AS(ConfigError, kind != ModelFileKind::kNoiseSwitch, option, " ", path,
                 " is a noise switch of two checkpoints: blend each of them");
}

}  // namespace

BlendResult blend_models(const BlendRequest& a) {
  LFNET_CHECK_AS(ConfigError, std::isfinite(a.alpha) && a.alpha >= 0 && a.alpha <= 1,
                 "--alpha must lie in [0, 1] (0: the base's weights, 1: the model's), got ",
                 a.alpha);
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = {a.model, a.base};
  check_output_file(a.out, policy);
  OutputLock lock(a.out);
  check_checkpoint_file(a.model, "--model");
  check_checkpoint_file(a.base, "--base");
  auto model = train::load_checkpoint(a.model);
  const auto base = train::load_checkpoint(a.base);
  const auto architecture = [](const train::Checkpoint& c) {
    return c.network.value("architecture", std::string());
  };
  LFNET_CHECK_AS(CheckpointError, architecture(model) == architecture(base), "--model ", a.model,
                 " (", architecture(model), ") and --base ", a.base, " (", architecture(base),
                 ") are networks of different architectures");
  // The trainable parameters, as the model's own network names them: its buffers are its camera.
  const auto net = train::build_net(model, a.model);
  std::set<std::string> parameters;
  for (const auto& p : net->named_parameters()) parameters.insert(p.key());
  BlendResult result;
  std::string first_kept;
  for (auto& [name, tensor] : model.model) {
    if (parameters.count(name) == 0) continue;
    const auto it = base.model.find(name);
    if (it == base.model.end() || it->second.sizes() != tensor.sizes() ||
        !it->second.is_floating_point()) {
      if (result.kept++ == 0) first_kept = name;
      continue;
    }
    tensor = ((1 - a.alpha) * it->second.to(torch::kFloat64) + a.alpha * tensor.to(torch::kFloat64))
                 .to(tensor.scalar_type())
                 .contiguous();
    ++result.blended;
  }
  LFNET_CHECK_AS(CheckpointError, result.blended > 0, "--model ", a.model, " and --base ", a.base,
                 " share no parameter of the same name and shape: nothing to blend");
  // A model finetuned from its base shares most of its layers (a colour net all but its input
  // and output); two networks of other widths or depths share next to none.
  LFNET_CHECK_AS(CheckpointError, result.blended >= result.kept, "--model ", a.model,
                 " and --base ", a.base, " share ", result.blended, " of ",
                 result.blended + result.kept, " parameters (", first_kept,
                 " differs): they are not one network finetuned from the other; nothing written");
  model.optimizer.clear();
  model.training.origin["blend"] = {
      {"model", a.model}, {"base", a.base}, {"alpha", a.alpha}, {"blended", result.blended}};
  if (!a.command_line.empty()) model.command_line = a.command_line;
  train::save_checkpoint(model, a.out);
  return result;
}

}  // namespace lfnet::pipeline

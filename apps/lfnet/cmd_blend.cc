// lfnet blend: a finetuned checkpoint's weights blended with those of the checkpoint it was
// finetuned from (weight-space ensembling; docs/training.md, pipeline/blend.h).
#include <cstdio>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/blend.h"

namespace lfnet::app {

void add_blend_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "blend", "Blend a finetuned model's weights with those of the model it was finetuned from");
  auto a = std::make_shared<pipeline::BlendRequest>();
  input_path(cmd->add_option(
                 "--model", a->model,
                 "the finetuned model (checkpoint): its camera and layers of its own are kept"))
      ->required()
      ->transform(zoo_model_file);
  input_path(cmd->add_option("--base", a->base,
                             "the model it was finetuned from (checkpoint or zoo name)"))
      ->required()
      ->transform(zoo_model_file);
  cmd->add_option(
      "--alpha", a->alpha,
      "each shared weight becomes (1 - alpha) base + alpha model: 0 to 1 (default 0.5)");
  output_file(cmd->add_option("--out", a->out, "checkpoint to write"))->required();
  add_force_flag(cmd, a->force);
  cmd->callback([a] {
    a->command_line = "lfnet blend --model " + a->model + " --base " + a->base + " --alpha " +
                      CLI::detail::to_string(a->alpha) + " --out " + a->out;
    const auto r = pipeline::blend_models(*a);
    std::printf("blended %lld parameters of %s with %s at alpha %g, kept %lld of its own: %s\n",
                static_cast<long long>(r.blended), a->model.c_str(), a->base.c_str(), a->alpha,
                static_cast<long long>(r.kept), a->out.c_str());
  });
}

}  // namespace lfnet::app

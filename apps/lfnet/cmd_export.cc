// lfnet export: a checkpoint as a TorchScript file that LibTorch and Python run without lfnet
// (docs/export.md, pipeline/export.h).
#include <cstdio>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/export.h"

namespace lfnet::app {

void add_export_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "export", "Write a checkpoint's network as a TorchScript file for LibTorch and Python");
  auto a = std::make_shared<pipeline::ExportRequest>();
  input_path(
      cmd->add_option("--model", a->model, "trained model (checkpoint, or a zoo model's name)"))
      ->required()
      ->transform(zoo_model_file);
  output_file(cmd->add_option("--out", a->out, "TorchScript file to write (e.g. model.pt)"))
      ->required();
  // The comparison holds every patch's measurements and both outputs in memory (about 16 KB a
  // patch): bounded so that a typo cannot exhaust the memory after the file is written.
  cmd->add_option("--check", a->check,
                  "patches on which to compare the exported net with the checkpoint, 0 to 65536 "
                  "(0: none; the lfnet architecture is compared on one sensor image)")
      ->check(whole_number_in(0, 65536, "patches"));
  add_force_flag(cmd, a->force);
  cmd->callback([a] {
    const auto r = pipeline::export_model(*a);
    std::printf("exported %s (%s, %s, %lld phases) to %s: %.2f MB", a->model.c_str(), r.phi.c_str(),
                r.branches.c_str(), static_cast<long long>(r.phases), a->out.c_str(), r.megabytes);
    if (!r.compared.empty()) {
      std::printf("; max |exported - checkpoint| on %s: %.3g", r.compared.c_str(),
                  r.max_difference);
    }
    std::printf("\n");
  });
}

}  // namespace lfnet::app

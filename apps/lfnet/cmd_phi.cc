// lfnet phi: a camera's measurement model as a file. `phi export` writes any local Phi as a
// calibrated-Phi folder (docs/acquisition.md, "Calibrated Phi"), the format in which a measured
// camera response is given to --phi.
#include <spdlog/spdlog.h>

#include <cstdio>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/export.h"

namespace lfnet::app {

namespace {
void run_phi_export(const pipeline::PhiExportRequest& a) {
  const auto r = pipeline::export_phi(a);
  std::printf("wrote %s (%lld measurements, %lldx%lld views, period %lld) to %s%s\n",
              r.label.c_str(), static_cast<long long>(r.measurements),
              static_cast<long long>(r.rows), static_cast<long long>(r.cols),
              static_cast<long long>(r.period), a.out.c_str(),
              r.printable ? ", with its printable pattern (mask_<n>.png)" : "");
  if (r.code_file) {
    std::printf("the learned code's physical parameters are in %s/code.json\n", a.out.c_str());
  } else if (!r.missing_code.empty()) {
    spdlog::warn(
        "{} holds a {} code but not its physical parameters (it was trained on the code "
        "fixed): no code.json; export the model that learned it for those",
        a.phi, r.missing_code);
  }
}
}  // namespace

void add_phi_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand("phi", "Measurement models as files (calibrated Phi)");
  cmd->require_subcommand(1);
  auto* ex = cmd->add_subcommand(
      "export", "Write a Phi as a calibrated-Phi folder (phi.json and one image per measurement)");
  auto a = std::make_shared<pipeline::PhiExportRequest>();
  add_phi_option(ex, a->phi)->required();
  output_folder(ex->add_option("--out", a->out, "folder to write"))->required();
  ex->add_option("--grid", a->grid, "views U x V coded by a NAME[:N] Phi")->capture_default_str();
  add_force_flag(ex, a->force);
  ex->add_flag("--printable", a->printable,
               "also write each measurement's code as an 8-bit image to print (mask_<n>.png; "
               "always for a learned mask or aperture)");
  ex->callback([a] { run_phi_export(*a); });
}

}  // namespace lfnet::app

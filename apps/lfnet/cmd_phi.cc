// lfnet phi: a camera's measurement model as a file. `phi export` writes any local Phi as a
// calibrated-Phi folder (docs/acquisition.md, "Calibrated Phi"), the format in which a measured
// camera response is given to --phi.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>

#include "command.h"
#include "flags.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/io/phi_io.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/models.h"

namespace lfnet::app {

namespace {
struct PhiExportArgs {
  std::string phi, out, grid = "5x5";
  bool force = false, printable = false;
};

// "UxV" -> (U, V).
std::pair<int64_t, int64_t> parse_grid(const std::string& text) {
  const auto x = text.find('x');
  int64_t u = 0, v = 0;
  const bool ok = x != std::string::npos && CLI::detail::lexical_cast(text.substr(0, x), u) &&
                  CLI::detail::lexical_cast(text.substr(x + 1), v) && u >= 1 && v >= 1 &&
                  u <= optics::kMaxViews && v <= optics::kMaxViews;
  LFNET_CHECK_AS(ConfigError, ok, "--grid must be UxV with U and V in 1..", optics::kMaxViews,
                 ", got ", text);
  return {u, v};
}

void run_phi_export(const PhiExportArgs& a) {
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = pipeline::model_input_files(a.phi);  // a switch's members too
  check_output_folder(a.out, policy);
  optics::PhiSpec spec;
  if (pipeline::phi_argument_is_file(a.phi)) {
    spec = pipeline::phi_from_argument(a.phi);
  } else {
    spec = optics::PhiSpec::parse(a.phi);
    std::tie(spec.rows, spec.cols) = parse_grid(a.grid);
  }
  const auto phi = optics::make_phi(spec);
  const bool mask = a.printable || io::is_learned_mask(*phi);
  // A model that learned its code: the code's physical parameters too.
  const auto code =
      pipeline::phi_argument_is_file(a.phi) ? pipeline::learned_code_of(a.phi) : nlohmann::json();
  write_folder(a.out, policy, [&](const std::string& dir) {
    io::write_calibrated_phi(*phi, dir);
    if (mask) io::write_printable_mask(*phi, dir);
    if (!code.is_null()) write_json_file((std::filesystem::path(dir) / "code.json").string(), code);
    // Read it back: the folder must give the same camera, weight for weight.
    const auto back = optics::make_phi(io::read_calibrated_phi(dir));
    const int64_t t = phi->period();
    const double diff = (back->pixel_weights(0, 0, t, t, torch::kFloat64) -
                         phi->pixel_weights(0, 0, t, t, torch::kFloat64))
                            .abs()
                            .max()
                            .item<double>();
    LFNET_CHECK_AS(NumericalError, diff == 0, "the written Phi differs from ", spec.label(), " by ",
                   diff, " when read back: please report this");
  });
  std::printf("wrote %s (%lld measurements, %lldx%lld views, period %lld) to %s%s\n",
              spec.label().c_str(), static_cast<long long>(phi->measurements()),
              static_cast<long long>(phi->rows()), static_cast<long long>(phi->cols()),
              static_cast<long long>(phi->period()), a.out.c_str(),
              mask ? ", with its printable pattern (mask_<n>.png)" : "");
  if (!code.is_null()) {
    std::printf("the learned code's physical parameters are in %s/code.json\n", a.out.c_str());
  } else if (spec.name == "calibrated" &&
             spec.params.value("source", "").rfind("learned", 0) == 0) {
    // A learned code whose parameters this file does not hold: its weights alone are written.
    spdlog::warn(
        "{} holds a {} code but not its physical parameters (it was trained on the code "
        "fixed): no code.json; export the model that learned it for those",
        a.phi, spec.params.value("source", ""));
  }
}
}  // namespace

void add_phi_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand("phi", "Measurement models as files (calibrated Phi)");
  cmd->require_subcommand(1);
  auto* ex = cmd->add_subcommand(
      "export", "Write a Phi as a calibrated-Phi folder (phi.json and one image per measurement)");
  auto a = std::make_shared<PhiExportArgs>();
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

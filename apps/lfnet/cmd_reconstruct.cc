// lfnet reconstruct: a light field from the folder `lfnet simulate` writes, or from a camera's
// own sensor images and a Phi spec.
#include <spdlog/spdlog.h>

#include <optional>

#include "command.h"
#include "flags.h"
#include "lfnet/core/json.h"
#include "lfnet/core/process_time.h"
#include "lfnet/core/progress.h"
#include "lfnet/pipeline/budget.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/experiment.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/pipeline/stages.h"

namespace lfnet::app {

namespace {
struct ReconstructArgs {
  pipeline::ReconstructRequest request;
  std::string out;
  bool force = false;
  bool method_given = false;
  double budget = 0;                             // --budget SECONDS; 0: none
  std::optional<pipeline::Precision> precision;  // --precision as given; nullopt: auto
};

// Neither --model nor --method: the zoo's default model for the sensor's camera and colour
// (pipeline/zoo.h), else pinv; said either way.
void choose_default_model(pipeline::ReconstructRequest& q) {
  const auto d = pipeline::zoo_default_model(q.sensor, q.phi, q.cfa);
  if (!d.path.empty()) {
    q.model = d.path;
    spdlog::info("no --model: the zoo's default for {} ({}) is {} ({})", d.camera, d.colour, d.name,
                 d.path);
    return;
  }
  q.method = "pinv";
  if (!d.camera.empty()) {
    spdlog::info("no --model, and the zoo has no default for {} ({}): pinv", d.camera, d.colour);
  }
}

void run_reconstruct(ReconstructArgs a) {
  std::optional<pipeline::BudgetChoice> budget;
  if (a.budget > 0) {
    auto& q = a.request;
    pipeline::check_budget_request(
        {!q.model.empty(), a.method_given, q.self_ensemble, q.self_calibrate});
    budget = pipeline::budget_for_sensor(a.budget, q.sensor, q.phi, q.cfa, q.device, a.precision);
    q.model = budget->path;
    q.precision = budget->setting.precision;
  }
  if (a.request.model.empty() && !a.method_given) choose_default_model(a.request);
  OutputFolderPolicy policy;
  policy.force = a.force;
  // Every file it reads: a noise switch's members and the --method-options file too.
  policy.inputs = pipeline::model_input_files(a.request.model);
  for (const auto& path : split_paths(a.request.sensor)) policy.inputs.push_back(path);
  policy.inputs.insert(policy.inputs.end(),
                       {json_argument_file(a.request.method_options), a.request.dictionary,
                        a.request.phi, a.request.flat_field});
  check_output_folder(a.out, policy);
  // A whole-image model reconstructs whole sensor images, counted in pixels, not patches (the
  // model, read here to know, is read once: the cache passes it on).
  pipeline::ModelCache cache;
  const bool whole_image = !a.request.model.empty() && pipeline::needs_network(a.request.method) &&
                           !cache.model(a.request.model).network.patch_grid();
  // Its total is known once the work starts.
  ProgressBar bar("reconstruct", 0, whole_image ? "pixels" : "patches");
  int64_t shown = 0;
  auto request = a.request;
  request.coded = true;  // a grey light field in 16-bit codes, what its files hold
  auto r = pipeline::reconstruct_acquisition(
      request,
      [&](int64_t done, int64_t total) {
        bar.set_total(total);
        bar.advance(done - shown);
        shown = done;
      },
      &cache);
  bar.finish();
  if (budget) pipeline::record_budget(*budget, r.record);
  pipeline::write_reconstruction(r, a.out, policy);
  spdlog::info("reconstructed {} with {} in {:.2f} s ({:.2f} s end to end) into {}",
               r.lf.shape_string(), a.request.method, r.record["seconds"].get<double>(),
               process_seconds(), a.out);
}
}  // namespace

void add_reconstruct_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "reconstruct",
      "Reconstruct a light field from coded measurements: the folder lfnet simulate writes, or "
      "a camera's own sensor image with --phi");
  auto a = std::make_shared<ReconstructArgs>();
  auto& q = a->request;
  input_path(
      cmd->add_option("--sensor", q.sensor,
                      "acquisition folder (sensor.json with sensor.tif or measurements.f32), or a "
                      "sensor image of N channels (one file per colour channel, comma-separated)"))
      ->required();
  output_folder(
      cmd->add_option("--out", a->out,
                      "output light-field folder (views, grid.png, EPIs, viewer index.html)"))
      ->required();
  add_reconstruction_flags(
      cmd, {&q.model, nullptr, &q.phi, &q.device, &q.precision, &q.tile, &q.options.stride, nullptr,
            &q.self_ensemble, &q.self_ensemble_passes, &q.method_options});
  add_self_calibrate_flag(cmd, q.self_calibrate);
  auto* method = cmd->add_option(
      "--method", q.method,
      pipeline::method_list(/*reconstruction=*/true) +
          " (default net; without --model, net with the zoo's default model for the sensor's "
          "camera and colour, pinv where the zoo has none)");
  add_dictionary_option(cmd, q.dictionary);
  add_batch_option(cmd, q.options.batch);
  add_window_flag(cmd, q.options.window);
  add_post_filter_flag(cmd, q.post_filter);
  add_cfa_option(cmd, q.cfa);
  add_demosaic_option(cmd, q.demosaic);
  add_flat_field_option(cmd, q.flat_field);
  add_match_mean_flag(cmd, q.match_mean);
  add_force_flag(cmd, a->force);
  add_cnn_mode_option(cmd, q.cnn_mode);
  cmd->add_option("--noise-sigma", q.noise_sigma,
                  "the sensor's noise sigma (relative to white) for noise-aware models (default: "
                  "what the acquisition's sensor.json records, else estimated from the sensor "
                  "image, docs/acquisition.md)")
      ->check(kNoiseSigma);
  add_budget_option(cmd, a->budget);
  cmd->callback([a, method, cmd] {
    a->method_given = method->count() > 0;
    a->precision = given_precision(cmd, a->request.precision);
    run_reconstruct(*a);
  });
}

}  // namespace lfnet::app

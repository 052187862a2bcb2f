// lfnet evaluate: simulate measurements of a light field with known truth, reconstruct, score
// (pipeline::evaluate_request); prints the record, writes it and the reconstruction.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "command.h"
#include "flags.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/process_time.h"
#include "lfnet/core/runtime.h"
#include "lfnet/pipeline/budget.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/models.h"

namespace lfnet::app {

namespace {
struct EvaluateArgs {
  pipeline::EvaluateRequest request;
  std::string json, out;
  bool force = false;
  double budget = 0;  // --budget SECONDS; 0: none
  bool method_given = false;
  std::optional<pipeline::Precision> precision;  // --precision as given; nullopt: auto
};

void run_evaluate(EvaluateArgs& a) {
  auto& q = a.request;
  std::optional<pipeline::BudgetChoice> budget;
  if (a.budget > 0) {
    pipeline::check_budget_request({!q.model.empty(), a.method_given, q.self_ensemble,
                                    q.self_calibrate, q.mode != optics::SimulationMode::kSensor});
    budget = pipeline::budget_for_light_field(a.budget,
                                              pipeline::light_field_pixels(q.lf, q.layout, q.scene),
                                              q.phi, q.cfa, q.device, a.precision);
    q.model = budget->path;
    q.precision = budget->setting.precision;
  }
  OutputFolderPolicy policy;
  policy.force = a.force;
  // Every file it reads: a noise switch's members and the files of its JSON options too.
  policy.inputs = pipeline::model_input_files(q.model);
  policy.inputs.insert(
      policy.inputs.end(),
      {q.lf, q.scene, q.dictionary, q.effects, q.flat_field, json_argument_file(q.method_options),
       json_argument_file(q.camera_error), json_argument_file(q.cfa)});
  if (!a.out.empty()) check_output_folder(a.out, policy);
  // The lock makes --json's missing folders (gone again if no record comes) and keeps other
  // writers off.
  std::optional<OutputLock> json_lock;
  const bool json_stdout = a.json == "-";  // the record on standard output, as bench writes it
  if (!a.json.empty() && !json_stdout) {
    OutputFolderPolicy json_policy = policy;
    json_policy.option = "--json";
    json_policy.inputs.push_back(a.out);
    check_output_file(a.json, json_policy);
    json_lock.emplace(a.json, "--json");
  }
  q.keep_estimate = !a.out.empty();
  const auto r = pipeline::evaluate_request(q);
  auto record = r.record;
  if (budget) pipeline::record_budget(*budget, record);
  // The outputs first, the records last: a record's end_to_end_seconds is the command's time
  // from its start up to that record, every other output written.
  if (!a.out.empty()) {
    write_folder(a.out, policy,
                 [&](const std::string& dir) { pipeline::write_evaluation(r, record, dir); });
  }
  record["end_to_end_seconds"] = process_seconds();
  if (json_stdout) {
    std::printf("%s\n", record.dump(2).c_str());
    return;
  }
  if (!a.json.empty()) write_json_file(a.json, record);
  const double psnr = record["psnr_db"].is_null() ? INFINITY : record["psnr_db"].get<double>();
  // Shot and read noise are named by the Gaussian sigma of the same variance.
  const double noise = record.value("equivalent_sigma", q.noise);
  // A whole-image model has no stride.
  const std::string stride = record.value("whole_image", false)
                                 ? std::string("whole image")
                                 : "stride " + std::to_string(q.stride);
  std::printf(
      "%s on %s (%s, %s, %s, noise %.3g): PSNR %.2f dB, SSIM %.4f, %.2f s (%.2f s end to "
      "end)\n",
      record["method"].get<std::string>().c_str(), r.light_field.c_str(), r.phi.c_str(),
      to_string(q.mode).c_str(), stride.c_str(), noise, psnr, record["ssim"].get<double>(),
      record["seconds"].get<double>(), record["end_to_end_seconds"].get<double>());
}
}  // namespace

void add_evaluate_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "evaluate", "Simulate a light field's measurements, reconstruct them and report PSNR/SSIM");
  auto a = std::make_shared<EvaluateArgs>();
  auto& q = a->request;
  add_reconstruction_flags(
      cmd, {&q.model, nullptr, &q.phi, &q.device, &q.precision, &q.tile, &q.stride, nullptr,
            &q.self_ensemble, &q.self_ensemble_passes, &q.method_options});
  add_self_calibrate_flag(cmd, q.self_calibrate);
  add_lf_option(cmd, q.lf);
  add_scene_option(cmd, q.scene);
  add_views_option(cmd, q.views);
  add_orient_option(cmd, q.orient);
  add_layout_option(cmd, q.layout);
  add_noise_option(cmd, q.noise);
  add_effects_option(cmd, q.effects);
  cmd->add_flag("--estimate-noise", q.estimate_noise,
                "noise-aware models are told the noise estimated from the sensor image, not the "
                "simulation's: a camera whose noise is unknown (docs/acquisition.md)");
  add_cfa_option(cmd, q.cfa);
  add_demosaic_option(cmd, q.demosaic);
  auto* camera_error = add_camera_error_option(cmd, q.camera_error);
  cmd->add_flag("--as-still", q.as_still,
                "the still-scene baseline of a time-coded camera (--phi NAME:N@T): the method (or "
                "--model, of the camera's still equivalent) reconstructs as if nothing moved, its "
                "estimate held in every frame (docs/video.md)");
  cmd->add_flag("--tell-camera-error", q.tell_camera_error,
                "lfnet models: the net is told the camera's Phi with that error (its weights over "
                "one period; no vignetting), as if it had been measured (docs/acquisition.md, "
                "\"Self-calibration\")")
      ->needs(camera_error);
  add_flat_field_option(cmd, q.flat_field);
  add_mode_option(cmd, q.mode);
  auto* method = cmd->add_option(
      "--method", q.method, pipeline::method_list() + " (default net with --model, pinv without)");
  add_budget_option(cmd, a->budget);
  add_dictionary_option(cmd, q.dictionary);
  add_json_option(cmd, a->json);
  output_folder(cmd->add_option(
      "--out", a->out,
      "write the reconstruction as a light-field folder with a viewer (index.html)"));
  add_force_flag(cmd, a->force);
  add_seed_option(cmd, q.seed);
  cmd->add_option("--choice", q.choice,
                  "what this evaluation decides (an alpha, an epoch, which model ships), kept in "
                  "the record; made on a test-set light field, lfnet report marks it "
                  "(docs/protocol.md)");
  add_batch_option(cmd, q.batch);
  add_window_flag(cmd, q.window);
  cmd->callback([a, method, cmd] {
    a->method_given = method->count() > 0;
    a->precision = given_precision(cmd, a->request.precision);
    run_evaluate(*a);
  });
}

}  // namespace lfnet::app

// lfnet evaluate: simulate measurements of a light field with known truth, reconstruct, score
// (pipeline::evaluate_request); prints the record, writes it and the reconstruction.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "command.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/process_time.h"
#include "lfnet/core/runtime.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/viewer.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/recon/method_registry.h"

namespace lfnet::app {

namespace {
struct EvaluateArgs {
  pipeline::EvaluateRequest request;
  std::string json, out;
  bool force = false;
};

void run_evaluate(EvaluateArgs& a) {
  auto& q = a.request;
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
  // The outputs first, the records last: a record's end_to_end_seconds is the command's time
  // from its start up to that record, every other output written.
  if (!a.out.empty()) {
    const LightFieldViews est(r.estimate);  // 16-bit codes or float32
    write_folder(a.out, policy, [&](const std::string& dir) {
      // What each step freed is returned before the next (the peak is one step's, not all).
      release_free_memory();
      io::write_light_field(est, dir);
      release_free_memory();
      io::write_previews(est, dir);
      release_free_memory();
      io::ViewerPage page;
      page.title = record["method"].get<std::string>() + " on " + r.light_field;
      page.truth = LightFieldViews(r.truth);
      page.record = record;
      io::write_viewer(est, (std::filesystem::path(dir) / "index.html").string(), page);
      record["end_to_end_seconds"] = process_seconds();
      write_json_file((std::filesystem::path(dir) / "evaluation.json").string(), record);
    });
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
      optics::to_string(q.mode).c_str(), stride.c_str(), noise, psnr, record["ssim"].get<double>(),
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
  input_path(cmd->add_option("--lf", q.lf, "light field folder with the truth"));
  input_path(cmd->add_option("--scene", q.scene, "or a procedural scene spec"));
  cmd->add_option("--views", q.views, "angular window R0:R1,C0:C1 (1-based; default central)");
  cmd->add_option(
      "--orient", q.orient,
      "reorient the folder's angular axes: flip-u, flip-v, transpose (comma-separated)");
  cmd->add_option("--layout", q.layout,
                  "file-naming pattern of --lf: view_{row}_{col}.png, or "
                  "img{index}.png:cols=9[:col-major] (docs/conventions.md)");
  cmd->add_option("--noise", q.noise, "Gaussian noise sigma, relative to a white scene's mean")
      ->check(kNoiseSigma);
  input_path(cmd->add_option(
                 "--effects", q.effects,
                 "sensor effects JSON file: shot, read noise and the rest (docs/acquisition.md); "
                 "--noise sets its Gaussian sigma"))
      ->check(CLI::ExistingFile);
  cmd->add_flag("--estimate-noise", q.estimate_noise,
                "noise-aware models are told the noise estimated from the sensor image, not the "
                "simulation's: a camera whose noise is unknown (docs/acquisition.md)");
  input_path(cmd->add_option(
                 "--cfa", q.cfa,
                 "a single colour sensor behind a colour filter array: RGGB, BGGR, GRBG, GBRG or "
                 "JSON, inline or a file; scores colour and luma (docs/acquisition.md)"))
      ->check(kNotEmpty);
  add_demosaic_option(cmd, q.demosaic);
  auto* camera_error = input_path(cmd->add_option(
      "--camera-error", q.camera_error,
      "simulate a camera whose Phi differs from the model's: JSON, inline or a file, "
      "e.g. '{\"depth\": 0.1}' (depth, angular_shift_u/v, shift_y/x, period, "
      "vignetting; docs/acquisition.md)"));
  cmd->add_flag("--tell-camera-error", q.tell_camera_error,
                "lfnet models: the net is told the camera's Phi with that error (its weights over "
                "one period; no vignetting), as if it had been measured (docs/acquisition.md, "
                "\"Self-calibration\")")
      ->needs(camera_error);
  input_path(
      cmd->add_option("--flat-field", q.flat_field,
                      "the camera's white frame (an acquisition folder, or an image of its N "
                      "channels): its gain across the sensor, such as vignetting, is divided out "
                      "(docs/acquisition.md, \"Flat field\")"));
  add_enum_option(cmd, "--mode", q.mode, "simulation mode: sensor or per_patch");
  cmd->add_option("--method", q.method,
                  recon::method_list() + " (default net with --model, pinv without)");
  input_path(cmd->add_option("--dictionary", q.dictionary, "dictionary file for --method dict"));
  output_file(
      cmd->add_option("--json", a->json,
                      "write the evaluation record to this file (a new or empty file, or --force); "
                      "- prints it on standard output instead of the summary line"));
  output_folder(cmd->add_option(
      "--out", a->out,
      "write the reconstruction as a light-field folder with a viewer (index.html)"));
  cmd->add_flag("--force", a->force, "replace an existing --out folder and --json file");
  cmd->add_option("--seed", q.seed, "noise seed")->check(kSeed);
  cmd->add_option("--choice", q.choice,
                  "what this evaluation decides (an alpha, an epoch, which model ships), kept in "
                  "the record; made on a test-set light field, lfnet report marks it "
                  "(docs/protocol.md)");
  cmd->add_option("--batch", q.batch, "patches per forward pass")->check(kCount);
  cmd->add_flag("--window", q.window, "weight patch estimates by a smooth window when stitching");
  cmd->callback([a] { run_evaluate(*a); });
}

}  // namespace lfnet::app

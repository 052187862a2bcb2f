// lfnet evaluate: simulate measurements of a light field with known truth, reconstruct, score.
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/parallax.h"
#include "lfnet/core/runtime.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/experiment.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/pipeline/stages.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::app {

namespace {
struct EvaluateArgs {
  std::string model, lf, scene, phi, views, orient, layout, mode = "sensor", method, dictionary,
                                                            dict_method, dict_options, json, out;
  double noise = 0;
  int64_t stride = 5;
  int64_t batch = 1024;
  uint64_t seed = 0;
  bool window = false;
  bool force = false;
  std::string device = "cpu";
  std::string precision = "float32";
};

void run_evaluate(const EvaluateArgs& a) {
  LFNET_CHECK_AS(ConfigError, a.lf.empty() != a.scene.empty(),
                 "give exactly one of --lf DIR and --scene SCENE.json");
  LFNET_CHECK_AS(ConfigError, a.noise >= 0, "--noise must be >= 0");
  const std::string method = a.method.empty() ? (a.model.empty() ? "pinv" : "net") : a.method;
  LFNET_CHECK_AS(ConfigError, method == "dict" || (a.dict_method.empty() && a.dict_options.empty()),
                 "--dict-method and --dict-options apply to --method dict, not '", method, "'");
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = {a.lf, a.scene, a.model, a.dictionary};
  if (!a.out.empty()) check_output_folder(a.out, policy);
  if (!a.json.empty()) check_output_apart(a.json, policy.inputs, "--json");
  pipeline::MethodContext context;
  optics::PhiSpec spec;
  std::optional<nn::PatchShape> network_patch;  // the patch size of net, ae and cnn
  if (!a.model.empty()) {
    const auto model = pipeline::load_model(a.model, recon::needs_network(method));
    spec = optics::PhiSpec::from_json(model.phi, a.model + ":$.phi");
    if (!a.phi.empty()) {
      auto given = pipeline::phi_from_argument(a.phi);
      LFNET_CHECK_AS(ConfigError, given.name == spec.name && given.n == spec.n, "--phi ", a.phi,
                     " does not match the model ", a.model, ", which was trained for ",
                     spec.label());
    }
    if (recon::needs_network(method)) {
      context.net = model.net;
      context.script = model.script;
      network_patch = model.network.patch;
      if (context.net) {
        context.net->to(parse_device(a.device));
        nn::set_cnn_precision(context.net, nn::parse_precision(a.precision));
      } else {
        LFNET_CHECK_AS(ConfigError, a.device == "cpu" && a.precision == "float32",
                       "--device and --precision apply to checkpoints; ", a.model,
                       " is an exported TorchScript file");
      }
    }
  } else {
    LFNET_CHECK_AS(ConfigError, !recon::needs_network(method), "method '", method,
                   "' needs --model");
    LFNET_CHECK_AS(ConfigError, !a.phi.empty(), "--phi NAME[:N] is needed without --model");
    spec = pipeline::phi_from_argument(a.phi);
  }
  pipeline::LightFieldSources sources;
  if (!a.lf.empty()) sources.light_fields = {a.lf};
  if (!a.scene.empty()) sources.scenes = {a.scene};
  sources.views = a.views;
  sources.orient = a.orient;
  sources.layout = a.layout;
  if (!a.layout.empty()) io::parse_layout(a.layout);  // before any work
  AngularOrientation::parse(a.orient, "--orient");    // before any work
  if (!a.views.empty()) {
    auto [ru, rv] = parse_views(a.views);
    if (a.model.empty()) {
      spec.rows = ru.size();
      spec.cols = rv.size();
    }
  }
  const auto phi = optics::make_phi(spec);
  context.phi = phi.get();
  context.dictionary = a.dictionary;
  context.dict_method = a.dict_method;
  context.dict_options = a.dict_options;
  const auto truths = pipeline::load_sources(sources, phi->rows(), phi->cols());

  const auto o = pipeline::make_eval_options(a.mode, a.noise, a.seed, a.stride, a.batch, a.window,
                                             network_patch);
  torch::Tensor estimate;
  auto record =
      pipeline::evaluate_method(truths[0], method, context, o, a.out.empty() ? nullptr : &estimate);
  if (!a.model.empty()) record["model"] = a.model;
  record["device"] = a.device;
  if (recon::needs_network(method)) record["precision"] = a.precision;
  const double psnr = record["psnr_db"].is_null() ? INFINITY : record["psnr_db"].get<double>();
  std::printf("%s on %s (%s, %s, stride %lld, noise %.3g): PSNR %.2f dB, SSIM %.4f, %.2f s\n",
              method.c_str(), truths[0].name.c_str(), spec.label().c_str(), a.mode.c_str(),
              static_cast<long long>(a.stride), a.noise, psnr, record["ssim"].get<double>(),
              record["seconds"].get<double>());
  if (!a.json.empty()) write_json_file(a.json, record);
  if (!a.out.empty()) {
    LightField est(estimate);
    write_folder(a.out, policy, [&](const std::string& dir) {
      io::write_light_field(est, dir);
      io::write_previews(est, dir);
      write_json_file((std::filesystem::path(dir) / "evaluation.json").string(), record);
    });
  }
}
}  // namespace

void add_evaluate_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "evaluate", "Simulate a light field's measurements, reconstruct them and report PSNR/SSIM");
  auto a = std::make_shared<EvaluateArgs>();
  cmd->add_option("--model", a->model,
                  "trained model for net, ae and cnn: a checkpoint or a file lfnet export wrote");
  cmd->add_option("--lf", a->lf, "light field folder with the truth");
  cmd->add_option("--scene", a->scene, "or a procedural scene spec");
  cmd->add_option("--phi", a->phi,
                  "NAME[:N], a spec (.json) or a calibrated-Phi folder: needed without --model; "
                  "must match the model");
  cmd->add_option("--views", a->views, "angular window R0:R1,C0:C1 (1-based; default central)");
  cmd->add_option(
      "--orient", a->orient,
      "reorient the folder's angular axes: flip-u, flip-v, transpose (comma-separated)");
  cmd->add_option("--layout", a->layout,
                  "file-naming pattern of --lf: view_{row}_{col}.png, or "
                  "img{index}.png:cols=9[:col-major] (docs/conventions.md)");
  cmd->add_option("--noise", a->noise, "Gaussian noise sigma, relative to a white scene's mean")
      ->check(kFiniteNonNegative);
  cmd->add_option("--stride", a->stride, "patch stride (default 5)")->check(kStride);
  cmd->add_option("--mode", a->mode, "simulation mode: sensor or per_patch")
      ->check(CLI::IsMember({"sensor", "per_patch"}));
  cmd->add_option("--method", a->method,
                  "net, ae, cnn, dict, pinv, adjoint or no-parallax (default net with --model, "
                  "pinv without)");
  cmd->add_option("--dictionary", a->dictionary, "dictionary file for --method dict");
  add_dict_coding_options(cmd, a->dict_method, a->dict_options);
  cmd->add_option("--json", a->json, "write the evaluation record to this file");
  cmd->add_option("--out", a->out, "write the reconstruction as a light-field folder");
  cmd->add_flag("--force", a->force, "replace an existing --out folder");
  cmd->add_option("--seed", a->seed, "noise seed");
  cmd->add_option("--batch", a->batch, "patches per forward pass")->check(CLI::PositiveNumber);
  cmd->add_flag("--window", a->window, "weight patch estimates by a smooth window when stitching");
  cmd->add_option("--device", a->device, "cpu or cuda[:K] for the network (default cpu)");
  cmd->add_option("--precision", a->precision, "float32 (default) or bfloat16 for the CNN branch")
      ->check(CLI::IsMember({"float32", "bfloat16"}));
  cmd->callback([a] {
    parse_device(a->device);  // a clear error before any work
    run_evaluate(*a);
  });
}

}  // namespace lfnet::app

#include "lfnet/pipeline/evaluate.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/parallax.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/text.h"
#include "lfnet/cv/opencv.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/pipeline/sets.h"
#include "lfnet/pipeline/simulate.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/self_calibration.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

eval::EvalOptions make_eval_options(optics::SimulationMode mode, double noise, uint64_t seed,
                                    int64_t stride, int64_t batch, bool window,
                                    const std::optional<nn::PatchShape>& patch) {
  eval::EvalOptions o;
  o.mode = mode;
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

PreparedMethod prepare_method(const std::string& method, const MethodContext& c, int64_t patch_h,
                              int64_t patch_w) {
  cv::register_opencv();  // OpenCV's denoiser for pinv-nlm
  LFNET_CHECK(c.phi != nullptr, "method '", method, "' without a Phi");
  const auto& m = recon::find_method(method);
  PreparedMethod p;
  auto& r = p.resources;
  r.phi = c.phi;
  r.patch_h = patch_h;
  r.patch_w = patch_w;
  r.net = c.net;
  r.noisy_net = c.noisy_net;
  r.switch_sigma = c.switch_sigma;
  r.script = c.script.get();
  r.self_ensemble = c.self_ensemble;
  r.self_ensemble_passes = c.self_ensemble_passes;
  if (c.tile > 0) r.tile = c.tile;
  r.coded = c.coded;
  if (c.self_calibrate) {
    // Measured for the ASP: a displaced binary mask told to a mask net does worse than the
    // nominal one (docs/acquisition.md, "Self-calibration").
    if (c.phi->spec().name != "asp") {
      spdlog::warn("--self-calibrate is measured for ASP cameras only; with {} it may not help",
                   c.phi->spec().label());
    }
    p.calibration = std::make_shared<optics::CalibrationError>();
    r.self_calibrate = true;
    r.calibration = p.calibration;
  }
  if (c.method_options.is_object() && c.method_options.contains(method)) {
    r.options = c.method_options[method];
  }
  p.options = m.read_options(r.options, "--method-options." + method);
  if (m.needs() == recon::MethodNeeds::kTruth) return p;  // computed from the truth
  if (m.needs() == recon::MethodNeeds::kDictionary) {
    if (c.dictionary_data) {
      r.dictionary = c.dictionary_data;
    } else if (!c.dictionary.empty()) {
      if (!c.cache) p.files = std::make_shared<ModelCache>();
      r.dictionary = &(c.cache ? *c.cache : *p.files).dictionary(c.dictionary);
    }
    p.report = std::make_shared<recon::SolverReport>();
    r.report = p.report;
  }
  if (c.self_ensemble) recon::check_self_ensemble(method, c.net, c.script.get());
  recon::check_ensemble_passes(c.self_ensemble, c.self_ensemble_passes);
  p.solver = recon::make_solver(method, r);
  p.image = recon::make_image_solver(method, r);
  LFNET_CHECK_AS(ConfigError, !c.self_calibrate || p.image, "--self-calibrate: method '", method,
                 "' is not a whole-image network (the lfnet architecture's net)");
  p.options = m.options_used(r);
  return p;
}

void check_method_options(const nlohmann::json& by_method, const std::vector<std::string>& methods,
                          const std::string& source) {
  cv::register_opencv();  // the denoisers pinv-nlm's options may name
  LFNET_CHECK_AS(ConfigError, by_method.is_object(), source,
                 ": expected a JSON object keyed by method, e.g. {\"dict\": {\"method\": "
                 "\"admm\"}}, got ",
                 by_method.dump());
  for (const auto& [name, options] : by_method.items()) {
    recon::find_method(name);  // an unknown method, with the known ones
    LFNET_CHECK_AS(ConfigError, std::find(methods.begin(), methods.end(), name) != methods.end(),
                   source, ": options for method '", name, "', which this command does not run (",
                   join(methods, ", "), ")");
    std::string path = source;
    path += ".";
    path += name;
    recon::check_method_options(name, options, path);
  }
}

nlohmann::json method_options_argument(const std::string& text,
                                       const std::vector<std::string>& methods,
                                       const std::string& source) {
  if (text.empty()) return nlohmann::json::object();
  auto options = read_json_argument(text, source);
  check_method_options(options, methods, json_argument_source(text, source));
  return options;
}

nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, const eval::EvalOptions& options,
                               torch::Tensor* estimate, bool show_progress) {
  LFNET_CHECK(context.phi != nullptr, "evaluation without a Phi");
  const auto& phi = *context.phi;
  eval::EvalResult result;
  auto prepared =
      prepare_method(method, context, options.reconstruct.patch_h, options.reconstruct.patch_w);
  // A whole-image model has no stride and no patches: its progress counts pixels.
  const bool whole_image = static_cast<bool>(prepared.image);
  const std::string label =
      method + " " + truth.name +
      (whole_image ? " (whole image)" : " stride " + std::to_string(options.reconstruct.stride));
  const auto report = prepared.report;
  if (recon::find_method(method).needs() == recon::MethodNeeds::kTruth) {
    result = eval::evaluate_no_parallax(truth.views().decode(), phi, options);
  } else {
    const recon::PatchSolver solver = prepared.solver;
    const recon::ImageSolver image = prepared.image;
    std::unique_ptr<ProgressBar> patches_bar;
    if (show_progress) {
      patches_bar = std::make_unique<ProgressBar>(
          label,
          whole_image ? 0
                      : PatchGrid(truth.views().height(), truth.views().width(),
                                  options.reconstruct.patch_h, options.reconstruct.patch_w,
                                  options.reconstruct.stride)
                            .size(),
          whole_image ? "pixels" : "patches");
    }
    int64_t shown = 0;
    result = eval::evaluate(
        truth.views(), phi, method, solver, options,
        [&](int64_t done, int64_t total) {
          if (patches_bar && whole_image) patches_bar->set_total(total);
          if (patches_bar) patches_bar->advance(done - shown);
          shown = done;
        },
        image);
  }
  result.record["light_field"] = truth.name;
  if (!prepared.options.empty()) result.record["method_options"] = prepared.options;
  if (context.self_ensemble) {
    result.record["self_ensemble"] = true;
    result.record["self_ensemble_passes"] =
        recon::ensemble_mirrors(context.net, context.script.get(), context.self_ensemble_passes)
            .size();
  }
  if (prepared.calibration) {
    record_estimated_camera_error(result.record, *prepared.calibration, label + ": ");
  }
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

void record_estimated_camera_error(nlohmann::json& record, const optics::CalibrationError& error,
                                   const std::string& what) {
  record["camera_error_estimated"] = error.to_json();
  spdlog::info(
      "{}angular shift estimated from the sensor image: {:.3f} views along U, {:.3f} "
      "along V",
      what, error.angular_shift_u, error.angular_shift_v);
}

void use_model(MethodContext& context, const ModelFile& model) {
  context.net = model.net;
  context.script = model.script;
  context.noisy_net = model.noisy;
  context.switch_sigma = model.switch_sigma;
}

void place_network(const ModelFile& model, const std::string& device, nn::Precision precision) {
  if (model.net) {
    for (auto net : {model.net, model.noisy}) {  // handles: the model's own nets
      if (net.is_empty()) continue;
      net->to(parse_device(device));
      nn::set_cnn_precision(net, precision);
    }
    return;
  }
  LFNET_CHECK_AS(ConfigError,
                 !model.scripted || (device == "cpu" && precision == nn::Precision::kFloat32),
                 "--device and --precision apply to checkpoints; ", model.path,
                 " is an exported TorchScript file");
}

void check_phi_argument(const ModelFile& model, const std::string& phi) {
  if (phi.empty()) return;
  const auto given = phi_from_argument(phi);
  const auto spec = optics::PhiSpec::from_json(model.phi, model.path + ":$.phi");
  LFNET_CHECK_AS(ConfigError, given.name == spec.name && given.n == spec.n, "--phi ", phi,
                 " does not match the model ", model.path, ", which was trained for ",
                 spec.label());
}

EvaluateResult evaluate_request(const EvaluateRequest& a) {
  const std::string method = a.method.empty() ? (a.model.empty() ? "pinv" : "net") : a.method;
  const auto method_options = method_options_argument(a.method_options, {method});
  LFNET_CHECK_AS(ConfigError, a.lf.empty() != a.scene.empty(),
                 "give exactly one of --lf DIR and --scene SCENE.json");
  LFNET_CHECK_AS(ConfigError, a.noise >= 0, "--noise must be >= 0");
  // Where the light field sits in the protocol (docs/protocol.md), read before any work.
  const nlohmann::json set = folder_set_record(a.lf);
  if (!a.choice.empty() && !set.is_null() && set.value("role", "") == "test") {
    spdlog::warn(
        "--choice '{}' on {}, a light field of the test set: choices are made on the validation "
        "set (docs/protocol.md); lfnet report marks this record",
        a.choice, set.value("name", a.lf));
  }
  std::optional<optics::SensorOptions> effects;  // read before any work
  if (!a.effects.empty()) {
    // As lfnet simulate reads them: the file, then --noise as its Gaussian sigma.
    effects = simulation_effects(a.effects, a.noise > 0 ? a.noise : -1, SimulateInput{}, "");
  }
  optics::CalibrationError camera_error;  // read before any work
  if (!a.camera_error.empty()) {
    camera_error =
        optics::CalibrationError::from_json(read_json_argument(a.camera_error, "--camera-error"),
                                            json_argument_source(a.camera_error, "--camera-error"));
    LFNET_CHECK_AS(ConfigError, camera_error.empty() || a.mode == optics::SimulationMode::kSensor,
                   "--camera-error is simulated in sensor mode only");
  }
  // --cfa, or the one a calibrated Phi's folder names.
  auto cfa = cfa_of_arguments(a.cfa, a.phi);
  if (cfa) {
    LFNET_CHECK_AS(ConfigError, a.mode == optics::SimulationMode::kSensor,
                   "--cfa is simulated in sensor mode only");
    cfa->check_demosaicable();
  }
  check_demosaic_argument(a.demosaic, cfa.has_value(), recon::needs_network(method), method);
  parse_device(a.device);  // a clear error before any work
  MethodContext context;
  optics::PhiSpec spec;
  std::optional<nn::PatchShape> network_patch;  // the patch size of net, ae and cnn
  nlohmann::json noise_switch;                  // a noise switch's members, for the record
  if (!a.model.empty()) {
    const auto model = load_model(a.model, recon::needs_network(method));
    if (recon::needs_network(method)) {
      model.check_cfa(cfa ? cfa->pattern() : "");
      noise_switch = model.noise_switch_record();
    }
    spec = optics::PhiSpec::from_json(model.phi, a.model + ":$.phi");
    check_phi_argument(model, a.phi);
    if (recon::needs_network(method)) {
      use_model(context, model);
      network_patch = model.network.patch_grid();
      place_network(model, a.device, a.precision);
    }
  } else {
    LFNET_CHECK_AS(ConfigError, !recon::needs_network(method), "method '", method,
                   "' needs --model");
    LFNET_CHECK_AS(ConfigError, !cfa || !recon::needs_network(method), "method '", method,
                   "' needs a colour model behind a colour filter array");
    LFNET_CHECK_AS(ConfigError, !a.phi.empty(), "--phi NAME[:N] is needed without --model");
    spec = phi_from_argument(a.phi);
  }
  LightFieldSources sources;
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
  if (a.self_ensemble) recon::check_self_ensemble(method, context.net, context.script.get());
  recon::check_ensemble_passes(a.self_ensemble, a.self_ensemble_passes);
  context.method_options = method_options;
  context.self_ensemble = a.self_ensemble;
  context.self_ensemble_passes = a.self_ensemble_passes;
  context.self_calibrate = a.self_calibrate;
  LFNET_CHECK_AS(ConfigError, a.tile >= 0, "--tile must be positive, got ", a.tile);
  context.tile = a.tile;
  const auto phi = optics::make_phi(spec);
  context.phi = phi.get();
  context.dictionary = a.dictionary;
  torch::Tensor flat_field;  // read before the light field
  if (!a.flat_field.empty()) {
    LFNET_CHECK_AS(ConfigError, a.mode == optics::SimulationMode::kSensor,
                   "--flat-field corrects a sensor image: sensor mode only");
    flat_field = read_flat_field(a.flat_field, *phi, cfa);
  }
  // A grey truth of 16-bit views is held in 16-bit codes, as the estimate is.
  const auto truths =
      load_sources(sources, phi->rows(), phi->cols(), false, cfa.has_value(), !cfa.has_value());

  auto o = make_eval_options(a.mode, a.noise, a.seed, a.stride, a.batch, a.window, network_patch);
  if (effects) o.effects = *effects;
  o.estimate_noise = a.estimate_noise;
  o.camera_error = camera_error;
  if (a.tell_camera_error) {
    // The camera as if measured: its nets hold the Phi with the error (recon/self_calibration.h).
    LFNET_CHECK_AS(ConfigError, context.net && context.net->architecture().whole_image(),
                   "--tell-camera-error: the model must be a checkpoint of the lfnet architecture");
    LFNET_CHECK_AS(ConfigError, !a.self_calibrate,
                   "--tell-camera-error and --self-calibrate: give one, not both");
    for (const auto& net : {context.net, context.noisy_net}) {
      if (!net.is_empty()) recon::tell_camera(net, *phi, camera_error);
    }
  }
  o.cfa = cfa;
  o.demosaic = a.demosaic;
  if (flat_field.defined()) {
    const auto views = truths[0].views();
    LFNET_CHECK_AS(ConfigError,
                   flat_field.size(0) == views.height() && flat_field.size(1) == views.width(),
                   "--flat-field ", a.flat_field, " is a white frame of ", flat_field.size(0), "x",
                   flat_field.size(1), " pixels; the light field's views are ", views.height(), "x",
                   views.width());
    o.flat_field = flat_field;
  }
  // A grey estimate is held in 16-bit codes, what its files hold: half the memory (the scores
  // differ from float32's by far less than their printed digits).
  context.coded = o.reconstruct.coded = !cfa;
  EvaluateResult result;
  result.record =
      evaluate_method(truths[0], method, context, o, a.keep_estimate ? &result.estimate : nullptr);
  if (!a.model.empty()) result.record["model"] = a.model;
  if (!noise_switch.is_null()) result.record["noise_switch"] = noise_switch;
  result.record["device"] = a.device;
  if (!set.is_null()) {
    result.record["set"] = {{"name", set.value("set", "")},
                            {"role", set.value("role", "")},
                            {"classes", set.value("classes", nlohmann::json::array())}};
  }
  if (!a.choice.empty()) result.record["choice"] = a.choice;
  if (a.tell_camera_error) result.record["camera_error_told"] = true;
  if (recon::needs_network(method)) result.record["precision"] = nn::to_string(a.precision);
  result.light_field = truths[0].name;
  if (a.keep_estimate) result.truth = truths[0].views().raw();
  result.phi = spec.label();
  return result;
}

}  // namespace lfnet::pipeline

#include "lfnet/pipeline/evaluate.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/parallax.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/process_time.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/text.h"
#include "lfnet/cv/opencv.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/viewer.h"
#include "lfnet/pipeline/reconstruct.h"
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
  if (!c.noisy_net.is_empty()) {
    p.switch_choice = std::make_shared<recon::SwitchChoice>();
    r.switch_choice = p.switch_choice;
  }
  r.exposure_target = c.exposure_target;
  if (c.exposure_target > 0) {
    p.exposure_gain = std::make_shared<double>(1.0);
    r.exposure_gain = p.exposure_gain;
  }
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

void record_switch_choice(nlohmann::json& record, const recon::SwitchChoice& choice) {
  record["noise_switch_choice"] = {{"member", choice.noisy ? "noisy" : "quiet"},
                                   {"white_share", choice.white_share},
                                   {"sigma", choice.sigma}};
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

std::optional<double> declared_motion_speed(const std::string& source) {
  std::error_code ec;
  const fs::path path(source);
  nlohmann::json doc;
  bool scene = false;
  if (fs::is_regular_file(path, ec)) {
    doc = read_json_file(source);
    scene = true;
  } else if (fs::is_regular_file(path / "scene.json", ec)) {  // render --frames
    doc = read_json_file((path / "scene.json").string());
    scene = true;
  } else if (fs::is_regular_file(path / "sequence.json", ec)) {  // render --lf
    doc = read_json_file((path / "sequence.json").string());
    const auto shift = doc.at("synthetic_motion").at("shift");
    return std::hypot(shift.at(0).get<double>(), shift.at(1).get<double>());
  } else {
    return std::nullopt;
  }
  if (!scene || !doc.contains("layers")) return std::nullopt;
  double fastest = 0;
  for (const auto& layer : doc["layers"]) {
    if (!layer.contains("motion") || !layer["motion"].contains("shift")) continue;
    const auto& s = layer["motion"]["shift"];
    fastest = std::max(fastest, std::hypot(s.at(0).get<double>(), s.at(1).get<double>()));
  }
  return std::round(fastest * 1000) / 1000;  // to a thousandth of a pixel: 1.9998 is 2
}

void add_frame_scores(nlohmann::json& record, int64_t frames, const std::string& source) {
  if (frames <= 1) return;
  record["frames"] = frames;
  const auto speed = declared_motion_speed(source);
  if (speed) record["motion_speed"] = *speed;
  record["per_frame_psnr_db"] = eval::per_frame_psnr(record.at("per_view_psnr_db"), frames);
}

namespace {
// A still method's estimates held in each of `frames` frames: patches (B, U V h w) and images
// (1, U, V, H, W) repeated along the stacked rows (docs/video.md).
void hold_still(PreparedMethod& p, int64_t frames) {
  if (p.solver) {
    p.solver = [solver = p.solver, frames](const torch::Tensor& y, const torch::Tensor& phase) {
      return solver(y, phase).repeat({1, frames});
    };
  }
  if (p.image) {
    p.image = [image = p.image, frames](const torch::Tensor& sensor, double sigma) {
      return image(sensor, sigma).repeat({1, frames, 1, 1, 1});
    };
  }
}
}  // namespace

nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, const eval::EvalOptions& options,
                               torch::Tensor* estimate, bool show_progress) {
  LFNET_CHECK(context.phi != nullptr, "evaluation without a Phi");
  const auto& phi = *context.phi;
  eval::EvalResult result;
  std::unique_ptr<optics::Phi> still;
  auto method_context = context;
  if (context.as_still) {
    LFNET_CHECK_AS(ConfigError, phi.frames() > 1,
                   "the still-scene baseline needs a time-coded "
                   "camera (NAME:N@T), not ",
                   phi.spec().label());
    still = optics::still_equivalent(phi);
    method_context.phi = still.get();
  }
  auto prepared = prepare_method(method, method_context, options.reconstruct.patch_h,
                                 options.reconstruct.patch_w);
  if (still) hold_still(prepared, phi.frames());
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
  if (still) {
    result.record["as_still"] = true;
    result.record["still_phi"] = still->spec().to_json();
  }
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
  if (prepared.switch_choice) record_switch_choice(result.record, *prepared.switch_choice);
  if (prepared.exposure_gain) result.record["exposure_gain"] = *prepared.exposure_gain;
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
  context.exposure_target = model.exposure_target;
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

namespace {

// lfnet evaluate as a controller: check() reads and checks every argument (the model, the Phi,
// the sensor's effects, the light field's place in the protocol) before any work, then run()
// loads the light field, simulates the camera and scores the method.
class Evaluation {
 public:
  explicit Evaluation(const EvaluateRequest& request)
      : a_(request),
        method_(request.method.empty() ? (request.model.empty() ? "pinv" : "net") : request.method),
        network_(recon::needs_network(method_)) {}

  void check() {
    context_.method_options = method_options_argument(a_.method_options, {method_});
    LFNET_CHECK_AS(ConfigError, a_.lf.empty() != a_.scene.empty(),
                   "give exactly one of --lf DIR and --scene SCENE.json");
    LFNET_CHECK_AS(ConfigError, a_.noise >= 0, "--noise must be >= 0");
    LFNET_CHECK_AS(ConfigError, a_.tile >= 0, "--tile must be positive, got ", a_.tile);
    check_protocol();
    read_sensor_effects();
    read_camera();
    check_sources();
    if (a_.self_ensemble) recon::check_self_ensemble(method_, context_.net, context_.script.get());
    recon::check_ensemble_passes(a_.self_ensemble, a_.self_ensemble_passes);
    context_.self_ensemble = a_.self_ensemble;
    context_.self_ensemble_passes = a_.self_ensemble_passes;
    context_.self_calibrate = a_.self_calibrate;
    context_.as_still = a_.as_still;
    context_.tile = a_.tile;
    context_.dictionary = a_.dictionary;
  }

  EvaluateResult run() {
    phi_ = optics::make_phi(spec_);
    context_.phi = phi_.get();
    torch::Tensor flat_field;  // read before the light field
    if (!a_.flat_field.empty()) flat_field = read_flat_field(a_.flat_field, *phi_, cfa_);
    // A grey truth of 16-bit views is held in 16-bit codes, as the estimate is.
    const auto truths = load_sources(sources_, phi_->rows(), phi_->cols(), false, cfa_.has_value(),
                                     !cfa_.has_value(), phi_->frames());
    auto o = options(truths[0], flat_field);
    if (a_.tell_camera_error) tell_camera_error();
    EvaluateResult result;
    result.record = evaluate_method(truths[0], method_, context_, o,
                                    a_.keep_estimate ? &result.estimate : nullptr);
    add_to_record(result.record);
    result.light_field = truths[0].name;
    if (a_.keep_estimate) result.truth = truths[0].views().raw();
    result.phi = spec_.label();
    return result;
  }

 private:
  // Where the light field sits in the protocol (docs/protocol.md).
  void check_protocol() {
    set_ = folder_set_record(a_.lf);
    if (!a_.choice.empty() && !set_.is_null() && set_.value("role", "") == "test") {
      spdlog::warn(
          "--choice '{}' on {}, a light field of the test set: choices are made on the validation "
          "set (docs/protocol.md); lfnet report marks this record",
          a_.choice, set_.value("name", a_.lf));
    }
  }

  // --effects, --camera-error, --cfa (or a calibrated Phi's), --demosaic, --flat-field, --device.
  void read_sensor_effects() {
    if (!a_.effects.empty()) {
      // As lfnet simulate reads them: the file, then --noise as its Gaussian sigma.
      effects_ = simulation_effects(a_.effects, a_.noise > 0 ? a_.noise : -1, SimulateInput{}, "");
    }
    const bool sensor = a_.mode == optics::SimulationMode::kSensor;
    if (!a_.camera_error.empty()) {
      camera_error_ = optics::CalibrationError::from_json(
          read_json_argument(a_.camera_error, "--camera-error"),
          json_argument_source(a_.camera_error, "--camera-error"));
      LFNET_CHECK_AS(ConfigError, camera_error_.empty() || sensor,
                     "--camera-error is simulated in sensor mode only");
    }
    cfa_ = cfa_of_arguments(a_.cfa, a_.phi);
    if (cfa_) {
      LFNET_CHECK_AS(ConfigError, sensor, "--cfa is simulated in sensor mode only");
      cfa_->check_demosaicable();
    }
    check_demosaic_argument(a_.demosaic, cfa_.has_value(), network_, method_);
    LFNET_CHECK_AS(ConfigError, a_.flat_field.empty() || sensor,
                   "--flat-field corrects a sensor image: sensor mode only");
    parse_device(a_.device);
  }

  // The model (its Phi, its nets placed on the device), or --phi alone.
  void read_camera() {
    if (a_.model.empty()) {
      LFNET_CHECK_AS(ConfigError, !network_, "method '", method_, "' needs --model");
      LFNET_CHECK_AS(ConfigError, !a_.phi.empty(), "--phi NAME[:N] is needed without --model");
      spec_ = phi_from_argument(a_.phi);
      return;
    }
    const auto model = load_model(a_.model, network_);
    if (network_) {
      model.check_cfa(cfa_ ? cfa_->pattern() : "");
      noise_switch_ = model.noise_switch_record();
    }
    spec_ = optics::PhiSpec::from_json(model.phi, a_.model + ":$.phi");
    if (a_.as_still) {
      // The model is a still camera's; --phi is the time-coded camera it stands in for.
      LFNET_CHECK_AS(ConfigError, !a_.phi.empty(),
                     "--as-still with --model needs --phi, the time-coded camera (NAME:N@T)");
      const auto camera = phi_from_argument(a_.phi);
      const auto still = optics::still_equivalent(*optics::make_phi(camera));
      LFNET_CHECK_AS(ConfigError, optics::same_response(*still, *optics::make_phi(spec_)),
                     "--as-still: ", a_.model, " was trained for ", spec_.label(),
                     ", but the still equivalent of ", camera.label(), " is ",
                     still->spec().label());
      spec_ = camera;
    } else {
      check_phi_argument(model, a_.phi);
    }
    if (network_) {
      use_model(context_, model);
      network_patch_ = model.network.patch_grid();
      place_network(model, a_.device, a_.precision);
    }
  }

  // --lf or --scene, with --views, --orient and --layout; --views sets a named Phi's views.
  void check_sources() {
    if (!a_.lf.empty()) sources_.light_fields = {a_.lf};
    if (!a_.scene.empty()) sources_.scenes = {a_.scene};
    sources_.views = a_.views;
    sources_.orient = a_.orient;
    sources_.layout = a_.layout;
    if (!a_.layout.empty()) io::parse_layout(a_.layout);
    AngularOrientation::parse(a_.orient, "--orient");
    if (!a_.views.empty()) {
      auto [ru, rv] = parse_views(a_.views);
      if (a_.model.empty()) {
        spec_.rows = ru.size();
        spec_.cols = rv.size();
      }
    }
  }

  eval::EvalOptions options(const NamedLightField& truth, const torch::Tensor& flat_field) {
    auto o = make_eval_options(a_.mode, a_.noise, a_.seed, a_.stride, a_.batch, a_.window,
                               network_patch_);
    if (effects_) o.effects = *effects_;
    o.estimate_noise = a_.estimate_noise;
    o.camera_error = camera_error_;
    o.cfa = cfa_;
    o.demosaic = a_.demosaic;
    if (flat_field.defined()) {
      const auto views = truth.views();
      LFNET_CHECK_AS(ConfigError,
                     flat_field.size(0) == views.height() && flat_field.size(1) == views.width(),
                     "--flat-field ", a_.flat_field, " is a white frame of ", flat_field.size(0),
                     "x", flat_field.size(1), " pixels; the light field's views are ",
                     views.height(), "x", views.width());
      o.flat_field = flat_field;
    }
    // A grey estimate is held in 16-bit codes, what its files hold: half the memory (the scores
    // differ from float32's by far less than their printed digits).
    context_.coded = o.reconstruct.coded = !cfa_;
    return o;
  }

  // The camera as if measured: its nets hold the Phi with the error (recon/self_calibration.h).
  void tell_camera_error() {
    LFNET_CHECK_AS(ConfigError,
                   !context_.net.is_empty() &&
                       context_.net->architecture().phi_input() == nn::PhiInput::kPixelWeights,
                   "--tell-camera-error: the model must be a checkpoint whose net holds its "
                   "camera's per-pixel weights (the lfnet or unrolled architecture)");
    LFNET_CHECK_AS(ConfigError, !a_.self_calibrate,
                   "--tell-camera-error and --self-calibrate: give one, not both");
    for (const auto& net : {context_.net, context_.noisy_net}) {
      if (!net.is_empty()) recon::tell_camera(net, *phi_, camera_error_);
    }
  }

  void add_to_record(nlohmann::json& record) const {
    if (!a_.model.empty()) record["model"] = a_.model;
    if (!noise_switch_.is_null()) record["noise_switch"] = noise_switch_;
    record["device"] = a_.device;
    if (!set_.is_null()) {
      record["set"] = {{"name", set_.value("set", "")},
                       {"role", set_.value("role", "")},
                       {"classes", set_.value("classes", nlohmann::json::array())}};
    }
    if (!a_.choice.empty()) record["choice"] = a_.choice;
    if (a_.tell_camera_error) record["camera_error_told"] = true;
    if (network_) record["precision"] = nn::to_string(a_.precision);
    add_frame_scores(record, phi_->frames(), a_.scene.empty() ? a_.lf : a_.scene);
  }

  const EvaluateRequest& a_;
  const std::string method_;
  const bool network_;  // the method needs --model
  MethodContext context_;
  nlohmann::json set_;  // the light field's set record (docs/protocol.md), or null
  std::optional<optics::SensorOptions> effects_;
  optics::CalibrationError camera_error_;
  std::optional<optics::ColourFilterArray> cfa_;
  optics::PhiSpec spec_;
  std::shared_ptr<optics::Phi> phi_;
  std::optional<nn::PatchShape> network_patch_;  // the patch size of net, ae and cnn
  nlohmann::json noise_switch_;                  // a noise switch's members, for the record
  LightFieldSources sources_;
};

}  // namespace

EvaluateResult evaluate_request(const EvaluateRequest& a) {
  Evaluation evaluation(a);
  evaluation.check();
  return evaluation.run();
}

void write_evaluation(const EvaluateResult& r, nlohmann::json& record, const std::string& dir) {
  const LightFieldViews est(r.estimate);  // 16-bit codes or float32
  io::ViewerPage page;
  page.title = record["method"].get<std::string>() + " on " + r.light_field;
  page.truth = LightFieldViews(r.truth);
  page.record = record;
  write_estimate(est, dir, page, record.value("frames", 1));
  record["end_to_end_seconds"] = process_seconds();
  write_json_file((fs::path(dir) / "evaluation.json").string(), record);
}

}  // namespace lfnet::pipeline

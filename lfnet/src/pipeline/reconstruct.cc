#include "lfnet/pipeline/reconstruct.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/process_time.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/version.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/io/viewer.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/noise_estimate.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/post_filter.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// A camera's own sensor images, one file of N channels per colour channel, as an acquisition.
io::Acquisition plain_sensor_acquisition(const std::string& files, const optics::PhiSpec& spec) {
  std::vector<torch::Tensor> channels;
  std::stringstream list(files);
  for (std::string file; std::getline(list, file, ',');) {
    auto image = io::read_image_channels(file);
    LFNET_CHECK_AS(ConfigError, image.size(0) == spec.n, file, " has ", image.size(0),
                   " channel(s) but the Phi ", spec.label(), " measures N = ", spec.n,
                   " per pixel: give one file of N channels per colour channel");
    LFNET_CHECK_AS(ConfigError, channels.empty() || image.sizes() == channels[0].sizes(), file,
                   " is ", image.size(1), "x", image.size(2), " but the first file is ",
                   channels[0].size(1), "x", channels[0].size(2));
    channels.push_back(image);
  }
  LFNET_CHECK_AS(ConfigError, !channels.empty(), "--sensor names no file");
  io::Acquisition acq;
  acq.sensor = torch::stack(channels);
  acq.meta = {{"phi", spec.to_json()},
              {"mode", "sensor"},
              {"light_field",
               {{"channels", acq.sensor.size(0)},
                {"height", acq.sensor.size(2)},
                {"width", acq.sensor.size(3)}}}};
  return acq;
}

}  // namespace

Reconstruction reconstruct_acquisition(const ReconstructRequest& a,
                                       const recon::ProgressCallback& progress, ModelCache* cache) {
  const std::string method = a.method;
  const auto needs = recon::find_method(method).needs();
  LFNET_CHECK_AS(ConfigError, needs != recon::MethodNeeds::kTruth, method,
                 " needs the true light field: it is a method of lfnet evaluate");
  LFNET_CHECK_AS(ConfigError, needs != recon::MethodNeeds::kDictionary || !a.dictionary.empty(),
                 "method '", method, "' needs --dictionary FILE (e.g. models/dictionary.ckpt)");
  const auto method_options = method_options_argument(a.method_options, {method});
  ModelCache local;
  ModelCache& files = cache ? *cache : local;
  // The model first: its Phi is the default for plain sensor images.
  ModelFile* model = nullptr;
  if (needs == recon::MethodNeeds::kNetwork) {
    LFNET_CHECK_AS(ConfigError, !a.model.empty(), "method '", method, "' needs --model");
    model = &files.model(a.model);
  }
  const bool folder = fs::is_directory(a.sensor);
  io::Acquisition acq;
  optics::PhiSpec spec;
  if (folder) {
    acq = io::read_acquisition(a.sensor);
    spec = optics::PhiSpec::from_json(acq.meta.at("phi"), a.sensor + "/sensor.json:$.phi");
    if (!a.phi.empty()) {
      // A calibrated camera is its weights, not its name: compare them too.
      auto given = phi_from_argument(a.phi);
      const bool same = given.label() == spec.label() &&
                        (given.name != "calibrated" || given.params == spec.params);
      LFNET_CHECK_AS(ConfigError, same, "--phi ", a.phi, " contradicts ", a.sensor,
                     "/sensor.json, which says ", spec.label(),
                     given.label() == spec.label() ? " with other weights" : "");
    }
  } else {
    LFNET_CHECK_AS(IoError, fs::exists(a.sensor) || a.sensor.find(',') != std::string::npos,
                   "--sensor ", a.sensor, " does not exist");
    LFNET_CHECK_AS(ConfigError, !a.phi.empty() || model,
                   "a plain sensor image needs --phi (or a --model, whose Phi is then used)");
    spec = a.phi.empty() ? optics::PhiSpec::from_json(model->phi, a.model + ":$.phi")
                         : phi_from_argument(a.phi);
    spec = optics::make_phi(spec)->spec();
    acq = plain_sensor_acquisition(a.sensor, spec);
    // Behind a colour filter array (--cfa, or the one a calibrated Phi names): one image.
    if (const auto cfa = optics::resolve_cfa(a.cfa, spec.to_json())) {
      LFNET_CHECK_AS(ConfigError, acq.sensor.size(0) == 1, "the camera of ", spec.label(),
                     " has a colour filter array: give its one sensor image of N channels");
      acq.meta["cfa"] = cfa->to_json();
      acq.meta["light_field"]["channels"] = 3;
    }
  }
  const auto phi = optics::make_phi(spec);
  // A colour filter array: one sensor image whose pixels each measure one colour. A colour
  // model reconstructs its colour light field; a patch method its mosaicked light field, each
  // view then demosaiced (bilinear).
  std::optional<optics::ColourFilterArray> cfa;
  if (acq.meta.contains("cfa")) {
    cfa = optics::ColourFilterArray::from_json(acq.meta["cfa"], a.sensor + "/sensor.json:$.cfa");
  }
  if (folder && !a.cfa.empty()) {
    // An acquisition records its colour filter array: --cfa may only repeat it.
    const auto given = optics::resolve_cfa(a.cfa, nlohmann::json());
    LFNET_CHECK_AS(ConfigError, cfa && given && given->to_json() == cfa->to_json(), "--cfa ", a.cfa,
                   " contradicts ", a.sensor, "/sensor.json, which records ",
                   cfa ? "another colour filter array" : "a grey sensor");
  }
  if (!a.flat_field.empty()) {
    // The camera's gain across the sensor, measured by its white frame, divided out.
    LFNET_CHECK_AS(ConfigError, acq.sensor.defined() && acq.sensor.size(0) == 1,
                   "--flat-field corrects one sensor image (sensor mode, grey or behind a colour "
                   "filter array); ",
                   a.sensor, " is not one");
    const auto gain = read_flat_field(a.flat_field, *phi, cfa);
    try {
      acq.sensor = optics::apply_flat_field(acq.sensor, gain);
    } catch (const ConfigError& e) {
      throw ConfigError("--flat-field " + a.flat_field + ": " + e.what());
    }
  }
  recon::ReconstructOptions o = a.options;
  recon::PatchSolver solver;
  recon::ImageSolver image;
  double train_mean = 0;
  const bool full = a.cnn_mode == recon::CnnMode::kFull;
  LFNET_CHECK_AS(ConfigError, !full || method == "net" || method == "cnn",
                 "--cnn-mode full needs --method net or cnn, not '", method, "'");
  if (model) {
    model->check_phi(spec.to_json());
    if (const auto grid = model->network.patch_grid()) {  // lfnet: whole images
      o.patch_h = grid->height;
      o.patch_w = grid->width;
    }
    if (model->net) {
      model->net->to(parse_device(a.device));
      nn::set_cnn_precision(model->net, a.precision);
    } else {
      LFNET_CHECK_AS(ConfigError,
                     a.device == "cpu" && a.precision == nn::Precision::kFloat32 && !full,
                     "--device, --precision and --cnn-mode full apply to checkpoints; ", a.model,
                     " is an exported TorchScript file");
    }
    train_mean = model->measurement_mean();
  }
  // A grey result that nothing processes further is held in 16-bit codes when asked for.
  o.coded = a.coded && !a.post_filter && !acq.meta.contains("cfa") &&
            acq.meta.at("light_field").at("channels").get<int64_t>() == 1;
  nlohmann::json options_used;                            // the method's options, complete
  std::shared_ptr<optics::CalibrationError> calibration;  // --self-calibrate's estimate
  {
    MethodContext context;
    context.phi = phi.get();
    if (model) use_model(context, *model);
    context.dictionary = a.dictionary;
    context.cache = &files;
    context.method_options = method_options;
    context.tile = a.tile;
    context.self_ensemble = a.self_ensemble;
    context.self_ensemble_passes = a.self_ensemble_passes;
    context.coded = o.coded;
    context.self_calibrate = a.self_calibrate;
    auto prepared = prepare_method(method, context, o.patch_h, o.patch_w);
    solver = prepared.solver;
    image = prepared.image;
    options_used = prepared.options;
    calibration = prepared.calibration;
    LFNET_CHECK_AS(ConfigError, !(image && full),
                   "--cnn-mode full applies to the paper's architecture; a model of the lfnet "
                   "architecture always reconstructs the whole image");
  }
  LFNET_CHECK_AS(ConfigError, !a.match_mean || train_mean > 0,
                 "--match-mean needs a model that records its training measurement mean");

  if (cfa) {
    LFNET_CHECK_AS(ConfigError, acq.sensor.defined(),
                   "a colour filter array's measurements must be a sensor image");
    cfa->check_demosaicable();
  }
  const bool network_method = model && needs == recon::MethodNeeds::kNetwork;
  check_demosaic_argument(a.demosaic, cfa.has_value(), network_method, method);
  if (network_method) model->check_cfa(cfa ? cfa->pattern() : "");
  if (cfa && !network_method) {
    LFNET_CHECK_AS(ConfigError, needs != recon::MethodNeeds::kNetwork && !image, "method '", method,
                   "' works on whole grey sensor images; ", a.sensor,
                   " is the sensor image of a colour filter array: use a colour model or a "
                   "patch method (pinv, adjoint, dict), whose light field is then demosaiced");
  }
  const auto& lf_meta = acq.meta.at("light_field");
  const int64_t c = lf_meta.at("channels").get<int64_t>();
  const int64_t h = lf_meta.at("height").get<int64_t>(), w = lf_meta.at("width").get<int64_t>();
  std::vector<torch::Tensor> channels;
  double scale = 1.0;
  // A noise-aware model is told the sensor's noise: --noise-sigma, else what the acquisition
  // records (simulate's sensor.json), else the noise estimated from each sensor image.
  // (A noise switch's members have a noise input, so it is noise-aware too.)
  // (A colour net is told the noise only: the estimator reads grey sensor images.)
  const bool noise_aware = ((model && model->network.arch().reads_noise(model->network)) ||
                            recon::find_method(method).reads_noise()) &&
                           !cfa;
  const bool noise_told = a.noise_sigma >= 0 || acq.meta.contains("noise_sigma");
  const double told_sigma = a.noise_sigma >= 0 ? a.noise_sigma : acq.meta.value("noise_sigma", 0.0);
  nlohmann::json estimated = nlohmann::json::array();  // per colour channel
  Stopwatch clock;
  if (acq.sensor.defined()) {
    const int64_t per_channel = PatchGrid(h, w, o.patch_h, o.patch_w, o.stride).size();
    const int64_t sensors = acq.sensor.size(0);  // 1 behind a colour filter array
    for (int64_t ch = 0; ch < sensors; ++ch) {
      // --match-mean scales a copy; otherwise the sensor image is used as read.
      auto sensor = a.match_mean ? acq.sensor[ch].clone() : acq.sensor[ch];
      if (a.match_mean) scale = recon::match_mean(sensor, train_mean);
      if (image) {
        double sigma = told_sigma;
        if (noise_aware && !noise_told) {
          sigma = optics::estimate_equivalent_sigma(*phi, sensor);
          estimated.push_back(sigma);
        }
        channels.push_back(image(sensor, sigma));
        // Whole images: the sensor's pixels, one channel's at a time.
        const int64_t pixels = sensor.size(-2) * sensor.size(-1);
        if (progress) progress((ch + 1) * pixels, sensors * pixels);
        continue;
      }
      if (full) {
        auto lf = recon::reconstruct_sensor_fully_convolutional(
            model->net, method, *phi, sensor, o, a.tile > 0 ? a.tile : recon::kDefaultCnnTile);
        channels.push_back(o.coded ? encode_codes(lf) : lf);
        if (progress) progress((ch + 1) * per_channel, sensors * per_channel);
        continue;
      }
      channels.push_back(
          recon::reconstruct_sensor(*phi, sensor, solver, o, [&](int64_t done, int64_t total) {
            if (progress) progress(ch * per_channel + done, sensors * total);
          }));
    }
    if (cfa && !image) {
      channels = {optics::demosaic(channels[0][0], *cfa, a.demosaic)};  // (3, U, V, H, W)
    }
  } else {
    LFNET_CHECK_AS(ConfigError, !a.match_mean,
                   "--match-mean applies to sensor images, not to per_patch measurements");
    LFNET_CHECK_AS(ConfigError, !full,
                   "--cnn-mode full needs a sensor image, not per-patch measurements");
    const auto& g = acq.meta.at("grid");
    const int64_t patch = g.at("patch").get<int64_t>();
    o.stride = g.at("stride").get<int64_t>();
    LFNET_CHECK_AS(ConfigError, patch == o.patch_h && patch == o.patch_w,
                   "the measurements are of ", patch, "x", patch,
                   " patches but the method reconstructs ", o.patch_h, "x", o.patch_w);
    PatchGrid grid(h, w, patch, patch, o.stride);
    for (int64_t ch = 0; ch < c; ++ch) {
      auto source = [&](int64_t r0, int64_t r1) {
        return optics::PatchMeasurements{
            acq.measurements[ch].slice(0, r0 * grid.cols(), r1 * grid.cols()),
            optics::patch_phases(*phi, grid, r0, r1)};
      };
      channels.push_back(recon::reconstruct_patches(
          *phi, grid, source, solver, o, [&](int64_t done, int64_t total) {
            if (progress) progress(ch * grid.size() + done, c * total);
          }));
    }
  }
  // One colour channel is the light field itself: no copy of it.
  torch::Tensor lf = channels.size() == 1 ? channels[0] : torch::cat(channels, 0);
  if (a.post_filter) {
    lf = recon::suppress_periodic(lf, o.stride);
    if (o.clamp) lf.clamp_(0.0, 1.0);
  }
  const double seconds = clock.seconds();
  Reconstruction r{o.coded ? LightFieldViews(lf) : LightFieldViews(LightField(lf)), {}};
  r.record = {{"method", method},
              {"model", needs == recon::MethodNeeds::kNetwork      ? a.model
                        : needs == recon::MethodNeeds::kDictionary ? a.dictionary
                                                                   : ""},
              {"sensor", a.sensor},
              {"stride", o.stride},
              {"seconds", seconds},
              {"phi", spec.to_json()},
              {"mode", acq.meta.value("mode", "sensor")},
              {"shape", r.lf.shape_string()},
              {"match_mean_scale", scale},
              {"post_filter", a.post_filter},
              {"window", o.window},
              {"device", a.device},
              {"cnn_mode", recon::to_string(a.cnn_mode)},
              {"tile", a.tile},  // 0: the method's default
              {"precision", nn::to_string(a.precision)},
              {"lfnet_version", kVersion}};
  if (cfa) r.record["cfa"] = cfa->to_json();
  if (cfa && !network_method) r.record["demosaic"] = optics::to_string(a.demosaic);
  if (!a.flat_field.empty()) r.record["flat_field"] = true;
  if (model && needs == recon::MethodNeeds::kNetwork && model->noise_switch()) {
    r.record["noise_switch"] = model->noise_switch_record();
  }
  if (!options_used.empty()) r.record["method_options"] = options_used;
  if (calibration) record_estimated_camera_error(r.record, *calibration, "");
  if (noise_aware) r.record["noise_sigma"] = noise_told ? nlohmann::json(told_sigma) : estimated;
  if (!estimated.empty()) {
    r.record["noise_sigma_estimated"] = true;
    spdlog::info("noise sigma estimated from the sensor image: {} (--noise-sigma overrides)",
                 estimated.dump());
  }
  return r;
}

void write_reconstruction(const Reconstruction& r, const std::string& out,
                          const OutputFolderPolicy& policy, bool end_to_end) {
  write_folder(out, policy, [&](const std::string& dir) {
    // What each step freed is returned before the next (the peak is one step's, not all).
    release_free_memory();
    Stopwatch step;
    io::write_light_field(r.lf, dir);
    spdlog::debug("views written in {:.2f} s", step.seconds());
    step.reset();
    release_free_memory();
    io::write_previews(r.lf, dir);
    spdlog::debug("grid and EPIs written in {:.2f} s", step.seconds());
    step.reset();
    release_free_memory();
    io::ViewerPage page;
    page.title = r.record.value("method", "") + " reconstruction of " +
                 fs::path(r.record.value("sensor", "")).filename().string();
    page.record = r.record;
    io::write_viewer(r.lf, (fs::path(dir) / "index.html").string(), page);
    spdlog::debug("viewer written in {:.2f} s", step.seconds());
    // Last: the command's time from its start, every other output written.
    auto record = r.record;
    if (end_to_end) record["end_to_end_seconds"] = process_seconds();
    write_json_file((fs::path(dir) / "reconstruction.json").string(), record);
  });
}

}  // namespace lfnet::pipeline

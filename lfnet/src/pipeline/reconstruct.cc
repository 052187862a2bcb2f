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
#include "lfnet/core/sequence.h"
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

// One reconstruction of an acquisition (reconstruct_acquisition), in the order of its steps:
// each step checks what it reads before any reconstruction work, so the first error a request
// meets is the same whatever follows it.
class AcquisitionReconstruction {
 public:
  AcquisitionReconstruction(const ReconstructRequest& request,
                            const recon::ProgressCallback& progress, ModelCache& files)
      : a_(request),
        progress_(progress),
        files_(files),
        method_(request.method),
        needs_(recon::find_method(request.method).needs()) {}

  Reconstruction run() {
    check_method();
    read_input();
    read_colour_filter();
    divide_flat_field();
    prepare_method_for_model();
    check_colour();
    decide_noise();
    Stopwatch clock;
    torch::Tensor lf =
        acq_.sensor.defined() ? reconstruct_sensor_images() : reconstruct_patch_measurements();
    if (a_.post_filter) {
      lf = recon::suppress_periodic(lf, o_.stride);
      if (o_.clamp) lf.clamp_(0.0, 1.0);
    }
    return result(lf, clock.seconds());
  }

 private:
  // The method's needs, and its model first: the model's Phi is the default for plain images.
  void check_method() {
    LFNET_CHECK_AS(ConfigError, needs_ != recon::MethodNeeds::kTruth, method_,
                   " needs the true light field: it is a method of lfnet evaluate");
    LFNET_CHECK_AS(ConfigError, needs_ != recon::MethodNeeds::kDictionary || !a_.dictionary.empty(),
                   "method '", method_, "' needs --dictionary FILE (e.g. models/dictionary.ckpt)");
    method_options_ = method_options_argument(a_.method_options, {method_});
    if (needs_ == recon::MethodNeeds::kNetwork) {
      LFNET_CHECK_AS(ConfigError, !a_.model.empty(), "method '", method_, "' needs --model");
      model_ = &files_.model(a_.model);
    }
  }

  // An acquisition folder, or a camera's own sensor image(s) with the Phi given or the model's.
  void read_input() {
    folder_ = fs::is_directory(a_.sensor);
    if (folder_) {
      acq_ = io::read_acquisition(a_.sensor);
      spec_ = optics::PhiSpec::from_json(acq_.meta.at("phi"), a_.sensor + "/sensor.json:$.phi");
      if (!a_.phi.empty()) {
        // A calibrated camera is its weights, not its name: compare them too.
        auto given = phi_from_argument(a_.phi);
        const bool same = given.label() == spec_.label() &&
                          (given.name != "calibrated" || given.params == spec_.params);
        LFNET_CHECK_AS(ConfigError, same, "--phi ", a_.phi, " contradicts ", a_.sensor,
                       "/sensor.json, which says ", spec_.label(),
                       given.label() == spec_.label() ? " with other weights" : "");
      }
    } else {
      LFNET_CHECK_AS(IoError, fs::exists(a_.sensor) || a_.sensor.find(',') != std::string::npos,
                     "--sensor ", a_.sensor, " does not exist");
      LFNET_CHECK_AS(ConfigError, !a_.phi.empty() || model_,
                     "a plain sensor image needs --phi (or a --model, whose Phi is then used)");
      spec_ = a_.phi.empty() ? optics::PhiSpec::from_json(model_->phi, a_.model + ":$.phi")
                             : phi_from_argument(a_.phi);
      spec_ = optics::make_phi(spec_)->spec();
      acq_ = plain_sensor_acquisition(a_.sensor, spec_);
      // Behind a colour filter array (--cfa, or the one a calibrated Phi names): one image.
      if (const auto cfa = optics::resolve_cfa(a_.cfa, spec_.to_json())) {
        LFNET_CHECK_AS(ConfigError, acq_.sensor.size(0) == 1, "the camera of ", spec_.label(),
                       " has a colour filter array: give its one sensor image of N channels");
        acq_.meta["cfa"] = cfa->to_json();
        acq_.meta["light_field"]["channels"] = 3;
      }
    }
    phi_ = optics::make_phi(spec_);
  }

  // A colour filter array: one sensor image whose pixels each measure one colour. A colour
  // model reconstructs its colour light field; a patch method its mosaicked light field, each
  // view then demosaiced.
  void read_colour_filter() {
    if (acq_.meta.contains("cfa")) {
      cfa_ =
          optics::ColourFilterArray::from_json(acq_.meta["cfa"], a_.sensor + "/sensor.json:$.cfa");
    }
    if (folder_ && !a_.cfa.empty()) {
      // An acquisition records its colour filter array: --cfa may only repeat it.
      const auto given = optics::resolve_cfa(a_.cfa, nlohmann::json());
      LFNET_CHECK_AS(ConfigError, cfa_ && given && given->to_json() == cfa_->to_json(), "--cfa ",
                     a_.cfa, " contradicts ", a_.sensor, "/sensor.json, which records ",
                     cfa_ ? "another colour filter array" : "a grey sensor");
    }
  }

  // The camera's gain across the sensor, measured by its white frame, divided out.
  void divide_flat_field() {
    if (a_.flat_field.empty()) return;
    LFNET_CHECK_AS(ConfigError, acq_.sensor.defined() && acq_.sensor.size(0) == 1,
                   "--flat-field corrects one sensor image (sensor mode, grey or behind a colour "
                   "filter array); ",
                   a_.sensor, " is not one");
    const auto gain = read_flat_field(a_.flat_field, *phi_, cfa_);
    try {
      acq_.sensor = optics::apply_flat_field(acq_.sensor, gain);
    } catch (const ConfigError& e) {
      throw ConfigError("--flat-field " + a_.flat_field + ": " + e.what());
    }
  }

  // The model on its device and in its precision, and the method's solver.
  void prepare_method_for_model() {
    o_ = a_.options;
    full_ = a_.cnn_mode == recon::CnnMode::kFull;
    LFNET_CHECK_AS(ConfigError, !full_ || method_ == "net" || method_ == "cnn",
                   "--cnn-mode full needs --method net or cnn, not '", method_, "'");
    if (model_) {
      model_->check_phi(spec_.to_json());
      if (const auto grid = model_->network.patch_grid()) {  // none for whole-image nets
        o_.patch_h = grid->height;
        o_.patch_w = grid->width;
      }
      if (model_->net) {
        model_->net->to(parse_device(a_.device));
        nn::set_cnn_precision(model_->net, a_.precision);
      } else {
        LFNET_CHECK_AS(ConfigError,
                       a_.device == "cpu" && a_.precision == nn::Precision::kFloat32 && !full_,
                       "--device, --precision and --cnn-mode full apply to checkpoints; ", a_.model,
                       " is an exported TorchScript file");
      }
      train_mean_ = model_->measurement_mean();
    }
    // A grey result that nothing processes further is held in 16-bit codes when asked for.
    o_.coded = a_.coded && !a_.post_filter && !acq_.meta.contains("cfa") &&
               acq_.meta.at("light_field").at("channels").get<int64_t>() == 1;
    MethodContext context;
    context.phi = phi_.get();
    if (model_) use_model(context, *model_);
    context.dictionary = a_.dictionary;
    context.cache = &files_;
    context.method_options = method_options_;
    context.tile = a_.tile;
    context.self_ensemble = a_.self_ensemble;
    context.self_ensemble_passes = a_.self_ensemble_passes;
    context.coded = o_.coded;
    context.self_calibrate = a_.self_calibrate;
    auto prepared = prepare_method(method_, context, o_.patch_h, o_.patch_w);
    solver_ = prepared.solver;
    image_ = prepared.image;
    options_used_ = prepared.options;
    calibration_ = prepared.calibration;
    switch_choice_ = prepared.switch_choice;
    exposure_gain_ = prepared.exposure_gain;
    LFNET_CHECK_AS(ConfigError, !(image_ && full_),
                   "--cnn-mode full applies to the paper's architecture; a model of a "
                   "whole-image architecture always reconstructs the whole image");
    LFNET_CHECK_AS(ConfigError, !a_.match_mean || train_mean_ > 0,
                   "--match-mean needs a model that records its training measurement mean");
  }

  void check_colour() {
    if (cfa_) {
      LFNET_CHECK_AS(ConfigError, acq_.sensor.defined(),
                     "a colour filter array's measurements must be a sensor image");
      cfa_->check_demosaicable();
    }
    network_method_ = model_ && needs_ == recon::MethodNeeds::kNetwork;
    check_demosaic_argument(a_.demosaic, cfa_.has_value(), network_method_, method_);
    if (network_method_) model_->check_cfa(cfa_ ? cfa_->pattern() : "");
    if (cfa_ && !network_method_) {
      LFNET_CHECK_AS(ConfigError, needs_ != recon::MethodNeeds::kNetwork && !image_, "method '",
                     method_, "' works on whole grey sensor images; ", a_.sensor,
                     " is the sensor image of a colour filter array: use a colour model or a "
                     "patch method (pinv, adjoint, dict), whose light field is then demosaiced");
    }
  }

  // A noise-aware model is told the sensor's noise: --noise-sigma, else what the acquisition
  // records (simulate's sensor.json), else the noise estimated from each sensor image. (A noise
  // switch's members have a noise input, so it is noise-aware too; a colour net is told the
  // noise only: the estimator reads grey sensor images.)
  void decide_noise() {
    noise_aware_ = ((model_ && model_->network.arch().reads_noise(model_->network)) ||
                    recon::find_method(method_).reads_noise()) &&
                   !cfa_;
    noise_told_ = a_.noise_sigma >= 0 || acq_.meta.contains("noise_sigma");
    told_sigma_ = a_.noise_sigma >= 0 ? a_.noise_sigma : acq_.meta.value("noise_sigma", 0.0);
  }

  // Sensor images, one per colour channel (one behind a colour filter array): whole images,
  // the CNN branch over the light field, or patches.
  torch::Tensor reconstruct_sensor_images() {
    const auto& lf_meta = acq_.meta.at("light_field");
    const int64_t h = lf_meta.at("height").get<int64_t>(), w = lf_meta.at("width").get<int64_t>();
    const int64_t per_channel = PatchGrid(h, w, o_.patch_h, o_.patch_w, o_.stride).size();
    const int64_t sensors = acq_.sensor.size(0);
    std::vector<torch::Tensor> channels;
    for (int64_t ch = 0; ch < sensors; ++ch) {
      // --match-mean scales a copy; otherwise the sensor image is used as read.
      auto sensor = a_.match_mean ? acq_.sensor[ch].clone() : acq_.sensor[ch];
      if (a_.match_mean) scale_ = recon::match_mean(sensor, train_mean_);
      if (image_) {
        double sigma = told_sigma_;
        if (noise_aware_ && !noise_told_) {
          sigma = optics::estimate_equivalent_sigma(*phi_, sensor);
          estimated_.push_back(sigma);
        }
        channels.push_back(image_(sensor, sigma));
        // Whole images: the sensor's pixels, one channel's at a time.
        const int64_t pixels = sensor.size(-2) * sensor.size(-1);
        if (progress_) progress_((ch + 1) * pixels, sensors * pixels);
      } else if (full_) {
        auto lf = recon::reconstruct_sensor_fully_convolutional(
            model_->net, method_, *phi_, sensor, o_,
            a_.tile > 0 ? a_.tile : recon::kDefaultCnnTile);
        channels.push_back(o_.coded ? encode_codes(lf) : lf);
        if (progress_) progress_((ch + 1) * per_channel, sensors * per_channel);
      } else {
        channels.push_back(
            recon::reconstruct_sensor(*phi_, sensor, solver_, o_, [&](int64_t done, int64_t total) {
              if (progress_) progress_(ch * per_channel + done, sensors * total);
            }));
      }
    }
    if (cfa_ && !image_) {
      channels = {optics::demosaic(channels[0][0], *cfa_, a_.demosaic)};  // (3, U, V, H, W)
    }
    // One colour channel is the light field itself: no copy of it.
    return channels.size() == 1 ? channels[0] : torch::cat(channels, 0);
  }

  // Per-patch measurements (simulate --mode per_patch), on the grid they were taken on.
  torch::Tensor reconstruct_patch_measurements() {
    LFNET_CHECK_AS(ConfigError, !a_.match_mean,
                   "--match-mean applies to sensor images, not to per_patch measurements");
    LFNET_CHECK_AS(ConfigError, !full_,
                   "--cnn-mode full needs a sensor image, not per-patch measurements");
    const auto& lf_meta = acq_.meta.at("light_field");
    const int64_t c = lf_meta.at("channels").get<int64_t>();
    const int64_t h = lf_meta.at("height").get<int64_t>(), w = lf_meta.at("width").get<int64_t>();
    const auto& g = acq_.meta.at("grid");
    const int64_t patch = g.at("patch").get<int64_t>();
    o_.stride = g.at("stride").get<int64_t>();
    LFNET_CHECK_AS(ConfigError, patch == o_.patch_h && patch == o_.patch_w,
                   "the measurements are of ", patch, "x", patch,
                   " patches but the method reconstructs ", o_.patch_h, "x", o_.patch_w);
    PatchGrid grid(h, w, patch, patch, o_.stride);
    std::vector<torch::Tensor> channels;
    for (int64_t ch = 0; ch < c; ++ch) {
      auto source = [&](int64_t r0, int64_t r1) {
        return optics::PatchMeasurements{
            acq_.measurements[ch].slice(0, r0 * grid.cols(), r1 * grid.cols()),
            optics::patch_phases(*phi_, grid, r0, r1)};
      };
      channels.push_back(recon::reconstruct_patches(
          *phi_, grid, source, solver_, o_, [&](int64_t done, int64_t total) {
            if (progress_) progress_(ch * grid.size() + done, c * total);
          }));
    }
    return channels.size() == 1 ? channels[0] : torch::cat(channels, 0);
  }

  // The light field and the record of how it was made.
  Reconstruction result(const torch::Tensor& lf, double seconds) {
    Reconstruction r{o_.coded ? LightFieldViews(lf) : LightFieldViews(LightField(lf)), {}};
    r.record = {{"method", method_},
                {"model", needs_ == recon::MethodNeeds::kNetwork      ? a_.model
                          : needs_ == recon::MethodNeeds::kDictionary ? a_.dictionary
                                                                      : ""},
                {"sensor", a_.sensor},
                {"stride", o_.stride},
                {"seconds", seconds},
                {"phi", spec_.to_json()},
                {"mode", acq_.meta.value("mode", "sensor")},
                {"shape", r.lf.shape_string()},
                {"match_mean_scale", scale_},
                {"post_filter", a_.post_filter},
                {"window", o_.window},
                {"device", a_.device},
                {"cnn_mode", recon::to_string(a_.cnn_mode)},
                {"tile", a_.tile},  // 0: the method's default
                {"precision", nn::to_string(a_.precision)},
                {"lfnet_version", kVersion}};
    if (cfa_) r.record["cfa"] = cfa_->to_json();
    if (cfa_ && !network_method_) r.record["demosaic"] = optics::to_string(a_.demosaic);
    if (!a_.flat_field.empty()) r.record["flat_field"] = true;
    if (model_ && needs_ == recon::MethodNeeds::kNetwork && model_->noise_switch()) {
      r.record["noise_switch"] = model_->noise_switch_record();
    }
    if (!options_used_.empty()) r.record["method_options"] = options_used_;
    if (calibration_) record_estimated_camera_error(r.record, *calibration_, "");
    if (switch_choice_) record_switch_choice(r.record, *switch_choice_);
    if (exposure_gain_) r.record["exposure_gain"] = *exposure_gain_;
    if (noise_aware_) {
      r.record["noise_sigma"] = noise_told_ ? nlohmann::json(told_sigma_) : estimated_;
    }
    if (!estimated_.empty()) {
      r.record["noise_sigma_estimated"] = true;
      spdlog::info("noise sigma estimated from the sensor image: {} (--noise-sigma overrides)",
                   estimated_.dump());
    }
    return r;
  }

  const ReconstructRequest& a_;
  const recon::ProgressCallback& progress_;
  ModelCache& files_;
  const std::string method_;
  const recon::MethodNeeds needs_;
  nlohmann::json method_options_;
  ModelFile* model_ = nullptr;
  bool folder_ = false;
  io::Acquisition acq_;
  optics::PhiSpec spec_;
  std::unique_ptr<optics::Phi> phi_;
  std::optional<optics::ColourFilterArray> cfa_;
  recon::ReconstructOptions o_;
  recon::PatchSolver solver_;
  recon::ImageSolver image_;
  double train_mean_ = 0;
  bool full_ = false;
  nlohmann::json options_used_;                            // the method's options, complete
  std::shared_ptr<optics::CalibrationError> calibration_;  // --self-calibrate's estimate
  std::shared_ptr<recon::SwitchChoice> switch_choice_;     // a noise switch's member
  std::shared_ptr<double> exposure_gain_;                  // the exposure target's gain
  bool network_method_ = false;
  bool noise_aware_ = false, noise_told_ = false;
  double told_sigma_ = 0;
  nlohmann::json estimated_ = nlohmann::json::array();  // per colour channel
  double scale_ = 1.0;                                  // --match-mean's
};

}  // namespace

Reconstruction reconstruct_acquisition(const ReconstructRequest& a,
                                       const recon::ProgressCallback& progress, ModelCache* cache) {
  ModelCache local;
  return AcquisitionReconstruction(a, progress, cache ? *cache : local).run();
}

namespace {

// The views of one light field in `dir`, with its grid and EPIs.
void write_views(const LightFieldViews& lf, const std::string& dir) {
  // What each step freed is returned before the next (the peak is one step's, not all).
  release_free_memory();
  Stopwatch step;
  io::write_light_field(lf, dir);
  spdlog::debug("views written in {:.2f} s", step.seconds());
  step.reset();
  release_free_memory();
  io::write_previews(lf, dir);
  spdlog::debug("grid and EPIs written in {:.2f} s", step.seconds());
}

}  // namespace

void write_estimate(const LightFieldViews& lf, const std::string& dir, const io::ViewerPage& page,
                    int64_t frames) {
  LFNET_CHECK(frames >= 1 && lf.rows() % frames == 0, "write_estimate: ", lf.rows(),
              " stacked rows are not ", frames, " frames");
  if (frames > 1) {
    // A sequence: each frame's rows of the stacked estimate in its own frame_t folder.
    const int64_t rows = lf.rows() / frames;
    for (int64_t t = 0; t < frames; ++t) {
      write_views(lf.window({t * rows, (t + 1) * rows}, {0, lf.cols()}),
                  sequence_frame_dir(dir, t));
    }
  } else {
    write_views(lf, dir);
  }
  // One page for the whole sequence: its time slider steps the frames.
  release_free_memory();
  Stopwatch step;
  auto viewer = page;
  viewer.frames = frames;
  io::write_viewer(lf, (fs::path(dir) / "index.html").string(), viewer);
  spdlog::debug("viewer written in {:.2f} s", step.seconds());
}

void write_reconstruction(const Reconstruction& r, const std::string& out,
                          const OutputFolderPolicy& policy, bool end_to_end) {
  write_folder(out, policy, [&](const std::string& dir) {
    io::ViewerPage page;
    page.title = r.record.value("method", "") + " reconstruction of " +
                 fs::path(r.record.value("sensor", "")).filename().string();
    page.record = r.record;
    write_estimate(r.lf, dir, page,
                   r.record.contains("phi") ? r.record["phi"].value("frames", 1) : 1);
    // Last: the command's time from its start, every other output written.
    auto record = r.record;
    if (end_to_end) record["end_to_end_seconds"] = process_seconds();
    write_json_file((fs::path(dir) / "reconstruction.json").string(), record);
  });
}

}  // namespace lfnet::pipeline

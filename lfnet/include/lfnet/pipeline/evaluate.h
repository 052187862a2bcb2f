// Evaluating a method on a light field with known truth: simulate the sensor, reconstruct,
// score (docs/reconstruction.md).
#pragma once

#include <torch/torch.h>
#include <nlohmann/json.hpp>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/eval/evaluate.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/methods.h"

namespace lfnet::pipeline {

// What a method needs besides the measurements: the one description every command fills
// (evaluate, reconstruct, batch, bench, an experiment's evaluation), turned into a method's
// resources in one place (prepare_method).
struct MethodContext {
  const optics::Phi* phi = nullptr;
  nn::LightFieldNet net{nullptr};        // for net, ae, cnn
  nn::LightFieldNet noisy_net{nullptr};  // a noise switch's net for noisy images
  double switch_sigma = 0;               // and the sigma from which it takes over
  double exposure_target = 0;  // dim sensor images brightened to it (recon/method_registry.h)
  std::shared_ptr<nn::ScriptedNetwork> script;        // or an exported net (used when set)
  std::string dictionary;                             // for dict: a dictionary file,
  const dict::Dictionary* dictionary_data = nullptr;  // or the dictionary itself (used when set)
  ModelCache* cache =
      nullptr;  // where to read it (and keep it) for many calls; none: read it each call
  // The options of the methods, keyed by method name (--method-options): given, not completed.
  nlohmann::json method_options = nlohmann::json::object();
  bool self_ensemble = false;        // lfnet architecture: average over the Phi's mirrors
  int64_t self_ensemble_passes = 0;  // at most this many of them (0: all)
  int64_t tile = 0;                  // whole-image methods' spatial tile (0: their default)
  // Whole-image methods return 16-bit codes (recon::MethodResources::coded); the patch methods
  // take theirs from recon::ReconstructOptions::coded.
  bool coded = false;
  // Whole-image networks estimate the camera's angular shift from each sensor image and are told
  // the Phi so displaced (recon/self_calibration.h; --self-calibrate).
  bool self_calibrate = false;
  // A time-coded Phi's sequence reconstructed as if nothing moved: the method runs on the
  // Phi's still equivalent (optics::still_equivalent) and its estimate is held in every frame.
  bool as_still = false;
};

// A method ready to run on one Phi and patch size.
struct PreparedMethod {
  recon::MethodResources resources;
  recon::PatchSolver solver;  // none for evaluation baselines (MethodNeeds::kTruth)
  recon::ImageSolver image;   // empty for methods that go patch by patch
  std::shared_ptr<recon::SolverReport> report;  // iterative methods' non-convergence
  nlohmann::json options;                       // the method's options, complete ({}: none)
  std::shared_ptr<ModelCache> files;            // a dictionary read without the context's cache
  // With self-calibration: the camera error estimated from the last sensor image.
  std::shared_ptr<optics::CalibrationError> calibration;
  // With a noise switch: which member reconstructed the last sensor image, and why.
  std::shared_ptr<recon::SwitchChoice> switch_choice;
  // With an exposure target: the gain applied to the last sensor image.
  std::shared_ptr<double> exposure_gain;
};

// A noise switch's choice (PreparedMethod::switch_choice) into `record`, as
// record["noise_switch_choice"]: {"member": "quiet" or "noisy", "white_share", "sigma"}.
void record_switch_choice(nlohmann::json& record, const recon::SwitchChoice& choice);

// The method `method` with the context's resources, its options checked: the one place that
// turns a MethodContext into recon::MethodResources. `patch_h` x `patch_w`: the patch of patch
// methods (a network's own, else 9 x 9).
PreparedMethod prepare_method(const std::string& method, const MethodContext& context,
                              int64_t patch_h, int64_t patch_w);

// --method-options: a JSON object, inline or in a file ("" is {}), keyed by method name, each
// value that method's options, e.g. {"dict": {"method": "admm"}, "pinv-nlm": {"denoiser":
// "nlm"}} (docs/methods.md "Method options"). Read and checked against `methods` (the methods
// the command runs: every key must be one of them, every value its method's options) before
// any work; `source` names it in errors.
nlohmann::json method_options_argument(const std::string& text,
                                       const std::vector<std::string>& methods,
                                       const std::string& source = "--method-options");

// The same check for options already read (a config's $.evaluation.method_options).
void check_method_options(const nlohmann::json& by_method, const std::vector<std::string>& methods,
                          const std::string& source);

// The model's networks (a checkpoint's, an exported one, a noise switch's two) in `context`.
void use_model(MethodContext& context, const ModelFile& model);

// A self-calibration's estimate (PreparedMethod::calibration) into `record`, as
// camera_error_estimated, and said in the log; `what` opens the line ("" none).
void record_estimated_camera_error(nlohmann::json& record, const optics::CalibrationError& error,
                                   const std::string& what);

// Puts a model's network where the command asked (the flags every reconstructing command
// shares): a checkpoint's net moved to `device` with `precision`; an exported file, which runs
// on the CPU in float32, refuses other values. `model` is named in the error.
void place_network(const ModelFile& model, const std::string& device, nn::Precision precision);

// Throws a ConfigError unless the Phi `phi` (a --phi argument) is the one the model was trained
// for. Empty `phi`: nothing to check.
void check_phi_argument(const ModelFile& model, const std::string& phi);

// The evaluation options of the command line: simulation mode, Gaussian noise sigma (0: none),
// noise seed, patch stride, solver batch, window stitching, and the model's patch size when
// there is a model (else the default 9 x 9).
eval::EvalOptions make_eval_options(optics::SimulationMode mode, double noise, uint64_t seed,
                                    int64_t stride, int64_t batch, bool window,
                                    const std::optional<nn::PatchShape>& patch);

// Evaluates `method` on one grey light field; the record names the light field and method.
// `show_progress` draws a progress bar over the patches.
nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, const eval::EvalOptions& options,
                               torch::Tensor* estimate = nullptr, bool show_progress = true);

// What `lfnet evaluate` does with one light field (a folder or a procedural scene).
struct EvaluateRequest {
  std::string lf;              // light-field folder with the truth
  std::string scene;           // or a procedural scene spec (exactly one of lf and scene)
  std::string views;           // angular window R0:R1,C0:C1 (1-based; "" = central)
  std::string orient;          // flip-u, flip-v, transpose (comma-separated)
  std::string layout;          // file-naming pattern of lf (docs/conventions.md)
  std::string model;           // checkpoint or exported model ("" for models-free methods)
  std::string phi;             // NAME[:N], a spec or a calibrated-Phi folder; must match model
  std::string method;          // "" = net with a model, pinv without
  std::string dictionary;      // dictionary file for dict
  std::string method_options;  // --method-options: JSON or file, keyed by method
  optics::SimulationMode mode = optics::SimulationMode::kSensor;
  double noise = 0;             // Gaussian noise sigma, relative to a white scene's mean
  std::string effects;          // sensor effects JSON file (shot, read, ...); noise on top
  bool estimate_noise = false;  // noise-aware methods are told the noise estimated, not the truth
  std::string camera_error;     // --camera-error: JSON or file (optics/calibration.h); "" none
  bool as_still = false;        // the still-scene baseline (MethodContext::as_still, docs/video.md)
  bool tell_camera_error = false;  // lfnet nets are told the camera's Phi with that error
  std::string flat_field;  // --flat-field: the camera's white frame (read_flat_field); "" none
  std::string cfa;         // --cfa: a Bayer pattern or a JSON file (optics/cfa.h); "" a grey sensor
  optics::Demosaic demosaic = optics::Demosaic::kBilinear;  // --demosaic: of pinv's views
  uint64_t seed = 0;                                        // noise seed
  int64_t stride = 5;                                       // patch stride
  int64_t batch = 1024;                                     // patches per forward pass
  bool window = false;         // weight patch estimates by a smooth window when stitching
  int64_t tile = 0;            // whole-image methods' spatial tile (0: their default, 256)
  std::string device = "cpu";  // cpu or cuda[:K] for a checkpoint's network
  nn::Precision precision = nn::Precision::kFloat32;  // of the CNN branch (lfnet: the U-Net)
  bool keep_estimate = false;                         // return the reconstruction too
  bool self_ensemble = false;        // lfnet architecture: average over the Phi's mirror images
  int64_t self_ensemble_passes = 0;  // at most this many of them (0: all)
  bool self_calibrate = false;       // lfnet architecture: estimate the camera's angular shift
  // What this evaluation decides (a sweep's value, a training step, which model ships), written
  // into the record as "choice": lfnet report marks a choice made on the test set.
  std::string choice;
};

// One evaluation's outcome.
struct EvaluateResult {
  nlohmann::json record;    // evaluate_method's record with model, device and precision
  torch::Tensor estimate;   // the reconstruction (with keep_estimate): grey in 16-bit codes
  torch::Tensor truth;      // the light field it was scored against (with keep_estimate): codes or
                            // float32, as LightFieldViews reads it
  std::string light_field;  // the truth's name
  std::string phi;          // the Phi's label, e.g. asp:2
};

// Checks the request (before any work), loads the model, the Phi and the truth, and evaluates.
EvaluateResult evaluate_request(const EvaluateRequest& request);
// The motion a sequence's source declares, in px per sub-frame: the fastest layer's shift of a
// scene file or of a rendered sequence's scene.json, or the whole-image shift of a synthetic one
// (sequence.json; docs/video.md), to a thousandth of a pixel. None for a source that declares
// nothing (a still folder).
std::optional<double> declared_motion_speed(const std::string& source);
// A time-coded camera's record of T = `frames` sub-frames gains `frames`, each frame's PSNR
// (per_frame_psnr_db, from its per_view_psnr_db) and the motion `source` declares
// (motion_speed); a still camera's (T = 1) stays as it is.
void add_frame_scores(nlohmann::json& record, int64_t frames, const std::string& source);

// Writes an evaluation's estimate into `dir`: its views, their previews, the viewer page beside
// the truth (r.keep_estimate), then evaluation.json of `record`, whose end_to_end_seconds is set
// once the rest is written. Each step's memory is returned before the next.
void write_evaluation(const EvaluateResult& r, nlohmann::json& record, const std::string& dir);

}  // namespace lfnet::pipeline

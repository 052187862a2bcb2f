// The flags several commands take, each declared once here with one help text, in groups
// (docs/reconstruction.md, "Flags every command shares"): camera and device (--phi --device
// --cnn-mode), sensor (--mode --noise --seed --cfa
// --flat-field --camera-error --effects), light-field input (--lf --scene --layout --orient
// --views), patches (--batch --window --dictionary --post-filter --match-mean) and output (--json
// --force). A command binds the flag to its own field. The commands that reconstruct bind their
// model group (--model --phi
// --device --precision --tile --stride, the self-ensemble, --method-options) with
// add_reconstruction_flags. tests/apps/cli_test.cc holds every flag to one help text across the
// commands.
#pragma once

#include <CLI/CLI.hpp>

#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/catalog.h"
#include "paths.h"

namespace lfnet::app {

// ---- camera and device --------------------------------------------------------------------

inline CLI::Option* add_phi_option(CLI::App* cmd, std::string& phi) {
  return input_path(cmd->add_option(
                        "--phi", phi,
                        "the camera: a Phi model NAME[:N][@T] (asp, mask, aperture, random, "
                        "lenslet; over T sub-frames also time_aperture, coded_exposure, "
                        "exposure_aperture: docs/video.md), a PHI.json spec, a calibrated-Phi "
                        "folder, a model file or a zoo "
                        "model's name; with a model or an acquisition, for what they do not say, "
                        "and it must match the model"))
      ->transform(zoo_model_file);
}

inline CLI::Option* add_device_option(CLI::App* cmd, std::string& device) {
  return cmd->add_option("--device", device,
                         "cpu or cuda[:K]: where the network runs (default cpu; train: the "
                         "config's training.device)");
}

inline CLI::Option* add_cnn_mode_option(CLI::App* cmd, pipeline::CnnMode& mode) {
  return add_enum_option(cmd, "--cnn-mode", mode,
                         "the paper net's CNN branch per patch ('patches', the default) or once "
                         "over the light field in tiles ('full'; docs/performance.md)");
}

// ---- sensor ---------------------------------------------------------------------------------

inline CLI::Option* add_mode_option(CLI::App* cmd, pipeline::SimulationMode& mode) {
  return add_enum_option(cmd, "--mode", mode,
                         "simulation mode: sensor (the default), one sensor image; or per_patch, "
                         "every patch measured alone (the paper's protocol)");
}

template <typename T>
CLI::Option* add_noise_option(CLI::App* cmd, T& sigma) {
  return cmd
      ->add_option("--noise", sigma,
                   "Gaussian noise sigma of the measurements, relative to a white scene's mean "
                   "measurement (1)")
      ->check(kNoiseSigma);
}

template <typename T>
CLI::Option* add_seed_option(CLI::App* cmd, T& seed) {
  return cmd
      ->add_option("--seed", seed,
                   "seed of the random draws: the noise, and bench's procedural scene")
      ->check(kSeed);
}

inline CLI::Option* add_cfa_option(CLI::App* cmd, std::string& cfa) {
  return input_path(cmd->add_option(
                        "--cfa", cfa,
                        "a single colour sensor behind a colour filter array: RGGB, BGGR, GRBG, "
                        "GBRG or per-pixel colour responses as JSON, inline or a file (an "
                        "acquisition folder records its own; docs/acquisition.md)"))
      ->check(kNotEmpty);
}

inline CLI::Option* add_flat_field_option(CLI::App* cmd, std::string& flat_field) {
  return input_path(
      cmd->add_option("--flat-field", flat_field,
                      "the camera's white frame (an acquisition folder, or an image of its N "
                      "channels): its gain across the sensor, such as vignetting, is divided out "
                      "of every sensor image (docs/acquisition.md, \"Flat field\")"));
}

inline CLI::Option* add_camera_error_option(CLI::App* cmd, std::string& camera_error) {
  return input_path(cmd->add_option(
      "--camera-error", camera_error,
      "simulate a camera whose Phi differs from the nominal one (--phi or the model's): JSON, "
      "inline or a file, e.g. '{\"depth\": 0.1}' (depth, angular_shift_u/v, shift_y/x, period, "
      "vignetting; docs/acquisition.md)"));
}

inline CLI::Option* add_effects_option(CLI::App* cmd, std::string& effects) {
  return input_path(cmd->add_option("--effects", effects,
                                    "sensor effects JSON file: shot, read noise and the rest "
                                    "(docs/acquisition.md); --noise sets its Gaussian sigma"));
}

// ---- light-field input ----------------------------------------------------------------------

inline CLI::Option* add_lf_option(CLI::App* cmd, std::string& folder) {
  return input_path(cmd->add_option("--lf", folder, "light field folder of sub-aperture images"));
}

inline CLI::Option* add_scene_option(CLI::App* cmd, std::string& scene) {
  return input_path(cmd->add_option(
      "--scene", scene,
      "a procedural scene spec (JSON; configs/scenes/, docs/scenes.md), rendered at its own "
      "size"));
}

inline CLI::Option* add_layout_option(CLI::App* cmd, std::string& layout) {
  return cmd->add_option("--layout", layout,
                         "file-naming pattern of --lf: view_{row}_{col}.png, or "
                         "img{index}.png:cols=9[:col-major] (docs/conventions.md)");
}

inline CLI::Option* add_orient_option(CLI::App* cmd, std::string& orient) {
  return cmd->add_option(
      "--orient", orient,
      "reorient the folder's angular axes: flip-u, flip-v, transpose (comma-separated)");
}

inline CLI::Option* add_views_option(CLI::App* cmd, std::string& views) {
  return cmd->add_option("--views", views,
                         "angular window R0:R1,C0:C1, 1-based inclusive (default: the central "
                         "5x5)");
}

// ---- patches --------------------------------------------------------------------------------

inline CLI::Option* add_batch_option(CLI::App* cmd, int64_t& batch) {
  return cmd->add_option("--batch", batch, "patches per solver call (bounds memory)")
      ->check(kCount);
}

inline CLI::Option* add_window_flag(CLI::App* cmd, bool& window) {
  return cmd->add_flag("--window", window,
                       "weight patch estimates by a smooth window when stitching");
}

inline CLI::Option* add_dictionary_option(CLI::App* cmd, std::string& dictionary) {
  return input_path(cmd->add_option("--dictionary", dictionary,
                                    "dictionary file of --method dict (lfnet train's dict "
                                    "stage writes one; bench learns a small one without it)"));
}

inline CLI::Option* add_post_filter_flag(CLI::App* cmd, bool& post_filter) {
  return cmd->add_flag(
      "--post-filter", post_filter,
      "suppress artefacts that repeat with the patch stride (a spectral notch per view)");
}

inline CLI::Option* add_match_mean_flag(CLI::App* cmd, bool& match_mean) {
  return cmd->add_flag("--match-mean", match_mean,
                       "scale real measurements to the training data's mean (the paper's step)");
}

// ---- output ---------------------------------------------------------------------------------

inline CLI::Option* add_json_option(CLI::App* cmd, std::string& json) {
  return output_file(cmd->add_option("--json", json,
                                     "also write the command's record as JSON to this file (a "
                                     "new or empty file, or --force); '-': standard output"));
}

inline CLI::Option* add_force_flag(CLI::App* cmd, bool& force) {
  return cmd->add_flag("--force", force,
                       "replace the outputs that exist (--out, --json, a run folder) instead of "
                       "refusing them");
}

// The flags every command that reconstructs (evaluate, reconstruct, batch, bench) shares, bound
// once here so that their names, checks and help are the same in all four (docs/reconstruction.md,
// "Flags every command shares"). Each member points at the command's field, and every one must
// be given. bench times several models and strides (`models`, `strides`; its --stride N is
// --strides N), the others take one (`model`, `stride`). --threads is the program's option and
// may also follow the command's name (main.cc).
struct ReconstructionFlags {
  std::string* model = nullptr;
  std::vector<std::string>* models = nullptr;  // instead of `model`
  std::string* phi = nullptr;
  std::string* device = nullptr;
  pipeline::Precision* precision = nullptr;
  int64_t* tile = nullptr;
  int64_t* stride = nullptr;
  std::vector<int64_t>* strides = nullptr;  // instead of `stride`
  bool* self_ensemble = nullptr;
  int64_t* ensemble_passes = nullptr;
  std::string* method_options = nullptr;
};

// --budget SECONDS (reconstruct, evaluate, batch): the most accurate zoo model that fits.
inline CLI::Option* add_budget_option(CLI::App* cmd, double& budget) {
  return cmd
      ->add_option("--budget", budget,
                   "seconds: run the most accurate zoo model for the camera whose reconstruction "
                   "fits them on this machine, as timed by lfnet bench --calibrate (timed on "
                   "first use; docs/models.md, \"A time budget\")")
      ->check(CLI::PositiveNumber);
}

// The --precision given on the command line; nullopt for auto (the default), which a budget
// decides per model.
inline std::optional<pipeline::Precision> given_precision(const CLI::App* cmd,
                                                          pipeline::Precision resolved) {
  const auto* o = cmd->get_option("--precision");
  if (o->count() == 0 || o->results().back() == "auto") return std::nullopt;
  return resolved;
}

inline void add_reconstruction_flags(CLI::App* cmd, const ReconstructionFlags& f) {
  if ((f.model == nullptr) == (f.models == nullptr) ||
      (f.stride == nullptr) == (f.strides == nullptr) || !f.phi || !f.device || !f.precision ||
      !f.tile || !f.self_ensemble || !f.ensemble_passes || !f.method_options) {
    throw std::logic_error("add_reconstruction_flags: every shared flag needs one target");
  }
  const std::string model =
      "trained model for net, ae and cnn: a checkpoint, a file lfnet export wrote, or the name "
      "of a zoo model (lfnet models)";
  if (f.models) {
    input_path(cmd->add_option("--model", *f.models,
                               model + "; repeatable, the network methods run with each (default: "
                                       "an untrained network of --architecture)"))
        ->transform(zoo_model_file);
  } else {
    input_path(cmd->add_option("--model", *f.model, model))->transform(zoo_model_file);
  }
  add_phi_option(cmd, *f.phi);
  add_device_option(cmd, *f.device);
  // auto is chosen once the command line is read, when the models and the device are known.
  auto precision_auto = std::make_shared<bool>(true);
  cmd->add_option_function<std::string>(
      "--precision",
      [precision = f.precision, precision_auto](const std::string& text) {
        *precision_auto = text == "auto";
        if (*precision_auto) return;
        try {
          *precision = pipeline::parse_precision(text);
        } catch (const ConfigError&) {
          throw CLI::ValidationError("--precision",
                                     "'" + text + "' is unknown (known: auto, float32, bfloat16)");
        }
      },
      "auto (default), float32 or bfloat16 for the paper net's CNN branch or lfnet's U-Net; "
      "auto: bfloat16 on a CPU where native bfloat16 is measured faster, for models verified in "
      "it (bfloat16.json beside the model), float32 elsewhere (docs/performance.md)");
  cmd->parse_complete_callback([f, precision_auto] {
    if (!*precision_auto) return;
    std::vector<std::string> models;
    if (f.models) models = *f.models;
    if (f.model && !f.model->empty()) models.push_back(*f.model);
    *f.precision = pipeline::choose_precision(models, *f.device);
  });
  cmd->add_option(
         "--tile", *f.tile,
         "spatial tile of whole-image models (default: the whole image up to 800 x 800 pixels, "
         "else the largest tiles whose crops with halos fit 512 x 512; a colour net 640 and "
         "720) and of --cnn-mode full (default 128)")
      ->check(kCount);
  if (f.strides) {
    cmd->add_option("--strides", *f.strides,
                    "patch strides, comma-separated (default 9,5,2; 9: non-overlapping 9x9 "
                    "patches)")
        ->delimiter(',')
        ->check(kStride);
    auto* strides = f.strides;
    cmd->add_option_function<int64_t>(
           "--stride", [strides](const int64_t& v) { *strides = {v}; },
           "patch stride of patch methods: one stride, as --strides N")
        ->check(kStride);
  } else {
    cmd->add_option("--stride", *f.stride,
                    "patch stride of patch methods (default 5; whole-image models have none)")
        ->check(kStride);
  }
  add_self_ensemble_options(cmd, *f.self_ensemble, *f.ensemble_passes);
  input_path(cmd->add_option(
      "--method-options", *f.method_options,
      "options of the methods with options (" + pipeline::methods_with_options() +
          "), keyed by method: a JSON object or file, e.g. '{\"dict\": {\"method\": "
          "\"admm\"}}' (docs/methods.md)"));
}

}  // namespace lfnet::app

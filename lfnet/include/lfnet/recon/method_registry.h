// The reconstruction methods by name (docs/methods.md): one class per method, registered once.
// Commands, bench, batch and the report read the list from here. Adding a method takes its
// class and one registration line (docs/methods.md).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "lfnet/core/fields.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/methods.h"
#include "lfnet/recon/reconstruct.h"

namespace lfnet::recon {

// What a method needs besides the measurements and the Phi.
enum class MethodNeeds {
  kNothing,     // linear methods
  kNetwork,     // a trained model (--model)
  kDictionary,  // a dictionary file (--dictionary)
  kTruth,       // the true light field: an evaluation baseline, not a reconstruction
};

// A noise switch's choice for the last sensor image (MethodResources::switch_choice).
struct SwitchChoice {
  bool noisy = false;        // the noise-aware member ran
  double white_share = 1.0;  // optics::white_noise_share of the image (1: not needed)
  double sigma = 0.0;        // the sigma told (or estimated) times white_share: what decided
};

// The largest gain MethodResources::exposure_target applies.
constexpr double kMaxExposureGain = 4.0;

// What a method's solver may use; the caller fills in what the method needs.
struct MethodResources {
  const optics::Phi* phi = nullptr;
  int64_t patch_h = 9, patch_w = 9;
  nn::LightFieldNet net{nullptr};  // kNetwork: a checkpoint's network,
  // with a noise switch (pipeline::ModelFile): the whole-image net for sigmas >= switch_sigma
  nn::LightFieldNet noisy_net{nullptr};
  double switch_sigma = 0;
  // A noise switch's choice for each sensor image goes here (optional).
  std::shared_ptr<SwitchChoice> switch_choice;
  // Whole-image networks of a checkpoint: a sensor image whose exposure (optics::sensor_exposure)
  // is below this is brightened to it, by a gain of at most kMaxExposureGain, reconstructed and
  // dimmed back (0: never); each gain goes to *exposure_gain (optional).
  double exposure_target = 0;
  std::shared_ptr<double> exposure_gain;
  const nn::ScriptedNetwork* script = nullptr;   // or an exported one (used when set)
  const dict::Dictionary* dictionary = nullptr;  // kDictionary
  // The method's options as given (--method-options; docs/methods.md "Method options"),
  // read by the method itself (MethodWithOptions); {} for its defaults.
  nlohmann::json options = nlohmann::json::object();
  std::shared_ptr<SolverReport> report;  // iterative methods: non-convergence counts
  int64_t tile = 0;                      // whole-image methods: spatial tile (0: automatic)
  bool self_ensemble = false;            // whole-image methods: average over the Phi's mirrors
  int64_t self_ensemble_passes = 0;      // at most this many of them (0: all)
  // Whole-image methods: return 16-bit codes (int16; core/light_field.h), a plain tiled pass
  // encoding each tile as it is done (half the memory of float32).
  bool coded = false;
  // Whole-image networks: estimate the camera's angular shift from each sensor image and tell
  // the net the Phi so displaced (recon/self_calibration.h); each estimate goes to *calibration.
  bool self_calibrate = false;
  std::shared_ptr<optics::CalibrationError> calibration;
};

class Method {
 public:
  virtual ~Method() = default;
  virtual std::string name() const = 0;
  virtual std::string summary() const = 0;  // one line for help texts and docs
  virtual MethodNeeds needs() const { return MethodNeeds::kNothing; }
  // A baseline to compare with (the linear, dictionary and evaluation baselines), not one of the
  // learned reconstructions: the report's figures draw it as such.
  virtual bool baseline() const { return false; }
  // Whether the image solver uses the noise sigma it is given (a classical denoiser's strength),
  // so that a sensor image of unknown noise should be told an estimate (optics/noise_estimate.h).
  // Networks say so through their own noise input instead.
  virtual bool reads_noise() const { return false; }
  // The patch solver; a ConfigError when a needed resource is missing. kTruth methods have
  // none (the evaluation computes them from the truth).
  virtual PatchSolver solver(const MethodResources& resources) const = 0;
  // The whole-image solver, for sensor images; empty when the method works on patches only
  // (then sensor images are reconstructed patch by patch with solver()).
  virtual ImageSolver image_solver(const MethodResources&) const { return {}; }
  // Nominal floating-point operations per patch (lfnet bench), 0 when unknown.
  virtual double patch_flops(const MethodResources&) const { return 0; }
  // The method's options, checked: `given` (a JSON object; `path` names it in errors, e.g.
  // "--method-options") read strictly, returned complete as records write them. A method
  // without options (the default) refuses every key.
  virtual nlohmann::json read_options(const nlohmann::json& given, const std::string& path) const;
  // The options it runs with, given `resources`: read_options of resources.options, unless
  // the method completes them from its resources (dict: from its dictionary's record).
  virtual nlohmann::json options_used(const MethodResources& resources) const {
    return read_options(resources.options, "--method-options");
  }
  // Its options' defaults ({} without options), for help texts and docs.
  virtual nlohmann::json default_options() const { return nlohmann::json::object(); }
};

// The base of a method with options: Options is a struct with fields() (and optionally
// validate()), read from MethodResources::options by options(), so that the method declares
// its options once and every command reads them the same way.
template <typename Options>
class MethodWithOptions : public Method {
 public:
  nlohmann::json read_options(const nlohmann::json& given, const std::string& path) const override {
    return fields_to_json(options_from_json<Options>(given, path));
  }
  nlohmann::json default_options() const override { return fields_to_json(Options{}); }

 protected:
  static Options options(const MethodResources& r) {
    return options_from_json<Options>(r.options, "--method-options");
  }
};

// Adds a method, replacing one of the same name.
void register_method(std::unique_ptr<Method> method);

// The method called `name`; unknown names are a ConfigError listing the known ones.
const Method& find_method(const std::string& name);

// Every registered method's name, in registration order (net, ae, cnn, dict, pinv, pinv-nlm,
// adjoint, no-parallax for the built-ins): the order of tables and legends.
std::vector<std::string> registered_methods();

// Whether `name` is a registered baseline (Method::baseline); false for an unknown name.
bool is_baseline(const std::string& name);

// "a, b, c": the registered methods, optionally without those needing `excluded`.
std::string method_list(std::optional<MethodNeeds> excluded = std::nullopt);

// "dict, pinv-nlm": the registered methods that take options.
std::string methods_with_options();

// The options of `name` read from `given` and checked (Method::read_options) before any work;
// returned complete. `path` names the source in errors.
nlohmann::json check_method_options(const std::string& name, const nlohmann::json& given,
                                    const std::string& path = "--method-options");

// The solver of `name` with `resources`, after checking that they hold what it needs (the
// message names the option that supplies it).
PatchSolver make_solver(const std::string& name, const MethodResources& resources);

// The whole-image solver of `name` with `resources`, or an empty one when the method (with
// these resources) reconstructs patch by patch. Checks the resources as make_solver does.
ImageSolver make_image_solver(const std::string& name, const MethodResources& resources);

}  // namespace lfnet::recon

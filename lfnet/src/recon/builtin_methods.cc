#include "lfnet/recon/builtin_methods.h"

#include <algorithm>

#include "lfnet/core/error.h"
#include "lfnet/core/light_field.h"
#include "lfnet/dict/omp.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/noise_estimate.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/self_calibration.h"

namespace lfnet::recon {

// One factory per built-in method, each defined beside its class.
std::unique_ptr<Method> make_network_method(const std::string& branch);  // net, ae or cnn
std::unique_ptr<Method> make_dictionary_method();
std::unique_ptr<Method> make_pinv_method();
std::unique_ptr<Method> make_adjoint_method();   // adjoint_method.cc
std::unique_ptr<Method> make_pinv_nlm_method();  // pinv_nlm_method.cc
std::unique_ptr<Method> make_no_parallax_method();

double linear_patch_flops(const MethodResources& r) {
  return 2.0 * static_cast<double>(r.phi->measurements() * r.patch_h * r.patch_w) *
         static_cast<double>(r.phi->rows() * r.phi->cols() * r.patch_h * r.patch_w);
}

double pinv_patch_flops(const MethodResources& r) {
  if (!r.phi->local()) return linear_patch_flops(r);
  return 2.0 * static_cast<double>(r.phi->measurements() * r.phi->rows() * r.phi->cols() *
                                   r.patch_h * r.patch_w);
}

void register_builtin_methods(const MethodSink& add) {
  add(make_network_method("net"));
  add(make_network_method("ae"));
  add(make_network_method("cnn"));
  add(make_dictionary_method());
  add(make_pinv_method());
  add(make_pinv_nlm_method());
  add(make_adjoint_method());
  add(make_no_parallax_method());
}

namespace {

// net (both branches averaged), ae or cnn (one branch, plus the residual base).
class NetworkMethod : public Method {
 public:
  explicit NetworkMethod(std::string branch) : branch_(std::move(branch)) {}
  std::string name() const override { return branch_; }
  std::string summary() const override {
    return branch_ == "net" ? "the trained two-branch network (--model)"
                            : "the trained network's " + branch_ + " branch alone (--model)";
  }
  MethodNeeds needs() const override { return MethodNeeds::kNetwork; }
  PatchSolver solver(const MethodResources& r) const override {
    if (is_image(r)) {
      check_image_branch();
      // A whole-image net needs a whole sensor image: image_solver() serves sensor images.
      return [](const torch::Tensor&, const torch::Tensor&) -> torch::Tensor {
        throw ConfigError(
            "a whole-image architecture reconstructs sensor images, not per-patch measurements");
      };
    }
    return r.script ? script_solver(*r.script, branch_) : network_solver(r.net, branch_);
  }
  ImageSolver image_solver(const MethodResources& r) const override {
    if (!is_image(r)) return {};
    check_image_branch();
    const int64_t tile = r.tile;
    const bool coded = r.coded;
    // Passes that hold a float32 result anyway encode it at the end.
    auto maybe_coded = [coded](const torch::Tensor& lf) { return coded ? encode_codes(lf) : lf; };
    LFNET_CHECK_AS(ConfigError, !r.self_calibrate || !r.script,
                   "self-calibration tells the net another Phi: it needs a checkpoint, not an "
                   "exported network");
    LFNET_CHECK_AS(ConfigError, !r.self_calibrate || !r.self_ensemble,
                   "self-calibration and the self-ensemble do not go together: a displaced "
                   "camera's response has not the nominal Phi's mirror symmetries");
    if (r.script) {
      const auto* script = r.script;
      if (r.self_ensemble) {
        const auto mirrors = ensemble_mirrors(script->pixel_weights(), r.self_ensemble_passes);
        return [script, tile, mirrors, maybe_coded](const torch::Tensor& sensor,
                                                    double noise_sigma) {
          return maybe_coded(reconstruct_mirrored(
              mirrors, sensor,
              [&](const torch::Tensor& mirrored, const SensorMirror&, const ProgressCallback&) {
                return script->reconstruct_image(mirrored, tile, false, noise_sigma).unsqueeze(0);
              }));
        };
      }
      return [script, tile, maybe_coded](const torch::Tensor& sensor, double noise_sigma) {
        return maybe_coded(script->reconstruct_image(sensor, tile, true, noise_sigma).unsqueeze(0));
      };
    }
    // `coded_out`: the result in 16-bit codes.
    auto solver_of = [&r, tile](const nn::LightFieldNet& net, bool coded_out) -> ImageSolver {
      if (r.self_ensemble) {
        const int64_t passes = r.self_ensemble_passes;
        return [net, tile, passes, coded_out](const torch::Tensor& sensor, double noise_sigma) {
          auto lf = reconstruct_sensor_mirrored(net, sensor, tile, true, noise_sigma, {}, passes);
          return coded_out ? encode_codes(lf) : lf;
        };
      }
      if (r.self_calibrate) {
        const optics::Phi* phi = r.phi;
        auto found = r.calibration;
        return [net, phi, tile, coded_out, found](const torch::Tensor& sensor, double noise_sigma) {
          // The camera's angular shift from its own sensor image, then the whole image with the
          // net told the Phi so displaced; the net holds the nominal Phi again afterwards.
          const auto calibration = estimate_angular_shift(net, *phi, sensor, noise_sigma);
          if (found) *found = calibration.error;
          tell_camera(net, *phi, calibration.error);
          const NominalPhiOnExit nominal(net, *phi);
          return reconstruct_sensor_tiled(net, sensor, tile, true, noise_sigma, {}, coded_out);
        };
      }
      return [net, tile, coded_out](const torch::Tensor& sensor, double noise_sigma) {
        return reconstruct_sensor_tiled(net, sensor, tile, true, noise_sigma, {}, coded_out);
      };
    };
    // A sensor image dimmer than exposure_target is brightened to it (its noise sigma with it),
    // reconstructed, and the light field dimmed back: the net sees the exposures it trained on.
    auto exposed_of = [&r, coded, maybe_coded,
                       &solver_of](const nn::LightFieldNet& net) -> ImageSolver {
      auto as_is = solver_of(net, coded);
      if (r.exposure_target <= 0) return as_is;
      auto in_float = coded ? solver_of(net, false) : as_is;
      const optics::Phi* phi = r.phi;
      const double target = r.exposure_target;
      auto applied = r.exposure_gain;
      return [as_is, in_float, phi, target, applied, maybe_coded](const torch::Tensor& sensor,
                                                                  double noise_sigma) {
        const double exposure = optics::sensor_exposure(*phi, sensor);
        const double gain = std::clamp(target / std::max(exposure, 1e-12), 1.0, kMaxExposureGain);
        if (applied) *applied = gain;
        if (gain == 1.0) return as_is(sensor, noise_sigma);
        return maybe_coded(in_float(sensor * gain, noise_sigma * gain).div_(gain));
      };
    };
    if (r.noisy_net.is_empty()) return exposed_of(r.net);
    // A noise switch: the part of the sigma the image is told (or estimated) that is the
    // sensor's own, white noise picks the net; scene detail and noise the scene's views carry
    // are the quiet net's to keep (docs/models.md, "One model for any noise").
    auto quiet = exposed_of(r.net), noisy = exposed_of(r.noisy_net);
    const double from = r.switch_sigma;
    const optics::Phi* phi = r.phi;
    auto choice = r.switch_choice;
    return [quiet, noisy, from, phi, choice](const torch::Tensor& sensor, double noise_sigma) {
      const double share = noise_sigma < from ? 1.0 : optics::white_noise_share(*phi, sensor);
      const bool loud = noise_sigma * share >= from;
      if (choice) *choice = {loud, share, noise_sigma * share};
      return loud ? noisy(sensor, noise_sigma) : quiet(sensor, noise_sigma);
    };
  }
  double patch_flops(const MethodResources& r) const override {
    if (r.net.is_empty()) return 0;
    nn::BranchSelection run;
    run.ae = branch_ != "cnn";
    run.cnn = branch_ != "ae";
    return nn::patch_flops(r.net->options(), run);
  }

 private:
  // Whether the model (a checkpoint's net or an exported one) reconstructs whole images.
  static bool is_image(const MethodResources& r) { return whole_image_model(r.net, r.script); }
  void check_image_branch() const {
    LFNET_CHECK_AS(ConfigError, branch_ == "net", "method '", branch_,
                   "' names a branch of the paper's network; a model of a whole-image "
                   "architecture has none: use --method net");
  }
  std::string branch_;
};

// dict: sparse coding in a learned dictionary (OMP or ADMM-LASSO). Its options are
// dict::SparseCodingOptions: OMP with 10 atoms, then the dictionary's own recommendation (its
// record's "coding", set when it was tuned), then the options given.
class DictionaryMethod : public MethodWithOptions<dict::SparseCodingOptions> {
 public:
  std::string name() const override { return "dict"; }
  std::string summary() const override {
    return "sparse coding in a K-SVD dictionary (--dictionary; OMP or ADMM, by its options)";
  }
  MethodNeeds needs() const override { return MethodNeeds::kDictionary; }
  bool baseline() const override { return true; }  // the paper's baseline
  PatchSolver solver(const MethodResources& r) const override {
    return dictionary_solver(*r.phi, *r.dictionary, coding(r), r.patch_h, r.patch_w, r.report);
  }
  double patch_flops(const MethodResources& r) const override {
    if (!r.dictionary) return 0;
    return dict::omp_patch_flops(static_cast<double>(r.phi->measurements() * r.patch_h * r.patch_w),
                                 static_cast<double>(r.dictionary->dimension()),
                                 static_cast<double>(r.dictionary->size()),
                                 static_cast<double>(coding(r).omp.max_atoms));
  }
  nlohmann::json options_used(const MethodResources& r) const override {
    return r.dictionary ? coding(r).to_json() : read_options(r.options, "--method-options");
  }

 private:
  static dict::SparseCodingOptions coding(const MethodResources& r) {
    options(r);  // the options given, checked on their own: errors name their own keys
    nlohmann::json merged = dict::SparseCodingOptions{}.to_json();
    const auto& record = r.dictionary->training;
    if (record.is_object() && record.contains("coding") && record["coding"].is_object()) {
      merged.merge_patch(record["coding"]);
      dict::SparseCodingOptions::from_json(merged, "the dictionary's coding");
    }
    merged.merge_patch(r.options);
    return dict::SparseCodingOptions::from_json(merged, "--method-options");
  }
};

// pinv: the Tikhonov-regularised pseudo-inverse of each patch matrix.
class PinvMethod : public Method {
 public:
  std::string name() const override { return "pinv"; }
  std::string summary() const override { return "the regularised pseudo-inverse (linear)"; }
  bool baseline() const override { return true; }
  PatchSolver solver(const MethodResources& r) const override {
    return pinv_solver(*r.phi, r.patch_h, r.patch_w);
  }
  double patch_flops(const MethodResources& r) const override { return pinv_patch_flops(r); }
};

// no-parallax: every view is the angular mean of the truth (an evaluation baseline).
class NoParallaxMethod : public Method {
 public:
  std::string name() const override { return "no-parallax"; }
  std::string summary() const override {
    return "every view set to the angular mean of the truth (a baseline of lfnet evaluate)";
  }
  MethodNeeds needs() const override { return MethodNeeds::kTruth; }
  bool baseline() const override { return true; }
  PatchSolver solver(const MethodResources&) const override {
    throw ConfigError("no-parallax needs the true light field: it is a method of lfnet evaluate");
  }
};

}  // namespace

std::unique_ptr<Method> make_network_method(const std::string& branch) {
  return std::make_unique<NetworkMethod>(branch);
}
std::unique_ptr<Method> make_dictionary_method() { return std::make_unique<DictionaryMethod>(); }
std::unique_ptr<Method> make_pinv_method() { return std::make_unique<PinvMethod>(); }
std::unique_ptr<Method> make_no_parallax_method() { return std::make_unique<NoParallaxMethod>(); }

}  // namespace lfnet::recon

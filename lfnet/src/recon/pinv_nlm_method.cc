// pinv-nlm: the pseudo-inverse, then a denoiser of the views (non-local means: OpenCV's by
// default, lfnet's own as "nlm"): the classical baseline for noisy sensor images
// (docs/methods.md).
#include "lfnet/core/error.h"
#include "lfnet/core/light_field.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/builtin_methods.h"
#include "lfnet/recon/denoise.h"

namespace lfnet::recon {

namespace {

// Its options: the denoiser (recon::find_denoiser) and the denoiser's own options.
struct PinvNlmOptions {
  std::string denoiser = "opencv-nlm";
  nlohmann::json options = nlohmann::json::object();

  template <typename Fields>
  void fields(Fields& f) {
    f("denoiser", denoiser);
    f("options", options);
  }
};

class PinvNlmMethod : public MethodWithOptions<PinvNlmOptions> {
 public:
  std::string name() const override { return "pinv-nlm"; }
  bool reads_noise() const override { return true; }
  bool baseline() const override { return true; }
  std::string summary() const override {
    return "the pseudo-inverse, then non-local means of the views (sensor images; the noise "
           "sigma sets its strength; OpenCV's by default)";
  }
  nlohmann::json read_options(const nlohmann::json& given, const std::string& path) const override {
    auto o = options_from_json<PinvNlmOptions>(given, path);
    const Denoiser* denoiser = nullptr;
    try {
      denoiser = &find_denoiser(o.denoiser);
    } catch (const ConfigError& e) {
      throw ConfigError(path + ".denoiser: " + e.what());
    }
    o.options = denoiser->read_options(o.options, path + ".options");
    return fields_to_json(o);
  }
  PatchSolver solver(const MethodResources&) const override {
    return [](const torch::Tensor&, const torch::Tensor&) -> torch::Tensor {
      throw ConfigError("pinv-nlm denoises whole sensor images, not per-patch measurements");
    };
  }
  ImageSolver image_solver(const MethodResources& r) const override {
    const nlohmann::json o = read_options(r.options, "--method-options");
    const Denoiser* denoiser = &find_denoiser(o["denoiser"].get<std::string>());
    const nlohmann::json& denoiser_options = o["options"];
    // The pseudo-inverse's noise per unit of measurement noise (the same for every phase of
    // the periodic models, up to their small differences: the mean over phases). A local
    // model's rows hold its per-pixel pseudo-inverses and zeros.
    const bool local = r.phi->local();
    const auto pinv = local ? optics::pixel_pinv_stack(*r.phi, r.patch_h, r.patch_w)
                            : optics::pinv_matrix_stack(*r.phi, r.patch_h, r.patch_w);
    double gain = 0;
    for (int64_t i = 0; i < pinv.size(0); ++i) {
      const auto rows = local ? pinv[i].permute({1, 2, 0}).reshape({-1, pinv.size(1)}) : pinv[i];
      gain += pinv_noise_sigma(rows, 1.0);
    }
    gain /= static_cast<double>(pinv.size(0));
    const PatchSolver solver = local ? pixel_pinv_solver(pinv) : pinv_solver(pinv);
    ReconstructOptions ro;
    ro.patch_h = r.patch_h;
    ro.patch_w = r.patch_w;
    ro.stride = r.phi->local() ? r.patch_h : ro.stride;  // per pixel: overlaps add nothing
    ro.clamp = false;                                    // clamping would bias the noise
    const optics::Phi* phi = r.phi;
    const bool coded = r.coded;
    return [phi, solver, gain, ro, denoiser, denoiser_options, coded](const torch::Tensor& sensor,
                                                                      double sigma) {
      auto lf = reconstruct_sensor(*phi, sensor, solver, ro);  // (1, U, V, H, W)
      const auto shape = lf.sizes().vec();
      auto views = lf.reshape({shape[1] * shape[2], shape[3], shape[4]});
      auto out = denoiser->denoise(views, sigma * gain, denoiser_options).reshape(shape);
      return coded ? encode_codes(out) : out.clamp(0.0, 1.0);
    };
  }
  double patch_flops(const MethodResources& r) const override { return pinv_patch_flops(r); }
};

}  // namespace

// Declared and registered in builtin_methods.cc.
std::unique_ptr<Method> make_pinv_nlm_method() { return std::make_unique<PinvNlmMethod>(); }

}  // namespace lfnet::recon

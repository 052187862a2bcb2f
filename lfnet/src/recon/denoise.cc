#include "lfnet/recon/denoise.h"

#include <torch/torch.h>

#include <cmath>

#include "lfnet/core/error.h"
#include "lfnet/core/registry.h"

namespace lfnet::recon {

void NlmOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, search >= 0 && search <= 50, "search: must be in 0..50, got ",
                 search);
  LFNET_CHECK_AS(ConfigError, patch >= 0 && patch <= 20, "patch: must be in 0..20, got ", patch);
  LFNET_CHECK_AS(ConfigError, h > 0 && std::isfinite(h), "h: must be > 0, got ", h);
}

torch::Tensor non_local_means(const torch::Tensor& x, double sigma, const NlmOptions& o) {
  LFNET_CHECK_AS(ConfigError, x.dim() == 3, "non_local_means: expected (C, H, W), got ", x.sizes());
  LFNET_CHECK_AS(ConfigError, o.search >= 0 && o.patch >= 0 && o.h > 0,
                 "non_local_means: search and patch radii must be >= 0 and h > 0");
  LFNET_CHECK_AS(ConfigError, sigma >= 0 && std::isfinite(sigma),
                 "non_local_means: sigma must be finite and >= 0, got ", sigma);
  if (sigma == 0) return x;
  torch::NoGradGuard no_grad;
  const int64_t h = x.size(1), w = x.size(2), s = o.search, p = o.patch, r = s + p;
  const auto img = x.to(torch::kFloat32).contiguous();
  // Reflection needs the pad to be smaller than the image; replicate beyond that.
  const bool reflect = r < h && r < w;
  auto padded = reflect ? torch::reflection_pad2d(img.unsqueeze(0), {r, r, r, r})
                        : torch::replication_pad2d(img.unsqueeze(0), {r, r, r, r});
  padded = padded.squeeze(0);
  const double two_var = 2 * sigma * sigma, scale = 1.0 / ((o.h * sigma) * (o.h * sigma));
  auto acc = torch::zeros_like(img), total = torch::zeros({h, w}, img.options());
  for (int64_t dy = -s; dy <= s; ++dy) {
    for (int64_t dx = -s; dx <= s; ++dx) {
      // The candidate image at this offset, over the patch margin too (for the patch sums).
      auto cand = padded.slice(1, s + dy, s + dy + h + 2 * p).slice(2, s + dx, s + dx + w + 2 * p);
      auto centre = padded.slice(1, s, s + h + 2 * p).slice(2, s, s + w + 2 * p);
      auto diff = (centre - cand).square().mean(0, true).unsqueeze(0);  // (1, 1, h + 2p, w + 2p)
      auto d2 = torch::avg_pool2d(diff, {2 * p + 1, 2 * p + 1}, {1, 1}).squeeze(0).squeeze(0);
      auto weight = torch::exp(-(d2 - two_var).clamp_min(0.0) * scale);  // (h, w)
      acc += weight.unsqueeze(0) * cand.slice(1, p, p + h).slice(2, p, p + w);
      total += weight;
    }
  }
  return (acc / total.unsqueeze(0)).to(x.scalar_type());
}

double pinv_noise_sigma(const torch::Tensor& pinv_matrix, double sigma) {
  LFNET_CHECK(pinv_matrix.dim() == 2, "pinv_noise_sigma: expected a matrix, got ",
              pinv_matrix.sizes());
  return sigma * std::sqrt(pinv_matrix.to(torch::kFloat64).square().sum(1).mean().item<double>());
}

namespace {

// lfnet's own non-local means over all views at once.
class NlmDenoiser : public DenoiserWithOptions<NlmOptions> {
 public:
  std::string name() const override { return "nlm"; }
  std::string summary() const override {
    return "lfnet's non-local means: (2 patch + 1)^2 neighbourhoods of all views at once, within "
           "a (2 search + 1)^2 window, strength h times the noise sigma";
  }

 protected:
  torch::Tensor run(const torch::Tensor& views, double sigma,
                    const NlmOptions& options) const override {
    return non_local_means(views, sigma, options);
  }
};

NamedRegistry<Denoiser>& denoisers() {
  static NamedRegistry<Denoiser> r(
      [](NamedRegistry<Denoiser>& builtins) { builtins.add(std::make_unique<NlmDenoiser>()); });
  return r;
}

}  // namespace

void register_denoiser(std::unique_ptr<Denoiser> denoiser) {
  LFNET_CHECK(denoiser != nullptr, "register_denoiser: no denoiser");
  denoisers().add(std::move(denoiser));
}

const Denoiser& find_denoiser(const std::string& name) {
  if (const Denoiser* d = denoisers().find(name)) return *d;
  std::string hint;
  if (name.rfind("opencv", 0) == 0) {
    hint =
        "; OpenCV's denoisers are registered by lfnet's program (built with OpenCV), not by "
        "the numerical core alone";
  }
  throw ConfigError("unknown denoiser '" + name + "' (known: " + denoisers().list() + ")" + hint);
}

std::vector<std::string> registered_denoisers() { return denoisers().names(); }

}  // namespace lfnet::recon

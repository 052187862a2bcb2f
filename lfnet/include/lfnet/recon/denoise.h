// The denoisers of the `pinv-nlm` baseline (docs/methods.md), by name: lfnet's own non-local
// means (Buades, Coll and Morel 2005) for light fields, built in as "nlm", and any registered
// by a library outside the numerical core (OpenCV's as "opencv-nlm", lfnet/cv/opencv.h).
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"

namespace lfnet::recon {

// lfnet's non-local means: the views are the channels of one image, so the similarity of two
// neighbourhoods is measured over every view at once and all views share the weights:
// parallax does not blur the views apart.
struct NlmOptions {
  int64_t search = 5;  // search radius: (2 s + 1)^2 candidate offsets
  int64_t patch = 1;   // patch radius: (2 p + 1)^2 pixels of every channel are compared
  double h = 0.35;     // filtering strength, in units of the noise sigma

  template <typename Fields>
  void fields(Fields& f) {
    f("search", search);
    f("patch", patch);
    f("h", h, Range::above(0, 100));
  }
  void validate() const;
};

// Denoises x (C, H, W) whose channels carry independent Gaussian noise of `sigma`: each pixel
// becomes the mean of the pixels of its search window, weighted by
// exp(-max(d^2 - 2 sigma^2, 0) / (h sigma)^2), d^2 the mean squared difference of the two
// neighbourhoods over all channels. Returns x unchanged for sigma = 0. Reflects at the borders.
torch::Tensor non_local_means(const torch::Tensor& x, double sigma, const NlmOptions& options = {});

// The noise sigma of the per-pixel pseudo-inverse's views when the measurements carry
// Gaussian noise of `sigma`: sigma times the root mean square of the rows' norms of the
// pseudo-inverse (UV h w, N h w), a pinv_matrix.
double pinv_noise_sigma(const torch::Tensor& pinv_matrix, double sigma);

// A denoiser of views (C, H, W) in [0, 1] whose pixels carry Gaussian noise of a known sigma.
class Denoiser {
 public:
  virtual ~Denoiser() = default;
  virtual std::string name() const = 0;
  virtual std::string summary() const = 0;
  // Its options read from `given` (a JSON object; `path` names it in errors) and checked;
  // returned complete.
  virtual nlohmann::json read_options(const nlohmann::json& given,
                                      const std::string& path) const = 0;
  // The denoised views; `options` as read_options accepts them. sigma = 0 returns `views`.
  virtual torch::Tensor denoise(const torch::Tensor& views, double sigma,
                                const nlohmann::json& options) const = 0;
};

// The base of a denoiser whose options are the struct Options (fields(), validate()).
template <typename Options>
class DenoiserWithOptions : public Denoiser {
 public:
  nlohmann::json read_options(const nlohmann::json& given, const std::string& path) const override {
    return fields_to_json(options_from_json<Options>(given, path));
  }
  torch::Tensor denoise(const torch::Tensor& views, double sigma,
                        const nlohmann::json& options) const override {
    return run(views, sigma, options_from_json<Options>(options, name() + " options"));
  }

 protected:
  virtual torch::Tensor run(const torch::Tensor& views, double sigma,
                            const Options& options) const = 0;
};

// Adds a denoiser, replacing one of the same name.
void register_denoiser(std::unique_ptr<Denoiser> denoiser);

// The denoiser called `name`; an unknown name is a ConfigError listing the known ones (and,
// for OpenCV's, that this build has no OpenCV).
const Denoiser& find_denoiser(const std::string& name);

// Every registered denoiser's name, "nlm" first.
std::vector<std::string> registered_denoisers();

}  // namespace lfnet::recon

// Learnable codes: a Phi whose weights are a differentiable function of parameters that keep
// the camera physical (docs/acquisition.md, "Learnable codes"), so that the code can be trained
// with a reconstruction network. Each family gives pixel weights M_n(u, v) over a period of
// T x T pixels, normalised like every built-in Phi (a white light field measures 1 on average),
// and the Phi they make is a `calibrated` one: every command uses it like a measured camera.
#pragma once

#include <torch/torch.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

#include "lfnet/core/fields.h"
#include "lfnet/optics/phi.h"

namespace lfnet::nn {

// Which family of codes, and how it starts.
//   mask:     a coded mask near the sensor: a transmittance in [0, 1] per measurement, view and
//             pixel of a T x T period, the sigmoid of a free parameter;
//   aperture: a coded aperture: a transmittance in [0, 1] per measurement (shot) and view, the
//             same at every pixel (T = 1);
//   asp:      Angle Sensitive Pixels: per measurement and pixel of the period, a grating's
//             frequency beta (>= 0), orientation gamma and phase alpha (radians), and a
//             modulation depth m in [0, max_depth] (a sigmoid), the response
//             (1 + m cos(beta (cos(gamma) theta_u + sin(gamma) phi_v) + alpha)) / 2 of
//             optics/asp.h, so that a learned tile can be fabricated.
struct LearnedPhiOptions {
  std::string family = "mask";
  int64_t period = 1;           // T (mask and asp; an aperture is the same at every pixel)
  double max_depth = 1.0;       // asp: the largest modulation depth the device allows, in (0, 1]
  std::string init = "random";  // mask, aperture: "random" (uniform transmittances); asp: "table"
  uint64_t seed = 0;            // of the random start
  double init_spread = 0.5;     // asp: the spread of the random part of its start, radians

  template <typename Fields>
  void fields(Fields& f) {
    f("family", family);
    f("period", period);
    f("max_depth", max_depth);
    f("init", init);
    f("seed", seed);
    f("init_spread", init_spread, Range::closed(0, 10));
  }
  // Throws ConfigError naming the bad field.
  void validate() const;
};

// The `calibrated` Phi spec of pixel weights (N, U, V, T, T), normalised as they are (its
// params: period, weights in float64, normalise false, and `source`, e.g. "learned mask").
optics::PhiSpec calibrated_spec(const torch::Tensor& weights, const std::string& source);

class LearnedPhiImpl : public torch::nn::Module {
 public:
  // A code of `n` measurements for a rows x cols grid of views.
  LearnedPhiImpl(const LearnedPhiOptions& options, int64_t n, int64_t rows, int64_t cols);

  // The pixel weights (N, U, V, T, T), float32, differentiable in the parameters, before
  // normalisation: transmittances for mask and aperture, the ASP response for asp.
  torch::Tensor response() const;
  // The same normalised so a white light field measures 1 on average (optics::normalise_white).
  torch::Tensor weights() const;
  // The Phi of the current weights: `calibrated`, its weights those of weights().
  optics::PhiSpec spec() const;
  // The parameters in their physical units, for people: transmittances (N, U, V, T, T), or the
  // ASP's beta, gamma, alpha and m per measurement and pixel.
  nlohmann::json physical() const;
  // mask: the transmittances rounded to 0 or 1 (normalised): the code a binary mask prints.
  torch::Tensor binarised_weights() const;
  // mask, aperture: the binarised weights in the forward pass, with the gradient of the
  // transmittances (straight through the rounding, Bengio et al. 2013), so a code learns to be
  // rounded.
  torch::Tensor straight_through_weights() const;

  const LearnedPhiOptions& options() const { return options_; }

 private:
  LearnedPhiOptions options_;
  int64_t n_, rows_, cols_;
  torch::Tensor logits_;                        // mask (N, U, V, T, T); aperture (N, U, V)
  torch::Tensor beta_, gamma_, alpha_, depth_;  // asp: (N, T, T) each; depth before its sigmoid
  torch::Tensor theta_, phi_;                   // asp: view angles in [-1, 1], (U, 1) and (1, V)
};
TORCH_MODULE(LearnedPhi);

}  // namespace lfnet::nn

#include "lfnet/nn/pixel_phi.h"

#include <torch/torch.h>

#include "lfnet/core/error.h"
#include "lfnet/nn/image_net.h"

namespace lfnet::nn {

void check_crop_multiple(const NetworkOptions& o, int64_t multiple,
                         const std::string& architecture) {
  if (o.patch.height % multiple != 0 || o.patch.width % multiple != 0) {
    throw ConfigError("patch: the " + architecture +
                      " architecture's training crops need sides that are multiples of " +
                      std::to_string(multiple) + ", got " + o.patch.to_json().dump());
  }
}

void register_pixel_phi(LightFieldNetImpl& net) {
  const auto& o = net.options();
  const auto& p = o.patch;
  net.phi = net.register_buffer("phi", torch::zeros({o.measurements, p.rows, p.cols, 1, 1}));
  net.pixel_pinv =
      net.register_buffer("pixel_pinv", torch::zeros({1, 1, o.measurements, p.rows * p.cols}));
  if (o.frames > 1) {
    net.pixel_hold =
        net.register_buffer("pixel_hold", torch::zeros({1, 1, o.measurements, p.rows * p.cols}));
  }
}

void check_pixel_weights(const LightFieldNetImpl& net, const torch::Tensor& weights,
                         const std::string& architecture) {
  const auto& o = net.options();
  const auto& p = o.patch;
  LFNET_CHECK(
      weights.dim() == 5 && weights.size(0) == o.measurements && weights.size(1) == p.rows &&
          weights.size(2) == p.cols && weights.size(3) >= 1 && weights.size(3) == weights.size(4),
      "set_phi: the ", architecture, " architecture expects the pixel weights of one period (",
      o.measurements, ", ", p.rows, ", ", p.cols, ", T, T), got ", weights.sizes());
  LFNET_CHECK_AS(NumericalError, torch::isfinite(weights).all().item<bool>(),
                 "set_phi: the pixel weights contain NaN or inf");
}

void store_pixel_phi(LightFieldNetImpl& net, const torch::Tensor& weights) {
  torch::NoGradGuard no_grad;
  const int64_t frames = net.options().frames;
  auto w = weights.to(torch::kFloat64);
  const auto inverse = pixel_pseudo_inverses(w, net.options().pinv_lambda);
  if (frames > 1) {
    // A time-coded Phi: the still-equivalent pseudo-inverse (the sub-frames' weights summed)
    // held in every frame, the estimate of a scene that does not move; the minimum-norm one
    // leaves each pixel's unexposed sub-frames dark (docs/video.md).
    const auto s = w.sizes();
    const auto still = w.view({s[0], frames, s[1] / frames, s[2], s[3], s[4]}).sum(1);
    const auto hold =
        pixel_pseudo_inverses(still, net.options().pinv_lambda).repeat({1, 1, 1, frames});
    net.pixel_hold.set_(hold.to(net.phi.options()).contiguous());
  }
  net.phi.set_(weights.to(net.phi.options()).contiguous().clone());
  net.pixel_pinv.set_(inverse.to(net.phi.options()).contiguous());
}

torch::Tensor pixel_period_maps(const torch::Tensor& period, const torch::Tensor& phase,
                                int64_t batch, int64_t h, int64_t w) {
  const int64_t t = period.size(0);
  const auto ph = phase.defined() ? phase.to(torch::kCPU) : torch::zeros({batch}, torch::kInt64);
  const auto rows =
      (torch::arange(h, torch::kInt64).unsqueeze(0) + ph.div(t, "floor").unsqueeze(1)) % t;
  const auto cols = (torch::arange(w, torch::kInt64).unsqueeze(0) + (ph % t).unsqueeze(1)) % t;
  const auto device = period.device();
  return period.index({rows.unsqueeze(2).to(device), cols.unsqueeze(1).to(device)});
}

int64_t pixel_phases(const LightFieldNetImpl& net) { return net.phi.size(3) * net.phi.size(4); }

std::vector<size_t> pixel_phase_axes(const std::string& name, size_t rank) {
  if (name == "phi" && rank == 5) return {3, 4};
  if (name == "pixel_pinv" || name == "pixel_hold") return {0, 1};
  return {};
}

double tiled_image_flops(const ImageTiling& tiling, double pixel_flops, int64_t height,
                         int64_t width, int64_t tile) {
  double pixels = 0;
  for (const auto& t : image_tiles(tiling, height, width, tile)) {
    pixels += static_cast<double>((t.a1 - t.a0) * (t.b1 - t.b0));
  }
  return pixel_flops * pixels;
}

}  // namespace lfnet::nn

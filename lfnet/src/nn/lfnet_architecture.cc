// lfnet's own architecture (docs/architectures.md): the per-pixel Tikhonov pseudo-inverse of the
// sensor image, refined by a U-Net over the spatial axes (nn/image_net.h) whose channels are the
// views. Fully convolutional: trained on crops, it reconstructs whole sensor images.
#include <torch/torch.h>

#include <numeric>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/nn/image_net.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/pixel_phi.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/cfa.h"

namespace lfnet::nn {

namespace {

// The methods of an exported net of the lfnet architecture (docs/export.md). The U-Net is the
// submodule `image`, traced from the C++ module itself; these methods repeat only the
// per-pixel pseudo-inverse, the padding and the noise channel of this file, op for op
// (reconstruct, simulate, forward and the input checks are every whole-image net's:
// kWholeImageScriptSource). A net of a time-coded camera has its own forward_image, which also
// reads the held still estimate (unet_input).
constexpr const char* kPixelMapSource = R"TS(
def pixel_map_image(self, maps: Tensor, sensor: Tensor, phase: int) -> Tensor:
    t = maps.size(0)
    x = sensor.to(maps.dtype)
    if t == 1:
        return torch.einsum("nk,bnij->bkij", [maps[0][0], x])
    h = x.size(2)
    w = x.size(3)
    rows = torch.remainder(torch.arange(h, device=x.device) + phase // t, t)
    cols = torch.remainder(torch.arange(w, device=x.device) + phase % t, t)
    m = maps.index_select(0, rows).index_select(1, cols)
    return torch.einsum("ijnk,bnij->bkij", [m, x])

def pixel_pinv_image(self, sensor: Tensor, phase: int = 0) -> Tensor:
    return self.pixel_map_image(self.pixel_pinv, sensor, phase)

def with_noise(self, x: Tensor, noise_sigma: float) -> Tensor:
    if self.noise_input:
        return torch.cat([x, x.new_full([x.size(0), 1, x.size(2), x.size(3)], noise_sigma)], 1)
    return x
)TS";

constexpr const char* kForwardSource = R"TS(
def forward_image(self, sensor: Tensor, phase: int = 0, noise_sigma: float = 0.0) -> Tensor:
    self.check_sensor_images(sensor, phase)
    b = sensor.size(0)
    h = sensor.size(2)
    w = sensor.size(3)
    m = self.multiple
    ph = (m - h % m) % m
    pw = (m - w % m) % m
    start, x = self.estimates(sensor, phase)
    if ph > 0 or pw > 0:
        start = torch.constant_pad_nd(start, [0, pw, 0, ph])
        x = torch.constant_pad_nd(x, [0, pw, 0, ph])
    out = start + self.image.forward(self.with_noise(x, noise_sigma))
    return out.narrow(2, 0, h).narrow(3, 0, w).reshape([b, self.patch_shape[0], self.patch_shape[1], h, w])
)TS";

// The estimate the U-Net corrects and what it reads (unet_input): a still net's pseudo-inverse,
// twice; a time-coded camera's held still estimate, and that beside the pseudo-inverse.
constexpr const char* kStillEstimatesSource = R"TS(
def estimates(self, sensor: Tensor, phase: int) -> Tuple[Tensor, Tensor]:
    base = self.pixel_pinv_image(sensor, phase)
    return base, base
)TS";

constexpr const char* kFramesEstimatesSource = R"TS(
def estimates(self, sensor: Tensor, phase: int) -> Tuple[Tensor, Tensor]:
    start = self.pixel_map_image(self.pixel_hold, sensor, phase)
    return start, torch.cat([start, self.pixel_pinv_image(sensor, phase)], 1)
)TS";

// The prefix of the U-Net's parameter names: the network's submodule "image"; its options are
// the section of the same name.
constexpr std::string_view kImagePrefix = "image.";
constexpr const char* kImageSection = "image";

// The U-Net's input: the per-pixel estimate `base` (B, C U V, h, w), and for a net of a
// time-coded camera the held still estimate `start` before it (B, 2 T U V, h, w).
torch::Tensor unet_input(const LightFieldNetImpl& net, const torch::Tensor& base,
                         const torch::Tensor& start) {
  return net.options().frames > 1 ? torch::cat({start, base}, 1) : base;
}

// `start` (the pseudo-inverse, or a time-coded Phi's held still estimate) plus the U-Net's
// correction read from `base` (B, C U V, h, w), with a noise channel (B sigmas, undefined: 0)
// when the net is noise-aware.
torch::Tensor refine(LightFieldNetImpl& net, const torch::Tensor& base, const torch::Tensor& noise,
                     const torch::Tensor& start) {
  const auto image = image_layers(net);
  const auto x = unet_input(net, base, start);
  // The correction is a fresh tensor: `start` is added into it.
  if (!image->options().noise_input) return image->forward(x).add_(start);
  auto sigma =
      noise.defined() ? noise.to(base.options()) : torch::zeros({base.size(0)}, base.options());
  auto channel = sigma.view({-1, 1, 1, 1}).expand({base.size(0), 1, base.size(2), base.size(3)});
  return image->forward(torch::cat({x, channel}, 1)).add_(start);
}

// A colour net's CFA response at every pixel of crops (B, h, w) whose pixel (0, 0) has phase
// `phase` (B, undefined: 0), from the response tile (3, L, L) of the net's period: (B, 3, h, w).
torch::Tensor response_maps(const torch::Tensor& tile, const torch::Tensor& phase, int64_t batch,
                            int64_t h, int64_t w) {
  return pixel_period_maps(tile.permute({1, 2, 0}), phase, batch, h, w)  // (B, h, w, 3)
      .permute({0, 3, 1, 2});
}

// Bilinear demosaicing inside a colour net: per-pixel estimates `base` (B, K, h, w), each pixel
// in the one colour of its response (B, 3, h, w), to (B, 3 K, h, w), colour-major. A pixel keeps
// its own colour; a missing colour is the bilinear-weighted mean of that colour's pixels among
// its 3 x 3 neighbours within the crop (a tile's halo keeps its edges away from its core). For a
// Bayer pattern this is optics::demosaic but on the image's outermost pixels, where that mirrors
// the image.
torch::Tensor demosaic_base(const torch::Tensor& base, const torch::Tensor& response) {
  const auto kernel =
      torch::tensor({0.25, 0.5, 0.25, 0.5, 1.0, 0.5, 0.25, 0.5, 0.25}, torch::kFloat64)
          .to(base.options())
          .view({1, 1, 3, 3});
  std::vector<torch::Tensor> colours;
  for (int64_t c = 0; c < 3; ++c) {
    const auto own = response.select(1, c).unsqueeze(1).to(base.options());  // (B, 1, h, w)
    const auto sum = optics::filter_channels(base * own, kernel, 1).squeeze(2);
    const auto weight = torch::conv2d(own, kernel, {}, 1, 1).clamp_min(1e-6);
    colours.push_back(own * base + (1 - own) * (sum / weight));
  }
  return torch::cat(colours, 1);
}

// The per-pixel pseudo-inverse (B, U V, h, w) of crops of phase `phase` (B, undefined: 0) as
// the U-Net's base: itself for a grey net, demosaiced for a colour net (B, 3 U V, h, w), by
// `network.demosaic`: bilinear within the crop, or malvar with the crop's edges mirrored.
torch::Tensor colour_base(const LightFieldNetImpl& net, const torch::Tensor& pinv,
                          const torch::Tensor& phase) {
  if (net.options().colours() == 1) return pinv;
  const auto response =
      response_maps(net.cfa_response, phase, pinv.size(0), pinv.size(2), pinv.size(3));
  if (net.options().demosaic == optics::Demosaic::kMalvar) {
    const auto rgb = optics::demosaic_malvar(pinv, response.to(pinv.options()));
    return rgb.reshape({pinv.size(0), 3 * pinv.size(1), pinv.size(2), pinv.size(3)});
  }
  return demosaic_base(pinv, response);
}

// The parameters of a still net's input and output layers that a net of the same U-Net for a
// time-coded camera of T sub-frames starts from (train --init): the input layer reads each
// sub-frame's copy of the held still estimate with 1/T of the still net's weights and the
// time-coded pseudo-inverse with none, and the output layer gives every sub-frame the still
// net's correction. The video net so starts as the still net applied as if nothing moved.
// False, leaving `dst` alone, for any other parameter.
bool frames_from_still(const std::string& name, const torch::Tensor& src, torch::Tensor& dst,
                       int64_t views, int64_t frames) {
  torch::NoGradGuard no_grad;
  const int64_t extra = src.dim() == 4 ? src.size(1) - views : -1;  // the noise channel
  if (name == "input.weight" && src.dim() == 4 && dst.dim() == 4 && src.size(0) == dst.size(0) &&
      extra >= 0 && dst.size(1) == 2 * frames * views + extra) {
    dst.zero_();
    for (int64_t t = 0; t < frames; ++t) {
      dst.narrow(1, t * views, views).copy_(src.narrow(1, 0, views) / static_cast<double>(frames));
    }
    if (extra > 0) dst.narrow(1, 2 * frames * views, extra).copy_(src.narrow(1, views, extra));
    return true;
  }
  if ((name == "output.weight" || name == "output.bias") && src.size(0) == views &&
      dst.size(0) == frames * views && src.dim() == dst.dim()) {
    for (int64_t t = 0; t < frames; ++t) dst.narrow(0, t * views, views).copy_(src);
    return true;
  }
  return false;
}

// The parameters of a grey net's input and output layers that a colour net of the same U-Net
// starts from (train --init): the input layer reads the luma of the three colours as the grey
// net read its grey views (and the noise channel as it did), and the output layer adds the grey
// net's correction to every colour. The colour net so starts as the demosaiced pseudo-inverse
// corrected by the grey net on its luma. False, leaving `dst` alone, for any other parameter.
bool colour_from_grey(const std::string& name, const torch::Tensor& src, torch::Tensor& dst,
                      int64_t views) {
  static constexpr double kLuma[3] = {0.299, 0.587, 0.114};  // LightField::grey
  torch::NoGradGuard no_grad;
  if (name == "input.weight" && src.dim() == 4 && src.size(0) == dst.size(0) &&
      dst.size(1) == src.size(1) + 2 * views && src.size(1) >= views) {
    for (int64_t c = 0; c < 3; ++c) {
      dst.narrow(1, c * views, views).copy_(src.narrow(1, 0, views) * kLuma[c]);
    }
    const int64_t extra = src.size(1) - views;  // the noise channel
    if (extra > 0) dst.narrow(1, 3 * views, extra).copy_(src.narrow(1, views, extra));
    return true;
  }
  if ((name == "output.weight" || name == "output.bias") && src.size(0) == views &&
      dst.size(0) == 3 * views && src.dim() == dst.dim()) {
    for (int64_t c = 0; c < 3; ++c) dst.narrow(0, c * views, views).copy_(src);
    return true;
  }
  return false;
}

class LfnetArchitecture : public NetworkArchitecture {
 public:
  std::string name() const override { return kLfnetArchitecture; }
  std::string summary() const override {
    return "lfnet's U-Net over the per-pixel pseudo-inverse of the whole sensor image";
  }
  bool whole_image() const override { return true; }
  PhiInput phi_input() const override { return PhiInput::kPixelWeights; }
  bool learns_code() const override { return true; }
  bool reads_noise(const NetworkOptions& o) const override { return image_options(o).noise_input; }
  bool colour() const override { return true; }

  // Its options: the U-Net's, the section "image".
  std::string options_section() const override { return kImageSection; }
  nlohmann::json default_options() const override { return fields_to_json(ImageNetOptions{}); }

  void validate(const NetworkOptions& o) const override {
    const auto image = image_options(o);
    image.validate(kImageSection);
    check_crop_multiple(o, image.multiple(), name());
  }

  void build(LightFieldNetImpl& net) const override {
    const auto& o = net.options();
    const auto& p = o.patch;
    const int64_t views = p.rows * p.cols;
    register_pixel_phi(net);
    if (o.colours() > 1) {
      net.cfa_response = net.register_buffer("cfa_response", torch::zeros({3, 1, 1}));
    }
    const int64_t channels = o.colours() * views;
    const auto image = image_options(o);
    // A time-coded camera's net also reads the held still estimate (unet_input).
    const int64_t in = (o.frames > 1 ? 2 : 1) * channels + (image.noise_input ? 1 : 0);
    net.register_module("image", ImageNet(image, in, channels));
  }

  void set_phi(LightFieldNetImpl& net, const torch::Tensor& stack) const override {
    const auto& o = net.options();
    check_pixel_weights(net, stack, name());
    torch::NoGradGuard no_grad;
    auto weights = stack;
    if (o.colours() > 1) {
      // The code and the CFA repeat together over the least common multiple of their periods.
      const auto cfa = optics::ColourFilterArray::bayer(o.cfa);
      const int64_t t = stack.size(3), l = std::lcm(t, cfa.period());
      weights = stack.repeat({1, 1, 1, l / t, l / t});
      net.cfa_response.set_(cfa.response()
                                .repeat({1, l / cfa.period(), l / cfa.period()})
                                .to(net.phi.options())
                                .contiguous());
    }
    store_pixel_phi(net, weights);
  }

  int64_t phases(const LightFieldNetImpl& net) const override { return pixel_phases(net); }
  // The period axes of the pixel weights, pseudo-inverses and CFA response (3, T, T).
  std::vector<size_t> phase_axes(const std::string& name, size_t rank) const override {
    if (name == "cfa_response" && rank == 3) return {1, 2};
    return pixel_phase_axes(name, rank);
  }

  NetworkOutputs forward_all(LightFieldNetImpl& net, const torch::Tensor& y,
                             const torch::Tensor& phase, const torch::Tensor& noise,
                             const BranchSelection&) const override {
    const auto& o = net.options();
    const auto& p = o.patch;
    auto ph = net.check_phase(y, phase);
    // A crop: its pixel (0, 0) has the crop's phase.
    auto sensor = y.reshape({y.size(0), o.measurements, p.height, p.width});
    auto base = colour_base(net, net.pixel_pinv_image(sensor, ph), ph);
    const std::vector<int64_t> shape{y.size(0), o.colours(), p.rows, p.cols, p.height, p.width};
    const auto start = o.frames > 1 ? net.pixel_hold_image(sensor, ph) : base;
    NetworkOutputs out;
    out.base = start.view(shape);
    out.output = refine(net, base, noise, start).view(shape);
    return out;
  }

  torch::Tensor forward_image(LightFieldNetImpl& net, const torch::Tensor& sensor, int64_t phase,
                              double noise_sigma) const override {
    const auto& o = net.options();
    LFNET_CHECK(sensor.dim() == 4, "forward_image: expected (B, N, H, W), got ", sensor.sizes());
    const auto& p = o.patch;
    const int64_t m = image_layers(net)->options().multiple(), h = sensor.size(2),
                  w = sensor.size(3);
    const int64_t ph = round_up(h, m) - h, pw = round_up(w, m) - w;
    LFNET_CHECK(phase >= 0 && phase < net.phases(), "forward_image: phase ", phase, " outside [0, ",
                net.phases(), ")");
    const auto phases =
        phase == 0 ? torch::Tensor() : torch::full({sensor.size(0)}, phase, torch::kInt64);
    // Demosaiced before padding: the padding is no measurement.
    auto base = colour_base(net, net.pixel_pinv_image(sensor, phases), phases);
    auto start = o.frames > 1 ? net.pixel_hold_image(sensor, phases) : base;
    if (ph > 0 || pw > 0) {
      base = torch::constant_pad_nd(base, {0, pw, 0, ph});
      start = torch::constant_pad_nd(start, {0, pw, 0, ph});
    }
    auto out = refine(net, base, torch::full({sensor.size(0)}, noise_sigma, base.options()), start);
    out = out.slice(2, 0, h).slice(3, 0, w);
    if (o.colours() == 1) return out.reshape({sensor.size(0), p.rows, p.cols, h, w});
    return out.reshape({sensor.size(0), o.colours(), p.rows, p.cols, h, w});
  }

  ImageTiling image_tiling(const NetworkOptions& o) const override {
    auto tiling = image_options(o).tiling();
    if (o.colours() > 1) {
      tiling.whole = kAutoTileWholeColour;
      tiling.crop = kAutoTileCropColour;
    }
    return tiling;
  }

  void set_precision(LightFieldNetImpl& net, torch::Dtype dtype) const override {
    image_layers(net)->set_precision(dtype);
  }
  void emulate_precision(LightFieldNetImpl& net, torch::Dtype dtype) const override {
    image_layers(net)->emulate_precision(dtype);
  }

  double patch_flops(const NetworkOptions& o, const BranchSelection&) const override {
    return image_pixel_flops(o) * static_cast<double>(o.patch.pixels());
  }

  double image_flops(const NetworkOptions& o, int64_t height, int64_t width,
                     int64_t tile) const override {
    return tiled_image_flops(image_tiling(o), image_pixel_flops(o), height, width, tile);
  }

  std::string script(const LightFieldNetImpl& net, ScriptBuilder& builder) const override {
    const auto& o = net.options();
    LFNET_CHECK_AS(ConfigError, o.colours() == 1, "a colour net (cfa ", o.cfa,
                   ") cannot be exported to TorchScript yet; ", "use its checkpoint");
    for (const auto& b : net.named_buffers()) builder.buffer(b.key(), b.value());
    auto module = image_layers(net);  // the same module, callable
    const auto& image = module->options();
    const int64_t channels =
        (o.frames > 1 ? 2 : 1) * o.patch.rows * o.patch.cols + (image.noise_input ? 1 : 0);
    const int64_t m = image.multiple();
    // The U-Net has no size-dependent operations, so one trace serves every image size.
    builder.trace(
        "image", [&](const torch::Tensor& x) { return module->forward(x); },
        torch::rand({1, channels, 2 * m, 2 * m}));
    builder.tiling(image_tiling(o));
    builder.attribute("noise_input", image.noise_input);
    return std::string(kPixelMapSource) +
           (o.frames > 1 ? kFramesEstimatesSource : kStillEstimatesSource) + kForwardSource +
           kWholeImageScriptSource;
  }

  WarmStart warm_start(const LightFieldNetImpl& net, const std::string& name,
                       const torch::Tensor& src, torch::Tensor& dst,
                       const WarmStartSource& from) const override {
    // A colour net starts from a grey one (colour_from_grey).
    const auto& o = net.options();
    const bool grey_source = !from.network.is_object() || from.network.value("cfa", "").empty();
    if (o.colours() > 1 && grey_source && src.sizes() != dst.sizes() &&
        name.rfind(kImagePrefix, 0) == 0 &&
        colour_from_grey(name.substr(kImagePrefix.size()), src, dst, o.patch.rows * o.patch.cols)) {
      return WarmStart::kWidened;
    }
    // A time-coded camera's net starts as a still net held over its sub-frames.
    const bool still_source = !from.network.is_object() || from.network.value("frames", 1) == 1;
    if (o.frames > 1 && still_source && src.sizes() != dst.sizes() &&
        name.rfind(kImagePrefix, 0) == 0 &&
        frames_from_still(name.substr(kImagePrefix.size()), src, dst,
                          o.colours() * o.patch.rows / o.frames * o.patch.cols, o.frames)) {
      return WarmStart::kMapped;
    }
    // A wider U-Net starts as the narrower one (embed_narrow_parameter).
    if (src.sizes() != dst.sizes() && name.rfind(kImagePrefix, 0) == 0 &&
        embed_narrow_parameter(name.substr(kImagePrefix.size()), src, dst)) {
      return WarmStart::kWidened;
    }
    return NetworkArchitecture::warm_start(net, name, src, dst, from);
  }

  std::vector<std::string> finish_warm_start(LightFieldNetImpl& net,
                                             const WarmStartSource& from) const override {
    // A deeper U-Net starts as the shallower one (ImageNetImpl::start_new_levels).
    std::vector<std::string> names;
    if (!from.network.is_object() || !from.network.contains(kImageSection)) return names;
    const int64_t from_levels = from.network[kImageSection].value("levels", int64_t{0});
    if (from_levels < 1 || from_levels >= image_layers(net)->options().levels) return names;
    for (const auto& name : image_layers(net)->start_new_levels(from_levels)) {
      names.push_back(std::string(kImagePrefix) + name);
    }
    return names;
  }
};

}  // namespace

torch::Tensor LightFieldNetImpl::pixel_hold_image(const torch::Tensor& sensor,
                                                  const torch::Tensor& phase) const {
  LFNET_CHECK(pixel_hold.defined(), "pixel_hold_image: a net of ", options_.frames,
              " frame(s) holds no still estimate");
  return pixel_map_image(pixel_hold, sensor, phase);
}

torch::Tensor LightFieldNetImpl::pixel_pinv_image(const torch::Tensor& sensor,
                                                  const torch::Tensor& phase) const {
  LFNET_CHECK(pixel_pinv.defined(), "pixel_pinv_image: the ", architecture().name(),
              " architecture has no per-pixel pseudo-inverse");
  return pixel_map_image(pixel_pinv, sensor, phase);
}

torch::Tensor LightFieldNetImpl::pixel_map_image(const torch::Tensor& pixel_pinv,
                                                 const torch::Tensor& sensor,
                                                 const torch::Tensor& phase) const {
  LFNET_CHECK(sensor.dim() == 4 && sensor.size(1) == options_.measurements,
              "pixel_pinv_image: expected sensor crops (B, ", options_.measurements,
              ", h, w), got ", sensor.sizes());
  const int64_t t = pixel_pinv.size(0), h = sensor.size(2), w = sensor.size(3);
  const auto x = sensor.to(pixel_pinv.scalar_type());
  if (t == 1) return torch::einsum("nk,bnij->bkij", {pixel_pinv[0][0], x});
  // The map of pixel (i, j) of a crop of phase (py, px) is the tile's entry
  // ((py + i) mod T, (px + j) mod T).
  auto ph = phase.defined() ? phase.to(torch::kCPU) : torch::zeros({x.size(0)}, torch::kInt64);
  auto out = torch::empty({x.size(0), pixel_pinv.size(3), h, w}, x.options());
  auto iota = [&](int64_t n) { return torch::arange(n, torch::kInt64).to(x.device()); };
  const auto values = std::get<0>(at::_unique(ph));
  for (int64_t k = 0; k < values.size(0); ++k) {
    const int64_t v = values[k].item<int64_t>();
    auto rows = (iota(h) + v / t) % t, cols = (iota(w) + v % t) % t;
    auto map = pixel_pinv.index_select(0, rows).index_select(1, cols);  // (h, w, N, U V)
    auto index = torch::nonzero(ph == v).squeeze(1).to(x.device());
    out.index_copy_(0, index, torch::einsum("ijnk,bnij->bkij", {map, x.index_select(0, index)}));
  }
  return out;
}

torch::Tensor pixel_pseudo_inverses(const torch::Tensor& weights, double lambda) {
  LFNET_CHECK(weights.dim() == 5 && weights.size(3) == weights.size(4),
              "pixel_pseudo_inverses: expected pixel weights (N, U, V, T, T), got ",
              weights.sizes());
  // Per pixel, A (N, U V) -> A^T (A A^T + lambda I)^-1, stored transposed as (N, U V).
  const int64_t n = weights.size(0), views = weights.size(1) * weights.size(2), t = weights.size(3);
  const auto a = weights.reshape({n, views, t, t}).permute({2, 3, 0, 1});  // (T, T, N, U V)
  const auto gram = torch::matmul(a, a.transpose(2, 3)) + lambda * torch::eye(n, a.options());
  return at::linalg_solve(gram, a);
}

ImageNetOptions image_options(const NetworkOptions& o) {
  return o.unchecked_section<ImageNetOptions>(kImageSection);
}

void set_image_options(NetworkOptions& o, const ImageNetOptions& image) {
  o.set_section(kImageSection, image);
}

std::shared_ptr<ImageNetImpl> image_layers(const LightFieldNetImpl& net) {
  return net.layer<ImageNetImpl>("image");
}

std::unique_ptr<NetworkArchitecture> make_lfnet_architecture() {
  return std::make_unique<LfnetArchitecture>();
}

}  // namespace lfnet::nn

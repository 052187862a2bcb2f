// The unrolled data-consistency architecture (docs/architectures.md, "The unrolled network"):
// K iterations of a learned denoiser and a half-quadratic-splitting step with the camera's
// per-pixel Phi A and its pseudo-inverse A^+ = A^T (A A^T + lambda I)^-1 in the loop,
//   x_0 = A^+ y,   z_k = x_(k-1) + D_k(x_(k-1)),   x_k = z_k + s_k A^+ (y - A z_k),
// the family of LFCA and DeepULFCam. The step s_k is learned and starts at 1, where x_k is the
// exact minimiser of ||A x - y||^2 + lambda ||x - z_k||^2. The denoisers D_k are small U-Nets
// over the views (nn/image_net.h), one per iteration or one shared. Like lfnet's U-Net it is
// fully convolutional: trained on crops of a local Phi, it reconstructs whole sensor images.
// Grey only; noise-aware when its denoiser reads the noise.
#include <torch/torch.h>

#include <functional>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/fields.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/nn/image_net.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/pixel_phi.h"
#include "lfnet/nn/script.h"

namespace lfnet::nn {

namespace {

constexpr const char* kUnrolledArchitecture = "unrolled";

// The architecture's own options: the section "unrolled" of the network options.
struct UnrolledOptions {
  int64_t iterations = 3;  // K: denoiser and data-consistency steps
  bool shared = false;     // one denoiser for every iteration (K times fewer parameters)
  ImageNetOptions denoiser{16, 3, 1, {}, false};

  template <typename Fields>
  void fields(Fields& f) {
    f("iterations", iterations, Range::closed(1, 16));
    f("shared", shared);
    f("denoiser", denoiser);
  }
  void validate() const { denoiser.validate("denoiser"); }
  int64_t denoisers() const { return shared ? 1 : iterations; }
};

UnrolledOptions unrolled_options(const NetworkOptions& o) {
  return o.section<UnrolledOptions>(kUnrolledArchitecture);
}

std::string denoiser_name(const UnrolledOptions& u, int64_t k) {
  return u.shared ? "denoiser" : "denoiser" + std::to_string(k);
}

// The iterations on sensor crops `y` (B, N, h, w) whose pixel (0, 0) has phase `phase` (B,
// undefined: 0), with noise sigmas `noise` (B, undefined: 0): (B, U V, h, w), and the
// pseudo-inverse it starts from in `start`.
torch::Tensor iterate(const LightFieldNetImpl& net, const torch::Tensor& y,
                      const torch::Tensor& phase, const torch::Tensor& noise,
                      torch::Tensor* start = nullptr) {
  const auto u = unrolled_options(net.options());
  const int64_t b = y.size(0), h = y.size(2), w = y.size(3);
  const auto x_in = y.to(net.pixel_pinv.scalar_type());
  const auto n = net.phi.size(0), views = net.phi.size(1) * net.phi.size(2), t = net.phi.size(3);
  const auto period_a = net.phi.reshape({n, views, t, t}).permute({2, 3, 0, 1});  // (T, T, N, U V)
  // A z and A^+ r at every pixel: one matrix for a code of period 1, else each pixel's own
  // (B, h, w, N, U V).
  std::function<torch::Tensor(const torch::Tensor&)> measure, invert;
  if (t == 1) {
    const auto a = period_a[0][0], p = net.pixel_pinv[0][0];  // (N, U V)
    measure = [a](const torch::Tensor& z) { return torch::einsum("nk,bkij->bnij", {a, z}); };
    invert = [p](const torch::Tensor& r) { return torch::einsum("nk,bnij->bkij", {p, r}); };
  } else {
    const auto a = pixel_period_maps(period_a, phase, b, h, w);
    const auto p = pixel_period_maps(net.pixel_pinv, phase, b, h, w);
    measure = [a](const torch::Tensor& z) { return torch::einsum("bijnk,bkij->bnij", {a, z}); };
    invert = [p](const torch::Tensor& r) { return torch::einsum("bijnk,bnij->bkij", {p, r}); };
  }
  auto x = invert(x_in);
  if (start != nullptr) *start = x;
  torch::Tensor channel;
  if (u.denoiser.noise_input) {
    const auto sigma = noise.defined() ? noise.to(x.options()) : torch::zeros({b}, x.options());
    channel = sigma.view({-1, 1, 1, 1}).expand({b, 1, h, w});
  }
  const auto step = net.named_parameters(false)["step"];
  for (int64_t k = 0; k < u.iterations; ++k) {
    const auto denoiser = net.layer<ImageNetImpl>(denoiser_name(u, k));
    const auto in = channel.defined() ? torch::cat({x, channel}, 1) : x;
    const auto z = x + denoiser->forward(in);
    x = z + step[k] * invert(x_in - measure(z));
  }
  return x;
}

// The methods of an exported unrolled net (docs/export.md); its denoisers are the submodules
// `denoiser<k>` (or `denoiser`), traced from the C++ modules. They repeat `iterate` op for op;
// `denoise` is written per net (its K branches).
constexpr const char* kUnrolledSource = R"TS(
def pixel_maps(self, period: Tensor, phase: int, h: int, w: int) -> Tensor:
    t = period.size(0)
    rows = torch.remainder(torch.arange(h, device=period.device) + phase // t, t)
    cols = torch.remainder(torch.arange(w, device=period.device) + phase % t, t)
    return period.index_select(0, rows).index_select(1, cols)

def forward_image(self, sensor: Tensor, phase: int = 0, noise_sigma: float = 0.0) -> Tensor:
    self.check_sensor_images(sensor, phase)
    b = sensor.size(0)
    h = sensor.size(2)
    w = sensor.size(3)
    m = self.multiple
    y = sensor.to(self.pixel_pinv.dtype)
    y = torch.constant_pad_nd(y, [0, (m - w % m) % m, 0, (m - h % m) % m])
    hp = y.size(2)
    wp = y.size(3)
    n = self.phi.size(0)
    t = self.phi.size(3)
    a = self.pixel_maps(self.phi.reshape([n, -1, t, t]).permute([2, 3, 0, 1]), phase, hp, wp)
    p = self.pixel_maps(self.pixel_pinv, phase, hp, wp)
    x = torch.einsum("ijnk,bnij->bkij", [p, y])
    for k in range(self.iterations):
        inp = x
        if self.noise_input:
            inp = torch.cat([x, x.new_full([b, 1, hp, wp], noise_sigma)], 1)
        z = x + self.denoise(k, inp)
        r = y - torch.einsum("ijnk,bkij->bnij", [a, z])
        x = z + self.step[k] * torch.einsum("ijnk,bnij->bkij", [p, r])
    return x.narrow(2, 0, h).narrow(3, 0, w).reshape([b, self.patch_shape[0], self.patch_shape[1], h, w])
)TS";

class UnrolledArchitecture : public NetworkArchitecture {
 public:
  std::string name() const override { return kUnrolledArchitecture; }
  std::string summary() const override {
    return "K unrolled steps of a small U-Net denoiser and data consistency with the Phi";
  }
  bool whole_image() const override { return true; }
  PhiInput phi_input() const override { return PhiInput::kPixelWeights; }
  bool reads_noise(const NetworkOptions& o) const override {
    return unrolled_options(o).denoiser.noise_input;
  }
  std::string options_section() const override { return kUnrolledArchitecture; }
  nlohmann::json default_options() const override { return fields_to_json(UnrolledOptions{}); }

  void validate(const NetworkOptions& o) const override {
    check_crop_multiple(o, unrolled_options(o).denoiser.multiple(), name());
  }

  void build(LightFieldNetImpl& net) const override {
    const auto& o = net.options();
    const auto u = unrolled_options(o);
    const int64_t views = o.patch.rows * o.patch.cols;
    register_pixel_phi(net);
    net.register_parameter("step", torch::ones({u.iterations}));
    const int64_t in = views + (u.denoiser.noise_input ? 1 : 0);
    for (int64_t k = 0; k < u.denoisers(); ++k) {
      net.register_module(denoiser_name(u, k), ImageNet(u.denoiser, in, views));
    }
  }

  void set_phi(LightFieldNetImpl& net, const torch::Tensor& weights) const override {
    check_pixel_weights(net, weights, name());
    store_pixel_phi(net, weights);
  }

  int64_t phases(const LightFieldNetImpl& net) const override { return pixel_phases(net); }
  std::vector<size_t> phase_axes(const std::string& name, size_t rank) const override {
    return pixel_phase_axes(name, rank);
  }

  NetworkOutputs forward_all(LightFieldNetImpl& net, const torch::Tensor& y,
                             const torch::Tensor& phase, const torch::Tensor& noise,
                             const BranchSelection&) const override {
    const auto& p = net.options().patch;
    const auto ph = net.check_phase(y, phase);
    const auto sensor = y.reshape({y.size(0), net.options().measurements, p.height, p.width});
    const std::vector<int64_t> shape{y.size(0), 1, p.rows, p.cols, p.height, p.width};
    NetworkOutputs out;
    out.output = iterate(net, sensor, ph, noise, &out.base).view(shape);
    out.base = out.base.view(shape);
    return out;
  }

  torch::Tensor forward_image(LightFieldNetImpl& net, const torch::Tensor& sensor, int64_t phase,
                              double noise_sigma) const override {
    LFNET_CHECK(sensor.dim() == 4, "forward_image: expected (B, N, H, W), got ", sensor.sizes());
    LFNET_CHECK(phase >= 0 && phase < net.phases(), "forward_image: phase ", phase, " outside [0, ",
                net.phases(), ")");
    const auto& p = net.options().patch;
    const int64_t m = unrolled_options(net.options()).denoiser.multiple();
    const int64_t b = sensor.size(0), h = sensor.size(2), w = sensor.size(3);
    // Padded with zeros below and right, so pixel (0, 0) keeps its phase.
    const auto padded =
        torch::constant_pad_nd(sensor, {0, round_up(w, m) - w, 0, round_up(h, m) - h});
    const auto phases = torch::full({b}, phase, torch::kInt64);
    const auto out = iterate(net, padded, phases, torch::full({b}, noise_sigma));
    return out.slice(2, 0, h).slice(3, 0, w).reshape({b, p.rows, p.cols, h, w});
  }

  ImageTiling image_tiling(const NetworkOptions& o) const override {
    const auto u = unrolled_options(o);
    // Each iteration's U-Net widens the receptive field; the data-consistency steps are per pixel.
    return {u.denoiser.multiple(), u.iterations * u.denoiser.receptive_radius()};
  }

  void set_precision(LightFieldNetImpl& net, torch::Dtype dtype) const override {
    const auto u = unrolled_options(net.options());
    for (int64_t k = 0; k < u.denoisers(); ++k) {
      net.layer<ImageNetImpl>(denoiser_name(u, k))->set_precision(dtype);
    }
  }
  void emulate_precision(LightFieldNetImpl& net, torch::Dtype dtype) const override {
    const auto u = unrolled_options(net.options());
    for (int64_t k = 0; k < u.denoisers(); ++k) {
      net.layer<ImageNetImpl>(denoiser_name(u, k))->emulate_precision(dtype);
    }
  }

  // Per pixel: the pseudo-inverse, then per iteration the denoiser, A z and A^+ r.
  double patch_flops(const NetworkOptions& o, const BranchSelection&) const override {
    return pixel_flops(o) * static_cast<double>(o.patch.pixels());
  }
  double image_flops(const NetworkOptions& o, int64_t height, int64_t width,
                     int64_t tile) const override {
    return tiled_image_flops(image_tiling(o), pixel_flops(o), height, width, tile);
  }

  std::string script(const LightFieldNetImpl& net, ScriptBuilder& builder) const override {
    const auto& o = net.options();
    const auto u = unrolled_options(o);
    for (const auto& b : net.named_buffers()) builder.buffer(b.key(), b.value());
    const int64_t views = o.patch.rows * o.patch.cols;
    const int64_t m = u.denoiser.multiple();
    std::string denoise = "\ndef denoise(self, k: int, x: Tensor) -> Tensor:\n";
    for (int64_t k = 0; k < u.denoisers(); ++k) {
      const auto name = denoiser_name(u, k);
      auto module = net.layer<ImageNetImpl>(name);
      builder.trace(
          name, [&](const torch::Tensor& x) { return module->forward(x); },
          torch::rand({1, views + (u.denoiser.noise_input ? 1 : 0), 2 * m, 2 * m}));
      if (u.shared) {
        denoise += "    return self.denoiser.forward(x)\n";
      } else {
        denoise +=
            "    if k == " + std::to_string(k) + ":\n        return self." + name + ".forward(x)\n";
      }
    }
    if (!u.shared) denoise += "    raise ValueError(\"denoise: no such iteration\")\n";
    builder.tiling(image_tiling(o));
    builder.attribute("noise_input", u.denoiser.noise_input);
    builder.attribute("iterations", u.iterations);
    return std::string(kUnrolledSource) + denoise + kWholeImageScriptSource;
  }

 private:
  static double pixel_flops(const NetworkOptions& o) {
    const auto u = unrolled_options(o);
    const double views = static_cast<double>(o.patch.rows * o.patch.cols);
    const double dc = 2.0 * static_cast<double>(o.measurements) * views;  // one per-pixel product
    return dc +
           static_cast<double>(u.iterations) *
               (u.denoiser.pixel_flops(static_cast<int64_t>(views), static_cast<int64_t>(views)) +
                2 * dc);
  }
};

}  // namespace

std::unique_ptr<NetworkArchitecture> make_unrolled_architecture() {
  return std::make_unique<UnrolledArchitecture>();
}

}  // namespace lfnet::nn

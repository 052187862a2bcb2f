// The paper architecture (Gupta et al. 2017, docs/training.md): an autoencoder branch on the
// measurement vector and a 4D CNN branch on the scaled Phi^T y of a patch, averaged, with an
// optional fixed residual. Its layers are AutoencoderBranch and CnnBranch (nn/network.h).
#include <torch/torch.h>

#include <cmath>
#include <sstream>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"

namespace lfnet::nn {

namespace {

// The methods every exported net of the paper architecture shares. The branches are the
// submodules `ae` and `cnn`, traced from the C++ modules themselves (ScriptBuilder::trace);
// these methods repeat only the Phi stacks' products of this file and network.cc and the
// patches and stitching of patches.cc and reconstruct.cc, op for op (same ATen calls on the
// same shapes), so the results agree with the C++ net to float rounding; keep them in step when
// those change.
constexpr const char* kPatchSource = R"TS(
def _apply_stack(self, y: Tensor, phase: Optional[Tensor], stack: Tensor) -> Tensor:
    p = stack.size(0)
    if p == 1:
        return y.matmul(stack[0])
    if phase is None:
        raise ValueError("a Phi with {} phases needs the phase of every patch".format(p))
    if y.size(0) == 0:
        return torch.zeros([0, stack.size(2)], dtype=y.dtype, device=y.device)
    order = torch.sort(phase, stable=True, dim=0, descending=False)[1]
    counts = torch.bincount(phase, None, p)
    ordered = y.index_select(0, order)
    parts: List[Tensor] = []
    offset = 0
    for i in range(p):
        c = int(counts[i])
        if c > 0:
            parts.append(ordered.narrow(0, offset, c).matmul(stack[i]))
            offset += c
    inverse = torch.empty_like(order)
    inverse[order] = torch.arange(order.size(0), dtype=order.dtype, device=order.device)
    return torch.cat(parts, 0).index_select(0, inverse)

def _check(self, y: Tensor, phase: Optional[Tensor]) -> Tuple[Tensor, Optional[Tensor]]:
    h = self.patch_shape[2]
    w = self.patch_shape[3]
    m = self.measurements * h * w
    if y.dim() == 4:
        y = y.reshape([y.size(0), -1])
    if y.dim() != 2 or y.size(1) != m:
        raise ValueError("expected measurements (B, {}) (N = {} times {} pixels) or (B, {}, {}, {}), got {}".format(m, self.measurements, h * w, self.measurements, h, w, y.size()))
    if y.dtype != torch.float32:
        y = y.to(torch.float32)
    phases = self.period * self.period
    if phase is None:
        if phases != 1:
            raise ValueError("this net's Phi has {} phases; give the phase of every patch".format(phases))
        return y, None
    if phase.dim() != 1 or phase.size(0) != y.size(0) or phase.dtype != torch.int64:
        raise ValueError("phase must be ({}) int64, got {} {}".format(y.size(0), phase.size(), phase.dtype))
    if phase.numel() > 0:
        lo = int(phase.min())
        hi = int(phase.max())
        if lo < 0 or hi >= phases:
            raise ValueError("phases must lie in [0, {}), got [{}, {}]".format(phases, lo, hi))
    return y, phase

def _adjoint(self, y: Tensor, phase: Optional[Tensor]) -> Tensor:
    x = self._apply_stack(y, phase, self.phi_stack())
    if phase is None or self.adjoint_scale.size(0) == 1:
        return x * self.adjoint_scale[0]
    return x * self.adjoint_scale.index_select(0, phase).unsqueeze(1)

def forward_branch(self, y: Tensor, phase: Optional[Tensor], branch: str) -> Tensor:
    parts = self._parts(y, phase)
    out = parts["output"]
    if branch == "ae" or branch == "cnn":
        if branch not in parts:
            raise ValueError("the model was trained as '{}' and has no '{}' branch".format(self.branches, branch))
        if self.branches == "net":
            out = parts[branch]
            if "base" in parts:
                out = out + parts["base"]
    elif branch != "net":
        raise ValueError("unknown branch '{}' (known: net, ae, cnn)".format(branch))
    s = self.patch_shape
    return out.reshape([out.size(0), s[0], s[1], s[2], s[3]])

def forward(self, y: Tensor, phase: Optional[Tensor] = None) -> Tensor:
    return self.forward_branch(y, phase, "net")

def _origins(self, extent: int, size: int, stride: int) -> List[int]:
    if extent < size:
        raise ValueError("a sensor image of {} pixels is smaller than one patch of {}".format(extent, size))
    out: List[int] = []
    o = 0
    while o + size <= extent:
        out.append(o)
        o += stride
    if out[-1] + size < extent:
        out.append(extent - size)
    return out

def reconstruct(self, sensor: Tensor, stride: int = 5, batch: int = 2048, window: bool = False, clamp: bool = True) -> Tensor:
    s = self.patch_shape
    nu = s[0]
    nv = s[1]
    h = s[2]
    w = s[3]
    nm = self.measurements
    if sensor.dim() != 3 or sensor.size(0) != nm:
        raise ValueError("expected a sensor image (N = {}, H, W), got {}".format(nm, sensor.size()))
    if stride < 1 or batch < 1:
        raise ValueError("stride and batch must be positive, got {} and {}".format(stride, batch))
    H = sensor.size(1)
    W = sensor.size(2)
    blk = self.block
    if h % blk != 0 or w % blk != 0:
        raise ValueError("the Phi mixes the pixels of {}-pixel blocks: {}x{} patches are not crops of one sensor image".format(blk, h, w))
    ys = self._origins(H, h, stride)
    xs = self._origins(W, w, stride)
    for o in ys + xs:
        if o % blk != 0:
            raise ValueError("a patch at {} is off the {}-pixel block grid, so its measurements are not a crop of the sensor image; use a stride that is a multiple of {} on an image whose sides are multiples of {}".format(o, blk, blk, blk))
    t = self.period
    dev = sensor.device
    xs_t = torch.tensor(xs, dtype=torch.int64, device=dev)
    nx = len(xs)
    cols_idx = (xs_t.unsqueeze(1) + torch.arange(w, device=dev).unsqueeze(0)).reshape([-1])
    x_pix = xs_t.view([1, -1, 1, 1]) + torch.arange(w, device=dev).view([1, 1, 1, w])
    weight = torch.ones([h * w], dtype=torch.float64, device=dev)
    if window:
        wy = torch.sin(3.141592653589793 * (torch.arange(h, dtype=torch.float64, device=dev) + 0.5) / h)
        wx = torch.sin(3.141592653589793 * (torch.arange(w, dtype=torch.float64, device=dev) + 0.5) / w)
        weight = (wy.unsqueeze(1) * wx.unsqueeze(0)).reshape([-1])
    total = torch.zeros([nu, nv, H * W], dtype=torch.float64, device=dev)
    count = torch.zeros([H * W], dtype=torch.float64, device=dev)
    band = max(1, batch // max(1, nx))
    r0 = 0
    while r0 < len(ys):
        r1 = min(len(ys), r0 + band)
        ny = r1 - r0
        ys_t = torch.tensor(ys[r0:r1], dtype=torch.int64, device=dev)
        rows_idx = (ys_t.unsqueeze(1) + torch.arange(h, device=dev).unsqueeze(0)).reshape([-1])
        crop = sensor.index_select(1, rows_idx).index_select(2, cols_idx)
        n = ny * nx
        y = crop.view([nm, ny, h, nx, w]).permute([1, 3, 0, 2, 4]).reshape([n, nm * h * w]).to(torch.float32)
        phase = ((ys_t.remainder(t) * t).unsqueeze(1) + xs_t.remainder(t).unsqueeze(0)).reshape([-1])
        parts: List[Tensor] = []
        b0 = 0
        while b0 < n:
            b1 = min(n, b0 + batch)
            parts.append(self.forward(y[b0:b1], phase[b0:b1]).reshape([b1 - b0, -1]))
            b0 = b1
        est = torch.cat(parts, 0).reshape([n, nu, nv, h, w])
        if not bool(torch.isfinite(est).all()):
            raise ValueError("the reconstruction produced NaN or infinite values in patch rows {}..{}".format(r0, r1 - 1))
        y_pix = ys_t.view([-1, 1, 1, 1]) + torch.arange(h, device=dev).view([1, 1, h, 1])
        idx = (y_pix * W + x_pix).reshape([-1])
        src = est.to(torch.float64).view([n, nu, nv, h * w]).mul(weight).permute([1, 2, 0, 3]).reshape([nu, nv, -1])
        total.index_add_(2, idx, src)
        count.index_add_(0, idx, weight.repeat([n]))
        r0 = r1
    out = (total / count).to(torch.float32).view([nu, nv, H, W])
    if clamp:
        out = out.clamp(0.0, 1.0)
    return out

def simulate(self, lf: Tensor) -> Tensor:
    s = self.patch_shape
    nu = s[0]
    nv = s[1]
    hw = s[2] * s[3]
    nm = self.measurements
    if lf.dim() != 4 or lf.size(0) != nu or lf.size(1) != nv:
        raise ValueError("expected a light field ({}, {}, H, W), got {}".format(nu, nv, lf.size()))
    lf = lf.to(torch.float32)
    H = lf.size(2)
    W = lf.size(3)
    stack = self.phi_stack()
    t = self.period
    blk = self.block
    if self.local:
        # The first pixel of the patch at origin (py, px) has the weights of every pixel of
        # that phase.
        g = stack[:, ::hw, ::hw]
        out = torch.zeros([nm, H, W], dtype=torch.float32, device=lf.device)
        for py in range(t):
            for px in range(t):
                sub = lf[:, :, py::t, px::t]
                hs = sub.size(2)
                ws = sub.size(3)
                if hs > 0 and ws > 0:
                    out[:, py::t, px::t] = g[py * t + px].matmul(sub.reshape([nu * nv, hs * ws])).view([nm, hs, ws])
        return out
    if t != 1 or H % blk != 0 or W % blk != 0:
        raise ValueError("simulate needs an image whose sides are multiples of the {}-pixel block, got {}x{}".format(blk, H, W))
    w = s[3]
    i = torch.arange(blk, device=lf.device)
    pix = (i.unsqueeze(1) * w + i.unsqueeze(0)).reshape([-1])
    rows = (torch.arange(nm, device=lf.device).unsqueeze(1) * hw + pix.unsqueeze(0)).reshape([-1])
    cols = (torch.arange(nu * nv, device=lf.device).unsqueeze(1) * hw + pix.unsqueeze(0)).reshape([-1])
    g = stack[0].index_select(0, rows).index_select(1, cols)
    by = H // blk
    bx = W // blk
    blocks = lf.reshape([nu * nv, by, blk, bx, blk]).permute([1, 3, 0, 2, 4]).reshape([by * bx, -1])
    meas = blocks.matmul(g.t())
    return meas.view([by, bx, nm, blk, blk]).permute([2, 0, 3, 1, 4]).reshape([nm, H, W])
)TS";

// The exported net's method _parts (forward_all): the traced branches' outputs combined as
// forward_all combines them.
std::string parts_source(const PaperOptions& o) {
  std::ostringstream s;
  const bool need_adjoint =
      o.has_cnn() || o.ae.input == AeInput::kAdjoint || o.residual == Residual::kAdjoint;
  s << "def _parts(self, y: Tensor, phase: Optional[Tensor]) -> Dict[str, Tensor]:\n"
    << "    y, ph = self._check(y, phase)\n"
    << "    ps = self.patch_shape\n"
    << "    shape = [y.size(0), 1, ps[0], ps[1], ps[2], ps[3]]\n"
    << "    parts: Dict[str, Tensor] = {}\n";
  if (need_adjoint) s << "    x0 = self._adjoint(y, ph)\n";
  if (o.has_ae())
    s << "    ae = self.ae.forward(" << (o.ae.input == AeInput::kAdjoint ? "x0" : "y")
      << ")\n    parts[\"ae\"] = ae\n";
  if (o.has_cnn()) s << "    cnn = self.cnn.forward(x0.view(shape))\n    parts[\"cnn\"] = cnn\n";
  if (o.has_ae() && o.has_cnn()) {
    const double a = o.head_weights[0], b = o.head_weights[1];
    if (a + b == 1.0) {
      s << "    out = torch.lerp(cnn, ae, " << ScriptBuilder::literal(a) << ")\n";
    } else {
      s << "    out = torch.add(cnn * " << ScriptBuilder::literal(b)
        << ", ae, alpha=" << ScriptBuilder::literal(a) << ")\n";
    }
  } else {
    s << "    out = " << (o.has_ae() ? "ae" : "cnn") << "\n";
  }
  if (o.residual == Residual::kPinv) {
    s << "    base = self._apply_stack(y, ph, self.base_stack()).view(shape)\n";
  } else if (o.residual == Residual::kAdjoint) {
    s << "    base = x0.view(shape)\n";
  }
  if (o.residual != Residual::kNone) s << "    parts[\"base\"] = base\n    out = out + base\n";
  s << "    parts[\"output\"] = out\n    return parts\n\n";
  return s.str();
}

// s_p Phi_p^T y for patches of phase `phase` (checked), as (B, U V h w).
torch::Tensor scaled_adjoint(const LightFieldNetImpl& net, const torch::Tensor& y,
                             const torch::Tensor& phase) {
  auto x = apply_phase_stack(y, phase, net.phi);
  if (net.phases() == 1) return x * net.adjoint_scale[0];
  return x * net.adjoint_scale.index_select(0, phase).unsqueeze(1);
}

class PaperArchitecture : public NetworkArchitecture {
 public:
  std::string name() const override { return kPaperArchitecture; }
  std::string summary() const override {
    return "the two-branch network of Gupta et al. (autoencoder and 4D CNN, averaged) on patches";
  }
  bool whole_image() const override { return false; }
  PhiInput phi_input() const override { return PhiInput::kPatchMatrices; }
  // Its options: the section "paper".
  std::string options_section() const override { return kPaperSection; }
  nlohmann::json default_options() const override {
    const PaperOptions defaults;  // named: GCC 12 warns of a temporary's vectors
    return fields_to_json(defaults);
  }

  void validate(const NetworkOptions& options) const override {
    auto fail = [](const std::string& field, const std::string& what) {
      throw ConfigError(std::string(kPaperSection) + "." + field + ": " + what);
    };
    const auto o = paper_options(options);
    if (o.kernel < 1 || o.kernel % 2 == 0) {
      fail("kernel", "must be odd and positive, got " + std::to_string(o.kernel));
    }
    if (o.ae.hidden.size() != 5) {
      fail("ae.hidden",
           "needs the 5 widths of fc1 .. fc5, got " + std::to_string(o.ae.hidden.size()));
    }
    for (auto w : o.ae.hidden) {
      if (w < 1) fail("ae.hidden", "widths must be positive, got " + std::to_string(w));
    }
    if (o.cnn.channels < 1) fail("cnn.channels", "must be positive");
    if (o.cnn.depth < 1) fail("cnn.depth", "must be >= 1");
    if (o.head_weights.size() != 2 || !std::isfinite(o.head_weights[0]) ||
        !std::isfinite(o.head_weights[1])) {
      fail("head_weights", "needs two finite weights (ae, cnn)");
    }
  }

  void build(LightFieldNetImpl& net) const override {
    const auto& o = net.options();
    const auto paper = paper_options(o);
    const int64_t m = o.measurement_size(), d = o.patch.size();
    net.phi = net.register_buffer("phi", torch::zeros({1, m, d}));
    net.adjoint_scale = net.register_buffer("adjoint_scale", torch::ones({1}));
    if (paper.residual == Residual::kPinv) {
      net.base = net.register_buffer("base", torch::zeros({1, m, d}));
    }
    if (paper.has_ae()) net.register_module("ae", AutoencoderBranch(o));
    if (paper.has_cnn()) net.register_module("cnn", CnnBranch(o));
  }

  void set_phi(LightFieldNetImpl& net, const torch::Tensor& stack) const override {
    const auto& o = net.options();
    const int64_t m = o.measurement_size(), d = o.patch.size();
    LFNET_CHECK(stack.dim() == 3 && stack.size(0) >= 1 && stack.size(1) == m && stack.size(2) == d,
                "set_phi: expected patch matrices (P, ", m, ", ", d, ") for N = ", o.measurements,
                " and a ", o.patch.rows, "x", o.patch.cols, "x", o.patch.height, "x", o.patch.width,
                " patch, got ", stack.sizes());
    LFNET_CHECK_AS(NumericalError, torch::isfinite(stack).all().item<bool>(),
                   "set_phi: the patch matrices contain NaN or inf");
    torch::NoGradGuard no_grad;
    auto a = stack.to(torch::kFloat64).contiguous();
    // s_p = <t, 1> / <t, t> with t = Phi_p^T Phi_p 1: least squares for s t ~ 1.
    auto t = torch::matmul(a.sum(2).unsqueeze(1), a).squeeze(1);
    auto tt = t.square().sum(1);
    auto scale = torch::where(tt > 0, t.sum(1) / tt, torch::ones_like(tt));
    auto opts = net.phi.options();
    net.phi.set_(stack.to(opts).contiguous().clone());
    net.adjoint_scale.set_(scale.to(opts).contiguous());
    if (net.base.defined()) net.base.set_(pinv_stack(a, o.pinv_lambda).to(opts).contiguous());
  }

  int64_t phases(const LightFieldNetImpl& net) const override { return net.phi.size(0); }
  std::vector<size_t> phase_axes(const std::string& name, size_t) const override {
    if (name == "phi" || name == "adjoint_scale" || name == "base") return {0};
    return {};
  }

  NetworkOutputs forward_all(LightFieldNetImpl& net, const torch::Tensor& y,
                             const torch::Tensor& phase, const torch::Tensor&,
                             const BranchSelection& run) const override {
    const auto o = paper_options(net.options());
    auto ph = net.check_phase(y, phase);
    const auto& p = net.options().patch;
    const std::vector<int64_t> shape{y.size(0), 1, p.rows, p.cols, p.height, p.width};
    const bool run_ae = run.ae && o.has_ae(), run_cnn = run.cnn && o.has_cnn();
    const bool need_adjoint =
        run_cnn || (run_ae && o.ae.input == AeInput::kAdjoint) || o.residual == Residual::kAdjoint;
    torch::Tensor x0 = need_adjoint ? scaled_adjoint(net, y, ph) : torch::Tensor();

    NetworkOutputs out;
    if (run_ae) out.ae = ae_branch(net)->forward(o.ae.input == AeInput::kAdjoint ? x0 : y);
    if (run_cnn) out.cnn = cnn_branch(net)->forward(x0.view(shape));
    if (out.ae.defined() && out.cnn.defined()) {
      const double a = o.head_weights[0], b = o.head_weights[1];
      // One fused kernel: lerp(cnn, ae, a) = (1 - a) cnn + a ae when the weights sum to 1.
      out.output =
          a + b == 1.0 ? torch::lerp(out.cnn, out.ae, a) : torch::add(out.cnn * b, out.ae, a);
    } else {
      out.output = out.ae.defined() ? out.ae : out.cnn;
    }
    if (o.residual == Residual::kPinv) {
      out.base = apply_phase_stack(y, ph, net.base).view(shape);
    }
    if (o.residual == Residual::kAdjoint) out.base = x0.view(shape);
    // With no branch run (a selection that leaves none), the output is the base alone.
    if (out.base.defined()) out.output = out.output.defined() ? out.output + out.base : out.base;
    return out;
  }

  void set_precision(LightFieldNetImpl& net, torch::Dtype dtype) const override {
    if (auto cnn = cnn_branch(net)) cnn->to(dtype);
  }

  double patch_flops(const NetworkOptions& options, const BranchSelection& run) const override {
    const auto& p = options.patch;
    const auto o = paper_options(options);
    const double d = static_cast<double>(p.size());
    const double m = static_cast<double>(options.measurement_size());
    auto conv = [&](int64_t cin, int64_t cout) {
      return conv4d_flops(1, cin, cout, p.rows, p.cols, p.height, p.width, o.kernel);
    };
    const bool ae = run.ae && o.has_ae(), cnn = run.cnn && o.has_cnn();
    double flops = 0;
    if (cnn || (ae && o.ae.input == AeInput::kAdjoint)) flops += 2 * m * d;
    if (ae) {
      double in = static_cast<double>(ae_input_size(options, o));
      std::vector<int64_t> widths = o.ae.hidden;
      widths.push_back(p.size());
      for (auto w : widths) {
        flops += 2 * in * static_cast<double>(w);
        in = static_cast<double>(w);
      }
      flops += conv(1, 1);
    }
    if (cnn) flops += cnn_patch_flops(options);
    if (o.residual == Residual::kPinv) flops += 2 * m * d;
    return flops;
  }

  std::string script(const LightFieldNetImpl& net, ScriptBuilder& builder) const override {
    const auto o = paper_options(net.options());
    std::string accessors;
    for (const auto& b : net.named_buffers()) {
      if (b.key() == "phi") {
        accessors += builder.stack("phi", "phi_stack", b.value());
      } else if (b.key() == "base") {
        accessors += builder.stack("base", "base_stack", b.value());
      } else {
        builder.buffer(b.key(), b.value());
      }
    }
    const auto& ps = net.options().patch;
    // Two patches: the traced graph keeps no batch size (ScriptBuilder::trace).
    if (o.has_ae()) {
      auto module = ae_branch(net);  // the same module, callable
      builder.trace(
          "ae", [&](const torch::Tensor& x) { return module->forward(x); },
          torch::rand({2, ae_input_size(net.options(), o)}));
    }
    if (o.has_cnn()) {
      auto module = cnn_branch(net);
      builder.trace(
          "cnn", [&](const torch::Tensor& x) { return module->forward(x); },
          torch::rand({2, 1, ps.rows, ps.cols, ps.height, ps.width}));
    }
    return accessors + parts_source(o) + kPatchSource;
  }

  WarmStart warm_start(const LightFieldNetImpl& net, const std::string& name,
                       const torch::Tensor& src, torch::Tensor& dst,
                       const WarmStartSource& from) const override {
    // fc1 reads the measurements of the old Phi: carry it over to the new one (Phi switching,
    // map_measurement_weights), or start it afresh.
    if (name == "ae.fc1.weight" &&
        paper_options(net.options()).ae.input == AeInput::kMeasurements && from.phi_changed) {
      const auto& old_phi = from.phi;
      if (old_phi.defined() && old_phi.dim() == 3 && old_phi.size(0) == 1 && net.phases() == 1 &&
          src.dim() == 2 && src.size(0) == dst.size(0) && src.size(1) == old_phi.size(1)) {
        dst.copy_(map_measurement_weights(src, old_phi[0], net.phi[0].to(torch::kCPU),
                                          net.options().pinv_lambda));
        return WarmStart::kMapped;
      }
      return WarmStart::kReinitialised;
    }
    return NetworkArchitecture::warm_start(net, name, src, dst, from);
  }
};

}  // namespace

torch::Tensor LightFieldNetImpl::adjoint(const torch::Tensor& y, const torch::Tensor& phase) const {
  LFNET_CHECK(!architecture().whole_image(), "the ", architecture().name(),
              " architecture has no scaled adjoint");
  return scaled_adjoint(*this, y, check_phase(y, phase));
}

std::shared_ptr<AutoencoderBranchImpl> ae_branch(const LightFieldNetImpl& net) {
  return net.layer<AutoencoderBranchImpl>("ae");
}

std::shared_ptr<CnnBranchImpl> cnn_branch(const LightFieldNetImpl& net) {
  return net.layer<CnnBranchImpl>("cnn");
}

std::unique_ptr<NetworkArchitecture> make_paper_architecture() {
  return std::make_unique<PaperArchitecture>();
}

}  // namespace lfnet::nn

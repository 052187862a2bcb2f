#include "lfnet/nn/script.h"

#include <torch/csrc/jit/frontend/resolver.h>
#include <torch/csrc/jit/frontend/sugared_value.h>
#include <torch/csrc/jit/frontend/tracer.h>
#include <torch/csrc/jit/passes/fuse_linear.h>
#include <torch/csrc/jit/passes/shape_analysis.h>
#include <torch/csrc/jit/serialization/import.h>
#include <torch/torch.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/zip_check.h"

namespace lfnet::nn {

namespace {

namespace jit = torch::jit;

// The methods every exported net of the paper architecture shares. The branches are the
// submodules `ae` and `cnn`, traced from the C++ modules themselves (trace_forward); these
// methods repeat only the Phi stacks' products of network.cc and the patches and stitching of
// patches.cc and reconstruct.cc, op for op (same ATen calls on the same shapes), so the results
// agree with the C++ net to float rounding; keep them in step when those change.
constexpr const char* kCommonSource = R"TS(
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

// The methods of an exported net of the lfnet architecture (docs/export.md). The U-Net is the
// submodule `image`, traced from the C++ module itself; these methods repeat only the
// per-pixel pseudo-inverse, the padding and the noise channel of network.cc and the tiles of
// nn::image_tiles / recon::reconstruct_sensor_tiled, op for op.
constexpr const char* kImageSource = R"TS(
def pixel_pinv_image(self, sensor: Tensor, phase: int = 0) -> Tensor:
    t = self.pixel_pinv.size(0)
    x = sensor.to(self.pixel_pinv.dtype)
    if t == 1:
        return torch.einsum("nk,bnij->bkij", [self.pixel_pinv[0][0], x])
    h = x.size(2)
    w = x.size(3)
    rows = torch.remainder(torch.arange(h, device=x.device) + phase // t, t)
    cols = torch.remainder(torch.arange(w, device=x.device) + phase % t, t)
    m = self.pixel_pinv.index_select(0, rows).index_select(1, cols)
    return torch.einsum("ijnk,bnij->bkij", [m, x])

def forward_image(self, sensor: Tensor, phase: int = 0, noise_sigma: float = 0.0) -> Tensor:
    if sensor.dim() != 4 or sensor.size(1) != self.measurements:
        raise ValueError("forward_image: expected sensor images (B, N, H, W) with N the measurements")
    if phase < 0 or phase >= self.period * self.period:
        raise ValueError("forward_image: phase outside [0, period^2)")
    b = sensor.size(0)
    h = sensor.size(2)
    w = sensor.size(3)
    m = self.multiple
    ph = (m - h % m) % m
    pw = (m - w % m) % m
    base = self.pixel_pinv_image(sensor, phase)
    if ph > 0 or pw > 0:
        base = torch.constant_pad_nd(base, [0, pw, 0, ph])
    x = base
    if self.noise_input:
        x = torch.cat([base, base.new_full([b, 1, base.size(2), base.size(3)], noise_sigma)], 1)
    out = base + self.image.forward(x)
    return out.narrow(2, 0, h).narrow(3, 0, w).reshape([b, self.patch_shape[0], self.patch_shape[1], h, w])

def forward(self, sensor: Tensor, phase: int = 0, noise_sigma: float = 0.0) -> Tensor:
    return self.forward_image(sensor, phase, noise_sigma)

def reconstruct(self, sensor: Tensor, tile: int = 256, clamp: bool = True, noise_sigma: float = 0.0) -> Tensor:
    if sensor.dim() != 3 or sensor.size(0) != self.measurements:
        raise ValueError("reconstruct: expected a sensor image (N, H, W) with N the measurements")
    if tile < 1:
        raise ValueError("reconstruct: the tile must be positive")
    m = self.multiple
    t = self.period
    h = sensor.size(1)
    w = sensor.size(2)
    hp = (h + m - 1) // m * m
    wp = (w + m - 1) // m * m
    halo = (self.receptive_radius + m - 1) // m * m
    step = (tile + m - 1) // m * m
    padded = torch.constant_pad_nd(sensor.to(self.pixel_pinv.dtype), [0, wp - w, 0, hp - h])
    out = torch.empty([self.patch_shape[0], self.patch_shape[1], h, w], dtype=self.pixel_pinv.dtype, device=sensor.device)
    for y0 in range(0, hp, step):
        for x0 in range(0, wp, step):
            a0 = max(0, y0 - halo)
            a1 = min(hp, y0 + step + halo)
            b0 = max(0, x0 - halo)
            b1 = min(wp, x0 + step + halo)
            crop = padded.narrow(1, a0, a1 - a0).narrow(2, b0, b1 - b0).unsqueeze(0)
            est = self.forward_image(crop, (a0 % t) * t + b0 % t, noise_sigma)[0]
            th = min(y0 + step, h) - y0
            tw = min(x0 + step, w) - x0
            if th > 0 and tw > 0:
                out.narrow(2, y0, th).narrow(3, x0, tw).copy_(est.narrow(2, y0 - a0, th).narrow(3, x0 - b0, tw))
    if clamp:
        out.clamp_(0.0, 1.0)
    return out

def simulate(self, lf: Tensor) -> Tensor:
    t = self.phi.size(3)
    h = lf.size(2)
    w = lf.size(3)
    rows = torch.remainder(torch.arange(h, device=lf.device), t)
    cols = torch.remainder(torch.arange(w, device=lf.device), t)
    weights = self.phi.index_select(3, rows).index_select(4, cols)
    return (weights * lf.to(self.phi.dtype).unsqueeze(0)).sum([1, 2])
)TS";

// A float literal that TorchScript reads back as the same double.
std::string literal(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  std::string s(buf);
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

// The net-specific method _parts (forward_all): the traced branches' outputs combined as the
// C++ net combines them.
std::string network_source(const NetworkOptions& o) {
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
      s << "    out = torch.lerp(cnn, ae, " << literal(a) << ")\n";
    } else {
      s << "    out = torch.add(cnn * " << literal(b) << ", ae, alpha=" << literal(a) << ")\n";
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

// Registers `t` (P, M, D) as `<name>` or, when that halves its size, as flat `<name>_index`
// (int32) and `<name>_values`; returns the source of `<method>()`, which gives the dense
// stack (rebuilt once and cached in `<name>_cache`).
std::string register_stack(jit::Module& m, const std::string& name, const std::string& method,
                           const torch::Tensor& stack) {
  auto t = stack.detach().to(torch::kCPU, torch::kFloat32).contiguous();
  auto flat = t.reshape({-1});
  auto index = flat.view(torch::kInt32).nonzero().reshape({-1});  // by bit pattern: keeps -0.0
  const bool sparse = t.numel() < (int64_t{1} << 31) && 2 * index.numel() * 8 <= t.numel() * 4;
  std::ostringstream s;
  s << "def " << method << "(self) -> Tensor:\n";
  if (!sparse) {
    m.register_buffer(name, t.clone());
    s << "    return self." << name << "\n\n";
    return s.str();
  }
  m.register_buffer(name + "_index", index.to(torch::kInt32).contiguous());
  m.register_buffer(name + "_values", flat.index_select(0, index).contiguous());
  m.register_attribute(name + "_shape", c10::ListType::ofInts(),
                       c10::List<int64_t>(t.sizes().vec()));
  m.register_attribute(name + "_cache", c10::OptionalType::create(c10::TensorType::get()),
                       c10::IValue());
  s << "    cached = self." << name << "_cache\n"
    << "    if cached is not None and cached.device == self." << name << "_values.device:\n"
    << "        return cached\n"
    << "    n = 1\n    for d in self." << name << "_shape:\n        n = n * d\n"
    << "    dense = torch.zeros([n], dtype=self." << name << "_values.dtype, device=self." << name
    << "_values.device)\n"
    << "    dense[self." << name << "_index.to(torch.int64)] = self." << name << "_values\n"
    << "    dense = dense.view(self." << name << "_shape)\n"
    << "    self." << name << "_cache = dense\n"
    << "    return dense\n\n";
  return s.str();
}

// Resolves the exception types `raise` names (the default resolver knows only torch and
// builtins); the compiled code refers to them by name only.
struct ScriptResolver : jit::Resolver {
  std::shared_ptr<jit::SugaredValue> resolveValue(const std::string& name, jit::GraphFunction& fn,
                                                  const jit::SourceRange& loc) override {
    if (name == "ValueError") return std::make_shared<jit::ExceptionValue>(name);
    return jit::nativeResolver()->resolveValue(name, fn, loc);
  }
  c10::TypePtr resolveType(const std::string& name, const jit::SourceRange& loc) override {
    return jit::nativeResolver()->resolveType(name, loc);
  }
};

// TorchScript source compiled from C++ has no Python `torch` module to take dtypes from; in
// compiled code a dtype is its ScalarType number, so the names are replaced by those.
std::string with_dtypes(std::string source) {
  const std::pair<const char*, torch::ScalarType> names[] = {{"torch.int64", torch::kInt64},
                                                             {"torch.float32", torch::kFloat32},
                                                             {"torch.float64", torch::kFloat64}};
  for (const auto& [name, type] : names) {
    const std::string value = std::to_string(static_cast<int>(type));
    for (auto at = source.find(name); at != std::string::npos; at = source.find(name, at)) {
      source.replace(at, std::strlen(name), value);
    }
  }
  return source;
}

std::string class_name(const std::string& path) {
  // Flat class names: a dotted one would also open a namespace in the archive's code.
  std::string name = path.empty() ? "LightFieldNet" : path;
  for (auto& ch : name) {
    if (ch == '.') ch = '_';
  }
  return "__torch__.lfnet." + name;
}

std::string metadata_text(const jit::Module& m) { return m.attr("metadata").toStringRef(); }

// Gives `target` a `forward` traced from the C++ module `run` calls on one input, whose
// parameters `target` holds as the very same tensors, so the trace reads them as the module's
// attributes. Shapes are erased from the traced graph, and the modules traced here have no
// batch- or size-dependent operations (nn/conv4d.cc reshapes with an inferred batch; the
// U-Net has convolutions only), so the trace serves every batch and, for the U-Net, every
// image size (multiples of its multiple).
void trace_forward(const std::function<torch::Tensor(const torch::Tensor&)>& run,
                   const torch::Tensor& example, jit::Module& target) {
  torch::NoGradGuard no_grad;
  auto traced = jit::tracer::trace(
      jit::Stack{example},
      [&](jit::Stack inputs) -> jit::Stack { return {run(inputs.at(0).toTensor())}; },
      [](const torch::autograd::Variable&) { return std::string(); },
      /*strict=*/true, /*force_outplace=*/false, &target);
  auto graph = traced.first->graph;
  jit::EraseShapeInformation(graph);
  // The trace records a Linear layer as t + addmm, which the graph executor would decompose
  // into mm + add (rounding differently from the C++ layer); as aten::linear it runs as here.
  jit::FuseLinear(graph);
  auto* fn = target._ivalue()->compilation_unit()->create_function(
      c10::QualifiedName(*target.type()->name(), "forward"), graph);
  target.type()->addMethod(fn);
}

}  // namespace

nlohmann::json ScriptMetadata::to_json(const NetworkOptions& network, int64_t phases) const {
  return {{"format", "lfnet-torchscript"},
          {"format_version", kScriptFormatVersion},
          {"phi", phi},
          {"network", network.to_json()},
          {"config", config},
          {"patch", network.patch.to_json()},
          {"measurements", network.measurements},
          {"phases", phases},
          {"period", period},
          {"block", block},
          {"local", local},
          {"source", source}};
}

torch::jit::Module script_network(const LightFieldNet& net, const ScriptMetadata& meta) {
  const auto& o = net->options();
  const int64_t phases = net->phases();
  LFNET_CHECK_AS(ConfigError, meta.period >= 1 && phases == meta.period * meta.period,
                 "export: the net holds ", phases, " patch matrices but a Phi of period ",
                 meta.period, " has ", meta.period * meta.period, " phases");
  LFNET_CHECK_AS(ConfigError,
                 meta.block >= 1 && o.patch.height % meta.block == 0 &&
                     o.patch.width % meta.block == 0 && (meta.local || meta.period == 1),
                 "export: a Phi of block ", meta.block, " and period ", meta.period,
                 " does not fit ", o.patch.height, "x", o.patch.width, " patches");
  LFNET_CHECK_AS(ConfigError, !meta.local || meta.block == 1,
                 "export: a local Phi has 1-pixel blocks, got ", meta.block);

  auto cu = std::make_shared<jit::CompilationUnit>();
  jit::Module root(c10::QualifiedName(class_name("")), cu, /*shouldMangle=*/true);
  // One submodule per dotted prefix of a registered name (ae, ae.fc1, ...), so the exported
  // state_dict has the checkpoint's names.
  auto split = [](const std::string& full) {
    const auto dot = full.rfind('.');
    if (dot == std::string::npos) return std::make_pair(std::string(), full);
    return std::make_pair(full.substr(0, dot), full.substr(dot + 1));
  };
  std::map<std::string, jit::Module> children;
  auto module_at = [&](const std::string& path) -> jit::Module {
    if (path.empty()) return root;
    auto it = children.find(path);
    if (it == children.end()) {
      it =
          children.emplace(path, jit::Module(c10::QualifiedName(class_name(path)), cu, true)).first;
    }
    return it->second;
  };
  // The learned modules (the paper net's branches, the lfnet architecture's U-Net) are traced
  // with the net's own tensors (see trace_forward) and get copies afterwards.
  const bool image = o.is_image();
  for (const auto& p : net->named_parameters()) {
    const auto [path, leaf] = split(p.key());
    module_at(path).register_parameter(leaf, p.value(), false);
  }
  std::string accessors;
  for (const auto& b : net->named_buffers()) {
    if (!image && b.key() == "phi") {
      accessors += register_stack(root, "phi", "phi_stack", b.value());
    } else if (!image && b.key() == "base") {
      accessors += register_stack(root, "base", "base_stack", b.value());
    } else {
      const auto [path, leaf] = split(b.key());
      module_at(path).register_buffer(leaf, b.value().detach().clone());
    }
  }
  // Modules are handles: attaching a child before or after it is filled makes no difference.
  std::vector<std::string> paths;
  paths.reserve(children.size());
  for (const auto& entry : children) paths.push_back(entry.first);
  for (size_t i = 0; i < paths.size(); ++i) {
    const auto parent = split(paths[i]).first;
    if (!parent.empty() && !children.count(parent)) {
      module_at(parent);
      paths.push_back(parent);
    }
  }
  for (const auto& path : paths) {
    const auto [parent, leaf] = split(path);
    module_at(parent).register_module(leaf, children.at(path));
  }

  const auto& ps = o.patch;
  if (image) {
    LFNET_CHECK_AS(ConfigError, net->pixel_pinv.size(0) == meta.period,
                   "export: the net's Phi has period ", net->pixel_pinv.size(0), ", not ",
                   meta.period);
    auto unet = module_at("image");
    const int64_t channels = ps.rows * ps.cols + (o.image.noise_input ? 1 : 0);
    const int64_t m = o.image.multiple();
    auto module = net->image;  // a handle: the same module, callable
    trace_forward([&](const torch::Tensor& x) { return module->forward(x); },
                  torch::rand({1, channels, 2 * m, 2 * m}), unet);
  } else {
    // Two patches: the traced graph keeps no batch size (trace_forward).
    if (o.has_ae()) {
      auto ae = module_at("ae");
      auto module = net->ae;
      trace_forward([&](const torch::Tensor& x) { return module->forward(x); },
                    torch::rand({2, o.ae_input_size()}), ae);
    }
    if (o.has_cnn()) {
      auto cnn = module_at("cnn");
      auto module = net->cnn;
      trace_forward([&](const torch::Tensor& x) { return module->forward(x); },
                    torch::rand({2, 1, ps.rows, ps.cols, ps.height, ps.width}), cnn);
    }
  }
  for (const auto& p : net->named_parameters()) {
    const auto [path, leaf] = split(p.key());
    module_at(path).register_parameter(leaf, p.value().detach().clone(), false);
  }
  if (image) {
    root.register_attribute("multiple", c10::IntType::get(), o.image.multiple());
    root.register_attribute("receptive_radius", c10::IntType::get(), o.image.receptive_radius());
    root.register_attribute("noise_input", c10::BoolType::get(), o.image.noise_input);
  }
  const auto metadata = meta.to_json(o, phases);
  root.register_attribute("format_version", c10::IntType::get(), kScriptFormatVersion);
  root.register_attribute("metadata", c10::StringType::get(), metadata.dump(2));
  root.register_attribute("phi_spec", c10::StringType::get(), meta.phi.dump());
  root.register_attribute("branches", c10::StringType::get(), to_string(o.branches));
  root.register_attribute(
      "patch_shape", c10::ListType::ofInts(),
      c10::List<int64_t>({o.patch.rows, o.patch.cols, o.patch.height, o.patch.width}));
  root.register_attribute("measurements", c10::IntType::get(), o.measurements);
  root.register_attribute("period", c10::IntType::get(), meta.period);
  root.register_attribute("block", c10::IntType::get(), meta.block);
  root.register_attribute("local", c10::BoolType::get(), meta.local);
  root.define(with_dtypes(image ? std::string(kImageSource)
                                : accessors + network_source(o) + kCommonSource),
              std::make_shared<ScriptResolver>());
  root.eval();
  return root;
}

void export_network(const LightFieldNet& net, const ScriptMetadata& meta, const std::string& path) {
  auto module = script_network(net, meta);
  write_file_atomically(path, [&](const std::string& tmp) {
    try {
      module.save(tmp, {{kScriptMetadataFile, metadata_text(module)}});
    } catch (const c10::Error& e) {
      throw IoError("cannot write " + path + ": " + e.what_without_backtrace());
    }
  });
}

bool is_script_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError("cannot read model " + path + ": no such file or not readable");
  char magic[4] = {0, 0, 0, 0};
  in.read(magic, 4);
  return in.gcount() == 4 && std::memcmp(magic, "PK\x03\x04", 4) == 0;
}

torch::Tensor ScriptedNetwork::forward(const torch::Tensor& y, const torch::Tensor& phase,
                                       const std::string& branch) const {
  LFNET_CHECK_AS(ConfigError, !network.is_image(), "exported model ", path,
                 " is of the lfnet architecture, which reconstructs whole sensor images, not "
                 "patches");
  torch::NoGradGuard no_grad;
  c10::IValue ph = phase.defined() ? c10::IValue(phase) : c10::IValue();
  auto fn = module.get_method("forward_branch");
  return fn({y, ph, branch}).toTensor();
}

torch::Tensor ScriptedNetwork::reconstruct_image(const torch::Tensor& sensor, int64_t tile,
                                                 bool clamp, double noise_sigma) const {
  LFNET_CHECK_AS(ConfigError, network.is_image(), "exported model ", path,
                 " is of the paper's architecture, which reconstructs patches");
  torch::NoGradGuard no_grad;
  auto fn = module.get_method("reconstruct");
  return fn({sensor, tile, clamp, noise_sigma}).toTensor();
}

torch::Tensor ScriptedNetwork::pixel_weights() const {
  LFNET_CHECK_AS(ConfigError, network.is_image(), "exported model ", path,
                 " is of the paper's architecture, which holds patch matrices");
  return module.attr("phi").toTensor();
}

ScriptedNetwork load_script(const std::string& path) {
  const std::string where = "exported model " + path;
  if (!is_script_file(path)) {
    throw CheckpointError(where + " is not a TorchScript file (it is not a zip archive)");
  }
  check_zip_integrity(path, where);
  ScriptedNetwork net;
  net.path = path;
  jit::ExtraFilesMap extra{{kScriptMetadataFile, ""}};
  try {
    net.module = jit::load(path, torch::Device(torch::kCPU), extra);
  } catch (const c10::Error& e) {
    throw CheckpointError(where + " cannot be loaded: " + e.what_without_backtrace());
  } catch (const std::exception& e) {
    // A damaged code section fails in the TorchScript compiler, which reports the source
    // around the fault over several lines: keep the first.
    const std::string what = e.what();
    throw CheckpointError(where + " cannot be loaded: its TorchScript code is damaged (" +
                          what.substr(0, what.find('\n')) + ")");
  }
  std::string text = extra[kScriptMetadataFile];
  // A module saved again from Python without extra files still has the attribute.
  if (text.empty() && net.module.hasattr("metadata")) text = metadata_text(net.module);
  if (text.empty()) {
    throw CheckpointError(where + " is a TorchScript file without lfnet metadata (" +
                          kScriptMetadataFile + "); export it with lfnet export");
  }
  try {
    net.metadata = nlohmann::json::parse(text);
    const auto version = net.metadata.at("format_version").get<int64_t>();
    if (version != kScriptFormatVersion) {
      throw CheckpointError("it has format version " + std::to_string(version) +
                            "; this lfnet reads version " + std::to_string(kScriptFormatVersion) +
                            " (export it again)");
    }
    net.network = NetworkOptions::from_json(net.metadata.at("network"), "$.network");
    net.meta.phi = net.metadata.at("phi");
    net.meta.config = net.metadata.at("config");
    net.meta.period = net.metadata.at("period").get<int64_t>();
    net.meta.block = net.metadata.at("block").get<int64_t>();
    net.meta.local = net.metadata.at("local").get<bool>();
    net.meta.source = net.metadata.value("source", nlohmann::json::object());
    if (!net.module.hasattr("format_version") ||
        net.module.attr("format_version").toInt() != version) {
      throw CheckpointError("its module and its metadata disagree on the format version");
    }
  } catch (const CheckpointError& e) {
    throw CheckpointError(where + ": " + e.what());
  } catch (const ConfigError& e) {
    throw CheckpointError(where + " has invalid network options: " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw CheckpointError(where + " has malformed metadata: " + e.what());
  }
  return net;
}

void check_script_phi(const ScriptedNetwork& net, const nlohmann::json& phi_spec) {
  if (net.meta.phi == phi_spec) return;
  throw CheckpointError("exported model " + net.path + " was trained for Phi " +
                        phi_label(net.meta.phi) + " but the measurements come from Phi " +
                        phi_label(phi_spec) + ": they differ in " +
                        json_differences(net.meta.phi, phi_spec, "model", "measurements") +
                        ". Simulate with the model's Phi (--phi " + net.path +
                        "), or finetune the checkpoint for this Phi (train --init) and export it "
                        "again");
}

}  // namespace lfnet::nn

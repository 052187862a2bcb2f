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
#include "lfnet/nn/image_net.h"

namespace lfnet::nn {

namespace {

namespace jit = torch::jit;

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

// Splits a dotted name into its module path and leaf: "ae.fc1.weight" -> ("ae.fc1", "weight").
std::pair<std::string, std::string> split_name(const std::string& full) {
  const auto dot = full.rfind('.');
  if (dot == std::string::npos) return {std::string(), full};
  return {full.substr(0, dot), full.substr(dot + 1)};
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

ScriptBuilder::ScriptBuilder(const jit::Module& root) : root_(root) {}

jit::Module ScriptBuilder::module(const std::string& path) {
  if (path.empty()) return root_;
  auto it = children_.find(path);
  if (it != children_.end()) return it->second;
  jit::Module child(c10::QualifiedName(class_name(path)), root_._ivalue()->compilation_unit(),
                    /*shouldMangle=*/true);
  children_.emplace(path, child);
  // Modules are handles: attaching a child before it is filled makes no difference.
  const auto [parent, leaf] = split_name(path);
  module(parent).register_module(leaf, child);
  return child;
}

void ScriptBuilder::buffer(const std::string& name, const torch::Tensor& value) {
  const auto [path, leaf] = split_name(name);
  module(path).register_buffer(leaf, value.detach().clone());
}

std::string ScriptBuilder::stack(const std::string& name, const std::string& method,
                                 const torch::Tensor& value) {
  return register_stack(root_, name, method, value);
}

void ScriptBuilder::trace(const std::string& path,
                          const std::function<torch::Tensor(const torch::Tensor&)>& run,
                          const torch::Tensor& example) {
  auto target = module(path);
  trace_forward(run, example, target);
}

void ScriptBuilder::attribute(const std::string& name, int64_t value) {
  root_.register_attribute(name, c10::IntType::get(), value);
}

void ScriptBuilder::attribute(const std::string& name, bool value) {
  root_.register_attribute(name, c10::BoolType::get(), value);
}

void ScriptBuilder::tiling(const ImageTiling& tiling) {
  attribute("multiple", tiling.multiple);
  attribute("receptive_radius", tiling.receptive_radius);
  attribute("auto_tile_whole", tiling.whole);
  attribute("auto_tile_crop", tiling.crop);
}

std::string ScriptBuilder::literal(double value) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.17g", value);
  std::string s(buf);
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

// `reconstruct` with a tile of 0 repeats nn::auto_image_tile.
const char* const kWholeImageScriptSource = R"TS(
def check_sensor_images(self, sensor: Tensor, phase: int) -> None:
    if sensor.dim() != 4 or sensor.size(1) != self.measurements:
        raise ValueError("forward_image: expected sensor images (B, N, H, W) with N the measurements")
    if phase < 0 or phase >= self.period * self.period:
        raise ValueError("forward_image: phase outside [0, period^2)")

def forward(self, sensor: Tensor, phase: int = 0, noise_sigma: float = 0.0) -> Tensor:
    return self.forward_image(sensor, phase, noise_sigma)

def reconstruct(self, sensor: Tensor, tile: int = 0, clamp: bool = True, noise_sigma: float = 0.0) -> Tensor:
    if sensor.dim() != 3 or sensor.size(0) != self.measurements:
        raise ValueError("reconstruct: expected a sensor image (N, H, W) with N the measurements")
    if tile < 0:
        raise ValueError("reconstruct: the tile must be positive (0: automatic)")
    m = self.multiple
    t = self.period
    h = sensor.size(1)
    w = sensor.size(2)
    hp = (h + m - 1) // m * m
    wp = (w + m - 1) // m * m
    halo = (self.receptive_radius + m - 1) // m * m
    if tile == 0:
        if hp * wp <= self.auto_tile_whole * self.auto_tile_whole:
            tile = max(hp, wp)
        else:
            tile = max(self.auto_tile_crop - 2 * halo, 256) // m * m
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

torch::jit::Module script_network(const LightFieldNet& net, const ScriptMetadata& meta) {
  const auto& o = net->options();
  const int64_t phases = net->phases();
  LFNET_CHECK_AS(ConfigError, meta.period >= 1 && phases == meta.period * meta.period,
                 "export: the net holds ", phases, " phases but a Phi of period ", meta.period,
                 " has ", meta.period * meta.period);
  LFNET_CHECK_AS(ConfigError,
                 meta.block >= 1 && o.patch.height % meta.block == 0 &&
                     o.patch.width % meta.block == 0 && (meta.local || meta.period == 1),
                 "export: a Phi of block ", meta.block, " and period ", meta.period,
                 " does not fit ", o.patch.height, "x", o.patch.width, " patches");
  LFNET_CHECK_AS(ConfigError, !meta.local || meta.block == 1,
                 "export: a local Phi has 1-pixel blocks, got ", meta.block);

  auto cu = std::make_shared<jit::CompilationUnit>();
  jit::Module root(c10::QualifiedName(class_name("")), cu, /*shouldMangle=*/true);
  ScriptBuilder builder(root);
  // One submodule per dotted prefix of a registered name (ae, ae.fc1, ...), so the exported
  // state_dict has the checkpoint's names. The learned layers are traced with the net's own
  // tensors (ScriptBuilder::trace) and get copies afterwards.
  for (const auto& p : net->named_parameters()) {
    const auto [path, leaf] = split_name(p.key());
    builder.module(path).register_parameter(leaf, p.value(), false);
  }
  const std::string source = net->architecture().script(*net, builder);
  for (const auto& p : net->named_parameters()) {
    const auto [path, leaf] = split_name(p.key());
    builder.module(path).register_parameter(leaf, p.value().detach().clone(), false);
  }
  const auto metadata = meta.to_json(o, phases);
  root.register_attribute("format_version", c10::IntType::get(), kScriptFormatVersion);
  root.register_attribute("metadata", c10::StringType::get(), metadata.dump(2));
  root.register_attribute("phi_spec", c10::StringType::get(), meta.phi.dump());
  root.register_attribute("branches", c10::StringType::get(), to_string(o.branches()));
  root.register_attribute(
      "patch_shape", c10::ListType::ofInts(),
      c10::List<int64_t>({o.patch.rows, o.patch.cols, o.patch.height, o.patch.width}));
  root.register_attribute("measurements", c10::IntType::get(), o.measurements);
  root.register_attribute("period", c10::IntType::get(), meta.period);
  root.register_attribute("block", c10::IntType::get(), meta.block);
  root.register_attribute("local", c10::BoolType::get(), meta.local);
  root.define(with_dtypes(source), std::make_shared<ScriptResolver>());
  root.eval();
  return root;
}

void export_network(const LightFieldNet& net, const ScriptMetadata& meta, const std::string& path) {
  auto module = script_network(net, meta);
  // Archived in memory, then written by lfnet: LibTorch's file writer aborts the program when a
  // write fails (a full disk) while it finishes the archive.
  std::ostringstream bytes;
  try {
    module.save(bytes, {{kScriptMetadataFile, metadata_text(module)}});
  } catch (const c10::Error& e) {
    throw IoError("cannot write " + path + ": " + e.what_without_backtrace());
  }
  write_bytes_file(path, bytes.str());
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
  LFNET_CHECK_AS(ConfigError, !network.arch().whole_image(), "exported model ", path, " is of the ",
                 network.architecture,
                 " architecture, which reconstructs whole sensor images, not patches");
  torch::NoGradGuard no_grad;
  c10::IValue ph = phase.defined() ? c10::IValue(phase) : c10::IValue();
  auto fn = module.get_method("forward_branch");
  return fn({y, ph, branch}).toTensor();
}

torch::Tensor ScriptedNetwork::reconstruct_image(const torch::Tensor& sensor, int64_t tile,
                                                 bool clamp, double noise_sigma) const {
  LFNET_CHECK_AS(ConfigError, network.arch().whole_image(), "exported model ", path, " is of the ",
                 network.architecture, " architecture, which reconstructs patches");
  torch::NoGradGuard no_grad;
  // Resolved here, so that files exported before the automatic tile take it as well.
  if (tile <= 0 && sensor.dim() == 3) {
    tile = auto_image_tile(network.arch().image_tiling(network), sensor.size(1), sensor.size(2));
  }
  auto fn = module.get_method("reconstruct");
  return fn({sensor, tile, clamp, noise_sigma}).toTensor();
}

torch::Tensor ScriptedNetwork::pixel_weights() const {
  LFNET_CHECK_AS(ConfigError, network.arch().whole_image(), "exported model ", path, " is of the ",
                 network.architecture, " architecture, which holds patch matrices");
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
    net.network = NetworkOptions::from_file_json(net.metadata.at("network"), "$.network");
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

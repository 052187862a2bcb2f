// TorchScript export of a LightFieldNet (docs/export.md): one file that LibTorch
// (torch::jit::load) and Python (torch.jit.load) run without lfnet.
//
// The module is built in C++ (torch::nn modules cannot be scripted): the net's parameters and
// buffers become parameters and buffers of nested script modules under their registered names
// (ae.fc1.weight, cnn.conv3.bias, ...). The architecture (NetworkArchitecture::script) gives
// its learned layers forwards traced from the C++ modules themselves and the TorchScript source
// of the remaining methods, which repeats its C++ code op for op, so both give the same numbers
// to float rounding.
//
// Methods of the exported module (B patches, N measurements, a U x V x h x w patch):
//   forward(y, phase=None)            y (B, N h w) or (B, N, h, w) -> (B, U, V, h, w)
//   forward_branch(y, phase, branch)  branch "net", "ae" or "cnn" (a branch plus the residual)
//   reconstruct(sensor, stride=5, batch=2048, window=False, clamp=True)
//                                     sensor (N, H, W) -> light field (U, V, H, W)
//   simulate(lf)                      lf (U, V, H, W) -> noiseless sensor image (N, H, W)
//   phi_stack()                       the patch matrices (P, N h w, U V h w)
// A net of the lfnet architecture (whole images; its U-Net is the submodule `image`, traced
// from the C++ module) has instead:
//   forward(sensor, phase=0, noise_sigma=0.0)   sensor (B, N, H, W) -> (B, U, V, H, W)
//   reconstruct(sensor, tile=256, clamp=True, noise_sigma=0.0)
//                                     sensor (N, H, W) -> light field (U, V, H, W), in tiles
//   pixel_pinv_image(sensor, phase=0) the per-pixel pseudo-inverse (B, U V, H, W)
//   simulate(lf)                      lf (U, V, H, W) -> noiseless sensor image (N, H, W)
// and the attributes multiple, receptive_radius and noise_input; phi and pixel_pinv are
// plain buffers.
// Attributes: format_version, metadata (the JSON below), phi_spec (JSON), patch_shape
// [U, V, h, w], measurements, period, block. The same JSON is the extra file "lfnet.json".
// The Phi stack (and the pinv base) is stored as flat indices and values when that halves its
// size (per-pixel Phis have 1 / (h w) non-zeros): buffers phi_index / phi_values instead of
// phi; the module rebuilds the dense stack on first use.
#pragma once

#include <torch/csrc/jit/api/module.h>
#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <map>
#include <string>

#include "lfnet/nn/network.h"

namespace lfnet::nn {

// Bumped whenever the methods, attributes or metadata of exported files change meaning.
constexpr int64_t kScriptFormatVersion = 1;
// The extra file in the archive that holds the metadata JSON.
constexpr const char* kScriptMetadataFile = "lfnet.json";

// What an exported network carries besides its tensors.
struct ScriptMetadata {
  nlohmann::json phi = nlohmann::json::object();     // the Phi spec the net was trained for
  nlohmann::json config = nlohmann::json::object();  // the resolved config of the training run
  int64_t period = 1;  // Phi::period(): a patch at (y0, x0) has phase (y0 mod T) T + (x0 mod T)
  int64_t block = 1;   // Phi::block(): patch origins and sizes must be multiples of it
  bool local = true;   // Phi::local(): measurements at a pixel see only that pixel's rays
  nlohmann::json source = nlohmann::json::object();  // where the weights came from

  // The metadata JSON of a file exported from a net with these options and phases.
  nlohmann::json to_json(const NetworkOptions& network, int64_t phases) const;
};

// What an architecture's export (NetworkArchitecture::script) builds on: the exported module,
// whose submodules (one per dotted prefix of a registered name) already hold the net's
// parameters under their registered names.
class ScriptBuilder {
 public:
  explicit ScriptBuilder(const torch::jit::Module& root);
  // The submodule at a dotted path ("" for the root), made and attached on first use.
  torch::jit::Module module(const std::string& path);
  // A copy of `value` as the buffer of dotted name `name`.
  void buffer(const std::string& name, const torch::Tensor& value);
  // A stack of patch matrices (P, M, D) as the root's buffer `name` or, when that halves its
  // size, as flat `<name>_index` (int32) and `<name>_values`; returns the source of the method
  // `<method>()` that gives the dense stack (rebuilt once and cached).
  std::string stack(const std::string& name, const std::string& method, const torch::Tensor& value);
  // Gives the submodule at `path` a `forward` traced from the C++ module that `run` calls on one
  // input, `example`; the submodule holds that module's parameters as the very same tensors.
  // Shapes are erased from the traced graph: the module must have no batch- or size-dependent
  // operations.
  void trace(const std::string& path, const std::function<torch::Tensor(const torch::Tensor&)>& run,
             const torch::Tensor& example);
  // Attributes of the root.
  void attribute(const std::string& name, int64_t value);
  void attribute(const std::string& name, bool value);
  // The attributes multiple, receptive_radius, auto_tile_whole and auto_tile_crop of a
  // whole-image net tiled as `tiling` (kWholeImageScriptSource's reconstruct reads them).
  void tiling(const ImageTiling& tiling);
  // A float literal that TorchScript reads back as the same double.
  static std::string literal(double value);

 private:
  torch::jit::Module root_;
  std::map<std::string, torch::jit::Module> children_;
};

// The TorchScript methods every whole-image net's export shares, written on its
// forward_image(sensor, phase, noise_sigma) and the root's buffers phi (N, U, V, T, T) and
// pixel_pinv and attributes period and patch_shape and those of ScriptBuilder::tiling:
// reconstruct(sensor, tile, clamp, noise_sigma), the tiles of nn::image_tiles and
// recon::reconstruct_sensor_tiled op for op, simulate(lf), forward (forward_image), and
// check_sensor_images(sensor, phase), the input checks each forward_image starts with.
extern const char* const kWholeImageScriptSource;

// The TorchScript module of `net` (its parameters copied, detached). Throws ConfigError when
// the metadata does not fit the net (phases != period^2, a block that does not divide the
// patch).
torch::jit::Module script_network(const LightFieldNet& net, const ScriptMetadata& meta);

// script_network, written to `path` atomically (a temporary file, then rename).
void export_network(const LightFieldNet& net, const ScriptMetadata& meta, const std::string& path);

// Whether `path` is a TorchScript archive (a zip file) rather than an lfnet checkpoint.
// IoError when the file cannot be read.
bool is_script_file(const std::string& path);

// An exported network, loaded.
struct ScriptedNetwork {
  std::string path;
  torch::jit::Module module;
  nlohmann::json metadata;  // the full metadata JSON
  NetworkOptions network;   // parsed from metadata["network"]
  ScriptMetadata meta;      // parsed from the metadata

  // forward_branch(y, phase, branch) without autograd: (B, U, V, h, w). `phase` may be
  // undefined for a one-phase Phi.
  torch::Tensor forward(const torch::Tensor& y, const torch::Tensor& phase = {},
                        const std::string& branch = "net") const;
  // The lfnet architecture: reconstruct(sensor, tile, clamp, noise_sigma) of the module,
  // without autograd: sensor (N, H, W) -> (U, V, H, W). ConfigError for the paper's.
  torch::Tensor reconstruct_image(const torch::Tensor& sensor, int64_t tile, bool clamp,
                                  double noise_sigma) const;
  // The lfnet architecture: the per-pixel weights of one period of its Phi (its `phi`
  // buffer, (N, U, V, T, T)), as LightFieldNetImpl::phi. ConfigError for the paper's.
  torch::Tensor pixel_weights() const;
};

// Loads an exported file on the CPU. A missing file is an IoError; a TorchScript file without
// lfnet metadata, another format version or inconsistent metadata is a CheckpointError.
ScriptedNetwork load_script(const std::string& path);

// Throws CheckpointError unless the exported net was trained for `phi_spec` (equal JSON).
void check_script_phi(const ScriptedNetwork& net, const nlohmann::json& phi_spec);

}  // namespace lfnet::nn

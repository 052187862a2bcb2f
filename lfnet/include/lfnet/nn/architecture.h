// The architectures of the reconstruction network by name (docs/architecture.md, "Adding an
// architecture"): one class per architecture, registered in one line among the built-ins of
// registry() (nn/architecture.cc) or, from outside, by register_architecture.
//
// LightFieldNet is the module that holds an architecture's layers and buffers (their registered
// names are the checkpoint schema); everything that differs between architectures is asked of
// its class: how it builds and runs, which tensor of the Phi it takes, its FLOP model, its
// TorchScript export, its warm-start rules and whether it reconstructs whole sensor images.
// Checkpoints, export, bench, evaluate, reconstruct, batch and the trainer ask the class, never
// the name.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace lfnet::nn {

struct NetworkOptions;
struct NetworkOutputs;
struct BranchSelection;
class LightFieldNetImpl;
class ScriptBuilder;

// The names of the built-in architectures.
constexpr const char* kPaperArchitecture = "paper";  // Gupta et al.'s two branches on patches
constexpr const char* kLfnetArchitecture = "lfnet";  // lfnet's U-Net over whole sensor images

// What a net takes from its Phi (LightFieldNetImpl::set_phi).
enum class PhiInput {
  kPatchMatrices,  // (P, N h w, U V h w): one patch matrix per phase, at the patch size
  kPixelWeights,   // (N, U, V, T, T): the per-pixel weights of one period T (a local Phi)
};

// The automatic tile of a grey net reconstructs an image whose padded pixels fit in
// kAutoTileWhole^2 at once (593 x 840 does; lfnet-asp-n2's float32 pass then peaks near 1.4 GB),
// and a larger one in tiles whose crops, halos included, are at most kAutoTileCrop on a side,
// so that the peak stays bounded whatever the image's size.
constexpr int64_t kAutoTileWhole = 800;
constexpr int64_t kAutoTileCrop = 512;
// A colour net carries three times the views through its first and last layers: it runs whole
// only up to kAutoTileWholeColour^2 pixels, so 593 x 840 runs in two tiles (1.6 GB, not 2.0 GB
// whole, about 12 % slower).
constexpr int64_t kAutoTileWholeColour = 640;
constexpr int64_t kAutoTileCropColour = 720;

// How a whole-image net is run in tiles (recon::reconstruct_sensor_tiled): image sides are
// padded to `multiple`, and a tile needs a halo of `receptive_radius` pixels. The automatic tile
// (nn::auto_image_tile) runs an image whole when its padded pixels fit in `whole`^2, else in
// tiles whose crops, halos included, are at most `crop` on a side.
struct ImageTiling {
  int64_t multiple = 1;
  int64_t receptive_radius = 0;
  int64_t whole = kAutoTileWhole;
  int64_t crop = kAutoTileCrop;
};

// What train --init did with one parameter of the new net.
enum class WarmStart {
  kCopied,         // the checkpoint's tensor, as it is
  kMapped,         // carried over to the new Phi (a layer that reads measurements)
  kWidened,        // a narrower tensor embedded in the leading channels
  kReinitialised,  // left at its fresh initialisation
  kMismatch,       // shapes differ and the architecture cannot carry it over: an error
};

// The checkpoint a net is warm-started from, as the warm-start rules see it.
struct WarmStartSource {
  nlohmann::json network;    // its network options
  torch::Tensor phi;         // its `phi` buffer (undefined when it has none)
  bool phi_changed = false;  // whether the new net's Phi differs from it
};

class NetworkArchitecture {
 public:
  virtual ~NetworkArchitecture() = default;
  virtual std::string name() const = 0;     // the value of network.architecture
  virtual std::string summary() const = 0;  // one line for help texts and docs

  // True when the net reconstructs whole sensor images in one fully convolutional pass: no
  // patch grid and no stride (network.patch is its training crop), reconstructed by
  // recon::reconstruct_sensor_tiled; the self-ensemble and distillation apply. False: patches
  // on a grid, stitched (recon::reconstruct_sensor).
  virtual bool whole_image() const = 0;
  virtual PhiInput phi_input() const = 0;
  // True when a code can be learned with the net (train/joint_phi.h): its forward reads the
  // Phi only through the net's `phi` and `pixel_pinv`, which joint training swaps for the
  // code's inside the graph.
  virtual bool learns_code() const { return false; }
  // True when a net of `options` reads the sensor's noise sigma (a noise-aware net).
  virtual bool reads_noise(const NetworkOptions& options) const { return false; }
  // True when the architecture reconstructs colour behind a colour filter array (network.cfa).
  virtual bool colour() const { return false; }

  // The key of the architecture's own section of the network options (e.g. "unrolled"), ""
  // for none. NetworkOptions keeps the section as it was read (NetworkOptions::sections) and
  // writes it back; the architecture parses it (validate, build) and names its defaults here.
  virtual std::string options_section() const { return ""; }
  virtual nlohmann::json default_options() const { return nlohmann::json::object(); }

  // Checks the options only this architecture reads (the common ones are checked by
  // NetworkOptions::validate); a ConfigError names the field.
  virtual void validate(const NetworkOptions& options) const = 0;
  // Registers the layers and buffers on `net`, which holds the options.
  virtual void build(LightFieldNetImpl& net) const = 0;
  // Takes the Phi's tensor (phi_input) and derives the buffers that depend on it.
  virtual void set_phi(LightFieldNetImpl& net, const torch::Tensor& tensor) const = 0;
  // Distinct phases of the Phi the net holds (T^2 for a code of period T).
  virtual int64_t phases(const LightFieldNetImpl& net) const = 0;
  // The axes of the buffer `name` (of `rank` dimensions) that follow the Phi's phases or period,
  // which a checkpoint of another Phi may size differently; empty for a buffer that does not
  // depend on the Phi.
  virtual std::vector<size_t> phase_axes(const std::string& name, size_t rank) const = 0;
  // Training's forward: measurement vectors y (B, N h w) of patches (or crops) of phase `phase`
  // (B, undefined for one phase), noise sigma `noise` (B, undefined: 0), with the parts `run`
  // selects: the reconstruction (B, 1, U, V, h, w) and its parts.
  virtual NetworkOutputs forward_all(LightFieldNetImpl& net, const torch::Tensor& y,
                                     const torch::Tensor& phase, const torch::Tensor& noise,
                                     const BranchSelection& run) const = 0;
  // Whole-image nets: sensor images (B, N, H, W) whose pixel (0, 0) has phase `phase`, any H
  // and W, to (B, U, V, H, W). The others throw a ConfigError.
  virtual torch::Tensor forward_image(LightFieldNetImpl& net, const torch::Tensor& sensor,
                                      int64_t phase, double noise_sigma) const;
  // Whole-image nets: how they are tiled. The others throw a ConfigError.
  virtual ImageTiling image_tiling(const NetworkOptions& options) const;
  // Converts the layers that run in reduced precision for inference (bfloat16) to `dtype`.
  virtual void set_precision(LightFieldNetImpl& net, torch::Dtype dtype) const = 0;
  // Training for a run in `dtype` (training.precision): the layers set_precision converts keep
  // float32 weights but round as `dtype` would (ImageNetImpl::emulate_precision); float32 turns
  // it off. Default: float32 is a no-op and anything else a ConfigError.
  virtual void emulate_precision(LightFieldNetImpl& net, torch::Dtype dtype) const;

  // The FLOP model (lfnet bench): nominal floating-point operations of one patch (or one
  // training crop) through the parts `run` selects, and of a whole H x W image in tiles of
  // `tile` (0 when the architecture has no whole-image pass).
  virtual double patch_flops(const NetworkOptions& options, const BranchSelection& run) const = 0;
  virtual double image_flops(const NetworkOptions& options, int64_t height, int64_t width,
                             int64_t tile) const {
    return 0;
  }

  // Export (nn/script.h): registers the net's buffers and the traced forwards of its learned
  // layers on `builder`, and returns the TorchScript source of the exported file's methods.
  virtual std::string script(const LightFieldNetImpl& net, ScriptBuilder& builder) const = 0;

  // train --init: what to do with the checkpoint's tensor `src` for the parameter `name` of the
  // new net, whose tensor is `dst`. The default copies tensors of equal shape and refuses the
  // others; kMapped and kWidened write `dst` themselves.
  virtual WarmStart warm_start(const LightFieldNetImpl& net, const std::string& name,
                               const torch::Tensor& src, torch::Tensor& dst,
                               const WarmStartSource& from) const;
  // After every parameter: lets the architecture adjust what it started (a deeper net
  // starting as the shallow one). Returns the names of the parameters it set.
  virtual std::vector<std::string> finish_warm_start(LightFieldNetImpl& net,
                                                     const WarmStartSource& from) const {
    return {};
  }
};

// Adds an architecture, replacing one of the same name.
void register_architecture(std::unique_ptr<NetworkArchitecture> architecture);

// The architecture called `name`; an unknown name is a ConfigError listing the known ones.
const NetworkArchitecture& find_architecture(const std::string& name);

// Every registered architecture's name, in registration order (paper, lfnet, unrolled).
std::vector<std::string> registered_architectures();

// "paper, lfnet, unrolled": the registered architectures, for messages and help texts.
std::string architecture_list();

}  // namespace lfnet::nn

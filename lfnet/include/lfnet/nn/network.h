// The reconstruction network: one module, LightFieldNet, that holds the Phi and what is derived
// from it, and the layers its architecture registers on it (nn/architecture.h: "paper", the
// two-branch network of Gupta et al. 2017 on patches, docs/training.md; "lfnet", lfnet's U-Net
// over whole sensor images, and "unrolled", an unrolled data-consistency network,
// docs/architectures.md). An architecture's layers are its own: it registers them in build()
// and finds them by name (LightFieldNetImpl::layer). Its options are its own section of the
// options (NetworkOptions::sections: the paper architecture's "paper", lfnet's U-Net "image",
// "unrolled").
//
// The Phi is part of the net (the buffer `phi`), so a saved or exported model is
// self-contained. Registered names are the checkpoint schema. The paper architecture:
//   phi            (P, N h w, U V h w)  stacked patch matrices, one per phase (buffer)
//   adjoint_scale  (P)                  scale of Phi^T y per phase (buffer, derived from phi)
//   base           (P, N h w, U V h w)  Tikhonov pseudo-inverses (buffer, residual "pinv" only)
//   ae.fc1 .. ae.fc6 (.weight, .bias), ae.conv (.weight, .bias)
//   cnn.conv1 .. cnn.conv<depth> (.weight, .bias)
// The lfnet architecture:
//   phi            (N, U, V, T, T)      per-pixel weights of one period (buffer)
//   pixel_pinv     (T, T, N, U V)       per-pixel pseudo-inverses (buffer, derived from phi)
//   image.*                             the U-Net (nn/image_net.h)
// The unrolled architecture: phi and pixel_pinv as lfnet's, `step` (K), denoiser<k>.* (K U-Nets).
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/linear.h>
#include <torch/nn/pimpl.h>
#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/nn/conv4d.h"
#include "lfnet/nn/image_net.h"
#include "lfnet/optics/cfa.h"

namespace lfnet::nn {

// The size of a light-field patch (U, V, h, w) = (rows, cols, height, width).
struct PatchShape {
  int64_t rows = 5;    // U: angular rows
  int64_t cols = 5;    // V: angular columns
  int64_t height = 9;  // h: pixels
  int64_t width = 9;   // w: pixels

  template <typename Fields>
  void fields(Fields& f) {
    f("rows", rows);
    f("cols", cols);
    f("height", height);
    f("width", width);
  }
  int64_t pixels() const { return height * width; }
  int64_t size() const { return rows * cols * height * width; }  // 2025 by default
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
  bool operator==(const PatchShape& o) const {
    return rows == o.rows && cols == o.cols && height == o.height && width == o.width;
  }
};

// The closed sets of NetworkOptions, read and written by name (core/enum_names.h). The
// architecture is an open set: the registry's names (nn/architecture.h).
enum class Branches { kNet, kAe, kCnn };         // "net", "ae", "cnn"
enum class Residual { kNone, kPinv, kAdjoint };  // "none", "pinv", "adjoint"
enum class AeInput { kMeasurements, kAdjoint };  // "measurements", "adjoint"
std::string to_string(Branches value);
std::string to_string(Residual value);
std::string to_string(AeInput value);
Branches from_string(const std::string& name, Branches);
Residual from_string(const std::string& name, Residual);
AeInput from_string(const std::string& name, AeInput);

// The autoencoder branch's sizes and input.
struct AutoencoderOptions {
  // Output widths of fc1 .. fc5, alternately expanding and contracting; fc6 maps the last to
  // U V h w. The paper does not give widths. These keep the whole default checkpoint (model
  // and Adam moments, 3 x 4 bytes per parameter) under 10 MB: fc6 alone is 256 x 2025.
  std::vector<int64_t> hidden = {256, 128, 256, 128, 256};
  // What fc1 reads. "measurements": the measurement vector y (N h w values), as in the paper.
  // "adjoint": the scaled Phi^T y (U V h w values), which carries the patch's phase (periodic
  // masks) and does not change width when N does.
  AeInput input = AeInput::kMeasurements;

  template <typename Fields>
  void fields(Fields& f) {
    f("hidden", hidden, Range::closed(1, 1 << 16));
    f("input", input);
  }
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
};

// The 4D CNN branch's width and depth.
struct CnnOptions {
  int64_t channels = 16;  // hidden channels of the 4D CNN (1 in, 1 out)
  int64_t depth = 5;      // Conv4d layers, ReLU between (the paper's five)

  template <typename Fields>
  void fields(Fields& f) {
    f("channels", channels, Range::closed(1, 1024));
    f("depth", depth, Range::closed(1, 64));
  }
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
};

// The paper architecture's options: its section "paper" of the network options (paper_options).
struct PaperOptions {
  Branches branches = Branches::kNet;  // net (both branches, averaged), ae or cnn (one branch)
  int64_t kernel = 3;                  // Conv4d kernel size (odd)
  // Conv4d algorithm: auto, stacked, fused_output, fused_input
  Conv4dAlgorithm conv_algorithm = Conv4dAlgorithm::kAuto;
  AutoencoderOptions ae;
  CnnOptions cnn;
  // Weights of the (ae, cnn) outputs in the two-branch head; they apply to "net" only.
  std::vector<double> head_weights = {0.5, 0.5};
  // A fixed linear estimate added to the output, so the branches learn a correction:
  // "none" (the paper), "pinv" (Tikhonov pseudo-inverse, lambda = network.pinv_lambda) or
  // "adjoint" (the scaled Phi^T y). Off by default: docs/models.md saw no gain from it.
  Residual residual = Residual::kNone;

  template <typename Fields>
  void fields(Fields& f) {
    f("branches", branches);
    f("kernel", kernel, Range::closed(1, 15));
    f("conv_algorithm", conv_algorithm);
    f("ae", ae);
    f("cnn", cnn);
    f("head_weights", head_weights, Range::closed(0, 10));
    f("residual", residual);
  }
  bool has_ae() const { return branches != Branches::kCnn; }
  bool has_cnn() const { return branches != Branches::kAe; }
};

// The key of the paper architecture's section. Files written before it had one hold its keys
// at the top level of "network" (NetworkOptions::from_file_json moves them).
constexpr const char* kPaperSection = "paper";

// Everything that defines a LightFieldNet; stored in every checkpoint as "network".
struct NetworkOptions {
  // A registered architecture (nn/architecture.h). "paper": the two-branch network of Gupta et
  // al. on patches (its section "paper", paper_options). "lfnet": lfnet's own whole-image
  // architecture (its section "image", image_options): a U-Net over the per-pixel
  // pseudo-inverse of the sensor image, trained on crops of `patch` (docs/architectures.md).
  std::string architecture = kPaperArchitecture;
  PatchShape patch;          // the patch the net reconstructs (lfnet: the training crop)
  int64_t measurements = 2;  // N: measurement channels per pixel
  // Tikhonov weight of every pseudo-inverse derived from the Phi (the paper's "pinv" residual,
  // the per-pixel pseudo-inverses of local Phis) and of Phi switching.
  double pinv_lambda = 1e-3;
  // A colour net (an architecture whose colour() is true): the Bayer pattern ("RGGB", "BGGR",
  // "GRBG", "GBRG") of the colour filter array over the coded pixels. The net reads the single
  // mosaicked sensor image and reconstructs the three colours of every view jointly
  // (docs/architectures.md, "Colour"). Empty: a grey net.
  std::string cfa;
  // How a colour net demosaics its per-pixel pseudo-inverse into its layers' input:
  // "bilinear" or "malvar" (gradient-corrected, optics/cfa.h). Grey nets ignore it.
  optics::Demosaic demosaic = optics::Demosaic::kBilinear;
  // The option sections of the architectures (options_section(): "paper", "image",
  // "unrolled"), by key, as read: each is parsed and checked by its architecture
  // (section<T>()). A section of an architecture other than `architecture` is refused.
  nlohmann::json sections = nlohmann::json::object();
  // T: the sub-frames of a time-coded Phi (docs/video.md), whose views the patch stacks along
  // its rows (patch.rows = T U). The lfnet architecture then adds its U-Net's output to the
  // Phi's still-equivalent pseudo-inverse held in every frame (`pixel_hold`), and reads the
  // minimum-norm one, which shows each pixel's exposure code. Written only when above 1.
  int64_t frames = 1;

  template <typename Fields>
  void fields(Fields& f) {
    f("patch", patch);
    f("measurements", measurements);
    f("pinv_lambda", pinv_lambda, Range::closed(0, 1e3));
    f("architecture", architecture);
    f("cfa", cfa);
    f("demosaic", demosaic);
  }
  // Strict parsing: unknown keys and bad values are ConfigErrors naming the JSON path.
  static NetworkOptions from_json(const nlohmann::json& j, const std::string& path = "$");
  // A checkpoint's or an exported file's network options. Files written before each
  // architecture kept its own section hold every built-in's (a paper net's "image", the paper
  // options at the top level): the paper's keys move into its section, and the sections of
  // other architectures are dropped, not refused.
  static NetworkOptions from_file_json(const nlohmann::json& j, const std::string& path = "$");
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
  // Throws ConfigError naming the bad field (the architecture checks its own).
  void validate() const;
  // The section `key` read strictly into the Options struct T (its defaults where the section
  // or a key is absent); a ConfigError names the field, e.g. "unrolled.iterations: ...".
  template <typename T>
  T section(const std::string& key) const {
    const auto it = sections.find(key);
    return options_from_json<T>(it == sections.end() ? nlohmann::json::object() : *it, key);
  }
  // The same without T's validate(), for an architecture that checks the values itself (with
  // its own field paths).
  template <typename T>
  T unchecked_section(const std::string& key) const {
    T value;
    const auto it = sections.find(key);
    if (it == sections.end()) return value;
    JsonReader reader(*it, key);
    read_fields(reader, value);
    reader.finish();
    return value;
  }
  // Sets the section `key` to the fields of `value`.
  template <typename T>
  void set_section(const std::string& key, const T& value) {
    sections[key] = fields_to_json(value);
  }

  // The registered class of `architecture`; a ConfigError when none is.
  const NetworkArchitecture& arch() const { return find_architecture(architecture); }
  // The patch grid that reconstruction with this network uses: its patch shape, or none for a
  // whole-image architecture (its training crop is no patch).
  std::optional<PatchShape> patch_grid() const {
    if (arch().whole_image()) return std::nullopt;
    return patch;
  }
  // Colour channels of the light field the net reconstructs: 3 behind a CFA, else 1.
  int64_t colours() const { return cfa.empty() ? 1 : 3; }
  // The branches of the net, which staged training trains one at a time and the `ae` and
  // `cnn` methods run alone: the paper architecture's; "net" (one whole) for the others.
  Branches branches() const;
  // Sets them: the paper architecture's section; the others take "net" alone (a ConfigError).
  void set_branches(Branches value);
  bool has_ae() const { return architecture == kPaperArchitecture && branches() != Branches::kCnn; }
  bool has_cnn() const { return architecture == kPaperArchitecture && branches() != Branches::kAe; }
  int64_t measurement_size() const { return measurements * patch.pixels(); }  // N h w
};

// The paper architecture's options: the section "paper" of `o` (the defaults where it or a key
// is absent), read strictly; the architecture checks their values. set_paper_options writes
// them.
PaperOptions paper_options(const NetworkOptions& o);
void set_paper_options(NetworkOptions& o, const PaperOptions& paper);
// Width of the autoencoder's input: N h w ("measurements") or U V h w ("adjoint").
int64_t ae_input_size(const NetworkOptions& o, const PaperOptions& paper);

// Autoencoder branch: six fully connected layers with ReLU between, reshaped to a patch, then
// one Conv4d (1 -> 1 channel). No ReLU after fc6: its output is a light-field estimate.
class AutoencoderBranchImpl : public torch::nn::Module {
 public:
  explicit AutoencoderBranchImpl(const NetworkOptions& options);
  // (B, ae_input_size) -> (B, 1, U, V, h, w).
  torch::Tensor forward(const torch::Tensor& input);

  std::vector<torch::nn::Linear> fc;  // fc1 .. fc6
  Conv4d conv{nullptr};

 private:
  PatchShape patch_;
};
TORCH_MODULE(AutoencoderBranch);

// 4D CNN branch: `depth` Conv4d layers 1 -> C -> ... -> C -> 1 with ReLU between, run in the
// u-major layout so stacked layers need no transposes.
class CnnBranchImpl : public torch::nn::Module {
 public:
  explicit CnnBranchImpl(const NetworkOptions& options);
  // (B, 1, U, V, h, w) -> (B, 1, U, V, h, w).
  torch::Tensor forward(const torch::Tensor& x);

  std::vector<Conv4d> convs;  // conv1 .. conv<depth>
};
TORCH_MODULE(CnnBranch);

// Everything one forward pass computes, for analysis and tests.
struct NetworkOutputs {
  torch::Tensor output;  // (B, 1, U, V, h, w): the reconstruction
  torch::Tensor ae;      // the autoencoder branch's output (undefined without the branch)
  torch::Tensor cnn;     // the CNN branch's output (undefined without the branch)
  torch::Tensor base;    // the residual base (undefined when residual is "none")
};

// Which branches forward_all runs (those the net has; a branch it lacks is never run).
// Inference of one branch alone (the `ae` and `cnn` methods) need not pay for the other.
struct BranchSelection {
  bool ae = true;
  bool cnn = true;
};

// The reconstruction network of any registered architecture. Construct, then set_phi() with
// the tensor of the Phi the architecture takes (its phi_input: the patch matrices, or the
// per-pixel weights of one period; pipeline::phi_tensor gives either); until then `phi` is
// zero.
class LightFieldNetImpl : public torch::nn::Module {
 public:
  explicit LightFieldNetImpl(NetworkOptions options);

  // y: (B, N h w) measurement vectors of patches (or training crops); phase: (B) int64 indices
  // into the phi stack, may be undefined when there is one phase; noise: (B) sigma of each
  // patch's measurement noise, read by noise-aware nets only (undefined: 0). Returns (B, C, U,
  // V, h, w), C = options().colours().
  torch::Tensor forward(const torch::Tensor& y, const torch::Tensor& phase = {},
                        const torch::Tensor& noise = {});
  NetworkOutputs forward_all(const torch::Tensor& y, const torch::Tensor& phase = {});
  // The same with only the selected branches run; `output` combines those that ran (with
  // their head weights when both did, else the one alone, plus the residual base).
  NetworkOutputs forward_all(const torch::Tensor& y, const torch::Tensor& phase,
                             BranchSelection run);

  // Replaces the Phi. The paper architecture takes `stack` (P, N h w, U V h w) for any P >= 1
  // and recomputes the derived buffers (adjoint_scale, base); parameters are left alone (train
  // --init carries fc1 over). The lfnet architecture takes the pixel weights of one period T of
  // a local Phi, (N, U, V, T, T) (optics::Phi::pixel_weights at the origin), and derives
  // `pixel_pinv`.
  void set_phi(const torch::Tensor& stack);

  // Whole-image architectures: the reconstruction of sensor images (B, N, H, W) whose pixel
  // (0, 0) has phase `phase` (0 for a whole image): (B, U, V, H, W), or (B, 3, U, V, H, W) for a
  // colour net (the sensor images mosaicked by its CFA). The lfnet architecture
  // pads H and W to the U-Net's multiple (zeros, cropped off again). Peak memory grows with
  // H W: recon::reconstruct_sensor_tiled bounds it.
  // `noise_sigma`: the sensor's noise for a noise-aware net (ignored by others).
  torch::Tensor forward_image(const torch::Tensor& sensor, int64_t phase = 0,
                              double noise_sigma = 0.0);
  // Local Phis (lfnet, unrolled): the per-pixel Tikhonov pseudo-inverse of sensor crops
  // (B, N, h, w) whose pixel (0, 0) has phase `phase` (B) (undefined: 0), as (B, U V, h, w).
  torch::Tensor pixel_pinv_image(const torch::Tensor& sensor,
                                 const torch::Tensor& phase = {}) const;
  // `maps` (T, T, N, K) applied per pixel phase: (B, K, h, w).
  torch::Tensor pixel_map_image(const torch::Tensor& maps, const torch::Tensor& sensor,
                                const torch::Tensor& phase) const;
  // The same through `pixel_hold` (a net of a time-coded Phi, options().frames > 1): the
  // still-equivalent pseudo-inverse held in every frame (docs/video.md).
  torch::Tensor pixel_hold_image(const torch::Tensor& sensor,
                                 const torch::Tensor& phase = {}) const;

  // The scaled adjoint s_p Phi_p^T y as (B, U V h w), s_p the least-squares scale that maps
  // Phi_p^T Phi_p 1 closest to 1 (so a flat grey patch comes back near its own level).
  torch::Tensor adjoint(const torch::Tensor& y, const torch::Tensor& phase = {}) const;

  // Distinct phases of the net's Phi: T^2 for a code of period T.
  int64_t phases() const { return arch_->phases(*this); }
  // The Phi's period T: a patch or crop at (y0, x0) has phase (y0 mod T) T + (x0 mod T).
  int64_t period() const;
  const NetworkOptions& options() const { return options_; }
  const NetworkArchitecture& architecture() const { return *arch_; }

  // The layer the architecture registered as `name` (a direct submodule), as its class M;
  // a null pointer when it has none of that name and class.
  template <typename M>
  std::shared_ptr<M> layer(const std::string& name) const {
    for (const auto& child : named_children()) {
      if (child.key() == name) return std::dynamic_pointer_cast<M>(child.value());
    }
    return nullptr;
  }

  torch::Tensor phi, adjoint_scale, base;
  torch::Tensor pixel_pinv;  // local Phis: (T, T, N, U V) per-pixel pseudo-inverses
  // Time-coded Phis (frames > 1): (T, T, N, U V), the still-equivalent pseudo-inverse in every
  // frame; undefined otherwise.
  torch::Tensor pixel_hold;
  // A colour net: the CFA's response (3, T, T) over the period T of `phi` and `pixel_pinv`,
  // the least common multiple of the code's and the CFA's.
  torch::Tensor cfa_response;

  // Checks y (B, N h w) and phase; returns phase (undefined for one phase).
  torch::Tensor check_phase(const torch::Tensor& y, const torch::Tensor& phase) const;

 private:
  NetworkOptions options_;
  const NetworkArchitecture* arch_ = nullptr;  // owned by the registry
};
TORCH_MODULE(LightFieldNet);

// The paper architecture's branches, the layers "ae" and "cnn" of `net` (null when it has
// none: another architecture, or one branch only).
std::shared_ptr<AutoencoderBranchImpl> ae_branch(const LightFieldNetImpl& net);
std::shared_ptr<CnnBranchImpl> cnn_branch(const LightFieldNetImpl& net);

// The lfnet architecture's U-Net, the layer "image" of `net` (null for another architecture).
std::shared_ptr<ImageNetImpl> image_layers(const LightFieldNetImpl& net);
// The lfnet architecture's U-Net options: the section "image" of `o` (the defaults where it or a
// key is absent), read strictly; their values are checked by NetworkOptions::validate.
// set_image_options writes them.
ImageNetOptions image_options(const NetworkOptions& o);
void set_image_options(NetworkOptions& o, const ImageNetOptions& image);

// y (B, M) times the phase's matrix of `stack` (P, M, D): (B, D). Groups the batch by phase.
torch::Tensor apply_phase_stack(const torch::Tensor& y, const torch::Tensor& phase,
                                const torch::Tensor& stack);

// Tikhonov pseudo-inverses in the layout of the stack: (P, M, D) -> (P, M, D) with
// base_p = (Phi_p Phi_p^T + lambda I)^-1 Phi_p, so y base_p = (Phi_p^+ y)^T. Float64 inside.
torch::Tensor pinv_stack(const torch::Tensor& stack, double lambda);

// Weights of a layer that reads measurements of Phi A, carried over to Phi B (Phi switching):
// W_B = W_A Phi_A Phi_B^+ with Phi_B^+ = Phi_B^T (Phi_B Phi_B^T + lambda I)^-1, so that
// W_B Phi_B l = W_A Phi_A l for every light-field patch l in the row space of Phi_B.
// weight (H, M_A), phi_a (M_A, D), phi_b (M_B, D) -> (H, M_B).
torch::Tensor map_measurement_weights(const torch::Tensor& weight, const torch::Tensor& phi_a,
                                      const torch::Tensor& phi_b, double lambda);

// Arithmetic of the CNN branch's convolutions at inference.
enum class Precision {
  kFloat32,   // as trained
  kBFloat16,  // bfloat16 weights and activations (8-bit mantissa), float32 accumulation in
              // oneDNN; about 1.5 times faster on CPUs with AVX-512 BF16 (docs/performance.md)
};

// "float32" or "bfloat16"; anything else is a ConfigError.
Precision parse_precision(const std::string& name);
std::string to_string(Precision precision);
inline Precision from_string(const std::string& name, Precision) { return parse_precision(name); }

// Converts the layers that run in reduced precision (the architecture's set_precision: the
// paper's CNN branch, lfnet's U-Net) to `precision` (for inference: a net in bfloat16 is not
// for training or saving). Those layers cast their input to their weights' type and their
// output back to the input's type, so the rest of the net (the pseudo-inverse, the residual
// sum) stays float32.
void set_cnn_precision(LightFieldNet& net, Precision precision);
// Training for a run in `precision`: those layers keep float32 weights and round as `precision`
// would (NetworkArchitecture::emulate_precision); a ConfigError for an architecture without it.
void emulate_precision(LightFieldNet& net, Precision precision);

// The FLOP model (lfnet bench), from the same options that build the modules: nominal
// floating-point operations of one patch through the parts `run` selects (the architecture's
// patch_flops), and for the paper architecture of the CNN branch alone and of the CNN branch
// run fully convolutionally over an H x W light field in tiles of `tile` (halo included).
double patch_flops(const NetworkOptions& o, const BranchSelection& run);
double cnn_patch_flops(const NetworkOptions& o);
double cnn_full_flops(const NetworkOptions& o, int64_t height, int64_t width, int64_t tile);
// lfnet architecture: nominal floating-point operations per light-field pixel (pseudo-inverse
// and U-Net).
double image_pixel_flops(const NetworkOptions& o);
// Whole-image architectures: the operations of a whole H x W light field in tiles of `tile`
// (halo included, as recon::reconstruct_sensor_tiled computes them).
double image_full_flops(const NetworkOptions& o, int64_t height, int64_t width, int64_t tile);

// lfnet architecture: the per-pixel Tikhonov pseudo-inverses (T, T, N, U V) of the pixel
// weights (N, U, V, T, T) of one period: A^T (A A^T + lambda I)^-1 per pixel phase, stored
// transposed, in the weights' dtype and differentiable in them. set_phi stores them (in
// float64, cast to the net's dtype); a code trained with the net (train/joint_phi.h) reads them
// inside the graph.
torch::Tensor pixel_pseudo_inverses(const torch::Tensor& weights, double lambda);

// Number of trainable parameters.
int64_t parameter_count(const torch::nn::Module& module);

}  // namespace lfnet::nn

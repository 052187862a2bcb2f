// Reconstruction with the CNN branch run once over the whole light field (in tiles) rather
// than once per patch (docs/performance.md).
//
// Patch stitching runs the CNN on every patch separately, zero-padded at the patch border, and
// averages the overlapping estimates: at stride s every pixel is computed about (9 / s)^2 times.
// Here the CNN's input is the stitched scaled adjoint s_p Phi_p^T y of the patches (for a Phi
// that is periodic per pixel, the overlapping patches' estimates of a pixel differ only by
// the scale s_p of their phase), and the CNN runs once over it: each output pixel sees its
// true neighbours up to the receptive field (depth * (K - 1) / 2 pixels) instead of the zeros
// past its patch's border. That is not what the net was trained on, so the result differs
// from patch stitching; the autoencoder branch and the residual base still run per patch
// and are stitched.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/reconstruct.h"

namespace lfnet::recon {

// How patch estimates of the CNN branch are formed.
enum class CnnMode {
  kPatches,  // per patch, stitched (the paper's way and the default)
  kFull,     // once over the whole light field, in tiles
};

// "patches" or "full"; anything else is a ConfigError.
CnnMode parse_cnn_mode(const std::string& name);
std::string to_string(CnnMode mode);
inline CnnMode from_string(const std::string& name, CnnMode) { return parse_cnn_mode(name); }

// Spatial tile of the fully convolutional pass, without its halo of depth * (K - 1) / 2
// pixels on every side (the halo is recomputed, so larger tiles waste less).
constexpr int64_t kDefaultCnnTile = 128;

// The CNN branch over a whole single-channel light field x (U, V, H, W), in tiles of
// `tile` x `tile` pixels with a halo; returns (U, V, H, W) float32 on the CPU. The result
// equals running the branch on the whole light field at once with zero padding at the light
// field's border (activations outside the light field are zeroed after every layer), to float
// rounding. Runs on the device of the branch's weights.
torch::Tensor cnn_over_light_field(nn::CnnBranch cnn, const torch::Tensor& x,
                                   int64_t tile = kDefaultCnnTile);

// Reconstructs a grey light field (1, U, V, H, W) from a sensor image (N, H, W) with `net`'s
// method `method` (net or cnn; ae has no CNN and is a ConfigError), the CNN branch run by
// cnn_over_light_field over the stitched scaled adjoint. The autoencoder branch (weighted by
// its head weight) and the residual base are computed per patch and stitched as in
// reconstruct_sensor with `options`.
torch::Tensor reconstruct_sensor_fully_convolutional(
    nn::LightFieldNet net, const std::string& method, const optics::Phi& phi,
    const torch::Tensor& sensor, const ReconstructOptions& options, int64_t tile = kDefaultCnnTile);

// Spatial tile of the lfnet architecture's whole-image pass, without its halo: 0, automatic
// (nn::auto_image_tile: the whole image up to 800 x 800 pixels, else crops of 512 with halos;
// a colour net 640 and 720).
constexpr int64_t kDefaultImageTile = 0;

// Reconstructs a grey light field (1, U, V, H, W) from a sensor image (N, H, W) with a net of
// the lfnet architecture (a colour net: the colour light field (3, U, V, H, W) from its
// mosaicked sensor image), in tiles of about `tile` x `tile` pixels (rounded up to the U-Net's
// multiple; 0: nn::auto_image_tile) with a halo of its receptive radius, so peak memory depends on
// the tile, not on the image. The result equals net->forward_image on the whole image, to float
// rounding. Runs on the device of the net's weights; returns float32 on the CPU, clamped to [0, 1]
// when `clamp`. `noise_sigma` conditions a noise-aware net. `progress` gets (tiles done,
// tiles in all). `coded`: the result is 16-bit codes (int16, clamped; core/light_field.h),
// each tile encoded as it is done, so the light field is held in half the memory. `origin`:
// the phase of the sensor image's pixel (0, 0) in the net's period (row * T + column).
torch::Tensor reconstruct_sensor_tiled(nn::LightFieldNet net, const torch::Tensor& sensor,
                                       int64_t tile = kDefaultImageTile, bool clamp = true,
                                       double noise_sigma = 0.0,
                                       const ProgressCallback& progress = {}, bool coded = false,
                                       int64_t origin = 0);

// A mirror image under which a Phi is symmetric: it measures the mirrored light field (x and
// v reversed with `flip_x`, y and u with `flip_y`) as the mirrored sensor image with its
// measurements permuted: measurement k of the mirrored image is measurement `measurements[k]`
// of the sensor image, mirrored.
struct SensorMirror {
  bool flip_x = false;
  bool flip_y = false;
  std::vector<int64_t> measurements;
};

// The mirrors of a Phi, the identity first, from the per-pixel weights (N, U, V, T, T) that an
// lfnet net holds (its `phi` buffer): those of the four (none, x, y, both) that map every
// weight image onto one of the weight images, all of them once (to 1e-5 of the largest
// weight). `asp:2` has all four. A Phi of period T > 1 keeps the identity alone (its mirror
// images would depend on the image's size).
std::vector<SensorMirror> phi_mirrors(const torch::Tensor& pixel_weights);

// The pixel weights whose mirrors a net's self-ensemble uses: its `phi` buffer, or for a colour
// net whose code has period 1 (its weights repeated over the CFA's period) one period of the
// code: a Bayer pattern's mirror image is the same pattern at another phase
// (mirrored_origin), so the colour net's mirrors are its code's.
torch::Tensor mirror_weights(const nn::LightFieldNet& net);

// The phase (row * T + column in the net's period T) at which a net reads the mirror image `m`
// of an H x W sensor image (or crop) whose pixel (0, 0) has phase `origin`: `origin` for a grey
// net (whose mirrors need a code of period 1); for a colour net, the phase at which its CFA
// pattern shows what the mirror image holds.
int64_t mirrored_origin(const nn::LightFieldNet& net, const SensorMirror& m, int64_t height,
                        int64_t width, int64_t origin = 0);

// Whether the model, a checkpoint's network (`net`, empty without one) or an exported one
// (`script`, null without one), is of an architecture that reconstructs whole sensor images.
bool whole_image_model(const nn::LightFieldNet& net, const nn::ScriptedNetwork* script);

// Throws a ConfigError unless the self-ensemble applies: `method` "net" with a model of a
// whole-image architecture, a checkpoint's network (`net`, empty without one) or an exported one
// (`script`, null without one).
void check_self_ensemble(const std::string& method, const nn::LightFieldNet& net,
                         const nn::ScriptedNetwork* script = nullptr);

// Throws a ConfigError when `passes` (--ensemble-passes; 0: not given) is set without the
// self-ensemble.
void check_ensemble_passes(bool self_ensemble, int64_t passes);

// The mirrors a self-ensemble of at most `max_passes` passes uses (0: all): the first of
// phi_mirrors(pixel_weights), the identity first, then left to right, top to bottom, both.
// A ConfigError when `max_passes` is negative.
std::vector<SensorMirror> ensemble_mirrors(const torch::Tensor& pixel_weights,
                                           int64_t max_passes = 0);

// The mirrors the self-ensemble of a net uses: ensemble_mirrors of mirror_weights(net) for a
// checkpoint's network (`net`), of the pixel weights of an exported one (`script`) otherwise.
std::vector<SensorMirror> ensemble_mirrors(const nn::LightFieldNet& net,
                                           const nn::ScriptedNetwork* script, int64_t max_passes);

// A whole-image reconstruction, sensor (N, H, W) -> (C, U, V, H, W), of the mirror image
// `mirror` of a sensor image, given a progress callback for its own part of the work.
using SensorPass = std::function<torch::Tensor(
    const torch::Tensor& sensor, const SensorMirror& mirror, const ProgressCallback& progress)>;

// The self-ensemble of any whole-image reconstruction `pass`: the sensor image and its mirror
// images under `mirrors` (ensemble_mirrors) are reconstructed, mirrored back and averaged;
// clamped to [0, 1] when `clamp`. `progress` gets (done, total) over all passes.
torch::Tensor reconstruct_mirrored(const std::vector<SensorMirror>& mirrors,
                                   const torch::Tensor& sensor, const SensorPass& pass,
                                   bool clamp = true, const ProgressCallback& progress = {});

// The self-ensemble of reconstruct_sensor_tiled: the sensor image and its mirror images under
// the Phi's mirrors (ensemble_mirrors of mirror_weights(net), at most `max_passes` of them; 0:
// all; a colour net reads each mirror image at its mirrored_origin)
// are reconstructed, mirrored back and averaged, up to 4 passes. With every mirror it is
// equivariant: the mirror image of a light field reconstructs as the mirror image of its
// reconstruction.
torch::Tensor reconstruct_sensor_mirrored(nn::LightFieldNet net, const torch::Tensor& sensor,
                                          int64_t tile = kDefaultImageTile, bool clamp = true,
                                          double noise_sigma = 0.0,
                                          const ProgressCallback& progress = {},
                                          int64_t max_passes = 0);

// The self-ensemble of a batch of sensor crops (B, N, h, w), as training sees them: each
// crop's pixel (0, 0) has phase `phase` (B) (undefined: 0) and its measurements noise `noise`
// (B) (undefined: 0). The crops and their mirror images under
// ensemble_mirrors(mirror_weights(net), max_passes) run through net->forward_image (each at its
// mirrored_origin), are mirrored back and averaged: (B, C, U, V, h, w) (C = 1, or 3 for a
// colour net), not clamped, on the device of the net. For a whole image it equals
// reconstruct_sensor_mirrored without the clamp. It is the teacher of distillation
// (pipeline::DistillConfig).
torch::Tensor reconstruct_crops_mirrored(nn::LightFieldNet net, const torch::Tensor& sensor,
                                         const torch::Tensor& phase = {},
                                         const torch::Tensor& noise = {}, int64_t max_passes = 0);

}  // namespace lfnet::recon

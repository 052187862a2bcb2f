// lfnet's own architecture (docs/architectures.md): a U-Net over the spatial axes that refines
// the per-pixel pseudo-inverse of the whole sensor image. The views of the light field are its
// input and output channels, so every layer mixes all views of a neighbourhood; the levels
// halve the resolution, so the receptive field covers parallax the 9 x 9 patches of the paper
// cannot see. It is fully convolutional: trained on crops, it runs on whole images.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/conv.h>
#include <torch/nn/pimpl.h>
#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "lfnet/core/fields.h"
#include "lfnet/core/json.h"
#include "lfnet/nn/architecture.h"

namespace lfnet::nn {

// Widths and depth of the U-Net.
struct ImageNetOptions {
  int64_t channels = 32;  // feature channels at full resolution, doubled at every level
  int64_t levels = 3;     // resolutions: full, 1/2, 1/4 ... (1 = no down-sampling)
  int64_t blocks = 2;     // 3 x 3 convolutions (with ReLU) per level, encoder and decoder alike
  // Channels per level, top first, when not simply doubled: e.g. {48, 96, 192, 128} keeps a
  // fourth level from costing more parameters than the three above it. Empty: channels << l.
  // The first entry must be `channels`.
  std::vector<int64_t> widths;
  // Noise-aware: one more input channel holds the sigma of the measurements' noise (relative
  // to white), so one model serves every noise level (train with dataset.noise_range).
  bool noise_input = false;

  template <typename Fields>
  void fields(Fields& f) {
    f("channels", channels, Range::closed(1, 1024));
    f("levels", levels);
    f("blocks", blocks, Range::closed(1, 16));
    f("widths", widths);
    f("noise_input", noise_input);
  }
  void read(JsonReader& reader);
  nlohmann::json to_json() const;
  // Throws ConfigError naming the bad field, under `key` when given (e.g. "denoiser.levels:
  // ..."; read as a section, the section's key comes first).
  void validate(const std::string& key = "") const;

  // Feature channels at `level` (0 = full resolution).
  int64_t width(int64_t level) const {
    return widths.empty() ? channels << level : widths[static_cast<size_t>(level)];
  }
  // Image sides the net takes: multiples of 2^(levels - 1).
  int64_t multiple() const { return int64_t{1} << (levels - 1); }
  // Radius in full-resolution pixels beyond which an input pixel cannot change an output
  // pixel; tiles of tiled inference need a halo at least this wide (rounded to multiple()).
  int64_t receptive_radius() const;
  // Nominal floating-point operations per full-resolution pixel for `in` input and `out`
  // output channels.
  double pixel_flops(int64_t in, int64_t out) const;
  // How a net of this U-Net is tiled: its multiple and receptive radius.
  ImageTiling tiling() const { return {multiple(), receptive_radius()}; }
};

// One tile of tiled inference over an H x W image padded to the net's multiple: its core
// [y0, y0 + step) x [x0, x0 + step) and the crop computed for it, [a0, a1) x [b0, b1), the core
// with a halo of the receptive radius, both rounded to the multiple and clipped to the padded
// image. Tiles start at multiples of the multiple, so every crop down-samples on the grid of
// the whole image.
struct ImageTile {
  int64_t y0 = 0, x0 = 0, a0 = 0, a1 = 0, b0 = 0, b1 = 0;
};
// `v` rounded up to a multiple of `multiple` (v >= 0, multiple >= 1): an image side padded for a
// U-Net whose sides must be multiples of it.
int64_t round_up(int64_t v, int64_t multiple);

// The automatic tile (a `tile` of 0) for a height x width image: the whole padded image when it
// fits in tiling.whole^2 pixels, so that no halo is computed twice; else the largest tile whose
// crop with its halos fits in tiling.crop x tiling.crop, at least 256, a multiple of the
// multiple.
int64_t auto_image_tile(const ImageTiling& tiling, int64_t height, int64_t width);
// The tiles of `tile` x `tile` pixels (rounded up to the multiple; 0: auto_image_tile) covering
// height x width, row by row, for a whole-image net tiled as `tiling`
// (NetworkArchitecture::image_tiling); `step` receives the rounded tile side.
std::vector<ImageTile> image_tiles(const ImageTiling& tiling, int64_t height, int64_t width,
                                   int64_t tile, int64_t* step = nullptr);

// Finetuning a wider U-Net from a narrower one of the same depth (train --init): copies the
// narrow parameter `src` of the layer `name` (relative to the U-Net, e.g. "enc0_1.weight") into
// the leading channels of `dst`, and zeroes the weights by which those channels would read the
// new ones. Embedding every parameter so makes the wide net compute exactly what the narrow one
// did; the new channels keep their fresh initialisation and learn from there. An input
// convolution that gains input channels (noise_input switched on) is embedded the same way.
// Returns false, leaving `dst` alone, when `src` does not fit in `dst`.
bool embed_narrow_parameter(const std::string& name, const torch::Tensor& src, torch::Tensor& dst);

// The U-Net: (B, in, H, W) -> (B, out, H, W) with H and W multiples of options.multiple().
// Its last convolution starts at zero, so an untrained net adds nothing to its input's estimate.
class ImageNetImpl : public torch::nn::Module {
 public:
  ImageNetImpl(const ImageNetOptions& options, int64_t in, int64_t out);
  torch::Tensor forward(const torch::Tensor& x);
  // Converts the convolutions to `dtype` for inference (bfloat16, or float32 back), all but the
  // transposed ones: LibTorch 1.13's oneDNN path runs a bfloat16 transposed convolution as a
  // plain one, so those stay float32 and convert their input and output.
  void set_precision(torch::Dtype dtype);
  // Training for a bfloat16 run (training.precision, docs/performance.md): with `dtype`
  // bfloat16 the forward pass rounds to bfloat16 every tensor that set_precision(bfloat16)
  // would hold in it (the convolutions' inputs, weights, biases and outputs, the transposed
  // convolutions' outputs and the skip sums) and computes in float32, so the net meets the
  // rounding of a bfloat16 run while the optimiser keeps float32 weights; gradients pass the
  // rounding unchanged. float32 turns it off. The weights stay float32 either way.
  void emulate_precision(torch::Dtype dtype);
  bool emulates_bfloat16() const { return emulate_bfloat16_; }
  // Finetuning a deeper U-Net from a shallower one of `from_levels` levels (train --init), once
  // the shallow net's parameters are in place: the up-sampling from the shallow net's bottom
  // level starts at zero and that level's decoder blocks as the identity, so the deeper net
  // computes what the shallow one did (its encoder output, through ReLU, is not negative) and
  // the new levels below learn from there. Returns the names of the parameters it set.
  std::vector<std::string> start_new_levels(int64_t from_levels);

  const ImageNetOptions& options() const { return options_; }

 private:
  ImageNetOptions options_;
  torch::nn::Conv2d input_{nullptr}, output_{nullptr};
  std::vector<std::vector<torch::nn::Conv2d>> encoder_, decoder_;  // per level
  std::vector<torch::nn::Conv2d> down_;                            // level l -> l + 1
  std::vector<torch::nn::ConvTranspose2d> up_;                     // level l + 1 -> l
  bool emulate_bfloat16_ = false;                                  // emulate_precision
};
TORCH_MODULE(ImageNet);

}  // namespace lfnet::nn

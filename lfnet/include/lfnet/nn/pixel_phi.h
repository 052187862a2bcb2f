// What the architectures over a local Phi's per-pixel weights share (lfnet, unrolled;
// docs/architectures.md): the buffers `phi` (N, U, V, T, T) and `pixel_pinv` (T, T, N, U V) on
// the net, their checks, phases and period axes, training crops of a U-Net's multiple, and the
// FLOPs of an image in tiles.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include "lfnet/nn/architecture.h"
#include "lfnet/nn/network.h"

namespace lfnet::nn {

// ConfigError unless the training crop's sides are multiples of `multiple`.
void check_crop_multiple(const NetworkOptions& options, int64_t multiple,
                         const std::string& architecture);

// Registers `phi` (N, U, V, 1, 1) and `pixel_pinv` (1, 1, N, U V) on `net`, zero until set_phi.
void register_pixel_phi(LightFieldNetImpl& net);

// Checks the pixel weights of one period, (N, U, V, T, T), against the net's options and for
// NaN or inf; `architecture` names the net in the error.
void check_pixel_weights(const LightFieldNetImpl& net, const torch::Tensor& weights,
                         const std::string& architecture);

// Stores `weights` (N, U, V, T, T) as `phi` and their per-pixel Tikhonov pseudo-inverses
// (pixel_pseudo_inverses in float64, lambda = pinv_lambda) as `pixel_pinv`.
void store_pixel_phi(LightFieldNetImpl& net, const torch::Tensor& weights);

// The entries (B, h, w, ...) of crops (B, *, h, w) whose pixel (0, 0) has phase `phase` (B,
// undefined: 0), from a tile of one period (T, T, ...): pixel (i, j) of a crop of phase
// (py, px) takes the tile's entry ((py + i) mod T, (px + j) mod T).
torch::Tensor pixel_period_maps(const torch::Tensor& period, const torch::Tensor& phase,
                                int64_t batch, int64_t h, int64_t w);

// T^2: the phases of a net that holds the pixel weights of one period T.
int64_t pixel_phases(const LightFieldNetImpl& net);

// The period axes of `phi` (rank 5) and `pixel_pinv`; empty for any other buffer.
std::vector<size_t> pixel_phase_axes(const std::string& name, size_t rank);

// The FLOPs of an H x W image reconstructed in tiles of `tile` (halos included, as
// recon::reconstruct_sensor_tiled computes them), at `pixel_flops` per pixel.
double tiled_image_flops(const ImageTiling& tiling, double pixel_flops, int64_t height,
                         int64_t width, int64_t tile);

}  // namespace lfnet::nn

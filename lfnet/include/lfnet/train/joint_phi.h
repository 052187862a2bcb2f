// Training a code with its network (docs/training.md, "Learned codes"): the measurements of
// each training patch are simulated again from the learnable code (nn/learned_phi.h), inside
// the graph, and the lfnet architecture's per-pixel pseudo-inverse is computed from the same
// code (nn::pixel_pseudo_inverses), so the loss's gradient reaches the code's parameters as
// well as the network's.
#pragma once

#include <torch/torch.h>

#include <cstdint>

#include "lfnet/nn/learned_phi.h"
#include "lfnet/nn/loss.h"
#include "lfnet/nn/network.h"
#include "lfnet/train/batch_source.h"

namespace lfnet::train {

// The measurements (B, N h w) of patches `target` (B, 1, U, V, h, w) by a code of pixel weights
// `weights` (N, U, V, T, T), each patch of phase p = (y0 mod T) T + (x0 mod T) (`phase`, (B,)
// int64; undefined: 0) reading the tile from ((p / T), (p mod T)): what optics' patch
// simulation computes, differentiable in the weights.
torch::Tensor simulate_patches(const torch::Tensor& weights, const torch::Tensor& target,
                               const torch::Tensor& phase);

// The reconstruction (B, 1, U, V, h, w) by a lfnet-architecture `net` of `batch`'s targets
// measured by pixel weights `weights` (N, U, V, T, T): simulate_patches, Gaussian noise of the
// batch's sigmas drawn from `noise_seed` (a CPU generator, so the draws are the same on any
// device), and the net reading the weights' per-pixel pseudo-inverse for this pass only.
// Differentiable in the weights and the net.
torch::Tensor joint_forward(nn::LightFieldNet& net, const torch::Tensor& weights,
                            const Batch& batch, uint64_t noise_seed);

// The loss of a lfnet-architecture `net` on `batch` when its measurements come from `code`:
// the batch's targets simulated with code->weights() (noise of the batch's sigmas added, drawn
// from `noise_seed`), reconstructed by the net with the code's pseudo-inverse. `net` keeps its
// own buffers: after training, LightFieldNet::set_phi with the final weights stores them.
torch::Tensor joint_loss(nn::LightFieldNet& net, const nn::LearnedPhi& code, const Batch& batch,
                         const nn::ReconstructionLoss& loss, uint64_t noise_seed);

}  // namespace lfnet::train

// Synthetic training data for the train tests: smooth patches with parallax and random Phis.
#pragma once

#include <torch/torch.h>
#include <nlohmann/json.hpp>

#include <memory>

#include "lfnet/nn/network.h"
#include "lfnet/train/batch_source.h"

namespace lfnet::test {

// n patches (n, 1, U, V, h, w) in [0, 1]: a random smooth texture (offset plus three random
// sinusoids) seen from every view with a random disparity in [-1, 1] pixels per view step.
torch::Tensor smooth_patches(int64_t n, const nn::PatchShape& shape, uint64_t seed);

// A stack (P, M, D) of dense Gaussian patch matrices with entries N(0, 1 / D).
torch::Tensor gaussian_phi(int64_t phases, int64_t m, int64_t d, uint64_t seed);

// A stack (P, N h w, U V h w) of per-pixel matrices: measurement n at pixel (y, x) weighs the
// views of that pixel with random non-negative weights (like asp or a coded mask).
torch::Tensor per_pixel_phi(int64_t phases, int64_t n, const nn::PatchShape& shape, uint64_t seed);

// Measures `patches` with `phi` (phase i % P for patch i) and wraps them in a batch source.
std::unique_ptr<train::InMemoryBatchSource> make_source(const torch::Tensor& patches,
                                                        const torch::Tensor& phi,
                                                        uint64_t seed = 0);

// The small geometry of most train tests: 3 x 3 views of 5 x 5 pixels, N = 2, a small net.
nn::NetworkOptions small_net_options(const std::string& branches = "net");

// A small net of the lfnet architecture: 2 measurements of 3 x 3 views, crops of side x side,
// a U-Net of two levels of one block with `channels` features.
nn::NetworkOptions small_image_options(int64_t side, int64_t channels);

// A Phi spec JSON naming the synthetic Phi.
nlohmann::json synthetic_phi_spec(const std::string& name, int64_t n, uint64_t seed);

}  // namespace lfnet::test

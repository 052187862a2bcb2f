// Small networks for the tests that need a model: random weights and a checkpoint file.
#pragma once

#include <cstdint>
#include <string>

#include "lfnet/nn/network.h"
#include "lfnet/optics/phi.h"

namespace lfnet::test {

// Edits the paper architecture's section of `o` in place:
// edit_paper(o, [](nn::PaperOptions& p) { p.kernel = 5; }).
template <typename Edit>
void edit_paper(nn::NetworkOptions& o, Edit&& edit) {
  auto paper = nn::paper_options(o);
  edit(paper);
  nn::set_paper_options(o, paper);
}

// The same for lfnet's U-Net, the section "image".
template <typename Edit>
void edit_image(nn::NetworkOptions& o, Edit&& edit) {
  auto image = nn::image_options(o);
  edit(image);
  nn::set_image_options(o, image);
}

// The paper's two-branch network at toy size: 3 x 3 x 5 x 5 patches, N = 2, a 40-20-40-20-40
// autoencoder and a 3-layer CNN of 4 channels; `branches` "net", "ae" or "cnn".
nn::NetworkOptions small_network_options(const std::string& branches = "net");

// Random weights (N(0, 0.2^2)) everywhere in the U-Net of lfnet's architecture, its last
// convolution included, so the net is not the identity on its pseudo-inverse.
void randomise_image_net(nn::LightFieldNet& net, uint64_t seed);

// A small net of lfnet's architecture for asp:2 (crops of 16 x 16, `channels` channels, 2
// levels, 1 block), saved as a checkpoint: a colour net behind the Bayer pattern `cfa` unless it
// is empty; with `seed` 0 untrained (it returns the (demosaiced) pseudo-inverse), else with
// random U-Net weights from that seed (randomise_image_net).
void save_small_image_net(const std::string& cfa, uint64_t seed, const std::string& path,
                          int64_t channels = 6);

// `net`, trained for `phi` up to `stage` as far as the file says, saved as a checkpoint with a
// measurement mean of 0.3.
void save_net(const nn::LightFieldNet& net, const optics::Phi& phi, const std::string& stage,
              const std::string& path);

}  // namespace lfnet::test

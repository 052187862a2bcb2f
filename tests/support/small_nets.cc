#include "support/small_nets.h"

#include <torch/torch.h>

#include "lfnet/train/checkpoint.h"

namespace lfnet::test {

nn::NetworkOptions small_network_options(const std::string& branches) {
  nn::NetworkOptions o;
  o.patch = {3, 3, 5, 5};
  o.measurements = 2;
  edit_paper(o, [&](nn::PaperOptions& p) {
    p.branches = nn::from_string(branches, p.branches);
    p.ae.hidden = {40, 20, 40, 20, 40};
    p.cnn.channels = 4;
    p.cnn.depth = 3;
  });
  return o;
}

void randomise_image_net(nn::LightFieldNet& net, uint64_t seed) {
  torch::manual_seed(seed);
  torch::NoGradGuard no_grad;
  for (auto& p : lfnet::nn::image_layers(*net)->parameters()) p.copy_(torch::randn_like(p) * 0.2);
}

void save_net(const nn::LightFieldNet& net, const optics::Phi& phi, const std::string& stage,
              const std::string& path) {
  train::Checkpoint ck;
  ck.network = net->options().to_json();
  ck.phi = phi.spec().to_json();
  ck.config = {{"measurement_mean", 0.3}};
  ck.model = train::module_state(*net);
  ck.training.stage = stage;
  train::save_checkpoint(ck, path);
}

void save_small_image_net(const std::string& cfa, uint64_t seed, const std::string& path,
                          int64_t channels) {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  nn::NetworkOptions o;
  o.architecture = nn::kLfnetArchitecture;
  o.measurements = 2;
  o.patch = {5, 5, 16, 16};
  edit_image(o, [&](nn::ImageNetOptions& image) {
    image.channels = channels;
    image.levels = 2;
    image.blocks = 1;
  });
  o.cfa = cfa;
  nn::LightFieldNet net(o);
  net->set_phi(phi->pixel_weights(0, 0, 1, 1));
  if (seed != 0) randomise_image_net(net, seed);
  save_net(net, *phi, "joint", path);
}

}  // namespace lfnet::test

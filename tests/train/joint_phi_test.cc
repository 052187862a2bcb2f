// Training a code with its network (train/joint_phi.h): the same loss as the fixed-code path,
// and gradients that reach the code.
#include "lfnet/train/joint_phi.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/optics/phi.h"
#include "support/small_nets.h"

using namespace lfnet;

namespace {

nn::LightFieldNet small_lfnet(bool noise_input) {
  nn::NetworkOptions o;
  o.architecture = nn::kLfnetArchitecture;
  o.measurements = 2;
  o.patch = {5, 5, 12, 12};
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) {
    image.channels = 6;
    image.levels = 2;
    image.blocks = 1;
    image.noise_input = noise_input;
  });
  return nn::LightFieldNet(o);
}

nn::LearnedPhi mask_code(int64_t period) {
  nn::LearnedPhiOptions o;
  o.family = "mask";
  o.period = period;
  o.seed = 5;
  return nn::LearnedPhi(o, 2, 5, 5);
}

// Four smooth patches (B, 1, 5, 5, 12, 12) of phases 0, 4, 7, 8 for a period of 3.
train::Batch patches() {
  torch::manual_seed(9);
  const auto base = torch::rand({4, 1, 1, 1, 3, 3});
  auto target = torch::nn::functional::interpolate(base.view({4, 1, 3, 3}),
                                                   torch::nn::functional::InterpolateFuncOptions()
                                                       .size(std::vector<int64_t>{12, 12})
                                                       .mode(torch::kBilinear)
                                                       .align_corners(true))
                    .view({4, 1, 1, 1, 12, 12})
                    .expand({4, 1, 5, 5, 12, 12})
                    .contiguous();
  target = target + 0.05 * torch::rand({4, 1, 5, 5, 12, 12});
  return {torch::Tensor(), torch::tensor({0, 4, 7, 8}, torch::kInt64), target.clamp(0, 1), {}};
}

}  // namespace

TEST_CASE("a code's patches are simulated as the Phi it makes simulates them", "[train][joint]") {
  auto code = mask_code(3);
  const auto phi = optics::make_phi(code->spec());
  auto batch = patches();
  const auto y = train::simulate_patches(code->weights(), batch.target, batch.phase);
  for (int64_t i = 0; i < 4; ++i) {
    const int64_t p = batch.phase[i].item<int64_t>();
    const auto m = phi->patch_matrix(p / 3, p % 3, 12, 12);
    const auto want = torch::matmul(m, batch.target[i].reshape({-1}));
    CHECK(torch::allclose(y[i], want, 1e-4, 1e-5));
  }
}

TEST_CASE("the joint loss is the fixed-code loss, and its gradient reaches the code",
          "[train][joint]") {
  auto code = mask_code(3);
  auto net = small_lfnet(false);
  net->set_phi(code->weights().detach());
  auto batch = patches();
  const nn::ReconstructionLoss loss({}, 5, 5);
  batch.y = train::simulate_patches(code->weights(), batch.target, batch.phase).detach();
  const auto fixed = loss(net->forward(batch.y, batch.phase, {}), batch.target);
  const auto joint = train::joint_loss(net, code, batch, loss, 0);
  CHECK(joint.item<double>() == Approx(fixed.item<double>()).epsilon(1e-4));
  joint.backward();
  for (const auto& p : code->parameters()) {
    REQUIRE(p.grad().defined());
    CHECK(p.grad().abs().sum().item<double>() > 0);
  }
  CHECK(net->pixel_pinv.grad_fn() == nullptr);  // the net's own buffers are untouched
  // The pseudo-inverse it reads is the one set_phi stores.
  CHECK(torch::allclose(
      nn::pixel_pseudo_inverses(code->weights().detach(), net->options().pinv_lambda),
      net->pixel_pinv, 1e-4, 1e-6));
}

TEST_CASE("training the code alone lowers the loss of its network", "[train][joint]") {
  const nn::ReconstructionLoss loss({}, 5, 5);
  // A net that reads the code's pseudo-inverse and refines it, the net itself held fixed:
  // whatever the loss loses, the code's parameters won.
  torch::manual_seed(1);
  auto code = mask_code(1);
  auto net = small_lfnet(true);
  net->set_phi(code->weights().detach());
  for (auto& p : net->parameters()) p.requires_grad_(false);
  torch::optim::Adam adam(code->parameters(), torch::optim::AdamOptions(5e-2));
  auto batch = patches();
  batch.phase = torch::zeros({4}, torch::kInt64);  // a code the same at every pixel
  batch.noise = torch::full({4}, 0.02f);
  const auto before = code->weights().detach().clone();
  const double first = train::joint_loss(net, code, batch, loss, 0).item<double>();
  double last = 0;
  for (int step = 0; step < 40; ++step) {
    adam.zero_grad();
    auto l = train::joint_loss(net, code, batch, loss, 0);  // the same noise every step
    l.backward();
    adam.step();
    last = l.item<double>();
  }
  INFO("loss " << first << " -> " << last);
  CHECK(last < 0.8 * first);
  CHECK((code->weights().detach() - before).abs().max().item<double>() > 0.01);
  // The code stays physical while it learns.
  CHECK(code->response().min().item<float>() >= 0.0f);
  CHECK(code->response().max().item<float>() <= 1.0f);
  const nn::NetworkOptions paper_options;  // the paper's architecture
  auto paper = nn::LightFieldNet(paper_options);
  CHECK_THROWS_WITH(train::joint_loss(paper, mask_code(1), batch, loss, 0),
                    Catch::Contains("cannot learn a code"));
}

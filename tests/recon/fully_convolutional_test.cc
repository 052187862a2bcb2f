#include "lfnet/recon/fully_convolutional.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/methods.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

nn::LightFieldNet make_net(const optics::Phi& phi, int64_t kernel, const std::string& branches,
                           const std::string& residual) {
  nn::NetworkOptions o;
  o.measurements = phi.measurements();
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.kernel = kernel;
    p.branches = lfnet::nn::from_string(branches, p.branches);
    p.residual = lfnet::nn::from_string(residual, p.residual);
    p.cnn.channels = 4;
    p.cnn.depth = 3;
    p.ae.hidden = {32, 16, 32, 16, 32};
    if (branches == "net") p.head_weights = {0.3, 0.7};
  });
  torch::manual_seed(3);
  nn::LightFieldNet net(o);
  net->set_phi(optics::patch_matrix_stack(phi, 9, 9));
  return net;
}

}  // namespace

TEST_CASE("the CNN over a light field in tiles equals one pass over the whole", "[recon]") {
  nn::NetworkOptions o;
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.cnn.channels = 3;
    p.cnn.depth = 3;
  });
  torch::manual_seed(1);
  nn::CnnBranch cnn(o);
  // Larger biases make the zero padding of every layer's activations at the border matter.
  {
    torch::NoGradGuard no_grad;
    for (auto& conv : cnn->convs) conv->bias.uniform_(-0.5, 0.5);
  }
  auto x = torch::rand({5, 5, 20, 23});
  torch::Tensor whole;
  {
    torch::InferenceMode guard;
    whole = cnn->forward(x.view({1, 1, 5, 5, 20, 23}))[0][0];
  }
  for (int64_t tile : {7, 8, 20, 64}) {
    INFO("tile " << tile);
    test::require_close(recon::cnn_over_light_field(cnn, x, tile), whole, 1e-5);
  }
  CHECK_THROWS_AS(recon::cnn_over_light_field(cnn, x, 0), ConfigError);
}

TEST_CASE("with a 1x1x1x1 kernel and non-overlapping patches, full equals patch stitching",
          "[recon]") {
  // A pixelwise CNN never sees a patch border, and without overlap each pixel has one patch
  // estimate: both ways must then agree, head weights, autoencoder and residual base included.
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto lf = torch::rand({5, 5, 27, 36});
  auto sensor = optics::simulate_sensor(*phi, lf);
  recon::ReconstructOptions o;
  o.stride = 9;
  o.batch = 5;
  o.clamp = false;
  for (const auto& [branches, method, residual] :
       std::vector<std::tuple<std::string, std::string, std::string>>{{"net", "net", "none"},
                                                                      {"net", "cnn", "pinv"},
                                                                      {"cnn", "cnn", "adjoint"},
                                                                      {"net", "net", "pinv"}}) {
    INFO(branches << " " << method << " " << residual);
    auto net = make_net(*phi, 1, branches, residual);
    auto patches = recon::reconstruct_sensor(*phi, sensor, recon::network_solver(net, method), o);
    auto full = recon::reconstruct_sensor_fully_convolutional(net, method, *phi, sensor, o, 10);
    REQUIRE(full.sizes() == patches.sizes());
    test::require_close(full, patches, 1e-4);
  }
}

TEST_CASE("with a 3^4 kernel, full differs from patch stitching only by the patch borders",
          "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto lf = torch::rand({5, 5, 27, 36});
  auto sensor = optics::simulate_sensor(*phi, lf);
  recon::ReconstructOptions o;
  o.stride = 9;
  auto net = make_net(*phi, 3, "cnn", "none");
  auto patches = recon::reconstruct_sensor(*phi, sensor, recon::network_solver(net, "cnn"), o);
  auto full = recon::reconstruct_sensor_fully_convolutional(net, "cnn", *phi, sensor, o);
  const double diff = (full - patches).abs().max().item<double>();
  CHECK(diff > 1e-4);  // the border zeros a patch sees are gone
  CHECK(full.min().item<double>() >= 0.0);
  CHECK(full.max().item<double>() <= 1.0);
}

TEST_CASE("fully convolutional reconstruction rejects what it cannot do", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto sensor = optics::simulate_sensor(*phi, torch::rand({5, 5, 18, 18}));
  recon::ReconstructOptions o;
  auto net = make_net(*phi, 3, "net", "none");
  CHECK_THROWS_AS(recon::reconstruct_sensor_fully_convolutional(net, "ae", *phi, sensor, o),
                  ConfigError);
  auto ae_net = make_net(*phi, 3, "ae", "none");
  CHECK_THROWS_AS(recon::reconstruct_sensor_fully_convolutional(ae_net, "net", *phi, sensor, o),
                  ConfigError);
  CHECK(recon::parse_cnn_mode("full") == recon::CnnMode::kFull);
  CHECK(recon::to_string(recon::parse_cnn_mode("patches")) == "patches");
  CHECK_THROWS_AS(recon::parse_cnn_mode("tiles"), ConfigError);
}

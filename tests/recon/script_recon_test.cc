// The exported module's reconstruct and simulate methods against lfnet's own pipeline.
#include <catch2/catch.hpp>

#include "lfnet/nn/script.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/methods.h"
#include "lfnet/recon/reconstruct.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

struct Case {
  std::string phi;  // name:N
  nlohmann::json params = nlohmann::json::object();
  int64_t height, width, stride;
};

nn::NetworkOptions small_options() {
  nn::NetworkOptions o;
  o.patch = {3, 3, 5, 5};
  o.measurements = 2;
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.ae.hidden = {40, 20, 40, 20, 40};
    p.cnn.channels = 4;
    p.cnn.depth = 3;
    p.residual = lfnet::nn::Residual::kPinv;
  });
  return o;
}

}  // namespace

TEST_CASE("an exported net's reconstruct and simulate match lfnet's sensor pipeline",
          "[recon][script]") {
  lfnet::test::TempDir tmp;
  const std::vector<Case> cases = {
      {"asp:2", {}, 17, 23, 3}, {"mask:2", {}, 21, 19, 4}, {"random:2", {{"block", 5}}, 20, 25, 5}};
  int index = 0;
  for (const auto& c : cases) {
    INFO(c.phi);
    auto spec = optics::PhiSpec::parse(c.phi);
    spec.rows = 3;
    spec.cols = 3;
    if (!c.params.is_null()) spec.params = c.params;
    auto phi = optics::make_phi(spec);
    torch::manual_seed(index);
    nn::LightFieldNet net(small_options());
    net->set_phi(optics::patch_matrix_stack(*phi, 5, 5));
    nn::ScriptMetadata meta;
    meta.phi = phi->spec().to_json();
    meta.period = phi->period();
    meta.block = phi->block();
    meta.local = phi->local();
    const std::string path = tmp / ("m" + std::to_string(index++) + ".pt");
    nn::export_network(net, meta, path);
    auto loaded = nn::load_script(path);

    auto lf = torch::rand({3, 3, c.height, c.width});
    auto sensor = phi->forward(lf);
    torch::NoGradGuard no_grad;
    auto simulated = loaded.module.get_method("simulate")({lf}).toTensor();
    REQUIRE(simulated.sizes() == sensor.sizes());
    test::require_close(simulated, sensor, 1e-6);

    for (bool window : {false, true}) {
      INFO("window " << window);
      recon::ReconstructOptions o;
      o.patch_h = 5;
      o.patch_w = 5;
      o.stride = c.stride;
      o.batch = 7;  // several bands and batches
      o.window = window;
      o.clamp = false;
      auto want = recon::reconstruct_sensor(*phi, sensor, recon::network_solver(net, "net"), o)[0];
      auto got =
          loaded.module.get_method("reconstruct")({sensor, c.stride, 7, window, false}).toTensor();
      REQUIRE(got.sizes() == want.sizes());
      CHECK(want.std().item<double>() > 1e-3);
      test::require_close(got, want, 1e-5);
      // The solver that lfnet reconstruct runs on exported files gives the same.
      auto via_solver =
          recon::reconstruct_sensor(*phi, sensor, recon::script_solver(loaded, "net"), o)[0];
      test::require_close(via_solver, want, 1e-5);
    }
    // Clamped by default.
    auto clamped = loaded.module.get_method("reconstruct")({sensor, c.stride}).toTensor();
    CHECK(clamped.min().item<double>() >= 0.0);
    CHECK(clamped.max().item<double>() <= 1.0);
  }
}

TEST_CASE("an exported random-projection net refuses patches off the block grid",
          "[recon][script]") {
  lfnet::test::TempDir tmp;
  auto spec = optics::PhiSpec::parse("random:2");
  spec.rows = 3;
  spec.cols = 3;
  spec.params = {{"block", 5}};
  auto phi = optics::make_phi(spec);
  nn::LightFieldNet net(small_options());
  net->set_phi(optics::patch_matrix_stack(*phi, 5, 5));
  nn::ScriptMetadata meta;
  meta.phi = phi->spec().to_json();
  meta.block = phi->block();
  meta.local = false;
  nn::export_network(net, meta, tmp / "r.pt");
  auto loaded = nn::load_script(tmp / "r.pt");
  auto sensor = phi->forward(torch::rand({3, 3, 20, 20}));
  CHECK_THROWS_WITH(loaded.module.get_method("reconstruct")({sensor, 3}),
                    Catch::Contains("off the 5-pixel block grid"));
}

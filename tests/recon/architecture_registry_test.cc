// The architecture registry (nn/architecture.h): a third architecture, registered from outside
// the library by one call, is built, trained-for, saved, loaded and used to reconstruct by the
// code that serves the built-in ones, with no edit there.
#include "lfnet/nn/architecture.h"

#include <catch2/catch.hpp>

#include <algorithm>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

// The per-pixel pseudo-inverse of the whole sensor image, each view scaled by a learned gain:
// the smallest whole-image architecture with a parameter.
class GainArchitecture : public nn::NetworkArchitecture {
 public:
  std::string name() const override { return "gain-test"; }
  std::string summary() const override { return "per-pixel pseudo-inverse times a gain per view"; }
  bool whole_image() const override { return true; }
  nn::PhiInput phi_input() const override { return nn::PhiInput::kPixelWeights; }
  void validate(const nn::NetworkOptions&) const override {}
  void build(nn::LightFieldNetImpl& net) const override {
    const auto& o = net.options();
    const int64_t views = o.patch.rows * o.patch.cols;
    net.phi = net.register_buffer("phi",
                                  torch::zeros({o.measurements, o.patch.rows, o.patch.cols, 1, 1}));
    net.pixel_pinv = net.register_buffer("pixel_pinv", torch::zeros({1, 1, o.measurements, views}));
    net.register_parameter("gain", torch::ones({views}));
  }
  void set_phi(nn::LightFieldNetImpl& net, const torch::Tensor& w) const override {
    torch::NoGradGuard no_grad;
    const int64_t n = w.size(0), t = w.size(3);
    auto a = w.to(torch::kFloat64).reshape({n, w.size(1) * w.size(2), t, t}).permute({2, 3, 0, 1});
    auto gram = torch::matmul(a, a.transpose(2, 3)) +
                net.options().pinv_lambda * torch::eye(n, a.options());
    net.phi.set_(w.to(torch::kFloat32).contiguous().clone());
    net.pixel_pinv.set_(at::linalg_solve(gram, a).to(torch::kFloat32).contiguous());
  }
  int64_t phases(const nn::LightFieldNetImpl& net) const override {
    return net.phi.size(3) * net.phi.size(4);
  }
  std::vector<size_t> phase_axes(const std::string& name, size_t rank) const override {
    if (name == "phi" && rank == 5) return {3, 4};
    if (name == "pixel_pinv") return {0, 1};
    return {};
  }
  static torch::Tensor gain(nn::LightFieldNetImpl& net) {
    return net.named_parameters()["gain"].view({1, -1, 1, 1});
  }
  nn::NetworkOutputs forward_all(nn::LightFieldNetImpl& net, const torch::Tensor& y,
                                 const torch::Tensor& phase, const torch::Tensor&,
                                 const nn::BranchSelection&) const override {
    const auto& p = net.options().patch;
    auto sensor = y.reshape({y.size(0), net.options().measurements, p.height, p.width});
    nn::NetworkOutputs out;
    out.output = (net.pixel_pinv_image(sensor, net.check_phase(y, phase)) * gain(net))
                     .view({y.size(0), 1, p.rows, p.cols, p.height, p.width});
    return out;
  }
  torch::Tensor forward_image(nn::LightFieldNetImpl& net, const torch::Tensor& sensor,
                              int64_t phase, double) const override {
    const auto& p = net.options().patch;
    auto ph = phase == 0 ? torch::Tensor() : torch::full({sensor.size(0)}, phase, torch::kInt64);
    return (net.pixel_pinv_image(sensor, ph) * gain(net))
        .reshape({sensor.size(0), p.rows, p.cols, sensor.size(2), sensor.size(3)});
  }
  nn::ImageTiling image_tiling(const nn::NetworkOptions&) const override { return {1, 0}; }
  void set_precision(nn::LightFieldNetImpl&, torch::Dtype) const override {}
  double patch_flops(const nn::NetworkOptions& o, const nn::BranchSelection&) const override {
    return 3.0 *
           static_cast<double>(o.measurements * o.patch.rows * o.patch.cols * o.patch.pixels());
  }
  std::string script(const nn::LightFieldNetImpl&, nn::ScriptBuilder&) const override {
    throw ConfigError("gain-test is not exportable");
  }
};

}  // namespace

TEST_CASE("an architecture registered from outside the library runs through the registry",
          "[recon][architecture]") {
  CHECK(nn::registered_architectures() ==
        std::vector<std::string>{nn::kPaperArchitecture, nn::kLfnetArchitecture, "unrolled"});
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json({{"architecture", "gain-test"}}),
                    Catch::Contains("$.architecture") && Catch::Contains("paper, lfnet, unrolled"));
  nn::register_architecture(std::make_unique<GainArchitecture>());
  CHECK(nn::architecture_list() == "paper, lfnet, unrolled, gain-test");

  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  nn::NetworkOptions o;
  o.architecture = "gain-test";
  o.measurements = phi->measurements();
  o.patch = {phi->rows(), phi->cols(), 8, 8};
  nn::LightFieldNet net(o);
  net->set_phi(phi->pixel_weights(0, 0, 1, 1));
  CHECK_FALSE(o.patch_grid());  // a whole-image architecture has no patch grid
  CHECK(net->phases() == 1);

  const auto lf = test::parallax_light_field(5, 5, 20, 22, 1, -1).data()[0];
  const auto sensor = optics::simulate_sensor(*phi, lf);
  // With unit gains it is the per-pixel pseudo-inverse: the pinv method's result.
  recon::MethodResources r;
  r.phi = phi.get();
  recon::ReconstructOptions raw;
  raw.clamp = false;
  const auto pinv = recon::reconstruct_sensor(*phi, sensor, recon::make_solver("pinv", r), raw);
  r.net = net;
  const auto image = recon::make_image_solver("net", r);
  REQUIRE(image);  // the net method asks the class, which reconstructs whole images
  const auto est = image(sensor, 0.0);
  CHECK(torch::allclose(est, pinv.clamp(0.0, 1.0), 1e-5, 1e-5));
  // Tiles and the self-ensemble work for it as for lfnet's.
  CHECK(torch::allclose(recon::reconstruct_sensor_tiled(net, sensor, 4, true), est, 1e-5, 1e-5));
  CHECK(recon::reconstruct_sensor_mirrored(net, sensor, 8).sizes() == est.sizes());

  // A gain of 2 on one view doubles that view only.
  {
    torch::NoGradGuard no_grad;
    net->named_parameters()["gain"][7].fill_(2.0);
  }
  const auto twice = recon::reconstruct_sensor_tiled(net, sensor, 8, false);
  // View 7 is (u, v) = (1, 2); (1, 5, 5, H, W).
  CHECK(torch::allclose(twice.select(1, 1).select(1, 2), 2 * pinv.select(1, 1).select(1, 2), 1e-5,
                        1e-5));
  CHECK(torch::allclose(twice.select(1, 0), pinv.select(1, 0), 1e-5, 1e-5));

  // A checkpoint of it saves and loads, and gives the same reconstruction.
  test::TempDir tmp;
  test::save_net(net, *phi, "joint", tmp / "gain.ckpt");
  auto loaded = train::build_net(train::load_checkpoint(tmp / "gain.ckpt"));
  loaded->eval();
  CHECK(loaded->architecture().name() == "gain-test");
  CHECK(torch::equal(recon::reconstruct_sensor_tiled(loaded, sensor, 8, false), twice));
  // Training's forward on crops, with the gradient reaching its parameter.
  auto crops = sensor.unsqueeze(0).slice(2, 0, 8).slice(3, 0, 8).reshape({1, -1});
  auto out = loaded->forward(crops);
  CHECK(out.sizes() == torch::IntArrayRef({1, 1, 5, 5, 8, 8}));
  out.sum().backward();
  CHECK(loaded->named_parameters()["gain"].grad().abs().sum().item<double>() > 0);
  CHECK(nn::patch_flops(o, {}) > 0);
}

// The unrolled data-consistency architecture (nn/unrolled_architecture.cc): its options
// section, its iterations, data consistency, tiles, self-ensemble, checkpoints, bfloat16 and
// TorchScript export, through the code that serves every architecture.
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

nn::NetworkOptions unrolled_options(const optics::Phi& phi, bool shared = false, bool noise = false,
                                    double lambda = 1e-3) {
  return nn::NetworkOptions::from_json(
      {{"architecture", "unrolled"},
       {"pinv_lambda", lambda},
       {"measurements", phi.measurements()},
       {"patch", {{"rows", phi.rows()}, {"cols", phi.cols()}, {"height", 8}, {"width", 8}}},
       {"unrolled",
        {{"iterations", 2},
         {"shared", shared},
         {"denoiser", {{"channels", 6}, {"levels", 2}, {"blocks", 1}, {"noise_input", noise}}}}}});
}

void randomise(nn::LightFieldNet& net, uint64_t seed) {
  torch::manual_seed(seed);
  torch::NoGradGuard no_grad;
  for (auto& p : net->named_parameters()) {
    if (p.key() != "step") p.value().copy_(torch::randn_like(p.value()) * 0.2);
  }
}

double max_abs_diff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

// The sensor image (N, H, W) of light fields (B, U, V, H, W) through the net's Phi.
torch::Tensor measure(const optics::Phi& phi, const torch::Tensor& lf) {
  return optics::simulate_sensor(phi, lf);
}

}  // namespace

TEST_CASE("unrolled: its options are its own section, read strictly", "[recon][unrolled]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto o = unrolled_options(*phi);
  CHECK(o.arch().name() == "unrolled");
  CHECK(o.arch().whole_image());
  CHECK_FALSE(o.arch().colour());
  CHECK_FALSE(o.arch().learns_code());
  CHECK_FALSE(o.arch().reads_noise(o));
  CHECK(
      unrolled_options(*phi, false, true).arch().reads_noise(unrolled_options(*phi, false, true)));
  // Written back as read, and read again to the same options.
  const auto j = o.to_json();
  CHECK(j.at("unrolled").at("iterations") == 2);
  CHECK(nn::NetworkOptions::from_json(j).to_json() == j);
  // Unknown keys and bad values name their path; a section of another architecture is refused.
  auto bad = j;
  bad["unrolled"]["iteration"] = 3;
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json(bad, "$.network"),
                    Catch::Contains("$.network.unrolled.iteration"));
  bad = j;
  bad["unrolled"]["iterations"] = 0;
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json(bad, "$.network"),
                    Catch::Contains("$.network.unrolled.iterations"));
  bad = j;
  bad["unrolled"]["denoiser"]["levels"] = 0;
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json(bad, "$.network"),
                    Catch::Contains("unrolled.denoiser.levels"));
  bad = j;
  bad["architecture"] = "lfnet";
  bad["patch"]["height"] = 16;
  bad["patch"]["width"] = 16;
  CHECK_THROWS_WITH(
      nn::NetworkOptions::from_json(bad, "$.network"),
      Catch::Contains("$.network.unrolled") && Catch::Contains("another architecture"));
  bad = j;
  bad["cfa"] = "RGGB";
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json(bad, "$.network"),
                    Catch::Contains("$.network.cfa") && Catch::Contains("reconstructs colour"));
  bad = j;
  bad["patch"]["height"] = 9;  // the denoiser's U-Net of 2 levels takes even sides
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json(bad, "$.network"),
                    Catch::Contains("multiples of 2"));
  // K U-Nets, or one shared, and K steps.
  nn::LightFieldNet net(o), shared(unrolled_options(*phi, true));
  CHECK(net->named_parameters()["step"].numel() == 2);
  CHECK(nn::parameter_count(*net) == 2 * (nn::parameter_count(*shared) - 2) + 2);
}

TEST_CASE("unrolled: iterations keep data consistency and run as every whole-image net",
          "[recon][unrolled]") {
  // A code of period 2, so phases and tiles are exercised.
  auto spec = optics::PhiSpec::parse("mask:2");
  spec.params = {{"period", 2}};
  const auto phi = optics::make_phi(spec);
  REQUIRE(phi->period() == 2);
  // With a small lambda the pseudo-inverse reproduces the measurements: A A^+ y = y.
  nn::LightFieldNet net(unrolled_options(*phi, false, false, 1e-6));
  net->set_phi(phi->pixel_weights(0, 0, 2, 2));
  net->eval();
  const auto lf = test::parallax_light_field(5, 5, 22, 26, 1, -1).data()[0];
  const auto sensor = measure(*phi, lf);
  torch::NoGradGuard no_grad;

  // Fresh, its denoisers add nothing (their last convolutions start at zero) and the
  // data-consistency steps keep the per-pixel pseudo-inverse it starts from.
  const auto pinv = net->pixel_pinv_image(sensor.unsqueeze(0));
  const auto fresh = net->forward_image(sensor.unsqueeze(0));
  CHECK(max_abs_diff(fresh.reshape_as(pinv), pinv) < 1e-4);

  // Trained-like weights: the estimate moves away from the pseudo-inverse, yet with the step at
  // 1 its measurements stay those of the sensor (lambda small): A x = y.
  randomise(net, 3);
  const auto est = net->forward_image(sensor.unsqueeze(0))[0];  // (U, V, H, W)
  CHECK(max_abs_diff(est.reshape_as(pinv[0]), pinv[0]) > 1e-2);
  CHECK(max_abs_diff(measure(*phi, est), sensor) < 1e-2 * sensor.abs().max().item<double>());
  // With the steps at 0 the last denoiser's output is left as it is, off the measurements.
  net->named_parameters()["step"].zero_();
  const auto unchecked = net->forward_image(sensor.unsqueeze(0))[0];
  CHECK(max_abs_diff(measure(*phi, unchecked), sensor) >
        10 * max_abs_diff(measure(*phi, est), sensor));
  net->named_parameters()["step"].fill_(1.0);

  // Tiles (the receptive radius covers both iterations) and phases: tiles equal the whole.
  const auto whole = recon::reconstruct_sensor_tiled(net, sensor, 64, false);
  CHECK(max_abs_diff(whole[0], est) < 1e-5);
  CHECK(max_abs_diff(recon::reconstruct_sensor_tiled(net, sensor, 4, false), whole) < 1e-5);
  // The net method finds it by capability, and the self-ensemble runs.
  recon::MethodResources r;
  r.phi = phi.get();
  r.net = net;
  const auto image = recon::make_image_solver("net", r);
  REQUIRE(image);
  CHECK(max_abs_diff(image(sensor, 0.0), whole.clamp(0.0, 1.0)) < 1e-5);
  CHECK(recon::reconstruct_sensor_mirrored(net, sensor, 8).sizes() == whole.sizes());
  // Training's forward on crops of phase 1, with gradients to the steps and every denoiser.
  const auto crop = sensor.slice(1, 0, 8).slice(2, 1, 9).unsqueeze(0);
  torch::AutoGradMode grad(true);
  auto out = net->forward(crop.reshape({1, -1}), torch::full({1}, 1, torch::kInt64));
  CHECK(out.sizes() == torch::IntArrayRef({1, 1, 5, 5, 8, 8}));
  out.sum().backward();
  for (const auto& p : net->named_parameters()) {
    INFO(p.key());
    REQUIRE(p.value().grad().defined());
    CHECK(p.value().grad().abs().sum().item<double>() > 0);
  }
  CHECK(nn::patch_flops(net->options(), {}) > 0);
}

TEST_CASE("unrolled: checkpoints, bfloat16 and TorchScript give its numbers", "[recon][unrolled]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  for (const bool shared : {false, true}) {
    INFO("shared " << shared);
    nn::LightFieldNet net(unrolled_options(*phi, shared, true));
    net->set_phi(phi->pixel_weights(0, 0, 1, 1));
    randomise(net, 5);
    net->eval();
    const auto lf = test::parallax_light_field(5, 5, 20, 22, 1, -1).data()[0];
    const auto sensor = measure(*phi, lf);
    const auto want = recon::reconstruct_sensor_tiled(net, sensor, 8, false, 0.05);
    // The noise channel is read.
    CHECK(max_abs_diff(recon::reconstruct_sensor_tiled(net, sensor, 8, false, 0.0), want) > 1e-4);

    test::TempDir tmp;
    test::save_net(net, *phi, "joint", tmp / "u.ckpt");
    auto loaded = train::build_net(train::load_checkpoint(tmp / "u.ckpt"));
    loaded->eval();
    CHECK(loaded->options().to_json() == net->options().to_json());
    CHECK(torch::equal(recon::reconstruct_sensor_tiled(loaded, sensor, 8, false, 0.05), want));

    nn::ScriptMetadata meta;
    meta.phi = phi->spec().to_json();
    nn::export_network(net, meta, tmp / "u.pt");
    const auto scripted = nn::load_script(tmp / "u.pt");
    CHECK(max_abs_diff(scripted.reconstruct_image(sensor, 8, false, 0.05), want) < 1e-5);
    CHECK(max_abs_diff(scripted.reconstruct_image(sensor, 64, false, 0.05), want) < 1e-5);

    nn::set_cnn_precision(loaded, nn::Precision::kBFloat16);
    const auto bf16 = recon::reconstruct_sensor_tiled(loaded, sensor, 8, false, 0.05);
    CHECK(max_abs_diff(bf16, want) > 0);
    CHECK(max_abs_diff(bf16, want) < 0.02 * want.abs().max().item<double>());
  }
}

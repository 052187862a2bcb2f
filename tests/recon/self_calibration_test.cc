// Self-calibration (recon/self_calibration.h): the roughness criterion against hand-made light
// fields, telling the net a displaced camera, and the shipped default estimating the angular
// shift of a displaced ASP from one sensor image of a random scene it never saw.
#include "lfnet/recon/self_calibration.h"

#include <catch2/catch.hpp>

#include <filesystem>
#include <string>

#include "lfnet/core/error.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/train/checkpoint.h"
#include "support/test_support.h"

using namespace lfnet;
namespace fs = std::filesystem;

namespace {

nn::LightFieldNet shipped_default() {
  const auto path = (fs::path(LFNET_SOURCE_DIR) / "models" / "lfnet-asp-n2.ckpt").string();
  auto net = train::build_net(train::load_checkpoint(path), path);
  net->eval();
  return net;
}

// A grey random scene of the generator (procedural textures, disparities -2 to 2 px per view).
torch::Tensor grey_scene(uint64_t seed, int64_t size) {
  scene::RandomSceneOptions options;
  options.height = size;
  options.width = size;
  options.min_disparity = -2;
  options.max_disparity = 2;
  const auto lf = scene::render_scene(scene::random_scene(seed, options)).light_field.data();
  return lf.mean(0);  // (U, V, H, W)
}

double psnr(const torch::Tensor& a, const torch::Tensor& b) {
  return -10 * std::log10((a - b).pow(2).mean().item<double>());
}

}  // namespace

TEST_CASE("angular_roughness is the mean absolute step between neighbouring views",
          "[recon][self_calibration]") {
  // Views that grow by 0.1 per step along U and by 0.03 along V.
  auto u = torch::arange(5, torch::kFloat32).view({1, 5, 1, 1, 1});
  auto v = torch::arange(3, torch::kFloat32).view({1, 1, 3, 1, 1});
  auto lf = (0.1 * u + 0.03 * v).expand({1, 5, 3, 12, 10}).contiguous();
  CHECK(recon::angular_roughness(lf, 0) == Approx(0.1).epsilon(1e-6));
  CHECK(recon::angular_roughness(lf, 1) == Approx(0.03).epsilon(1e-5));
  // The margin leaves the border out: a border that differs between views does not count.
  auto bordered = lf.clone();
  bordered.index_put_({0, 4, torch::indexing::Slice(), 0}, 5.0);
  CHECK(recon::angular_roughness(bordered, 0, 1) == Approx(0.1).epsilon(1e-6));
  CHECK(recon::angular_roughness(bordered, 0, 0) > 0.11);
  // The same view everywhere has none; a margin that leaves nothing is refused.
  CHECK(recon::angular_roughness(torch::ones({1, 5, 5, 8, 8}), 0) == 0);
  CHECK_THROWS(recon::angular_roughness(lf, 0, 5));
  CHECK_THROWS(recon::angular_roughness(lf, 2));
}

TEST_CASE("tell_camera gives the net the displaced Phi's weights and the nominal ones back",
          "[recon][self_calibration]") {
  auto net = shipped_default();
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto nominal = net->phi.clone();
  optics::CalibrationError error;
  error.angular_shift_u = 0.3;
  recon::tell_camera(net, *phi, error);
  const auto displaced =
      optics::perturbed_pixel_weights(*phi, error, 0, 0, phi->period(), phi->period(), {});
  CHECK(torch::allclose(net->phi, displaced.to(torch::kFloat32), 1e-6, 1e-7));
  CHECK_FALSE(torch::allclose(net->phi, nominal, 1e-4, 1e-5));
  recon::tell_camera(net, *phi, {});
  CHECK(torch::allclose(net->phi, nominal, 1e-6, 1e-7));
}

TEST_CASE("the default estimates a displaced ASP's angular shift from one sensor image",
          "[recon][self_calibration]") {
  auto net = shipped_default();
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto truth = grey_scene(93001, 128);
  const auto nominal_phi = net->phi.clone();
  for (double shift : {0.0, 0.2, -0.3}) {
    CAPTURE(shift);
    optics::CalibrationError camera;
    camera.angular_shift_u = shift;
    const auto sensor = optics::perturbed_forward(*phi, camera, truth);
    const auto found = recon::estimate_angular_shift(net, *phi, sensor);
    CHECK(found.error.angular_shift_u == Approx(shift).margin(0.05));
    CHECK(found.error.angular_shift_v == 0);  // the pair does not vary along V: not searched
    CHECK(found.reconstructions >= 7);
    // The net holds the nominal Phi again.
    CHECK(torch::equal(net->phi, nominal_phi));
    if (shift == 0) continue;
    // Told the estimate, the net beats itself told the nominal Phi by a wide margin.
    const auto plain = recon::reconstruct_sensor_tiled(net, sensor)[0];
    recon::tell_camera(net, *phi, found.error);
    const auto told = recon::reconstruct_sensor_tiled(net, sensor)[0];
    recon::tell_camera(net, *phi, {});
    CHECK(psnr(told, truth) > psnr(plain, truth) + 2.0);
  }
}

TEST_CASE("self-calibration refuses what it cannot do", "[recon][self_calibration]") {
  auto net = shipped_default();
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto sensor = torch::rand({2, 32, 32});
  recon::SelfCalibrationOptions bad;
  bad.max_shift = 0;
  CHECK_THROWS_AS(recon::estimate_angular_shift(net, *phi, sensor, 0, bad), ConfigError);
  bad = {};
  bad.tolerance = 0.6;
  CHECK_THROWS_AS(recon::estimate_angular_shift(net, *phi, sensor, 0, bad), ConfigError);
  CHECK_THROWS(recon::estimate_angular_shift(net, *phi, torch::rand({32, 32})));
  const auto random = optics::make_phi(optics::PhiSpec::parse("random:2"));
  CHECK_THROWS_AS(recon::tell_camera(net, *random, {}), ConfigError);
}

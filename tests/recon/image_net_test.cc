// The lfnet architecture: its pseudo-inverse input, tiled inference and option checks.
#include <torch/torch.h>
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/reconstruct.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

nn::NetworkOptions image_options(const optics::Phi& phi, int64_t levels = 3) {
  nn::NetworkOptions o;
  o.architecture = lfnet::nn::kLfnetArchitecture;
  o.measurements = phi.measurements();
  o.patch = {phi.rows(), phi.cols(), 16, 16};
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) {
    image.channels = 6;
    image.levels = levels;
    image.blocks = 1;
  });
  return o;
}

nn::LightFieldNet image_net(const optics::Phi& phi, int64_t levels = 3) {
  nn::LightFieldNet net(image_options(phi, levels));
  const int64_t t = phi.period();
  net->set_phi(phi.pixel_weights(0, 0, t, t));
  return net;
}

// A randomised net that reads the noise sigma, with phi's weights over one period.
nn::LightFieldNet noise_aware_net(const optics::Phi& phi, uint64_t seed) {
  auto o = image_options(phi);
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) { image.noise_input = true; });
  nn::LightFieldNet net(o);
  net->set_phi(phi.pixel_weights(0, 0, phi.period(), phi.period()));
  test::randomise_image_net(net, seed);
  return net;
}

torch::Tensor random_light_field(const optics::Phi& phi, int64_t h, int64_t w, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  return torch::rand({phi.rows(), phi.cols(), h, w}, gen);
}

}  // namespace

TEST_CASE("an untrained lfnet net returns the per-pixel pseudo-inverse of the pinv method",
          "[recon][image]") {
  for (const std::string name : {"asp", "mask"}) {
    INFO(name);
    auto spec = optics::PhiSpec::parse(name + ":2");
    const auto phi = optics::make_phi(spec);
    auto lf = random_light_field(*phi, 41, 30, 3);
    auto sensor = optics::simulate_sensor(*phi, lf);
    recon::ReconstructOptions ro;
    ro.stride = 3;
    auto pinv = recon::reconstruct_sensor(
        *phi, sensor, recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9)), ro);
    auto net = image_net(*phi);
    // Tiles of 8 start at every phase of the mask's period.
    for (int64_t tile : {8, 12, 256}) {
      INFO("tile " << tile);
      auto est = recon::reconstruct_sensor_tiled(net, sensor, tile);
      REQUIRE(est.sizes() == pinv.sizes());
      CHECK(torch::allclose(est, pinv, 1e-5, 1e-5));
      // In 16-bit codes, each tile encoded as it is done: the float32 result's codes.
      const auto codes = recon::reconstruct_sensor_tiled(net, sensor, tile, true, 0.0, {}, true);
      REQUIRE(codes.scalar_type() == torch::kInt16);
      CHECK(torch::equal(codes, encode_codes(est)));
      // File-backed, as a large light field's, each finished row of tiles out of memory: the
      // same codes.
      const test::FileBackedEverything everything;
      const auto held = recon::reconstruct_sensor_tiled(net, sensor, tile, true, 0.0, {}, true);
      CHECK(lfnet::file_backed(held) == test::FileBackedEverything::available());
      CHECK(torch::equal(held, codes));
    }
    CHECK_THROWS_WITH(recon::reconstruct_sensor_tiled(net, sensor, 8, false, 0.0, {}, true),
                      Catch::Contains("clamped"));
  }
}

TEST_CASE("the pseudo-inverse of a crop follows optics::patch_phase", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("mask:3"));
  REQUIRE(phi->period() > 1);
  auto net = image_net(*phi);
  auto lf = random_light_field(*phi, 40, 40, 5);
  auto sensor = optics::simulate_sensor(*phi, lf);
  for (auto [y0, x0] : {std::pair<int64_t, int64_t>{0, 0}, {3, 7}, {5, 2}, {11, 13}}) {
    INFO(y0 << ", " << x0);
    const int64_t h = 8, w = 12;
    auto crop = sensor.slice(1, y0, y0 + h).slice(2, x0, x0 + w).unsqueeze(0);
    auto phase = torch::full({1}, optics::patch_phase(*phi, y0, x0), torch::kInt64);
    auto got = net->pixel_pinv_image(crop, phase).flatten();
    auto want = phi->pinv_matrix(y0, x0, h, w, 1e-3).matmul(crop.flatten());
    CHECK(torch::allclose(got, want, 1e-5, 1e-5));
  }
}

TEST_CASE("tiled inference of the lfnet architecture equals one pass over the whole image",
          "[recon][image]") {
  for (const std::string name : {"asp", "mask"}) {
    for (int64_t levels : {1, 3}) {
      INFO(name << ", " << levels << " levels");
      const auto phi = optics::make_phi(optics::PhiSpec::parse(name + ":2"));
      auto net = image_net(*phi, levels);
      test::randomise_image_net(net, 7 + levels);
      auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 70, 53, 9));
      torch::Tensor whole;
      {
        torch::NoGradGuard no_grad;
        whole = net->forward_image(sensor.unsqueeze(0)).unsqueeze(0).squeeze(1);
      }
      REQUIRE(whole.sizes() == torch::IntArrayRef({1, phi->rows(), phi->cols(), 70, 53}));
      // Without clamping, so the comparison sees every value; the U-Net's output is far from
      // the pseudo-inverse (random weights), so a wrong halo would show.
      for (int64_t tile : {0, 4, 16, 20, 64}) {  // 0: automatic
        INFO("tile " << tile);
        auto tiled = recon::reconstruct_sensor_tiled(net, sensor, tile, false);
        CHECK(torch::allclose(tiled, whole, 1e-4, 1e-4));
      }
    }
  }
}

TEST_CASE("the automatic tile is the whole image when it fits, else the largest that fits",
          "[recon][image]") {
  const nn::ImageTiling tiling{8, 60};  // a halo of 64
  // 593 x 840 pads to 600 x 840 (504,000 pixels <= 800^2): one tile, no halo.
  CHECK(nn::auto_image_tile(tiling, 593, 840) == 840);
  auto tiles = nn::image_tiles(tiling, 593, 840, 0);
  REQUIRE(tiles.size() == 1);
  CHECK((tiles[0].a0 == 0 && tiles[0].a1 == 600 && tiles[0].b0 == 0 && tiles[0].b1 == 840));
  // 800 x 801 pads to 800 x 808: too many pixels, so tiles of 512 - 2 x 64 = 384, each crop
  // with its halos at most 512 pixels on a side.
  CHECK(nn::auto_image_tile(tiling, 800, 801) == 384);
  tiles = nn::image_tiles(tiling, 2372, 3360, 0);
  CHECK(tiles.size() == size_t{7 * 9});
  for (const auto& t : tiles) CHECK((t.a1 - t.a0 <= 512 && t.b1 - t.b0 <= 512));
  // A halo too wide for the crop: tiles of 256 at least.
  CHECK(nn::auto_image_tile({16, 300}, 2000, 2000) == 256);
  CHECK(nn::auto_image_tile({1, 0}, 801, 800) == 512);
}

TEST_CASE("a crop through forward() is forward_image of that crop", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  auto net = image_net(*phi);
  test::randomise_image_net(net, 4);
  auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 40, 40, 2));
  const int64_t y0 = 5, x0 = 9;
  auto crop = sensor.slice(1, y0, y0 + 16).slice(2, x0, x0 + 16).unsqueeze(0).contiguous();
  const int64_t phase = optics::patch_phase(*phi, y0, x0);
  torch::NoGradGuard no_grad;
  auto via_forward = net->forward(crop.flatten(1), torch::full({1}, phase, torch::kInt64));
  auto via_image = net->forward_image(crop, phase);
  CHECK(torch::allclose(via_forward.squeeze(1), via_image, 1e-5, 1e-5));
}

TEST_CASE("the U-Net's FLOP count matches its layers", "[recon][image]") {
  nn::NetworkOptions o;
  o.architecture = lfnet::nn::kLfnetArchitecture;
  o.measurements = 2;
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) {
    image.channels = 8;
    image.levels = 1;
    image.blocks = 1;
  });
  // pinv (2 N V), input conv (V -> c), one block (c -> c), output conv (c -> V), 3 x 3 each.
  const double v = 25, c = 8;
  CHECK(nn::image_pixel_flops(o) ==
        Approx(2 * 2 * v + 2 * 9 * (v * c + c * c + c * v)).epsilon(1e-12));
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) { image.levels = 2; });
  // The second level adds a block at a quarter of the pixels, and the 2 x 2 down and up
  // convolutions between c and 2 c channels at a quarter of the pixels.
  const double two = 2 * 9 * (v * c + c * c + c * v) + 2 * 9 * c * c +
                     (2 * 9 * 2 * c * 2 * c + 2 * 2 * 4 * c * 2 * c) / 4;
  CHECK(nn::image_pixel_flops(o) == Approx(2 * 2 * v + two).epsilon(1e-12));
  // Widths {c, 12}: the second level's block and the 2 x 2 convolutions use 12 channels.
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) { image.widths = {8, 12}; });
  const double narrow =
      2 * 9 * (v * c + c * c + c * v) + 2 * 9 * c * c + (2 * 9 * 12 * 12 + 2 * 2 * 4 * c * 12) / 4;
  CHECK(nn::image_pixel_flops(o) == Approx(2 * 2 * v + narrow).epsilon(1e-12));
}

TEST_CASE("image.widths sets the channels of every level and is checked", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = image_options(*phi, 3);
  auto image = nn::image_options(o);
  image.widths = {6, 12, 8};
  nn::set_image_options(o, image);
  nn::LightFieldNet net(o);
  auto params = lfnet::nn::image_layers(*net)->named_parameters();
  CHECK(params["enc1_0.weight"].sizes() == torch::IntArrayRef{12, 12, 3, 3});
  CHECK(params["down1.weight"].sizes() == torch::IntArrayRef{8, 12, 2, 2});
  CHECK(params["up1.weight"].sizes() == torch::IntArrayRef{8, 12, 2, 2});
  CHECK(params["enc2_0.weight"].sizes() == torch::IntArrayRef{8, 8, 3, 3});
  const auto back = nn::NetworkOptions::from_json(o.to_json());
  CHECK(nn::image_options(back).widths == std::vector<int64_t>{6, 12, 8});
  // Doubled widths spelled out build the default net.
  image.widths = {6, 12, 24};
  nn::set_image_options(o, image);
  CHECK(nn::image_layers(*nn::LightFieldNet(o))->named_parameters()["enc2_0.weight"].size(0) == 24);
  image.widths = {6, 12};
  nn::set_image_options(o, image);
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("image.widths") && Catch::Contains("2 entries"));
  image.widths = {8, 12, 8};
  nn::set_image_options(o, image);
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("image.widths") && Catch::Contains("channels 6"));
  image.widths = {6, 0, 8};
  nn::set_image_options(o, image);
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("positive"));
}

TEST_CASE("the lfnet architecture's options and Phi are checked", "[recon][image]") {
  nn::NetworkOptions o;
  CHECK_THROWS_WITH(nn::NetworkOptions::from_json(nlohmann::json{{"architecture", "unet"}}),
                    Catch::Contains("$.architecture") && Catch::Contains("paper, lfnet"));
  o.architecture = lfnet::nn::kLfnetArchitecture;
  o.patch = {5, 5, 18, 16};
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("multiples of 4"));
  o.patch = {5, 5, 16, 16};
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) { image.levels = 0; });
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("image.levels"));
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) { image.levels = 3; });
  nn::LightFieldNet net(o);
  CHECK_THROWS_WITH(net->set_phi(torch::rand({1, 512, 6400})),
                    Catch::Contains("pixel weights of one period"));
  CHECK(!o.has_ae());
  CHECK(!o.has_cnn());
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  net->set_phi(phi->pixel_weights(0, 0, 1, 1));
  CHECK_THROWS_AS(recon::reconstruct_sensor_tiled(net, torch::rand({3, 20, 20})), ConfigError);
}

TEST_CASE("a noise-aware lfnet net reads the noise sigma, tiled or whole", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  auto net = noise_aware_net(*phi, 11);
  auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 44, 37, 6));
  torch::NoGradGuard no_grad;
  auto quiet = net->forward_image(sensor.unsqueeze(0), 0, 0.0);
  auto loud = net->forward_image(sensor.unsqueeze(0), 0, 0.2);
  CHECK((quiet - loud).abs().max().item<double>() > 1e-3);
  auto tiled = recon::reconstruct_sensor_tiled(net, sensor, 16, false, 0.2);
  CHECK(torch::allclose(tiled, loud, 1e-4, 1e-4));
  // Through forward(), the batch's noise tensor is that channel.
  auto crop = sensor.slice(1, 0, 16).slice(2, 0, 16).unsqueeze(0).contiguous();
  auto phase = torch::zeros({1}, torch::kInt64);
  CHECK(torch::allclose(net->forward(crop.flatten(1), phase, torch::full({1}, 0.2)).squeeze(1),
                        net->forward_image(crop, 0, 0.2), 1e-5, 1e-5));
}

TEST_CASE("lfnet's U-Net in bfloat16 stays close to float32 and keeps float32 outside",
          "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto net = image_net(*phi);
  test::randomise_image_net(net, 8);
  const auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 32, 24, 9));
  torch::NoGradGuard no_grad;
  const auto want = net->forward_image(sensor.unsqueeze(0));
  nn::set_cnn_precision(net, nn::Precision::kBFloat16);
  // All but the transposed convolutions (ImageNetImpl::set_precision).
  int64_t bf16 = 0, fp32 = 0;
  for (const auto& p : lfnet::nn::image_layers(*net)->parameters())
    (p.scalar_type() == torch::kBFloat16 ? bf16 : fp32)++;
  CHECK(bf16 > 2 * fp32);
  CHECK(fp32 == 4);  // two levels up, each a weight and a bias
  CHECK(net->pixel_pinv.scalar_type() == torch::kFloat32);
  const auto got = net->forward_image(sensor.unsqueeze(0));
  REQUIRE(got.scalar_type() == torch::kFloat32);
  // The pseudo-inverse stays float32: only the U-Net's correction is rounded, to about 2^-8 of
  // its size per layer.
  const double err = (want - got).abs().max().item<double>();
  CHECK(err > 0.0);
  const auto correction = want - net->pixel_pinv_image(sensor.unsqueeze(0), {}).view(want.sizes());
  CHECK(err < 0.05 * correction.abs().max().item<double>());
  nn::set_cnn_precision(net, nn::Precision::kFloat32);
  for (const auto& p : lfnet::nn::image_layers(*net)->parameters())
    CHECK(p.scalar_type() == torch::kFloat32);
}

TEST_CASE("a U-Net trained for bfloat16 computes what it computes in bfloat16, float32 weights",
          "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto net = image_net(*phi);
  test::randomise_image_net(net, 21);
  const auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 32, 24, 22));
  torch::Tensor fp32, bf16;
  {
    // (The round trip leaves the weights rounded to bfloat16, so both runs share them.)
    torch::NoGradGuard no_grad;
    nn::set_cnn_precision(net, nn::Precision::kBFloat16);
    bf16 = net->forward_image(sensor.unsqueeze(0));
    nn::set_cnn_precision(net, nn::Precision::kFloat32);
    fp32 = net->forward_image(sensor.unsqueeze(0));
  }
  nn::emulate_precision(net, nn::Precision::kBFloat16);
  CHECK(lfnet::nn::image_layers(*net)->emulates_bfloat16());
  const auto emulated = net->forward_image(sensor.unsqueeze(0));
  // The rounding of a bfloat16 run, up to the order of float32 sums: far closer to bfloat16's
  // output than float32's is.
  const double off = (fp32 - bf16).abs().max().item<double>();
  const double emulated_off = (emulated - bf16).abs().max().item<double>();
  REQUIRE(off > 0.0);
  CHECK(emulated_off < 0.1 * off);
  // Its weights stay float32 and receive gradients through the rounding.
  emulated.square().sum().backward();
  for (const auto& p : lfnet::nn::image_layers(*net)->parameters()) {
    CHECK(p.scalar_type() == torch::kFloat32);
    REQUIRE(p.grad().defined());
  }
  const auto& input = lfnet::nn::image_layers(*net)->named_parameters()["input.weight"];
  CHECK(input.grad().abs().sum().item<double>() > 0.0);
  nn::emulate_precision(net, nn::Precision::kFloat32);
  torch::NoGradGuard no_grad;
  CHECK(torch::equal(net->forward_image(sensor.unsqueeze(0)), fp32));
}

TEST_CASE("training for bfloat16 is refused where the architecture has no bfloat16 layers",
          "[recon][image]") {
  nn::NetworkOptions o;  // the paper's architecture
  nn::LightFieldNet net(o);
  CHECK_NOTHROW(nn::emulate_precision(net, nn::Precision::kFloat32));
  CHECK_THROWS_AS(nn::emulate_precision(net, nn::Precision::kBFloat16), ConfigError);
  CHECK_THROWS_WITH(nn::emulate_precision(net, nn::Precision::kBFloat16),
                    Catch::Contains("training.precision") && Catch::Contains("paper"));
}

TEST_CASE("a narrow U-Net embedded in a wider one computes what the narrow one did",
          "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto narrow_options = image_options(*phi);
  lfnet::test::edit_image(narrow_options, [&](lfnet::nn::ImageNetOptions& narrow_options_image) {
    narrow_options_image.blocks = 2;
  });
  nn::LightFieldNet narrow(narrow_options);
  narrow->set_phi(phi->pixel_weights(0, 0, 1, 1));
  test::randomise_image_net(narrow, 12);
  auto wide_options = narrow_options;
  lfnet::test::edit_image(wide_options, [&](lfnet::nn::ImageNetOptions& wide_options_image) {
    wide_options_image.channels = 10;
    wide_options_image.noise_input = true;  // the input convolution gains an input channel too
  });
  nn::LightFieldNet wide(wide_options);
  wide->set_phi(phi->pixel_weights(0, 0, 1, 1));
  test::randomise_image_net(wide, 13);
  const auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 24, 32, 14));
  torch::NoGradGuard no_grad;
  const auto want = narrow->forward_image(sensor.unsqueeze(0));
  CHECK((wide->forward_image(sensor.unsqueeze(0), 0, 0.1) - want).abs().max().item<double>() >
        1e-2);
  int64_t widened = 0;
  for (const auto& p : lfnet::nn::image_layers(*narrow)->named_parameters()) {
    auto dst = lfnet::nn::image_layers(*wide)->named_parameters()[p.key()];
    INFO(p.key());
    REQUIRE(nn::embed_narrow_parameter(p.key(), p.value(), dst));
    widened += dst.sizes() != p.value().sizes() ? 1 : 0;
  }
  // All but the output's bias, one per view either way.
  CHECK(widened == static_cast<int64_t>(lfnet::nn::image_layers(*narrow)->parameters().size()) - 1);
  // Whatever the new channels hold and whatever the noise input says.
  for (double sigma : {0.0, 0.3}) {
    lfnet::test::require_close(wide->forward_image(sensor.unsqueeze(0), 0, sigma), want, 1e-5);
  }
  // A wider parameter does not fit in a narrower one, which stays as it was.
  auto w = lfnet::nn::image_layers(*narrow)->named_parameters()["enc0_0.weight"];
  const auto before = w.clone();
  CHECK_FALSE(nn::embed_narrow_parameter(
      "enc0_0.weight", lfnet::nn::image_layers(*wide)->named_parameters()["enc0_0.weight"], w));
  CHECK(torch::equal(w, before));
}

TEST_CASE("a shallow U-Net's weights start a deeper one that computes what the shallow one did",
          "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto shallow = image_net(*phi, 2);
  test::randomise_image_net(shallow, 15);
  auto deep = image_net(*phi, 3);
  test::randomise_image_net(deep, 16);
  const auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 24, 32, 17));
  torch::NoGradGuard no_grad;
  const auto want = shallow->forward_image(sensor.unsqueeze(0));
  auto deep_params = lfnet::nn::image_layers(*deep)->named_parameters();
  for (const auto& p : lfnet::nn::image_layers(*shallow)->named_parameters()) {
    INFO(p.key());
    REQUIRE(deep_params.contains(p.key()));
    deep_params[p.key()].copy_(p.value());
  }
  // The shallow net's parameters alone: its bottom level now has a decoder and a level below.
  CHECK((deep->forward_image(sensor.unsqueeze(0)) - want).abs().max().item<double>() > 1e-2);
  const auto names = lfnet::nn::image_layers(*deep)->start_new_levels(2);
  CHECK(names ==
        std::vector<std::string>{"up1.weight", "up1.bias", "dec1_0.weight", "dec1_0.bias"});
  lfnet::test::require_close(deep->forward_image(sensor.unsqueeze(0)), want, 1e-5);
  CHECK_THROWS(lfnet::nn::image_layers(*deep)->start_new_levels(3));
}

TEST_CASE("a deeper U-Net with a narrower new level starts as the shallow one", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto shallow = image_net(*phi, 2);
  test::randomise_image_net(shallow, 25);
  auto o = image_options(*phi, 3);
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) { image.widths = {6, 12, 4}; });
  nn::LightFieldNet deep(o);
  const int64_t t = phi->period();
  deep->set_phi(phi->pixel_weights(0, 0, t, t));
  test::randomise_image_net(deep, 26);
  const auto sensor = optics::simulate_sensor(*phi, random_light_field(*phi, 24, 32, 27));
  torch::NoGradGuard no_grad;
  auto deep_params = lfnet::nn::image_layers(*deep)->named_parameters();
  for (const auto& p : lfnet::nn::image_layers(*shallow)->named_parameters()) {
    INFO(p.key());
    REQUIRE(deep_params[p.key()].sizes() == p.value().sizes());
    deep_params[p.key()].copy_(p.value());
  }
  lfnet::nn::image_layers(*deep)->start_new_levels(2);
  lfnet::test::require_close(deep->forward_image(sensor.unsqueeze(0)),
                             shallow->forward_image(sensor.unsqueeze(0)), 1e-5);
}

TEST_CASE("asp:2's mirror images are measured as mirrored sensor images", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto net = image_net(*phi);
  const auto mirrors = recon::phi_mirrors(net->phi);
  // The pair's response is odd in the vertical view angle and constant along the horizontal
  // one: reversing u swaps the pair, reversing v changes nothing.
  REQUIRE(mirrors.size() == 4);
  CHECK((!mirrors[0].flip_x && !mirrors[0].flip_y));
  CHECK(mirrors[0].measurements == std::vector<int64_t>{0, 1});
  CHECK((mirrors[1].flip_x && !mirrors[1].flip_y));
  CHECK(mirrors[1].measurements == std::vector<int64_t>{0, 1});
  CHECK((!mirrors[2].flip_x && mirrors[2].flip_y));
  CHECK(mirrors[2].measurements == std::vector<int64_t>{1, 0});
  CHECK((mirrors[3].flip_x && mirrors[3].flip_y));
  CHECK(mirrors[3].measurements == std::vector<int64_t>{1, 0});
  // What the simulator says: the mirrored light field's sensor image is the mirrored one.
  const auto lf = random_light_field(*phi, 23, 31, 4);  // (U, V, H, W)
  const auto sensor = optics::simulate_sensor(*phi, lf);
  for (const auto& m : mirrors) {
    INFO("flip x " << m.flip_x << ", flip y " << m.flip_y);
    auto mirrored_lf = lf;
    if (m.flip_y) mirrored_lf = mirrored_lf.flip({0, 2});
    if (m.flip_x) mirrored_lf = mirrored_lf.flip({1, 3});
    auto want = sensor.index_select(0, torch::tensor(m.measurements, torch::kInt64));
    if (m.flip_y) want = want.flip({1});
    if (m.flip_x) want = want.flip({2});
    CHECK(torch::allclose(optics::simulate_sensor(*phi, mirrored_lf), want, 1e-5, 1e-6));
  }
  // A periodic mask has no mirror that keeps its pattern.
  const auto mask = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  CHECK(recon::phi_mirrors(image_net(*mask)->phi).size() == 1);
}

TEST_CASE("the self-ensemble averages the mirror passes and is equivariant", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  // Untrained, the net is the per-pixel pseudo-inverse, which every mirror reproduces.
  auto net = image_net(*phi);
  const auto lf = random_light_field(*phi, 40, 48, 8);  // sides: multiples of the U-Net's 4
  const auto sensor = optics::simulate_sensor(*phi, lf);
  CHECK(torch::allclose(recon::reconstruct_sensor_mirrored(net, sensor, 16, false),
                        recon::reconstruct_sensor_tiled(net, sensor, 16, false), 1e-5, 1e-5));
  test::randomise_image_net(net, 21);
  const auto single = recon::reconstruct_sensor_tiled(net, sensor, 16, false);
  const auto ensemble = recon::reconstruct_sensor_mirrored(net, sensor, 16, false);
  CHECK_FALSE(torch::allclose(single, ensemble, 1e-3, 1e-3));
  // The mean of the four passes, each mirrored back.
  auto sum = torch::zeros_like(single);
  for (const auto& m : recon::phi_mirrors(net->phi)) {
    auto s = sensor.index_select(0, torch::tensor(m.measurements, torch::kInt64));
    if (m.flip_y) s = s.flip({1});
    if (m.flip_x) s = s.flip({2});
    auto est = recon::reconstruct_sensor_tiled(net, s, 48, false);
    if (m.flip_y) est = est.flip({1, 3});
    if (m.flip_x) est = est.flip({2, 4});
    sum += est;
  }
  CHECK(torch::allclose(ensemble, sum / 4, 1e-4, 1e-4));
  // Mirroring the light field mirrors its reconstruction (a single pass does not).
  const auto lf_x = lf.flip({1, 3});
  const auto ensemble_x =
      recon::reconstruct_sensor_mirrored(net, optics::simulate_sensor(*phi, lf_x), 16, false);
  CHECK(torch::allclose(ensemble_x, ensemble.flip({2, 4}), 1e-4, 1e-4));
  const auto single_x =
      recon::reconstruct_sensor_tiled(net, optics::simulate_sensor(*phi, lf_x), 16, false);
  CHECK_FALSE(torch::allclose(single_x, single.flip({2, 4}), 1e-3, 1e-3));
}

TEST_CASE("a self-ensemble of fewer passes averages the first mirrors", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto net = image_net(*phi);
  test::randomise_image_net(net, 23);
  const auto all = recon::ensemble_mirrors(net->phi);
  REQUIRE(all.size() == 4);
  const auto two = recon::ensemble_mirrors(net->phi, 2);
  REQUIRE(two.size() == 2);
  CHECK_FALSE((two[0].flip_x || two[0].flip_y));  // the identity first
  CHECK((two[1].flip_x && !two[1].flip_y));       // then left to right
  CHECK(recon::ensemble_mirrors(net->phi, 9).size() == 4);
  CHECK(recon::ensemble_mirrors(net->phi, 0).size() == 4);
  CHECK_THROWS_AS(recon::ensemble_mirrors(net->phi, -1), ConfigError);

  const auto lf = random_light_field(*phi, 40, 48, 9);
  const auto sensor = optics::simulate_sensor(*phi, lf);
  const auto single = recon::reconstruct_sensor_tiled(net, sensor, 16, false);
  // The left-to-right mirror image, reconstructed and mirrored back (x and v reversed).
  const auto mirrored =
      recon::reconstruct_sensor_tiled(net, sensor.flip({2}), 16, false).flip({2, 4});
  const auto pair = recon::reconstruct_sensor_mirrored(net, sensor, 16, false, 0.0, {}, 2);
  CHECK(torch::allclose(pair, (single + mirrored) / 2, 1e-4, 1e-4));
  CHECK_FALSE(torch::allclose(pair, recon::reconstruct_sensor_mirrored(net, sensor, 16, false),
                              1e-3, 1e-3));
  CHECK(torch::allclose(recon::reconstruct_sensor_mirrored(net, sensor, 16, false, 0.0, {}, 1),
                        single, 1e-5, 1e-5));
}

TEST_CASE(
    "the self-ensemble of crops equals that of the whole image and keeps each crop's "
    "phase and noise",
    "[recon][image]") {
  const auto asp = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto net = image_net(*asp);
  test::randomise_image_net(net, 25);
  const auto sensor = optics::simulate_sensor(*asp, random_light_field(*asp, 40, 48, 10));
  for (int64_t passes : {0, 2}) {
    INFO(passes << " passes");
    const auto crops = recon::reconstruct_crops_mirrored(net, sensor.unsqueeze(0), {}, {}, passes);
    REQUIRE(crops.sizes() == torch::IntArrayRef({1, 1, asp->rows(), asp->cols(), 40, 48}));
    CHECK(torch::allclose(
        crops[0], recon::reconstruct_sensor_mirrored(net, sensor, 16, false, 0.0, {}, passes), 1e-4,
        1e-4));
  }

  // A periodic mask has the identity alone: each crop is forward() at its own phase, and a
  // noise-aware net reads each crop's own sigma.
  const auto mask = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  auto noisy = noise_aware_net(*mask, 26);
  const auto image = optics::simulate_sensor(*mask, random_light_field(*mask, 40, 40, 11));
  std::vector<torch::Tensor> parts;
  std::vector<int64_t> phases;
  for (const auto& [y0, x0] : {std::pair<int64_t, int64_t>{5, 9}, {0, 0}, {12, 3}}) {
    parts.push_back(image.slice(1, y0, y0 + 16).slice(2, x0, x0 + 16));
    phases.push_back(optics::patch_phase(*mask, y0, x0));
  }
  const auto batch = torch::stack(parts).contiguous();
  const auto phase = torch::tensor(phases, torch::kInt64);
  REQUIRE((phase != phase[0]).any().item<bool>());
  const auto sigma = torch::tensor({0.0F, 0.2F, 0.1F});
  torch::Tensor expected;
  {
    torch::NoGradGuard no_grad;
    expected = noisy->forward(batch.flatten(1), phase, sigma);
  }
  CHECK(torch::allclose(recon::reconstruct_crops_mirrored(noisy, batch, phase, sigma), expected,
                        1e-4, 1e-4));
  CHECK_FALSE(torch::allclose(recon::reconstruct_crops_mirrored(noisy, batch, {}, sigma), expected,
                              1e-3, 1e-3));
  CHECK_THROWS(recon::reconstruct_crops_mirrored(noisy, batch, phase.narrow(0, 0, 2), sigma));
  nn::NetworkOptions paper;
  paper.measurements = asp->measurements();
  CHECK_THROWS_AS(recon::reconstruct_crops_mirrored(nn::LightFieldNet(paper), batch), ConfigError);
}

TEST_CASE("the self-ensemble applies to the net method of an lfnet model only", "[recon][image]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto net = image_net(*phi);
  CHECK_NOTHROW(recon::check_self_ensemble("net", net));
  CHECK_THROWS_WITH(recon::check_self_ensemble("pinv", net),
                    Catch::Contains("--self-ensemble applies to --method net"));
  CHECK_THROWS_AS(recon::check_self_ensemble("net", nn::LightFieldNet{nullptr}), ConfigError);
  // --ensemble-passes needs the self-ensemble.
  CHECK_NOTHROW(recon::check_ensemble_passes(true, 2));
  CHECK_NOTHROW(recon::check_ensemble_passes(false, 0));
  CHECK_THROWS_WITH(recon::check_ensemble_passes(false, 2),
                    Catch::Contains("--ensemble-passes applies to --self-ensemble"));
  nn::NetworkOptions paper;
  paper.measurements = phi->measurements();
  CHECK_THROWS_AS(recon::check_self_ensemble("net", nn::LightFieldNet(paper)), ConfigError);
}

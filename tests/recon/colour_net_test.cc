// A colour net of the lfnet architecture (network.cfa): its demosaiced pseudo-inverse input,
// tiled inference, its start from a grey net and what it refuses.
#include <torch/torch.h>
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/nn/image_net.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/train/checkpoint.h"
#include "lfnet/train/trainer.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

nn::NetworkOptions colour_options(const optics::Phi& phi, const std::string& cfa) {
  nn::NetworkOptions o;
  o.architecture = nn::kLfnetArchitecture;
  o.measurements = phi.measurements();
  o.patch = {phi.rows(), phi.cols(), 16, 16};
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) {
    image.channels = 6;
    image.levels = 3;
    image.blocks = 1;
  });
  o.cfa = cfa;
  return o;
}

nn::LightFieldNet net_of(const nn::NetworkOptions& o, const optics::Phi& phi) {
  nn::LightFieldNet net(o);
  net->set_phi(phi.pixel_weights(0, 0, phi.period(), phi.period()));
  return net;
}

// The camera: every colour of `lf` (3, U, V, H, W) coded by phi, then each pixel's own colour.
torch::Tensor colour_sensor(const optics::Phi& phi, const torch::Tensor& lf,
                            const optics::ColourFilterArray& cfa) {
  std::vector<torch::Tensor> colours;
  for (int64_t c = 0; c < 3; ++c) colours.push_back(optics::simulate_sensor(phi, lf[c]));
  return optics::mosaic(torch::stack(colours), cfa)[0];
}

torch::Tensor colour_light_field(const optics::Phi& phi, int64_t h, int64_t w, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  return torch::rand({3, phi.rows(), phi.cols(), h, w}, gen);
}

}  // namespace

TEST_CASE("an untrained colour net returns the pseudo-inverse demosaiced as pinv's views are",
          "[recon][image][colour]") {
  for (const std::string name : {"asp", "mask"}) {
    for (const std::string pattern : {"RGGB", "GBRG"}) {
      INFO(name << ", " << pattern);
      const auto phi = optics::make_phi(optics::PhiSpec::parse(name + ":2"));
      const auto cfa = optics::ColourFilterArray::bayer(pattern);
      const auto sensor = colour_sensor(*phi, colour_light_field(*phi, 37, 30, 3), cfa);
      // pinv's way: the mosaicked light field of a grey net's pseudo-inverse, then demosaiced.
      auto grey = net_of(colour_options(*phi, ""), *phi);
      const auto want =
          optics::demosaic(recon::reconstruct_sensor_tiled(grey, sensor, 256, false)[0], cfa);
      auto net = net_of(colour_options(*phi, pattern), *phi);
      // Tiles of 8 start at every phase of the code's and the CFA's period.
      for (int64_t tile : {8, 256}) {
        INFO("tile " << tile);
        const auto got = recon::reconstruct_sensor_tiled(net, sensor, tile, false);
        REQUIRE(got.sizes() == want.sizes());
        // Equal but on the image's outermost pixels, where pinv's demosaic mirrors the image
        // and the net's leaves out what lies beyond (as at a tile's edge).
        auto inner = [](const torch::Tensor& x) { return x.slice(3, 1, -1).slice(4, 1, -1); };
        CHECK(torch::allclose(inner(got), inner(want), 1e-5, 1e-5));
        CHECK((got - want).abs().max().item<double>() < 0.2);
      }
    }
  }
}

TEST_CASE("an untrained colour net with malvar demosaicing returns pinv's malvar demosaic",
          "[recon][image][colour]") {
  for (const std::string name : {"asp", "mask"}) {
    for (const std::string pattern : {"RGGB", "GRBG"}) {
      INFO(name << ", " << pattern);
      const auto phi = optics::make_phi(optics::PhiSpec::parse(name + ":2"));
      const auto cfa = optics::ColourFilterArray::bayer(pattern);
      const auto sensor = colour_sensor(*phi, colour_light_field(*phi, 37, 30, 5), cfa);
      auto grey = net_of(colour_options(*phi, ""), *phi);
      const auto mosaicked = recon::reconstruct_sensor_tiled(grey, sensor, 256, false)[0];
      const auto want = optics::demosaic(mosaicked, cfa, optics::Demosaic::kMalvar);
      auto o = colour_options(*phi, pattern);
      o.demosaic = optics::Demosaic::kMalvar;
      auto net = net_of(o, *phi);
      CHECK(nn::NetworkOptions::from_json(o.to_json()).demosaic == optics::Demosaic::kMalvar);
      // Both mirror the image at its edges; tiles of 8 start at every phase, their halos keep
      // a tile's own edges away from its core.
      for (int64_t tile : {8, 256}) {
        INFO("tile " << tile);
        const auto got = recon::reconstruct_sensor_tiled(net, sensor, tile, false);
        REQUIRE(got.sizes() == want.sizes());
        CHECK(torch::allclose(got, want, 1e-5, 1e-5));
      }
      // Not the bilinear demosaic.
      CHECK((want - optics::demosaic(mosaicked, cfa)).abs().max().item<double>() > 0.01);
    }
  }
}

TEST_CASE("tiled inference of a colour net equals one pass over the whole image",
          "[recon][image][colour]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  const auto cfa = optics::ColourFilterArray::bayer("GRBG");
  auto net = net_of(colour_options(*phi, "GRBG"), *phi);
  test::randomise_image_net(net, 21);
  CHECK(net->period() == 18);  // the mask's 9 and the CFA's 2
  const auto sensor = colour_sensor(*phi, colour_light_field(*phi, 50, 45, 4), cfa);
  torch::Tensor whole;
  {
    torch::NoGradGuard no_grad;
    whole = net->forward_image(sensor.unsqueeze(0))[0];
  }
  REQUIRE(whole.sizes() == torch::IntArrayRef({3, phi->rows(), phi->cols(), 50, 45}));
  for (int64_t tile : {8, 20, 64}) {
    INFO("tile " << tile);
    CHECK(torch::allclose(recon::reconstruct_sensor_tiled(net, sensor, tile, false), whole, 1e-4,
                          1e-4));
  }
  // A training crop through forward() is forward_image of that crop, at the crop's phase.
  const int64_t y0 = 5, x0 = 13;
  const auto crop = sensor.slice(1, y0, y0 + 16).slice(2, x0, x0 + 16).unsqueeze(0).contiguous();
  const int64_t phase = (y0 % 18) * 18 + x0 % 18;
  torch::NoGradGuard no_grad;
  const auto via_forward = net->forward(crop.flatten(1), torch::full({1}, phase, torch::kInt64));
  REQUIRE(via_forward.sizes() == torch::IntArrayRef({1, 3, phi->rows(), phi->cols(), 16, 16}));
  CHECK(torch::allclose(via_forward, net->forward_image(crop, phase), 1e-5, 1e-5));
}

TEST_CASE("a colour net runs whole only on smaller images; an export carries its limits",
          "[recon][image][colour]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto grey_options = colour_options(*phi, "RGGB");
  grey_options.cfa = "";
  const auto colour = net_of(colour_options(*phi, "RGGB"), *phi);
  const auto grey = net_of(grey_options, *phi);
  const auto colour_tiling = colour->architecture().image_tiling(colour->options());
  const auto grey_tiling = grey->architecture().image_tiling(grey->options());
  REQUIRE(colour_tiling.receptive_radius == grey_tiling.receptive_radius);
  CHECK((grey_tiling.whole == 800 && grey_tiling.crop == 512));
  CHECK((colour_tiling.whole == 640 && colour_tiling.crop == 720));
  // 593 x 840 (pads to 596 x 840): whole for a grey net, two tiles of 720 - 2 halos in colour.
  const int64_t halo = nn::round_up(colour_tiling.receptive_radius, colour_tiling.multiple);
  CHECK(nn::auto_image_tile(grey_tiling, 593, 840) == 840);
  CHECK(nn::auto_image_tile(colour_tiling, 593, 840) == 720 - 2 * halo);
  CHECK(nn::image_tiles(colour_tiling, 593, 840, 0).size() == 2);
  CHECK(nn::auto_image_tile(colour_tiling, 500, 800) == 800);  // 500 x 800 <= 640^2

  // An export carries the limits its `reconstruct` resolves a tile of 0 with (a grey net's:
  // colour nets are not exported).
  const test::TempDir tmp;
  nn::ScriptMetadata meta;
  meta.phi = phi->spec().to_json();
  meta.period = grey->period();
  nn::export_network(grey, meta, tmp / "g.pt");
  const auto scripted = nn::load_script(tmp / "g.pt");
  CHECK(scripted.module.attr("auto_tile_whole").toInt() == 800);
  CHECK(scripted.module.attr("auto_tile_crop").toInt() == 512);
}

TEST_CASE("a colour net starts from a grey one: the grey net's correction of the luma",
          "[recon][image][colour]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto grey_options = colour_options(*phi, "");
  lfnet::test::edit_image(grey_options, [&](lfnet::nn::ImageNetOptions& grey_options_image) {
    grey_options_image.noise_input = true;
  });
  auto grey = net_of(grey_options, *phi);
  test::randomise_image_net(grey, 5);
  auto options = grey_options;
  options.cfa = "RGGB";
  auto colour = net_of(options, *phi);
  test::randomise_image_net(colour, 6);
  nn::WarmStartSource from;
  from.network = grey_options.to_json();
  const auto report =
      train::warm_start_net(*colour, train::module_state(*grey), from, "", "the grey net");
  CHECK(report.widened.size() == 3);  // the input's weights, the output's weights and bias
  CHECK(report.mapped.empty());
  CHECK(report.reinitialised.empty());
  CHECK(report.copied.size() + 3 == colour->parameters().size());
  // Three equal colours (their luma is that colour) come out as the grey net's output, thrice.
  const int64_t views = phi->rows() * phi->cols();
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(8);
  const auto x = torch::rand({2, views, 16, 16}, gen);
  const auto sigma = torch::full({2, 1, 16, 16}, 0.05);
  torch::NoGradGuard no_grad;
  const auto want =
      lfnet::nn::image_layers(*grey)->forward(torch::cat({x, sigma}, 1)).repeat({1, 3, 1, 1});
  lfnet::test::require_close(
      lfnet::nn::image_layers(*colour)->forward(torch::cat({x, x, x, sigma}, 1)), want, 1e-5);
}

TEST_CASE("colour nets are checked", "[recon][image][colour]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = colour_options(*phi, "RGBG");
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("cfa") && Catch::Contains("unknown Bayer"));
  o.cfa = "RGGB";
  o.architecture = nn::kPaperArchitecture;
  // lfnet's U-Net options belong to lfnet alone.
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("image: these options belong to another"));
  o.sections = nlohmann::json::object();
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("reconstructs colour"));
  o = colour_options(*phi, "RGGB");
  CHECK_NOTHROW(o.validate());
  CHECK(nn::NetworkOptions::from_json(o.to_json()).cfa == "RGGB");
  auto net = net_of(o, *phi);
  CHECK_NOTHROW(recon::check_self_ensemble("net", net, nullptr));
}

TEST_CASE("a colour net's self-ensemble of crops reads each crop's mirror images at their phases",
          "[recon][image][colour]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto cfa = optics::ColourFilterArray::bayer("GRBG");
  auto net = net_of(colour_options(*phi, "GRBG"), *phi);
  const auto sensor = colour_sensor(*phi, colour_light_field(*phi, 33, 36, 12), cfa);
  // Crops of odd and even sides at every phase of the pattern, in one batch.
  std::vector<torch::Tensor> parts;
  std::vector<int64_t> phases;
  for (const auto& [y0, x0] : {std::pair<int64_t, int64_t>{0, 0}, {1, 0}, {0, 3}, {5, 7}}) {
    parts.push_back(sensor.slice(1, y0, y0 + 15).slice(2, x0, x0 + 16));
    phases.push_back((y0 % 2) * 2 + x0 % 2);
  }
  const auto crops = torch::stack(parts).contiguous();
  const auto phase = torch::tensor(phases, torch::kInt64);
  // Untrained, every pass is its crop's demosaiced pseudo-inverse, which a mirror image read
  // at the wrong phase would give with its colours swapped.
  torch::Tensor single;
  {
    torch::NoGradGuard no_grad;
    std::vector<torch::Tensor> one;
    for (int64_t b = 0; b < crops.size(0); ++b) {
      one.push_back(net->forward_image(crops.narrow(0, b, 1), phases[static_cast<size_t>(b)], 0));
    }
    single = torch::cat(one);
  }
  const auto ensemble = recon::reconstruct_crops_mirrored(net, crops, phase, {});
  REQUIRE(ensemble.sizes() == torch::IntArrayRef({4, 3, 5, 5, 15, 16}));
  CHECK(torch::allclose(ensemble, single, 1e-4, 1e-4));
  CHECK_FALSE(
      torch::allclose(recon::reconstruct_crops_mirrored(net, crops, {}, {}), single, 1e-3, 1e-3));
  // Trained (here: random), the whole image's crop is the whole image's self-ensemble.
  test::randomise_image_net(net, 33);
  CHECK(torch::allclose(recon::reconstruct_crops_mirrored(net, sensor.unsqueeze(0), {}, {})[0],
                        recon::reconstruct_sensor_mirrored(net, sensor, 256, false), 1e-4, 1e-4));
}

TEST_CASE("a colour net's self-ensemble reads each mirror image at its CFA's phase",
          "[recon][image][colour]") {
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  for (const std::string pattern : {"RGGB", "GBRG"}) {
    // Even and odd sides: a mirror image moves the pattern by one pixel or by none.
    for (const auto& [h, w] : {std::pair<int64_t, int64_t>{36, 30}, {32, 29}, {37, 29}}) {
      INFO(pattern << ", " << h << " x " << w);
      const auto cfa = optics::ColourFilterArray::bayer(pattern);
      auto net = net_of(colour_options(*phi, pattern), *phi);
      // The code of period 1 gives the colour net the four mirrors of asp:2.
      REQUIRE(recon::ensemble_mirrors(recon::mirror_weights(net)).size() == 4);
      CHECK(recon::mirror_weights(net).sizes() == torch::IntArrayRef({2, 5, 5, 1, 1}));
      const auto lf = colour_light_field(*phi, h, w, 9);
      const auto sensor = colour_sensor(*phi, lf, cfa);
      // Untrained, every pass is the demosaiced pseudo-inverse of what it reads, which a
      // mirror image read at the wrong phase would give with its colours swapped.
      const auto single = recon::reconstruct_sensor_tiled(net, sensor, 256, false);
      CHECK(torch::allclose(recon::reconstruct_sensor_mirrored(net, sensor, 256, false), single,
                            1e-4, 1e-4));
      // Trained (here: random), the passes differ; on odd sides a mirror keeps the CFA where
      // it was, so the mirrored light field's sensor image is the sensor image's mirror image:
      // its ensemble estimate is the mirror image of the light field's.
      test::randomise_image_net(net, 31);
      const auto ensemble = recon::reconstruct_sensor_mirrored(net, sensor, 16, false);
      REQUIRE(ensemble.sizes() == torch::IntArrayRef({3, 5, 5, h, w}));
      CHECK_FALSE(torch::allclose(ensemble, recon::reconstruct_sensor_tiled(net, sensor, 16, false),
                                  1e-3, 1e-3));
      if (h % 2 == 1 && w % 2 == 1) {
        const auto flipped = colour_sensor(*phi, lf.flip({2, 4}), cfa);
        CHECK(torch::allclose(recon::reconstruct_sensor_mirrored(net, flipped, 16, false),
                              ensemble.flip({2, 4}), 1e-4, 1e-4));
      }
    }
  }
}

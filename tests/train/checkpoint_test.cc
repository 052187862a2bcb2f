#include "lfnet/train/checkpoint.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/train/trainer.h"
#include "support/small_nets.h"
#include "support/test_support.h"
#include "synthetic.h"

using lfnet::CheckpointError;
using lfnet::nn::LightFieldNet;
using lfnet::nn::NetworkOptions;
using lfnet::train::Checkpoint;

using lfnet::test::read_bytes;
using lfnet::test::write_bytes;

namespace {

Checkpoint checkpoint_of(const LightFieldNet& net, const nlohmann::json& phi_spec) {
  Checkpoint ck;
  ck.network = net->options().to_json();
  ck.phi = phi_spec;
  ck.model = lfnet::train::module_state(*net);
  return ck;
}

}  // namespace

TEST_CASE("a checkpoint round-trips every field bit for bit", "[train][checkpoint]") {
  lfnet::test::TempDir dir;
  Checkpoint ck;
  ck.config = {{"train", {{"lr", 0.001}, {"epochs", 3}}}, {"note", "ünïcode"}};
  const NetworkOptions defaults;
  ck.network = defaults.to_json();
  ck.phi = lfnet::test::synthetic_phi_spec("asp", 2, 0);
  ck.command_line = "lfnet train cfg.json --out 'my dir'";
  auto sparse = torch::zeros({64, 64});
  sparse[3][5] = 1.5;
  sparse[60][1] = -0.0;  // kept by its bit pattern
  ck.model["dense"] = torch::randn({7, 3});
  ck.model["sparse"] = sparse;
  ck.model["double"] = torch::randn({5}, torch::kFloat64);
  ck.model["empty"] = torch::zeros({0, 4});
  ck.optimizer["w/step"] = torch::tensor(int64_t{12345678901});
  ck.optimizer["w/exp_avg"] = torch::randn({3, 3});
  ck.optimizer_options = {{"type", "adam"}, {"lr", 0.01}};
  ck.training.stage = "cnn";
  ck.training.epoch = 4;
  ck.training.step = 400;
  ck.training.best_metric = 31.25;
  ck.training.best_epoch = 3;
  ck.training.history = nlohmann::json::array({{{"epoch", 1}}, {{"epoch", 2}}});
  ck.training.rng_state = torch::randint(0, 255, {5056}, torch::kUInt8);
  const auto path = dir / "a.ckpt";
  lfnet::train::save_checkpoint(ck, path);
  auto back = lfnet::train::load_checkpoint(path);
  CHECK(back.format_version == lfnet::train::kCheckpointFormatVersion);
  CHECK(back.config == ck.config);
  CHECK(back.network == ck.network);
  CHECK(back.phi == ck.phi);
  CHECK(back.command_line == ck.command_line);
  CHECK(back.optimizer_options == ck.optimizer_options);
  CHECK(back.training.to_json() == ck.training.to_json());
  CHECK(torch::equal(back.training.rng_state, ck.training.rng_state));
  REQUIRE(back.model.size() == ck.model.size());
  for (const auto& [name, t] : ck.model) {
    INFO(name);
    CHECK(back.model.at(name).scalar_type() == t.scalar_type());
    CHECK(torch::equal(back.model.at(name), t));
  }
  CHECK(std::signbit(back.model.at("sparse")[60][1].item<float>()));
  CHECK(back.optimizer.at("w/step").item<int64_t>() == 12345678901);
  CHECK(torch::equal(back.optimizer.at("w/exp_avg"), ck.optimizer.at("w/exp_avg")));
  // No temporary file is left beside it.
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) {
    ++files;
    CHECK(e.path().filename() == "a.ckpt");
  }
  CHECK(files == 1);
}

TEST_CASE("save then load gives identical outputs for every model", "[train][checkpoint]") {
  lfnet::test::TempDir dir;
  int case_index = 0;
  for (const std::string branches : {"ae", "cnn", "net"}) {
    for (const std::string residual : {"none", "pinv"}) {
      for (int64_t phases : {1, 4}) {
        INFO(branches << " residual " << residual << " phases " << phases);
        torch::manual_seed(10 + case_index);
        auto o = lfnet::test::small_net_options(branches);
        lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
          p.residual = lfnet::nn::from_string(residual, p.residual);
          p.ae.input =
              case_index % 2 ? lfnet::nn::AeInput::kAdjoint : lfnet::nn::AeInput::kMeasurements;
        });
        LightFieldNet net(o);
        net->set_phi(
            lfnet::test::gaussian_phi(phases, o.measurement_size(), o.patch.size(), case_index));
        const auto path = dir / ("m" + std::to_string(case_index++) + ".ckpt");
        lfnet::train::save_checkpoint(checkpoint_of(net, {{"name", "random"}}), path);
        auto loaded = lfnet::train::build_net(lfnet::train::load_checkpoint(path));
        auto y = torch::rand({6, o.measurement_size()});
        auto phase = torch::arange(6, torch::kInt64).remainder(phases);
        auto want = net->forward(y, phase), got = loaded->forward(y, phase);
        CHECK(torch::equal(got, want));
        CHECK(loaded->options().to_json() == o.to_json());
      }
    }
  }
}

TEST_CASE("a checkpoint of another format version is refused", "[train][checkpoint]") {
  lfnet::test::TempDir dir;
  LightFieldNet net(lfnet::test::small_net_options());
  const auto path = dir / "v.ckpt";
  lfnet::train::save_checkpoint(checkpoint_of(net, {{"name", "asp"}}), path);
  auto bytes = read_bytes(path);
  bytes[8] = 7;  // the u32 version after the magic
  write_bytes(path, bytes);
  CHECK_THROWS_AS(lfnet::train::load_checkpoint(path), CheckpointError);
  CHECK_THROWS_WITH(lfnet::train::load_checkpoint(path),
                    Catch::Contains("format version 7") && Catch::Contains("reads version 1"));
}

TEST_CASE("truncated, corrupted, foreign and missing files are clear errors",
          "[train][checkpoint]") {
  lfnet::test::TempDir dir;
  LightFieldNet net(lfnet::test::small_net_options());
  const auto path = dir / "t.ckpt";
  lfnet::train::save_checkpoint(checkpoint_of(net, {{"name", "asp"}}), path);
  const auto bytes = read_bytes(path);

  write_bytes(path, bytes.substr(0, bytes.size() / 2));
  CHECK_THROWS_WITH(lfnet::train::load_checkpoint(path), Catch::Contains("truncated"));
  write_bytes(path, bytes.substr(0, 10));
  CHECK_THROWS_WITH(lfnet::train::load_checkpoint(path), Catch::Contains("truncated"));

  auto corrupted = bytes;
  corrupted[bytes.size() / 2] ^= 0x40;
  write_bytes(path, corrupted);
  CHECK_THROWS_WITH(lfnet::train::load_checkpoint(path), Catch::Contains("checksum"));

  write_bytes(path, "\x89PNG\r\n\x1a\n and then some image bytes");
  CHECK_THROWS_AS(lfnet::train::load_checkpoint(path), CheckpointError);
  CHECK_THROWS_WITH(lfnet::train::load_checkpoint(path),
                    Catch::Contains("not an lfnet checkpoint"));
  write_bytes(path, "");
  CHECK_THROWS_WITH(lfnet::train::load_checkpoint(path),
                    Catch::Contains("not an lfnet checkpoint"));

  CHECK_THROWS_AS(lfnet::train::load_checkpoint(dir / "absent.ckpt"), lfnet::IoError);
}

TEST_CASE("a checkpoint of another architecture is refused with the differences",
          "[train][checkpoint]") {
  auto o = lfnet::test::small_net_options();
  LightFieldNet net(o);
  auto state = lfnet::train::module_state(*net);
  auto wider = o;
  lfnet::test::edit_paper(wider, [&](lfnet::nn::PaperOptions& p) { p.cnn.channels = 6; });
  LightFieldNet other(wider);
  CHECK_THROWS_AS(lfnet::train::load_net_state(other, state, "checkpoint x"), CheckpointError);
  CHECK_THROWS_WITH(lfnet::train::load_net_state(other, state, "checkpoint x"),
                    Catch::Contains("checkpoint x holds another architecture") &&
                        Catch::Contains("cnn.conv1.weight"));
  auto deeper = o;
  lfnet::test::edit_paper(deeper, [&](lfnet::nn::PaperOptions& p) { p.cnn.depth = 4; });
  LightFieldNet other2(deeper);
  CHECK_THROWS_WITH(lfnet::train::load_net_state(other2, state, "ck"),
                    Catch::Contains("lacks cnn.conv4.weight"));
  LightFieldNet ae_only(lfnet::test::small_net_options("ae"));
  CHECK_THROWS_WITH(lfnet::train::load_net_state(ae_only, state, "ck"),
                    Catch::Contains("which this net lacks"));
  // Another number of Phi phases is not another architecture.
  LightFieldNet same(o);
  same->set_phi(lfnet::test::gaussian_phi(3, o.measurement_size(), o.patch.size(), 1));
  auto state3 = lfnet::train::module_state(*same);
  lfnet::train::load_net_state(net, state3, "ck");
  CHECK(net->phases() == 3);
  CHECK(torch::equal(net->phi, same->phi));
}

TEST_CASE("a checkpoint for another Phi is refused", "[train][checkpoint]") {
  LightFieldNet net(lfnet::test::small_net_options());
  auto ck = checkpoint_of(net, lfnet::test::synthetic_phi_spec("asp", 2, 0));
  lfnet::train::check_phi(ck, lfnet::test::synthetic_phi_spec("asp", 2, 0));
  CHECK_THROWS_AS(lfnet::train::check_phi(ck, lfnet::test::synthetic_phi_spec("mask", 2, 0)),
                  CheckpointError);
  CHECK_THROWS_WITH(lfnet::train::check_phi(ck, lfnet::test::synthetic_phi_spec("asp", 3, 0)),
                    Catch::Contains("trained for Phi") && Catch::Contains("--init"));
}

TEST_CASE("a default-sized checkpoint with Adam state stays under 10 MB", "[train][checkpoint]") {
  lfnet::test::TempDir dir;
  torch::manual_seed(0);
  NetworkOptions o;  // the defaults: 5 x 5 x 9 x 9, N = 2, both branches
  LightFieldNet net(o);
  net->set_phi(lfnet::test::per_pixel_phi(1, 2, o.patch, 3));
  lfnet::train::TrainerOptions options;
  options.progress = false;
  options.out_dir = dir.path().string();
  options.epochs = 1;
  options.batch_size = 4;
  lfnet::train::Trainer trainer(net, options,
                                {{}, lfnet::test::synthetic_phi_spec("asp", 2, 0), "test"});
  auto patches = lfnet::test::smooth_patches(10, o.patch, 1);
  auto source = lfnet::test::make_source(patches, net->phi, 2);
  trainer.fit(*source);
  const auto path = lfnet::train::last_checkpoint_path(dir.path().string());
  const auto bytes = std::filesystem::file_size(path);
  INFO("checkpoint bytes " << bytes);
  CHECK(bytes < 10'000'000);
  // Model and both Adam moments are there: at least 12 bytes per parameter.
  CHECK(bytes > 12 * static_cast<uintmax_t>(lfnet::nn::parameter_count(*net)));
  auto ck = lfnet::train::load_checkpoint(path);
  CHECK(ck.optimizer.size() == 3 * net->parameters().size());
  CHECK(torch::equal(ck.model.at("phi"), net->phi));
  // best.ckpt keeps the model only.
  const auto best = lfnet::train::best_checkpoint_path(dir.path().string());
  CHECK(std::filesystem::file_size(best) < 4'000'000);
  CHECK(lfnet::train::load_checkpoint(best).optimizer.empty());
  CHECK_THROWS_WITH(trainer.resume(best), Catch::Contains("no optimizer state"));
}

TEST_CASE("an lfnet-architecture checkpoint round-trips for every period", "[train][checkpoint]") {
  lfnet::test::TempDir dir;
  for (int64_t period : {1, 3}) {
    INFO("period " << period);
    auto o = lfnet::test::small_image_options(8, 4);
    lfnet::test::edit_image(
        o, [&](lfnet::nn::ImageNetOptions& image) { image.noise_input = period > 1; });
    torch::manual_seed(period);
    LightFieldNet net(o);
    net->set_phi(torch::rand({2, 3, 3, period, period}));
    {
      torch::NoGradGuard no_grad;
      for (auto& p : lfnet::nn::image_layers(*net)->parameters())
        p.copy_(torch::randn_like(p) * 0.1);
    }
    const auto path = dir / ("lfnet" + std::to_string(period) + ".ckpt");
    lfnet::train::save_checkpoint(checkpoint_of(net, {{"name", "mask"}}), path);
    auto loaded = lfnet::train::build_net(lfnet::train::load_checkpoint(path));
    auto y = torch::rand({4, o.measurements * o.patch.height * o.patch.width});
    auto phase = torch::arange(4, torch::kInt64).remainder(period * period);
    auto noise = torch::full({4}, 0.1);
    CHECK(torch::equal(loaded->forward(y, phase, noise), net->forward(y, phase, noise)));
    CHECK(loaded->options().to_json() == o.to_json());
  }
}

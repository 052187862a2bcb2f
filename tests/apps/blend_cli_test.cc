// lfnet blend (pipeline/blend.h): a finetuned model's weights blended with its base's, each
// shared parameter (1 - alpha) base + alpha model, the model's own layers and camera kept; bad
// input refused with nothing written.
#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "lfnet/nn/network.h"
#include "lfnet/optics/phi.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

namespace {

std::string bytes_of(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST_CASE("lfnet blend mixes the shared weights and keeps the model's own", "[app][blend]") {
  lfnet::test::TempDir tmp;
  const std::string colour = tmp / "colour.ckpt", grey = tmp / "grey.ckpt";
  lfnet::test::save_small_image_net("RGGB", 11, colour);
  lfnet::test::save_small_image_net("", 12, grey);
  const std::string lfnet = lfnet_binary() + " --threads 1 --log-level warn blend ";
  std::string out;
  const std::string blended = tmp / "blended.ckpt";
  REQUIRE(run_command(
              lfnet + "--model " + colour + " --base " + grey + " --alpha 0.25 --out " + blended,
              out) == 0);
  const auto b = lfnet::train::load_checkpoint(blended);
  const auto c = lfnet::train::load_checkpoint(colour);
  const auto g = lfnet::train::load_checkpoint(grey);
  const auto net = lfnet::train::build_net(c);
  int blended_count = 0, kept = 0;
  for (const auto& p : net->named_parameters()) {
    const auto& name = p.key();
    const auto& from_model = c.model.at(name);
    const auto it = g.model.find(name);
    if (it != g.model.end() && it->second.sizes() == from_model.sizes()) {
      // The two nets differ there: the blend is neither of them.
      REQUIRE_FALSE(torch::allclose(it->second, from_model));
      CHECK(torch::allclose(b.model.at(name), 0.75 * it->second + 0.25 * from_model, 1e-5, 1e-6));
      ++blended_count;
    } else {
      CHECK(torch::equal(b.model.at(name), from_model));
      ++kept;
    }
  }
  CHECK(blended_count > 0);
  CHECK(kept > 0);  // the colour net's input and output layers
  CHECK(torch::equal(b.model.at("phi"), c.model.at("phi")));
  CHECK(torch::equal(b.model.at("cfa_response"), c.model.at("cfa_response")));
  CHECK(b.optimizer.empty());
  CHECK(b.network == c.network);
  CHECK(b.training.origin.at("blend").at("alpha").get<double>() == 0.25);
  CHECK(out.find("blended " + std::to_string(blended_count) + " parameters") != std::string::npos);

  // alpha 1 is the model itself, alpha 0 the base's weights where they are shared.
  const std::string one = tmp / "one.ckpt", zero = tmp / "zero.ckpt";
  REQUIRE(run_command(lfnet + "--model " + colour + " --base " + grey + " --alpha 1 --out " + one,
                      out) == 0);
  REQUIRE(run_command(lfnet + "--model " + colour + " --base " + grey + " --alpha 0 --out " + zero,
                      out) == 0);
  const auto b1 = lfnet::train::load_checkpoint(one);
  const auto b0 = lfnet::train::load_checkpoint(zero);
  for (const auto& p : net->named_parameters()) {
    const auto& name = p.key();
    CHECK(torch::equal(b1.model.at(name), c.model.at(name)));
    const auto it = g.model.find(name);
    const bool shared = it != g.model.end() && it->second.sizes() == c.model.at(name).sizes();
    CHECK(torch::equal(b0.model.at(name), shared ? it->second : c.model.at(name)));
  }
}

TEST_CASE("lfnet blend refuses bad input and writes nothing", "[app][blend]") {
  lfnet::test::TempDir tmp;
  const std::string colour = tmp / "colour.ckpt", grey = tmp / "grey.ckpt";
  lfnet::test::save_small_image_net("RGGB", 11, colour);
  lfnet::test::save_small_image_net("", 12, grey);
  const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  const std::string paper = tmp / "paper.ckpt";
  {
    lfnet::nn::LightFieldNet net(lfnet::test::small_network_options());
    lfnet::test::save_net(net, *phi, "joint", paper);
  }
  const std::string lfnet = lfnet_binary() + " --threads 1 blend ";
  const std::string target = tmp / "out.ckpt";
  std::string out;
  SECTION("alpha outside [0, 1]") {
    CHECK(run_command(
              lfnet + "--model " + colour + " --base " + grey + " --alpha 1.5 --out " + target,
              out) != 0);
    CHECK(out.find("--alpha must lie in [0, 1]") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(target));
  }
  SECTION("networks of different architectures") {
    CHECK(run_command(lfnet + "--model " + colour + " --base " + paper + " --out " + target, out) !=
          0);
    CHECK(out.find("different architectures") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(target));
  }
  SECTION("networks of other widths: not one finetuned from the other") {
    const std::string wider = tmp / "wider.ckpt";
    lfnet::test::save_small_image_net("", 13, wider, 8);
    CHECK(run_command(lfnet + "--model " + wider + " --base " + grey + " --out " + target, out) !=
          0);
    CHECK(out.find("they are not one network finetuned from the other") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(target));
  }
  SECTION("a file that is not a checkpoint") {
    { std::ofstream(tmp / "junk.ckpt") << "not a checkpoint"; }
    CHECK(run_command(
              lfnet + "--model " + colour + " --base " + (tmp / "junk.ckpt") + " --out " + target,
              out) != 0);
    CHECK_FALSE(std::filesystem::exists(target));
  }
  SECTION("an existing output, and an input as the output") {
    { std::ofstream(target) << "keep me"; }
    CHECK(run_command(lfnet + "--model " + colour + " --base " + grey + " --out " + target, out) !=
          0);
    CHECK(bytes_of(target) == "keep me");
    const auto before = bytes_of(colour);
    CHECK(run_command(
              lfnet + "--model " + colour + " --base " + grey + " --out " + colour + " --force",
              out) != 0);
    CHECK(bytes_of(colour) == before);
  }
}

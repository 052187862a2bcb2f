// Every network checkpoint of the model zoo (models/zoo.json) reconstructs what it reconstructed
// when tests/recon/model_outputs.json was recorded: changes to the architectures
// (nn/architecture.h), checkpoints or methods must not change a shipped model's numbers. Each model
// reconstructs, through the method registry as the commands do, the sensor image its own Phi makes
// of one analytic light field with parallax. The record holds the sum, the sum of squares and 16
// samples of every reconstruction.
//
// To record the outputs anew (after a change that is meant to change them, or for a new model):
//   LFNET_WRITE_MODEL_OUTPUTS=1 build/tests/recon/recon_tests "[models]"
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lfnet/optics/cfa.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/reconstruct.h"
#include "lfnet/train/checkpoint.h"
#include "support/test_support.h"

using namespace lfnet;
namespace fs = std::filesystem;

namespace {

constexpr int64_t kHeight = 45, kWidth = 54;  // multiples of 9: random:N's blocks tile it

// A U x V light field of smooth texture whose views shift by 0.7 pixels per view step.
torch::Tensor analytic_light_field(int64_t rows, int64_t cols) {
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  auto u = (torch::arange(rows, opts) - (rows - 1) / 2.0).view({rows, 1, 1, 1});
  auto v = (torch::arange(cols, opts) - (cols - 1) / 2.0).view({1, cols, 1, 1});
  auto y = torch::arange(kHeight, opts).view({1, 1, kHeight, 1}) + 0.7 * u;
  auto x = torch::arange(kWidth, opts).view({1, 1, 1, kWidth}) + 0.7 * v;
  auto lf = 0.5 + 0.25 * torch::sin(0.37 * x + 0.23 * y) * torch::cos(0.11 * x - 0.07 * y) +
            0.15 * torch::sin(0.05 * x * y / 9.0);
  return lf.clamp(0.0, 1.0).to(torch::kFloat32);
}

// What the checkpoint at `path` reconstructs, summarised.
nlohmann::json reconstruct_summary(const fs::path& path) {
  const auto ckpt = train::load_checkpoint(path.string());
  auto net = train::build_net(ckpt, path.string());
  net->eval();
  const auto phi = optics::make_phi(optics::PhiSpec::from_json(ckpt.phi, path.string() + ":phi"));
  const auto lf = analytic_light_field(phi->rows(), phi->cols());
  torch::Tensor sensor;
  if (net->options().colours() == 1) {
    sensor = optics::simulate_sensor(*phi, lf);
  } else {
    // A colour net: three colours of the light field behind its colour filter array.
    std::vector<torch::Tensor> colours;
    for (const auto& c : {lf, 0.8 * lf + 0.1, 1.0 - lf}) {
      colours.push_back(optics::simulate_sensor(*phi, c));
    }
    sensor = optics::mosaic(torch::stack(colours),
                            optics::ColourFilterArray::bayer(net->options().cfa))[0];
  }
  recon::MethodResources r;
  r.phi = phi.get();
  r.net = net;
  torch::Tensor out;
  if (const auto image = recon::make_image_solver("net", r)) {
    out = image(sensor, 0.0);
  } else {
    const auto grid = net->options().patch_grid();
    REQUIRE(grid);
    r.patch_h = grid->height;
    r.patch_w = grid->width;
    recon::ReconstructOptions o;
    o.patch_h = grid->height;
    o.patch_w = grid->width;
    o.stride = phi->block() > 1 ? phi->block() : 5;
    out = recon::reconstruct_sensor(*phi, sensor, recon::make_solver("net", r), o);
  }
  const auto flat = out.to(torch::kFloat64).reshape({-1});
  nlohmann::json samples = nlohmann::json::array();
  const int64_t n = flat.numel();
  for (int64_t i = 0; i < 16; ++i) samples.push_back(flat[(i * 7919) % n].item<double>());
  return {{"shape", out.sizes().vec()},
          {"sum", flat.sum().item<double>()},
          {"sum_sq", flat.square().sum().item<double>()},
          {"samples", samples}};
}

}  // namespace

TEST_CASE("every checkpoint of the zoo reconstructs as recorded", "[recon][models]") {
  const auto files = lfnet::test::zoo_checkpoints();
  REQUIRE(files.size() >= 10);
  const fs::path record_path = fs::path(LFNET_SOURCE_DIR) / "tests/recon/model_outputs.json";
  nlohmann::json got = nlohmann::json::object();
  for (const auto& file : files) {
    const auto name = fs::relative(file, LFNET_SOURCE_DIR).generic_string();
    got[name] = reconstruct_summary(file);
  }
  if (std::getenv("LFNET_WRITE_MODEL_OUTPUTS") != nullptr) {
    fs::create_directories(record_path.parent_path());
    std::ofstream(record_path) << got.dump(1) << "\n";
    WARN("recorded the outputs of " << files.size() << " checkpoints in " << record_path);
    return;
  }
  std::ifstream in(record_path);
  REQUIRE(in.good());
  const auto want = nlohmann::json::parse(in);
  double largest = 0;
  for (const auto& [name, g] : got.items()) {
    INFO(name << " (record it with LFNET_WRITE_MODEL_OUTPUTS=1 if it is new)");
    REQUIRE(want.contains(name));
    const auto& w = want[name];
    CHECK(g["shape"] == w["shape"]);
    // Float rounding may differ between CPUs (other kernels); on one machine the outputs are
    // identical (docs/architecture.md).
    auto close = [&](double a, double b, double scale) {
      const double d = std::abs(a - b) / std::max(1.0, std::abs(scale));
      largest = std::max(largest, d);
      return d <= 1e-5;
    };
    CHECK(close(g["sum"].get<double>(), w["sum"].get<double>(), w["sum"].get<double>()));
    CHECK(close(g["sum_sq"].get<double>(), w["sum_sq"].get<double>(), w["sum_sq"].get<double>()));
    for (size_t i = 0; i < w["samples"].size(); ++i) {
      CHECK(close(g["samples"][i].get<double>(), w["samples"][i].get<double>(), 1.0));
    }
  }
  WARN(files.size() << " checkpoints: largest relative difference from the record " << largest);
}

// Patch measurements in the sensor and per-patch modes.
#include "lfnet/optics/measure.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::PatchGrid;
using lfnet::optics::make_phi;
using lfnet::optics::measure_patches;
using lfnet::optics::PhiSpec;
using lfnet::optics::SimulationMode;

namespace {

std::unique_ptr<lfnet::optics::Phi> phi_of(const std::string& text) {
  auto spec = PhiSpec::parse(text);
  spec.seed = 1;
  return make_phi(spec);
}

}  // namespace

TEST_CASE("simulation modes parse by name", "[optics][measure]") {
  CHECK(lfnet::optics::parse_simulation_mode("sensor") == SimulationMode::kSensor);
  CHECK(lfnet::optics::parse_simulation_mode("per_patch") == SimulationMode::kPerPatch);
  CHECK(lfnet::optics::to_string(SimulationMode::kPerPatch) == "per_patch");
  CHECK_THROWS_WITH(lfnet::optics::parse_simulation_mode("patch"), Catch::Contains("per_patch"));
}

TEST_CASE("per-patch and sensor modes agree for block-aligned patches", "[optics][measure]") {
  torch::manual_seed(8);
  auto lf = torch::rand({2, 5, 5, 36, 45});  // 2 colour channels; 36 x 45 holds whole 9-blocks
  const PatchGrid grid(36, 45, 9, 9, 9);
  for (const auto* text : {"asp:2", "aperture:3", "mask:2", "lenslet:2", "random:2"}) {
    auto phi = phi_of(text);
    auto sensor = measure_patches(*phi, lf, grid, SimulationMode::kSensor);
    auto per_patch = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch);
    INFO(text);
    REQUIRE(sensor.values.sizes() == torch::IntArrayRef({2 * 20, phi->measurements() * 81}));
    lfnet::test::require_close(per_patch.values, sensor.values, 1e-5);
    CHECK(torch::equal(per_patch.phases, sensor.phases));
  }
}

TEST_CASE("measurements are each patch's matrix times the patch", "[optics][measure]") {
  torch::manual_seed(9);
  auto lf = torch::rand({1, 5, 5, 30, 34}, torch::kFloat64);
  const PatchGrid grid(30, 34, 9, 9, 4);  // overlapping, origins off every period
  for (const auto* text : {"mask:2", "lenslet:3", "asp:4", "random:2"}) {
    auto phi = phi_of(text);
    auto stack = lfnet::optics::patch_matrix_stack(*phi, 9, 9, torch::kFloat64);
    CHECK(stack.size(0) == phi->period() * phi->period());
    auto m = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch);
    auto patches = grid.extract(lf).reshape({grid.size(), -1});
    auto want = torch::bmm(stack.index_select(0, m.phases), patches.unsqueeze(2)).squeeze(2);
    INFO(text);
    lfnet::test::require_close(m.values, want, 1e-5);
    // The phase of a patch is its origin modulo the period.
    const int64_t t = phi->period();
    const int64_t last = grid.size() - 1;
    CHECK(m.phases[last].item<int64_t>() == (grid.ys().back() % t) * t + grid.xs().back() % t);
  }
  // The compact per-pixel form of a local model agrees with the dense stack.
  auto mask = phi_of("mask:2");
  auto weights = lfnet::optics::pixel_weight_stack(*mask, 9, 9);
  auto dense = lfnet::optics::patch_matrix_stack(*mask, 9, 9);
  lfnet::test::require_close(dense[40], mask->patch_matrix(4, 4, 9, 9), 0);
  CHECK(weights.sizes() == torch::IntArrayRef({81, 2, 5, 5, 9, 9}));
  lfnet::test::require_close(weights[13], mask->pixel_weights(1, 4, 9, 9), 0);
  auto pinv = lfnet::optics::pinv_matrix_stack(*mask, 9, 9, 1e-3);
  CHECK(pinv.sizes() == torch::IntArrayRef({81, 2025, 162}));
}

TEST_CASE("random projections are crops of a sensor only on the block grid", "[optics][measure]") {
  auto lf = torch::rand({1, 5, 5, 30, 34});
  auto phi = phi_of("random:2");
  const PatchGrid grid(30, 34, 9, 9, 9);  // the last patch is flush with the border
  CHECK_THROWS_WITH(measure_patches(*phi, lf, grid, SimulationMode::kSensor),
                    Catch::Contains("per_patch"));
  auto m = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch);
  CHECK(m.values.size(0) == grid.size());
  CHECK((m.phases == 0).all().item<bool>());
  const PatchGrid small(30, 34, 5, 5, 5);
  CHECK_THROWS_AS(measure_patches(*phi, lf, small, SimulationMode::kSensor), lfnet::ConfigError);
}

TEST_CASE("per-patch noise does not depend on how the grid is split into bands",
          "[optics][measure]") {
  auto lf = torch::rand({3, 5, 5, 40, 40});
  const PatchGrid grid(40, 40, 9, 9, 5);
  auto effects = lfnet::optics::SensorOptions::from_json(
      nlohmann::json::parse(R"({"gaussian": {"sigma": 0.1}, "gain": {"spread": 0.1}})"));
  for (const auto* text : {"asp:2", "random:2"}) {
    auto phi = phi_of(text);
    auto all = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch, effects, 5);
    auto top = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch, effects, 5, 0, 3);
    auto rest =
        measure_patches(*phi, lf, grid, SimulationMode::kPerPatch, effects, 5, 3, grid.rows());
    // Bands are channel-major: interleave them back per channel.
    const int64_t c = 3, p_top = 3 * grid.cols();
    auto joined = torch::cat(
        {top.values.view({c, p_top, -1}), rest.values.view({c, grid.size() - p_top, -1})}, 1);
    INFO(text);
    // Equal up to the rounding of matrix products of another batch size.
    lfnet::test::require_close(joined.reshape({c * grid.size(), -1}), all.values, 1e-6);
    // Noise is drawn per patch, so overlapping patches disagree where they share pixels,
    // unlike crops of one noisy sensor image.
    auto clean = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch);
    CHECK_FALSE(torch::allclose(all.values, clean.values));
  }
  // The gain pattern is the sensor pixel's own: with gain alone, per-patch equals the crop of
  // the sensor image.
  auto gain_only = lfnet::optics::SensorOptions::from_json(
      nlohmann::json::parse(R"({"gain": {"spread": 0.1}})"));
  auto phi = phi_of("mask:2");
  auto a = measure_patches(*phi, lf, grid, SimulationMode::kPerPatch, gain_only, 5);
  auto b = measure_patches(*phi, lf, grid, SimulationMode::kSensor, gain_only, 5);
  lfnet::test::require_close(a.values, b.values, 1e-6);
}

TEST_CASE("sensor images are noiseless forward models plus the named effects",
          "[optics][measure]") {
  auto lf = torch::rand({1, 5, 5, 20, 20});
  auto phi = phi_of("asp:2");
  auto clean = lfnet::optics::simulate_sensor(*phi, lf);
  CHECK(torch::equal(clean, phi->forward(lf)));
  auto effects = lfnet::optics::SensorOptions::from_json(
      nlohmann::json::parse(R"({"gaussian": {"sigma": 0.2}})"));
  auto noisy = lfnet::optics::simulate_sensor(*phi, lf, effects, 3);
  CHECK(torch::equal(noisy, lfnet::optics::simulate_sensor(*phi, lf, effects, 3)));
  CHECK((noisy - clean).std().item<double>() == Approx(0.2).epsilon(0.1));
}

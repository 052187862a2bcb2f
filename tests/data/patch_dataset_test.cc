#include "lfnet/data/patch_dataset.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {
std::vector<LightField> fields() {
  torch::manual_seed(3);
  return {LightField(torch::rand({1, 5, 5, 60, 50})), LightField(torch::rand({3, 5, 5, 70, 70}))};
}
data::DatasetOptions small_options() {
  data::DatasetOptions o;
  o.train_patches = 200;
  o.validation_patches = 64;
  o.seed = 9;
  return o;
}
}  // namespace

TEST_CASE("training and validation patches share no pixel", "[data]") {
  // Mark every pixel with its row; a patch's rows tell where it came from.
  std::vector<LightField> lfs;
  for (int64_t h : {80}) {
    auto rows = torch::arange(h, torch::kFloat32).view({1, 1, 1, h, 1}).expand({1, 5, 5, h, 30});
    lfs.emplace_back(rows.clone() / 100.0);
  }
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  data::PatchDataset ds(lfs, *phi, o, 32);
  ds.start_epoch(0, 50);
  double train_max = 0;
  for (int64_t i = 0; i < ds.train_batches_per_epoch(); ++i) {
    train_max = std::max(train_max, ds.next_train().target.max().item<double>());
  }
  double val_min = 1;
  for (const auto& b : ds.validation()) val_min = std::min(val_min, b.target.min().item<double>());
  // Split row floor(0.85 * 80) = 68: training patches hold rows < 68, validation rows >= 68.
  CHECK(train_max < 0.68);
  CHECK(train_max > 0.6);  // training does reach up to the split
  CHECK(val_min >= 0.68);
}

TEST_CASE("measurements equal the sensor crop at the patch origin", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  auto lf = LightField(torch::rand({1, 5, 5, 70, 40}));
  auto o = small_options();
  o.augment = false;
  data::PatchDataset ds({lf}, *phi, o, 16);
  ds.start_epoch(0, 16);
  auto b = ds.next_train();
  // Find each target in the light field by brute force and compare with the sensor crop.
  auto sensor = optics::simulate_sensor(*phi, lf.data()[0]);
  int checked = 0;
  for (int64_t i = 0; i < 4; ++i) {
    for (int64_t y0 = 0; y0 + 9 <= 70 && checked <= i; ++y0) {
      for (int64_t x0 = 0; x0 + 9 <= 40; ++x0) {
        auto p = lf.data()[0].slice(2, y0, y0 + 9).slice(3, x0, x0 + 9);
        if (torch::equal(p, b.target[i][0])) {
          auto crop = sensor.slice(1, y0, y0 + 9).slice(2, x0, x0 + 9).reshape({-1});
          test::require_close(b.y[i], crop, 1e-5);
          CHECK(b.phase[i].item<int64_t>() == optics::patch_phase(*phi, y0, x0));
          ++checked;
          break;
        }
      }
    }
  }
  CHECK(checked == 4);
}

TEST_CASE("an epoch's batches follow from the seed and epoch alone", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.effects.gaussian = optics::SensorOptions::Gaussian{0.1};
  data::PatchDataset a(fields(), *phi, o), b(fields(), *phi, o);
  a.start_epoch(0, 32);
  a.next_train();
  a.start_epoch(3, 32);
  b.start_epoch(3, 32);
  auto ba = a.next_train(), bb = b.next_train();
  CHECK(torch::equal(ba.y, bb.y));
  CHECK(torch::equal(ba.target, bb.target));
  b.start_epoch(4, 32);
  CHECK_FALSE(torch::equal(b.next_train().target, ba.target));
}

TEST_CASE("augmentation keeps the angular and spatial axes consistent", "[data]") {
  // A light field whose views are shifts of one image: every augmented patch must still be
  // a shifted-view light field (view (u, v) at pixel (y, x) equals view (u+1, v) at (y-1, x)).
  auto base = torch::rand({80, 80});
  auto lf = torch::empty({1, 5, 5, 60, 60});
  for (int64_t u = 0; u < 5; ++u)
    for (int64_t v = 0; v < 5; ++v) lf[0][u][v] = base.slice(0, 10 + u, 70 + u).slice(1, 10 + v, 70 + v);
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  data::PatchDataset ds({LightField(lf)}, *phi, o);
  ds.start_epoch(0, 64);
  auto t = ds.next_train().target.squeeze(1);  // (B, U, V, h, w)
  // Pure translation by (u, v): view (u + 1, v) shifted by one row matches view (u, v), up to
  // a flip of both, so compare magnitudes of the relation in either direction.
  auto a = t.slice(1, 0, 4).slice(3, 1, 9);
  auto fwd = t.slice(1, 1, 5).slice(3, 0, 8);
  auto a2 = t.slice(1, 1, 5).slice(3, 1, 9);
  auto bwd = t.slice(1, 0, 4).slice(3, 0, 8);
  auto ok = ((a - fwd).abs().amax({1, 2, 3, 4}) < 1e-6) | ((a2 - bwd).abs().amax({1, 2, 3, 4}) < 1e-6);
  CHECK(ok.all().item<bool>());
}

TEST_CASE("light fields too small to split are a clear error", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  CHECK_THROWS_AS(data::PatchDataset({LightField(torch::rand({1, 5, 5, 12, 40}))}, *phi, small_options()),
                  ConfigError);
  CHECK_THROWS_AS(data::PatchDataset({LightField(torch::rand({1, 3, 3, 40, 40}))}, *phi, small_options()),
                  ConfigError);
}

#include "lfnet/data/patch_dataset.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <set>
#include <tuple>

#include "lfnet/core/error.h"
#include "lfnet/optics/cfa.h"
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

TEST_CASE("behind a colour filter array patches keep their colours and measure the mosaic",
          "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("mask:2"));  // period 9; with Bayer 18
  torch::manual_seed(5);
  auto lf = LightField(torch::rand({3, 5, 5, 70, 40}));
  auto o = small_options();
  o.augment = false;
  o.cfa = "GRBG";
  data::PatchDataset ds({lf}, *phi, o, 16);
  ds.start_epoch(0, 16);
  auto b = ds.next_train();
  REQUIRE(b.target.sizes() == torch::IntArrayRef({16, 3, 5, 5, 9, 9}));
  // The sensor image of the camera: every colour coded, then each pixel's own colour.
  std::vector<torch::Tensor> colours;
  for (int64_t c = 0; c < 3; ++c) colours.push_back(optics::simulate_sensor(*phi, lf.data()[c]));
  const auto cfa = optics::ColourFilterArray::bayer("GRBG");
  auto sensor = optics::mosaic(torch::stack(colours), cfa)[0];  // (N, H, W)
  std::set<int64_t> phases;
  int checked = 0;
  for (int64_t i = 0; i < 6; ++i) {
    for (int64_t y0 = 0; y0 + 9 <= 70 && checked <= i; ++y0) {
      for (int64_t x0 = 0; x0 + 9 <= 40; ++x0) {
        auto p = lf.data().slice(3, y0, y0 + 9).slice(4, x0, x0 + 9);
        if (torch::equal(p, b.target[i])) {
          auto crop = sensor.slice(1, y0, y0 + 9).slice(2, x0, x0 + 9).reshape({-1});
          test::require_close(b.y[i], crop, 1e-5);
          // The phase runs over 18 x 18: the code's period and the CFA's together.
          CHECK(b.phase[i].item<int64_t>() == (y0 % 18) * 18 + x0 % 18);
          phases.insert(b.phase[i].item<int64_t>());
          ++checked;
          break;
        }
      }
    }
  }
  CHECK(checked == 6);
  CHECK(phases.size() > 1);
  // A grey light field is grey in all three colours.
  data::PatchDataset grey({LightField(torch::rand({1, 5, 5, 80, 40}))}, *phi, o, 16);
  grey.start_epoch(0, 4);
  auto g = grey.next_train();
  REQUIRE(g.target.size(1) == 3);
  CHECK(torch::equal(g.target.select(1, 0), g.target.select(1, 2)));
  // A Phi that is not local has no pixels to put colours on.
  CHECK_THROWS_AS(
      data::PatchDataset({lf}, *optics::make_phi(optics::PhiSpec::parse("random:2")), o, 16),
      ConfigError);
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
    for (int64_t v = 0; v < 5; ++v)
      lf[0][u][v] = base.slice(0, 10 + u, 70 + u).slice(1, 10 + v, 70 + v);
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
  auto ok =
      ((a - fwd).abs().amax({1, 2, 3, 4}) < 1e-6) | ((a2 - bwd).abs().amax({1, 2, 3, 4}) < 1e-6);
  CHECK(ok.all().item<bool>());
}

TEST_CASE("light fields too small to split are a clear error", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  CHECK_THROWS_AS(
      data::PatchDataset({LightField(torch::rand({1, 5, 5, 12, 40}))}, *phi, small_options()),
      ConfigError);
  CHECK_THROWS_AS(
      data::PatchDataset({LightField(torch::rand({1, 3, 3, 40, 40}))}, *phi, small_options()),
      ConfigError);
}

namespace {
// A 9 x 9 light field whose view (u, v) holds the value (9 u + v) / 100 everywhere: a patch's
// views tell which window of the grid it came from.
LightField labelled_grid() {
  auto labels = torch::arange(81, torch::kFloat32).view({1, 9, 9, 1, 1}) / 100.0;
  return LightField(labels.expand({1, 9, 9, 70, 40}).clone());
}

// The window (u0, v0, step) that a (U, V, h, w) patch of labelled_grid() shows, or step 0.
std::tuple<int64_t, int64_t, int64_t> window_of(const torch::Tensor& patch) {
  auto label = [&](int64_t u, int64_t v) {
    return static_cast<int64_t>(std::lround(patch[u][v][0][0].item<double>() * 100.0));
  };
  const int64_t u0 = label(0, 0) / 9, v0 = label(0, 0) % 9;
  const int64_t step = label(0, 1) - label(0, 0);
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) {
      if (label(u, v) != 9 * (u0 + step * u) + v0 + step * v) return {0, 0, 0};
    }
  }
  return {u0, v0, step};
}
}  // namespace

TEST_CASE("training patches come from every angular window and step of a wider grid", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  o.angular_windows = lfnet::data::AngularWindows::kAny;
  o.angular_steps = {1, 2};
  data::PatchDataset ds({labelled_grid()}, *phi, o);
  ds.start_epoch(0, 200);
  const auto t = ds.next_train().target.squeeze(1);
  std::set<std::tuple<int64_t, int64_t, int64_t>> seen;
  for (int64_t i = 0; i < t.size(0); ++i) {
    const auto w = window_of(t[i]);
    REQUIRE(std::get<2>(w) != 0);  // a real window of the grid, views in order
    seen.insert(w);
  }
  // 25 windows at step 1 and one (the whole grid) at step 2; 200 draws see most of them.
  CHECK(seen.count({0, 0, 2}) == 1);
  CHECK(seen.size() >= 20);
  for (const auto& [u0, v0, step] : seen) CHECK(u0 + step * 4 <= 8);
  // Validation keeps the central window at step 1: views 3..7 of 9.
  for (const auto& b : ds.validation()) {
    const auto v = b.target.squeeze(1);
    for (int64_t i = 0; i < v.size(0); ++i) CHECK(window_of(v[i]) == std::make_tuple(2, 2, 1));
  }
  // The default draws the central window only, at step 1.
  auto plain = small_options();
  plain.augment = false;
  data::PatchDataset central({labelled_grid()}, *phi, plain);
  central.start_epoch(0, 64);
  const auto c = central.next_train().target.squeeze(1);
  for (int64_t i = 0; i < c.size(0); ++i) CHECK(window_of(c[i]) == std::make_tuple(2, 2, 1));
  // A step that does not fit a 5 x 5 grid falls back to its only window.
  o.angular_steps = {2};
  data::PatchDataset narrow({LightField(torch::rand({1, 5, 5, 70, 40}))}, *phi, o);
  narrow.start_epoch(0, 16);
  CHECK(narrow.next_train().target.size(0) == 16);
  // Bad options name themselves.
  const nlohmann::json every = {{"angular_windows", "every"}};
  JsonReader bad(every, "$");
  CHECK_THROWS_WITH(data::DatasetOptions::from_json(bad),
                    Catch::Contains("$.angular_windows") && Catch::Contains("central, any"));
  o.angular_windows = lfnet::data::AngularWindows::kAny;
  o.angular_steps = {0};
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("angular_steps"));
}

TEST_CASE("photometric jitter varies patches and their measurements stay consistent", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  o.jitter_gamma = 0.5;
  o.jitter_contrast = 0.3;
  o.jitter_brightness = 0.1;
  const LightField lf(torch::rand({1, 5, 5, 70, 40}) * 0.5 + 0.25);
  data::PatchDataset ds({lf}, *phi, o);
  ds.start_epoch(0, 128);
  const auto b = ds.next_train();
  const auto t = b.target.squeeze(1);
  CHECK(t.min().item<double>() >= 0.0);
  CHECK(t.max().item<double>() <= 1.0);
  // Patch means spread beyond the source's (about 0.5 +- 0.02 for 2025 uniform values).
  const auto means = t.mean({1, 2, 3, 4});
  CHECK((means.max() - means.min()).item<double>() > 0.15);
  // The measurements are those of the jittered patch (ASP is the same at every pixel).
  const auto m = phi->patch_matrix(0, 0, 9, 9);
  lfnet::test::require_close(b.y, t.reshape({t.size(0), -1}).matmul(m.t()), 1e-4, 1e-4);
  // Validation is never jittered: its patches are crops of the light field.
  data::PatchDataset plain({lf}, *phi, small_options());
  lfnet::test::require_close(ds.validation()[0].target, plain.validation()[0].target, 0.0);
  o.jitter_gamma = 2;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("jitter"));
}

TEST_CASE("noise-aware patches carry their sigma and measurements noisy by it", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  o.noise_range = {0.05, 0.2};
  data::PatchDataset noisy(fields(), *phi, o, 64);
  o.noise_range.clear();
  data::PatchDataset clean(fields(), *phi, o, 64);
  // The same draws (sigma draws come after all others), so the difference is the noise alone.
  noisy.start_epoch(0, 200);
  clean.start_epoch(0, 200);
  auto a = noisy.next_train(), b = clean.next_train();
  REQUIRE(a.noise.defined());
  CHECK_FALSE(b.noise.defined());
  REQUIRE(a.noise.sizes() == torch::IntArrayRef({200}));
  CHECK(a.noise.min().item<double>() >= 0.05);
  CHECK(a.noise.max().item<double>() <= 0.2);
  CHECK(a.noise.std().item<double>() > 0.02);  // drawn per patch, not one value
  CHECK(torch::equal(a.target, b.target));
  // Per patch, the measurement error's standard deviation is the patch's sigma.
  auto err = (a.y - b.y).std(1);
  CHECK(torch::allclose(err, a.noise, 0.0, 0.03));
  REQUIRE(noisy.validation().front().noise.defined());
  o.noise_range = {0.2, 0.1};
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("noise_range"));
}

TEST_CASE("shot and read noise patches carry their equivalent sigma", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  auto batch = [&](std::vector<double> range, double fraction) {
    o.noise_range = std::move(range);
    o.shot_read_fraction = fraction;
    o.shot_photons_range = {20, 200};
    o.read_electrons_range = {2, 5};
    o.train_patches = 400;
    data::PatchDataset ds(fields(), *phi, o, 64);
    ds.start_epoch(0, 400);
    return ds.next_train();
  };
  const auto clean = batch({}, 0), gaussian = batch({0.05, 0.2}, 0);
  const auto all = batch({0.05, 0.2}, 1), mixed = batch({0.05, 0.2}, 0.5);
  REQUIRE(torch::equal(all.target, clean.target));
  // Every patch's sigma is the noise of photons_at_white in [20, 200] with read noise of 2 to
  // 5 electrons at the patch's mean signal, and its measurement errors have that variance on
  // average (their signal-dependent variances average to the mean signal's).
  const auto mean = clean.y.mean(1);
  const auto lo = (mean / 200 + std::pow(2.0 / 200, 2)).sqrt();
  const auto hi = (mean / 20 + std::pow(5.0 / 20, 2)).sqrt();
  CHECK((all.noise >= lo - 1e-6).all().item<bool>());
  CHECK((all.noise <= hi + 1e-6).all().item<bool>());
  CHECK(all.noise.std().item<double>() > 0.01);  // drawn per patch
  const auto err = all.y - clean.y;
  const auto ratio = err.square().mean(1) / all.noise.square();
  CHECK(ratio.mean().item<double>() == Approx(1.0).epsilon(0.05));
  // Brighter measurements are noisier: shot noise, not a patch-wide sigma.
  const auto bright = clean.y > clean.y.median();
  const double bright_var = err.square().masked_select(bright).mean().item<double>();
  const double dark_var = err.square().masked_select(~bright).mean().item<double>();
  CHECK(bright_var > 1.1 * dark_var);
  // Mixed: a patch is either the Gaussian one or the shot-and-read one, about half each.
  const auto same = mixed.noise == gaussian.noise;
  const double share = same.to(torch::kFloat64).mean().item<double>();
  CHECK(share > 0.35);
  CHECK(share < 0.65);
  CHECK(torch::equal(mixed.noise.masked_select(~same), all.noise.masked_select(~same)));
  const auto rows = (~same).nonzero().squeeze(1);
  CHECK(torch::equal(mixed.y.index_select(0, rows), all.y.index_select(0, rows)));
  const auto kept = same.nonzero().squeeze(1);
  CHECK(torch::equal(mixed.y.index_select(0, kept), gaussian.y.index_select(0, kept)));
  o.noise_range.clear();
  o.shot_read_fraction = 0.5;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("needs a noise_range"));
  o.noise_range = {0, 0.1};
  o.shot_photons_range = {0, 10};
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("shot_photons_range"));
}

TEST_CASE("a clean fraction measures that share of noise-aware patches without noise", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  o.train_patches = 400;
  o.noise_range = {0.05, 0.2};
  auto batch = [&](double clean_fraction) {
    o.clean_fraction = clean_fraction;
    data::PatchDataset ds(fields(), *phi, o, 64);
    ds.start_epoch(0, 400);
    return ds.next_train();
  };
  const auto noisy = batch(0), mixed = batch(0.4);
  o.noise_range.clear();
  const auto clean = batch(0);
  REQUIRE(torch::equal(mixed.target, clean.target));
  const auto zero = mixed.noise == 0;
  const double share = zero.to(torch::kFloat64).mean().item<double>();
  CHECK(share > 0.3);
  CHECK(share < 0.5);
  // A clean patch's measurements are the noiseless ones; the others keep their noise.
  const auto rows = zero.nonzero().squeeze(1), kept = (~zero).nonzero().squeeze(1);
  CHECK(torch::equal(mixed.y.index_select(0, rows), clean.y.index_select(0, rows)));
  CHECK(torch::equal(mixed.y.index_select(0, kept), noisy.y.index_select(0, kept)));
  CHECK(torch::equal(mixed.noise.index_select(0, kept), noisy.noise.index_select(0, kept)));
  o.clean_fraction = 0.5;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("needs a noise_range"));
  o.noise_range = {0, 0.1};
  o.clean_fraction = 1.5;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("clean_fraction"));
}

TEST_CASE("calibration ranges give every patch its own camera", "[data]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.augment = false;
  auto batch = [&](const optics::CalibrationRanges& ranges) {
    o.calibration = ranges;
    data::PatchDataset ds(fields(), *phi, o, 64);
    ds.start_epoch(0, 200);
    return ds.next_train();
  };
  const auto nominal = batch({});
  optics::CalibrationRanges depth;
  depth.depth = 0.2;
  const auto perturbed = batch(depth);
  REQUIRE(torch::equal(perturbed.target, nominal.target));  // the same patches
  // Each patch's measurements are those of an ASP whose depth is off by at most 20 %: the
  // error grows with its modulation (measurements minus their channels' mean), by one factor
  // per patch that differs between patches.
  const auto b = nominal.y.size(0);
  const auto y0 = nominal.y.view({b, 2, -1}), y1 = perturbed.y.view({b, 2, -1});
  const auto mod0 = y0 - y0.mean(1, true), mod1 = y1 - y1.mean(1, true);
  CHECK(torch::allclose(y1.mean(1), y0.mean(1), 1e-4, 1e-5));  // the channels' sum is kept
  const auto factor = (mod1 * mod0).sum({1, 2}) / mod0.square().sum({1, 2});
  CHECK(factor.min().item<double>() >= 0.8 - 1e-4);
  CHECK(factor.max().item<double>() <= 1.2 + 1e-4);
  CHECK(factor.std().item<double>() > 0.05);
  CHECK(torch::allclose(mod1, mod0 * factor.view({b, 1, 1}), 1e-4, 1e-5));
  // Validation patches are measured by perturbed cameras too.
  o.calibration = depth;
  data::PatchDataset ds(fields(), *phi, o, 64);
  o.calibration = {};
  data::PatchDataset plain(fields(), *phi, o, 64);
  CHECK_FALSE(torch::allclose(ds.validation()[0].y, plain.validation()[0].y, 1e-4, 1e-5));
  // Only local codes can be perturbed pixel by pixel.
  auto random = optics::make_phi(optics::PhiSpec::parse("random:2"));
  o.calibration = depth;
  o.patch_h = o.patch_w = 9;
  CHECK_THROWS_WITH(data::PatchDataset(fields(), *random, o, 64), Catch::Contains("local Phi"));
  o.calibration.depth = 1.5;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("depth"));
}

TEST_CASE("noise in the views is in the truth and the measurements, on training patches only",
          "[data]") {
  // A constant light field: any spread in a target is the views' own noise.
  const LightField flat(torch::full({1, 5, 5, 60, 60}, 0.5f));
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.view_noise_range = {0.05, 0.05};
  o.view_noise_fraction = 0.5;
  data::PatchDataset ds({flat}, *phi, o, 32);
  ds.start_epoch(0, 200);
  const auto b = ds.next_train();
  const auto spread = b.target.flatten(1).std(1);  // per patch
  const auto noisy = spread > 0.01;
  const double share = noisy.to(torch::kFloat32).mean().item<double>();
  CHECK(share > 0.35);
  CHECK(share < 0.65);
  // The noisy patches' spread is the sigma asked for; the others' is none.
  CHECK(spread.masked_select(noisy).mean().item<double>() == Approx(0.05).epsilon(0.1));
  CHECK(spread.masked_select(~noisy).max().item<double>() < 1e-6);
  // The measurements are of the noisy views: a flat field's two ASP measurements vary only
  // where the views do.
  CHECK(b.y.flatten(1).std(1).masked_select(~noisy).max().item<double>() < 1e-5);
  CHECK(b.y.flatten(1).std(1).masked_select(noisy).min().item<double>() > 1e-3);
  for (const auto& v : ds.validation()) CHECK(v.target.std().item<double>() < 1e-6);
  // An epoch's noise follows from the seed.
  data::PatchDataset again({flat}, *phi, o, 32);
  again.start_epoch(0, 200);
  CHECK(torch::equal(again.next_train().target, b.target));
}

TEST_CASE("dim exposures scale a share of the training crops by a gain in the range", "[data]") {
  const LightField flat(torch::full({1, 5, 5, 60, 60}, 0.5f));
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.dark_fraction = 0.5;
  o.dark_gain_range = {0.2, 0.6};
  data::PatchDataset ds({flat}, *phi, o, 32);
  ds.start_epoch(0, 200);
  const auto b = ds.next_train();
  const auto level = b.target.flatten(1).mean(1);  // per patch
  const auto dark = level < 0.49;
  const double share = dark.to(torch::kFloat32).mean().item<double>();
  CHECK(share > 0.35);
  CHECK(share < 0.65);
  CHECK(level.min().item<double>() >= 0.5 * 0.2 - 1e-6);
  CHECK(level.masked_select(dark).max().item<double>() <= 0.5 * 0.6 + 1e-6);
  CHECK(level.masked_select(~dark).min().item<double>() == Approx(0.5));
  // The measurements are of the dimmed views: measurement over level is the same for all.
  const auto ratio = b.y.flatten(1).mean(1) / level;
  CHECK(torch::allclose(ratio, ratio.mean().expand_as(ratio), 1e-4, 1e-6));
  for (const auto& v : ds.validation()) CHECK(v.target.mean().item<double>() == Approx(0.5));
  // The crops are those a config without the option draws, each scaled by its own gain.
  torch::manual_seed(3);
  const LightField textured(torch::rand({1, 5, 5, 60, 60}) * 0.5 + 0.25);
  data::PatchDataset dimmed({textured}, *phi, o, 32), plain({textured}, *phi, small_options(), 32);
  dimmed.start_epoch(0, 64);
  plain.start_epoch(0, 64);
  const auto d = dimmed.next_train().target.flatten(1), p = plain.next_train().target.flatten(1);
  const auto gain = d.sum(1) / p.sum(1);
  CHECK(torch::allclose(d, p * gain.unsqueeze(1), 1e-4, 1e-6));
  CHECK(gain.min().item<double>() < 0.6);
  o.dark_gain_range = {0.0, 0.5};
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("dark_gain_range"));
  o.dark_gain_range = {0.5, 0.2};
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("dark_gain_range"));
}

TEST_CASE("chroma jitter scales and reorders a colour crop's colours about its grey", "[data]") {
  // A flat colour: every crop's target is this colour, jittered.
  const auto colour = torch::tensor({0.6f, 0.45f, 0.3f}).view({3, 1, 1, 1, 1});
  const LightField flat(colour.expand({3, 5, 5, 60, 60}).contiguous());
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.cfa = "RGGB";
  o.jitter_saturation = 0.5;
  data::PatchDataset ds({flat}, *phi, o, 32);
  ds.start_epoch(0, 200);
  const auto t = ds.next_train().target;                           // (B, 3, U, V, h, w)
  const auto rgb = t.flatten(2).mean(2);                           // (B, 3)
  const auto grey = rgb.mean(1);                                   // unchanged: 0.45
  const auto scale = (rgb.select(1, 0) - rgb.select(1, 2)) / 0.3;  // R - B over the original
  CHECK(torch::allclose(grey, torch::full_like(grey, 0.45), 1e-5, 1e-6));
  CHECK(scale.min().item<double>() >= std::exp(-0.5) - 1e-4);
  CHECK(scale.max().item<double>() <= std::exp(0.5) + 1e-4);
  CHECK(scale.min().item<double>() < 0.8);
  CHECK(scale.max().item<double>() > 1.3);
  CHECK(torch::allclose(rgb.select(1, 1), grey, 1e-5, 1e-6));  // G sat at the grey
  for (const auto& v : ds.validation()) {
    CHECK(torch::allclose(v.target.flatten(2).mean(2)[0], colour.flatten(), 1e-5, 1e-6));
  }
  // Reordered channels: every one of the six orders, each crop a permutation of the colour.
  o.jitter_saturation = 0;
  o.permute_channels = true;
  data::PatchDataset permuted({flat}, *phi, o, 32);
  permuted.start_epoch(0, 200);
  const auto p = permuted.next_train().target.flatten(2).mean(2);  // (B, 3)
  std::set<std::tuple<int, int, int>> orders;
  for (int64_t i = 0; i < p.size(0); ++i) {
    const auto sorted = std::get<0>(p[i].sort());
    CHECK(torch::allclose(sorted, torch::tensor({0.3f, 0.45f, 0.6f}), 1e-5, 1e-6));
    auto rank = [&](int c) { return static_cast<int>(std::lround(p[i][c].item<double>() * 20)); };
    orders.insert({rank(0), rank(1), rank(2)});
  }
  CHECK(orders.size() == 6);
  // The crops are those a config without the options draws: their grey is the same.
  torch::manual_seed(5);
  const LightField textured(torch::rand({3, 5, 5, 60, 60}) * 0.5 + 0.25);
  o.jitter_saturation = 0.5;
  auto plain_options = small_options();
  plain_options.cfa = "RGGB";
  data::PatchDataset jittered({textured}, *phi, o, 32), plain({textured}, *phi, plain_options, 32);
  jittered.start_epoch(0, 64);
  plain.start_epoch(0, 64);
  const auto a = jittered.next_train().target, b = plain.next_train().target;
  CHECK(!torch::allclose(a, b));
  // Clipping can move a pixel's grey, so compare where nothing clipped: most pixels.
  const auto same = (a.mean(1) - b.mean(1)).abs() < 1e-5;
  CHECK(same.to(torch::kFloat32).mean().item<double>() > 0.9);
  o.jitter_saturation = 2.5;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("jitter_saturation"));
}

TEST_CASE("correlated view noise is shared by neighbouring views and by the colours", "[data]") {
  const LightField flat(torch::full({3, 5, 5, 200, 60}, 0.5f));
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.cfa = "RGGB";
  o.augment = false;
  o.patch_h = o.patch_w = 24;  // enough pixels that chance correlations stay small
  o.view_noise_range = {0.05, 0.05};
  auto correlation = [](const torch::Tensor& a, const torch::Tensor& b) {
    const auto x = a.flatten() - a.mean(), y = b.flatten() - b.mean();
    return ((x * y).sum() / (x.norm() * y.norm())).item<double>();
  };
  for (double fraction : {0.0, 1.0}) {
    o.view_noise_correlated_fraction = fraction;
    data::PatchDataset ds({flat}, *phi, o, 32);
    ds.start_epoch(0, 8);
    const auto t = ds.next_train().target[0];  // (3, 5, 5, h, w)
    const double views = correlation(t[1][2][2], t[1][2][3]);
    const double colours = correlation(t[0][2][2], t[1][2][2]);
    INFO("correlated fraction " << fraction << ": views " << views << ", colours " << colours);
    if (fraction == 0) {
      CHECK(std::abs(views) < 0.1);
      CHECK(std::abs(colours) < 0.1);
    } else {
      CHECK(views > 0.3);
      CHECK(torch::equal(t[0], t[1]));  // the same noise in every colour
    }
  }
}

TEST_CASE("downscales add each light field at a finer scale", "[data]") {
  // Rows marked by their index: a downscaled copy's rows are the means of row pairs.
  auto rows =
      torch::arange(120, torch::kFloat32).view({1, 1, 1, 120, 1}).expand({1, 5, 5, 120, 40});
  const LightField lf(rows.clone() / 200.0);
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto o = small_options();
  o.patch_h = o.patch_w = 9;
  data::PatchDataset one({lf}, *phi, o, 32);
  CHECK(one.light_fields() == 1);
  o.downscales = {1, 2, 8};  // 8 leaves 15 x 5 pixels, too few for 9 x 9 patches: skipped
  data::PatchDataset two({lf}, *phi, o, 32);
  CHECK(two.light_fields() == 2);
  o.downscales = {};
  CHECK_THROWS_AS(data::PatchDataset({lf}, *phi, o, 32), ConfigError);
}

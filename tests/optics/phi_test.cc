// The measurement models: adjoints, patch matrices, normalisation, the ASP table, specs.
#include "lfnet/optics/phi.h"

#include <catch2/catch.hpp>

#include <algorithm>

#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/optics/asp.h"
#include "support/test_support.h"

using lfnet::optics::make_phi;
using lfnet::optics::PhiSpec;

namespace {

PhiSpec spec_of(const std::string& name, int64_t n, int64_t rows = 5, int64_t cols = 5) {
  PhiSpec s;
  s.name = name;
  s.n = n;
  s.rows = rows;
  s.cols = cols;
  s.seed = 7;
  if (name == "calibrated") {
    // A measured response has no generator: give it one, period 2, from a seeded draw.
    auto gen = torch::make_generator<at::CPUGeneratorImpl>(7);
    auto w = torch::rand({n * rows * cols * 4}, gen, torch::kFloat64);
    s.params = {
        {"period", 2},
        {"weights", std::vector<double>(w.data_ptr<double>(), w.data_ptr<double>() + w.numel())}};
  }
  return s;
}

// Every registered model: a new Phi is tested by registering it.
const std::vector<std::string> kModels = lfnet::optics::phi_names();

// |<A x, y> - <x, A^T y>| relative to ||A x|| ||y||.
double adjoint_error(const lfnet::optics::Phi& phi, torch::ScalarType dtype, int64_t h, int64_t w) {
  auto opts = torch::TensorOptions().dtype(dtype);
  torch::manual_seed(3);
  auto x = torch::rand({2, phi.rows(), phi.cols(), h, w}, opts);
  auto y = torch::rand({2, phi.measurements(), h, w}, opts);
  auto ax = phi.forward(x);
  auto aty = phi.adjoint(y);
  REQUIRE(ax.sizes() == y.sizes());
  REQUIRE(aty.sizes() == x.sizes());
  REQUIRE(ax.scalar_type() == dtype);
  const double lhs = (ax * y).sum().item<double>();
  const double rhs = (x * aty).sum().item<double>();
  return std::abs(lhs - rhs) / (ax.norm().item<double>() * y.norm().item<double>());
}

}  // namespace

TEST_CASE("the registry holds the built-in models", "[optics][phi]") {
  for (const char* name : {"asp", "mask", "aperture", "random", "lenslet", "calibrated"}) {
    CHECK(std::find(kModels.begin(), kModels.end(), name) != kModels.end());
  }
}

TEST_CASE("every model's adjoint is exact in float32 and float64", "[optics][phi]") {
  for (const auto& name : kModels) {
    for (int64_t n : {1, 2, 15, 25}) {
      auto phi = make_phi(spec_of(name, n));
      INFO(name << ":" << n);
      // 23 x 31 is a multiple of no period or block: the borders are exercised.
      CHECK(adjoint_error(*phi, torch::kFloat32, 23, 31) < 1e-5);
      CHECK(adjoint_error(*phi, torch::kFloat64, 23, 31) < 1e-12);
    }
  }
}

TEST_CASE("an image too wide for one band is coded band by band like its rows alone",
          "[optics][phi]") {
  // 2 x 25 views x 8192 columns is 409,600 values a row: a local Phi's forward and adjoint then
  // work on bands of about 20 rows, so 64 rows cross three band edges. Rows from 16 (or the phase-0
  // row before it) coded alone (one band: no banding) must equal the same rows of the whole image.
  for (const char* name : {"asp", "mask", "calibrated"}) {
    auto phi = make_phi(spec_of(name, 2));
    INFO(name);
    torch::manual_seed(5);
    auto x = torch::rand({2, 5, 5, 64, 8192});
    auto y = phi->forward(x);
    REQUIRE(y.sizes() == torch::IntArrayRef({2, 2, 64, 8192}));
    const int64_t a = 16 / phi->period() * phi->period();  // a row of phase 0
    CHECK(torch::allclose(y.narrow(2, a, 32), phi->forward(x.narrow(3, a, 32)), 1e-6, 1e-6));
    CHECK(torch::allclose(y.narrow(2, 0, 8), phi->forward(x.narrow(3, 0, 8)), 1e-6, 1e-6));
    auto back = phi->adjoint(y);
    REQUIRE(back.sizes() == x.sizes());
    CHECK(torch::allclose(back.narrow(3, a, 32), phi->adjoint(y.narrow(2, a, 32)), 1e-6, 1e-6));
    CHECK(torch::allclose(back.narrow(3, 0, 8), phi->adjoint(y.narrow(2, 0, 8)), 1e-6, 1e-6));
  }
}

TEST_CASE("models work on other angular sizes", "[optics][phi]") {
  for (const auto& name : kModels) {
    for (auto [u, v] : {std::pair<int64_t, int64_t>{3, 3}, {4, 6}, {1, 1}, {7, 7}}) {
      const int64_t n = std::min<int64_t>(u * v, 3);
      auto phi = make_phi(spec_of(name, n, u, v));
      INFO(name << " on " << u << "x" << v);
      CHECK(adjoint_error(*phi, torch::kFloat64, 20, 21) < 1e-12);
      auto full = make_phi(spec_of(name, u * v, u, v));
      CHECK(adjoint_error(*full, torch::kFloat64, 11, 13) < 1e-12);
    }
  }
}

TEST_CASE("patch matrices equal the forward model on crops at any origin", "[optics][phi]") {
  torch::manual_seed(5);
  auto lf = torch::rand({5, 5, 40, 44}, torch::kFloat64);
  for (const auto& name : kModels) {
    for (int64_t n : {2, 25}) {
      auto phi = make_phi(spec_of(name, n));
      auto sensor = phi->forward(lf);
      INFO(name << ":" << n);
      std::vector<std::pair<int64_t, int64_t>> origins = {{0, 0}, {3, 7}, {13, 22}, {29, 31}};
      for (int i = 0; i < 4; ++i) {  // and random ones
        origins.emplace_back(torch::randint(0, 40 - 9 + 1, {1}).item<int64_t>(),
                             torch::randint(0, 44 - 9 + 1, {1}).item<int64_t>());
      }
      int64_t h = 9, w = 9;
      if (name == "random") origins = {{0, 0}, {9, 18}, {27, 27}};
      for (auto [y0, x0] : origins) {
        if (name == "random" && y0 == 9) w = 18;  // two blocks side by side
        auto a = phi->patch_matrix(y0, x0, h, w, torch::kFloat64);
        REQUIRE(a.sizes() == torch::IntArrayRef({n * h * w, 25 * h * w}));
        auto patch = lf.slice(2, y0, y0 + h).slice(3, x0, x0 + w).reshape({-1});
        auto want = sensor.slice(1, y0, y0 + h).slice(2, x0, x0 + w).reshape({-1});
        INFO("origin " << y0 << ", " << x0);
        lfnet::test::require_close(torch::matmul(a, patch), want, 1e-12);
        w = 9;
      }
    }
  }
}

TEST_CASE("random projections have patch matrices only on the block grid", "[optics][phi]") {
  auto phi = make_phi(spec_of("random", 2));
  CHECK(phi->patch_consistent(9, 18));
  CHECK_FALSE(phi->patch_consistent(4, 0));
  CHECK_FALSE(phi->local());
  CHECK(phi->block() == 9);
  CHECK_THROWS_AS(phi->patch_matrix(4, 0, 9, 9), lfnet::ConfigError);
  CHECK_THROWS_AS(phi->patch_matrix(0, 0, 11, 11), lfnet::ConfigError);
  CHECK_THROWS_AS(phi->pixel_weights(0, 0, 9, 9), lfnet::ConfigError);
  // Mask and lenslet depend on the origin modulo their period, asp does not.
  CHECK(make_phi(spec_of("mask", 2))->period() == 9);
  CHECK(make_phi(spec_of("lenslet", 2))->period() == 5);
  CHECK(make_phi(spec_of("asp", 2))->period() == 1);
  auto mask = make_phi(spec_of("mask", 2));
  lfnet::test::require_close(mask->patch_matrix(3, 4, 9, 9), mask->patch_matrix(21, 13, 9, 9), 0);
  CHECK_FALSE(torch::equal(mask->patch_matrix(3, 4, 9, 9), mask->patch_matrix(4, 4, 9, 9)));
}

TEST_CASE("every non-negative Phi measures 1 on average for a white light field", "[optics][phi]") {
  for (const auto& name : {"asp", "mask", "aperture", "lenslet"}) {
    for (int64_t n : {1, 2, 15, 25}) {
      auto phi = make_phi(spec_of(name, n));
      // 45 x 90 holds whole mask (9) and lenslet (5) periods.
      auto y = phi->forward(torch::ones({5, 5, 45, 90}, torch::kFloat64));
      INFO(name << ":" << n);
      CHECK(y.mean().item<double>() == Approx(1.0).epsilon(1e-12));
      CHECK(y.min().item<double>() >= 0);
    }
  }
}

TEST_CASE("random rows have the mean norm of the asp rows at the same N", "[optics][phi]") {
  for (int64_t n : {1, 2, 25}) {
    auto asp = make_phi(spec_of("asp", n))->pixel_weights(0, 0, 1, 1, torch::kFloat64);
    const double want = asp.reshape({n, -1}).norm(2, {1}).mean().item<double>();
    for (const char* dist : {"gaussian", "bernoulli"}) {
      auto spec = spec_of("random", n);
      spec.params = {{"distribution", dist}};
      auto a = make_phi(spec)->patch_matrix(0, 0, 9, 9, torch::kFloat64);
      CHECK(a.norm(2, {1}).mean().item<double>() == Approx(want).epsilon(1e-12));
      if (std::string(dist) == "bernoulli") {
        auto mags = a.abs();
        CHECK((mags.max() - mags.min()).item<double>() < 1e-15);
      } else {
        // Zero-mean, Gaussian-looking entries: kurtosis near 3.
        auto z = (a - a.mean()) / a.std();
        CHECK(std::abs(a.mean().item<double>()) < 0.01 * a.std().item<double>());
        CHECK(z.pow(4).mean().item<double>() == Approx(3.0).epsilon(0.05));
      }
    }
  }
}

TEST_CASE("the ASP table: a complementary pair first, then a full Fourier basis", "[optics][asp]") {
  const double pi = 3.141592653589793;
  auto table = lfnet::optics::asp_table(5, 5, 25);
  REQUIRE(table.size() == 25);
  CHECK(table[0].alpha == 0);
  CHECK(table[1].alpha == Approx(pi));
  CHECK(table[0].gamma == 0);
  CHECK(table[0].beta == Approx(0.8 * pi));
  // Principal orientations at frequency 1 come before the rest: 0, 45, 90, 135 degrees.
  CHECK(table[2].gamma == Approx(pi / 4));
  CHECK(table[3].gamma == Approx(pi / 2));
  CHECK(table[4].gamma == Approx(3 * pi / 4));
  CHECK(table[5].alpha == Approx(pi / 2));  // quadrature
  // Every non-constant DFT frequency of the 5 x 5 grid appears in phase and in quadrature.
  std::set<std::tuple<int64_t, int64_t, bool>> seen;
  for (size_t i = 1; i < table.size(); ++i) {
    seen.insert({table[i].k_theta, table[i].k_phi, table[i].alpha > 1 && table[i].alpha < 2});
  }
  CHECK(seen.size() == 24);

  // A complementary pair sums to a conventional pixel A(u, v): constant with the full
  // aperture, the disk's soft edge with a disk aperture.
  for (const char* aperture : {"full", "disk"}) {
    auto spec = spec_of("asp", 2);
    spec.params = {{"aperture", aperture}, {"depth", 0.7}};
    auto m = make_phi(spec)->pixel_weights(0, 0, 1, 1, torch::kFloat64).view({2, 5, 5});
    auto pixel = m[0] + m[1];
    auto a = torch::ones({5, 5}, torch::kFloat64);
    if (std::string(aperture) == "disk") {
      for (int u = 0; u < 5; ++u) {
        for (int v = 0; v < 5; ++v) {
          const double r = std::hypot(-1 + 0.5 * u, -1 + 0.5 * v);
          a[u][v] = std::clamp((1.2 - r) / 0.2 + 0.5, 0.0, 1.0);
        }
      }
    }
    lfnet::test::require_close(pixel / pixel.max(), a, 1e-12);
    CHECK((m[0] - m[1]).abs().max().item<double>() > 0.1 * pixel.max().item<double>());
  }
  // In the "pairs" layout every pair sums to the same conventional pixel.
  auto spec = spec_of("asp", 8);
  spec.params = {{"layout", "pairs"}};
  auto m = make_phi(spec)->pixel_weights(0, 0, 1, 1, torch::kFloat64).view({4, 2, 25});
  auto sums = m.sum(1);
  lfnet::test::require_close(sums, sums[0][0].expand_as(sums), 1e-12);
}

TEST_CASE("ASP weights follow the documented formula", "[optics][asp]") {
  auto spec = spec_of("asp", 15);
  spec.params = {{"depth", 0.8}};
  auto w = make_phi(spec)->pixel_weights(2, 3, 1, 1, torch::kFloat64).view({15, 5, 5});
  auto table = lfnet::optics::asp_table(5, 5, 15, false, 0.0, 90.0);  // the default pair
  auto want = torch::empty({15, 5, 5}, torch::kFloat64);
  for (int n = 0; n < 15; ++n) {
    for (int u = 0; u < 5; ++u) {
      for (int v = 0; v < 5; ++v) {
        const double theta = -1 + 0.5 * u, phi = -1 + 0.5 * v;
        const auto& r = table[static_cast<size_t>(n)];
        want[n][u][v] =
            (1 + 0.8 * std::cos(r.beta * (std::cos(r.gamma) * theta + std::sin(r.gamma) * phi) +
                                r.alpha)) /
            2;
      }
    }
  }
  want /= want.sum({1, 2}).mean();
  lfnet::test::require_close(w, want, 1e-12);
}

TEST_CASE("ASP conditioning: full rank at every N, well conditioned at N = 25", "[optics][asp]") {
  // Reference values from an independent numpy construction of the same rows on the 5 x 5
  // grid's DFT frequencies: every AC direction has the same singular value; the spread comes
  // from the DC term that every non-negative ASP row shares.
  const std::map<int64_t, double> want = {{2, 1.414214}, {15, 15.43521}, {25, 25.46072}};
  for (auto [n, kappa] : want) {
    auto c = lfnet::optics::conditioning(*make_phi(spec_of("asp", n)));
    CHECK(c.piece == "pixel");
    CHECK(c.singular_values.size(0) == 1);
    CHECK(c.rank[0].item<int64_t>() == n);
    CHECK(c.condition[0].item<double>() == Approx(kappa).epsilon(1e-5));
  }
  // The hardware-like pairs layout loses rank: after the first pair (DC and one frequency),
  // each pair adds one new direction: 25 rows span 2 + 12 = 14.
  auto spec = spec_of("asp", 25);
  spec.params = {{"layout", "pairs"}};
  CHECK(lfnet::optics::conditioning(*make_phi(spec)).rank[0].item<int64_t>() == 14);
}

TEST_CASE("mask codes are shifted 50% open tiles", "[optics][mask]") {
  auto spec = spec_of("mask", 3);
  spec.params = {{"period", 9}, {"shift", 2}};
  auto phi = make_phi(spec);
  auto w = phi->pixel_weights(0, 0, 9, 9, torch::kFloat64);  // (N, U, V, T, T)
  auto centre = w.select(1, 2).select(1, 2);                 // (N, T, T): the tile itself
  for (int64_t n = 0; n < 3; ++n) {
    auto tile = centre[n];
    const double open_value = tile.max().item<double>();
    CHECK(((tile == open_value).sum().item<int64_t>()) == 41);  // round(0.5 * 81)
    CHECK(((tile == 0).sum().item<int64_t>()) == 40);
    for (int64_t u = 0; u < 5; ++u) {
      for (int64_t v = 0; v < 5; ++v) {
        // c_n((x + s (v - vc)) mod T, (y + s (u - uc)) mod T): a rolled copy of the tile.
        auto want = torch::roll(tile, {-2 * (u - 2), -2 * (v - 2)}, {0, 1});
        lfnet::test::require_close(w[n][u][v], want, 0);
      }
    }
  }
  // Exposures use independent codes; the seed changes them.
  CHECK_FALSE(torch::equal(centre[0], centre[1]));
  auto other = spec;
  other.seed = 8;
  CHECK_FALSE(
      torch::equal(make_phi(other)->pixel_weights(0, 0, 9, 9), phi->pixel_weights(0, 0, 9, 9)));
}

TEST_CASE("lenslets record one view per pixel of a super-pixel", "[optics][lenslet]") {
  torch::manual_seed(2);
  auto lf = torch::rand({5, 5, 10, 15});
  auto y = make_phi(spec_of("lenslet", 2))->forward(lf);
  for (int64_t yy = 0; yy < 10; ++yy) {
    for (int64_t x = 0; x < 15; ++x) {
      const int64_t k0 = (yy % 5) * 5 + (x % 5), k1 = (k0 + 1) % 25;
      CHECK(y[0][yy][x].item<float>() == lf[k0 / 5][k0 % 5][yy][x].item<float>());
      CHECK(y[1][yy][x].item<float>() == lf[k1 / 5][k1 % 5][yy][x].item<float>());
    }
  }
}

TEST_CASE("the Tikhonov pseudo-inverse", "[optics][pinv]") {
  // lambda -> 0 with N = U V on a full-rank model recovers a patch exactly.
  torch::manual_seed(4);
  auto patch = torch::rand({int64_t{25} * 9 * 9}, torch::kFloat64);
  for (const auto& name : {"asp", "aperture", "lenslet"}) {
    auto phi = make_phi(spec_of(name, 25));
    auto a = phi->patch_matrix(3, 5, 9, 9, torch::kFloat64);
    auto p = phi->pinv_matrix(3, 5, 9, 9, 0.0, torch::kFloat64);
    INFO(name);
    lfnet::test::require_close(torch::matmul(p, torch::matmul(a, patch)), patch, 1e-9);
  }
  // With lambda > 0 it is (A^T A + lambda I)^-1 A^T, for local and dense models alike.
  for (const auto& name : {"mask", "random"}) {
    auto phi = make_phi(spec_of(name, 2));
    auto a = phi->patch_matrix(0, 0, 9, 9, torch::kFloat64);
    auto normal = torch::matmul(a.t(), a) + 0.01 * torch::eye(a.size(1), torch::kFloat64);
    auto want = torch::linalg::solve(normal, a.t(), true);
    INFO(name);
    lfnet::test::require_close(phi->pinv_matrix(0, 0, 9, 9, 0.01, torch::kFloat64), want, 1e-9);
  }
  CHECK_THROWS(make_phi(spec_of("asp", 2))->pinv_matrix(0, 0, 9, 9, -1.0));
}

TEST_CASE("Phi specs round-trip through JSON and resolve their parameters", "[optics][spec]") {
  for (const auto& name : kModels) {
    auto phi = make_phi(spec_of(name, 3));
    const auto j = phi->spec().to_json();
    CHECK(j.at("params").is_object());
    CHECK((name == "lenslet" || !j.at("params").empty()));
    auto again = PhiSpec::from_json(nlohmann::json::parse(j.dump()));
    CHECK(again == phi->spec());
    auto rebuilt = make_phi(again);
    CHECK(rebuilt->spec() == phi->spec());
    lfnet::test::require_close(rebuilt->patch_matrix(0, 0, 9, 9), phi->patch_matrix(0, 0, 9, 9), 0);
  }
  auto p = PhiSpec::parse("mask:15");
  CHECK(p.name == "mask");
  CHECK(p.n == 15);
  CHECK(PhiSpec::parse("asp").n == 2);
  CHECK(PhiSpec::parse("asp:2").label() == "asp:2");
  CHECK_THROWS_AS(PhiSpec::parse("asp:two"), lfnet::ConfigError);
  CHECK_THROWS_AS(PhiSpec::parse("asp:0"), lfnet::ConfigError);
}

TEST_CASE("bad Phi specs are ConfigErrors that say what is wrong", "[optics][spec]") {
  CHECK_THROWS_WITH(make_phi(spec_of("ASP", 2)),
                    Catch::Contains("known: aperture, asp, calibrated, coded_exposure, "
                                    "exposure_aperture, lenslet, mask, random, time_aperture"));
  auto measured = spec_of("calibrated", 2);
  measured.params["weights"].erase(measured.params["weights"].begin());
  CHECK_THROWS_WITH(make_phi(measured), Catch::Contains("$.params.weights: expected N x U x V x "
                                                        "T x T = 2 x 5 x 5 x 2 x 2 = 200 values"));
  measured = spec_of("calibrated", 2);
  measured.params["weights"][7] = -0.5;
  CHECK_THROWS_WITH(make_phi(measured), Catch::Contains("$.params.weights[7]"));
  measured.params.erase("weights");
  CHECK_THROWS_WITH(make_phi(measured), Catch::Contains("$.params.weights: required"));
  CHECK_THROWS_WITH(make_phi(spec_of("asp", 26)), Catch::Contains("1..25"));
  auto spec = spec_of("mask", 2);
  spec.params = {{"periode", 9}};
  CHECK_THROWS_WITH(make_phi(spec), Catch::Contains("$.params.periode"));
  spec.params = {{"period", "nine"}};
  CHECK_THROWS_WITH(make_phi(spec), Catch::Contains("$.params.period"));
  auto j = nlohmann::json::parse(R"({"name": "asp", "n": 2, "colour": true})");
  CHECK_THROWS_WITH(PhiSpec::from_json(j, "$.phi"), Catch::Contains("$.phi.colour"));
  CHECK_THROWS_WITH(PhiSpec::from_json(nlohmann::json::parse(R"({"n": 2})")),
                    Catch::Contains("$.name"));
  CHECK_THROWS_WITH(PhiSpec::from_json(nlohmann::json::parse(R"({"name": "asp", "seed": -1})")),
                    Catch::Contains("$.seed"));
  auto bad_n = nlohmann::json::parse(R"({"name": "asp", "n": 30})");
  CHECK_THROWS_AS(PhiSpec::from_json(bad_n), lfnet::ConfigError);
  auto phi = make_phi(spec_of("asp", 2));
  CHECK_THROWS_WITH(phi->forward(torch::zeros({3, 3, 8, 8})), Catch::Contains("5x5"));
  CHECK_THROWS_WITH(phi->adjoint(torch::zeros({3, 8, 8})), Catch::Contains("2 measurements"));
}

TEST_CASE("an ASP quadrature pair is odd in the view angle and still sums to a pixel", "[optics]") {
  // asp:2 is the quadrature pair; pair_alpha 0 gives the even one.
  lfnet::optics::PhiSpec odd = lfnet::optics::PhiSpec::parse("asp:2");
  lfnet::optics::PhiSpec even = odd;
  even.params = {{"pair_alpha", 0.0}};
  CHECK(lfnet::optics::make_phi(odd)->spec().params["pair_alpha"] == 90.0);
  auto we = lfnet::optics::make_phi(even)->pixel_weights(0, 0, 1, 1).squeeze(-1).squeeze(-1);
  auto wo = lfnet::optics::make_phi(odd)->pixel_weights(0, 0, 1, 1).squeeze(-1).squeeze(-1);
  // (N, U, V): the difference of the pair flips sign when theta does for the odd pair only.
  auto de = (we[0] - we[1]).to(torch::kFloat64), dodd = (wo[0] - wo[1]).to(torch::kFloat64);
  CHECK(torch::allclose(de, de.flip({0}), 1e-6, 1e-6));
  CHECK(torch::allclose(dodd, -dodd.flip({0}), 1e-6, 1e-6));
  CHECK(dodd.abs().max().item<double>() > 0.01);
  // Both pairs add up to the same conventional pixel.
  CHECK(torch::allclose(we.sum(0), wo.sum(0), 1e-6, 1e-6));
  // The same rows, reordered: at N = 25 both tables span the same space.
  auto full_even = lfnet::optics::asp_table(5, 5, 25);
  auto full_odd = lfnet::optics::asp_table(5, 5, 25, false, 0.0, 90.0);
  REQUIRE(full_odd.size() == full_even.size());
  CHECK(full_odd[0].alpha != full_even[0].alpha);
  CHECK_THROWS_AS(lfnet::optics::asp_table(5, 5, 2, false, 10.0, 0.0), lfnet::ConfigError);
  // On 2 x 2 views the frequency along the rows is Nyquist, which has no odd row: asp:2 then
  // takes the even pair, and its resolved spec says so.
  auto column = lfnet::optics::PhiSpec::parse("asp:2");
  column.rows = 2;
  column.cols = 2;
  CHECK(lfnet::optics::make_phi(column)->spec().params["pair_alpha"] == 0.0);
  column.params = {{"pair_alpha", 90.0}};  // asked for explicitly: an error
  CHECK_THROWS_AS(lfnet::optics::make_phi(column), lfnet::ConfigError);
}

TEST_CASE("every number in a shipped camera spec has a domain", "[phi][domains]") {
  const std::filesystem::path dir = std::filesystem::path(LFNET_SOURCE_DIR) / "configs" / "cameras";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".json") continue;
    ++files;
    const auto found = lfnet::test::absurd_values_unrefused(
        lfnet::read_json_file(entry.path().string()), [](const nlohmann::json& j) {
          (void)lfnet::optics::make_phi(lfnet::optics::PhiSpec::from_json(j));
        });
    std::string all;
    for (const auto& line : found) all += line + "\n";
    INFO(entry.path().string() << "\n" << all);
    CHECK(found.empty());
  }
  CHECK(files >= 1);
}

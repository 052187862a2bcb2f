#include "lfnet/recon/reconstruct.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/core/metrics.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/methods.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {
torch::Tensor smooth_lf(int64_t h, int64_t w) {
  // A light field with some parallax: a smooth texture shifted by one pixel per view.
  auto base = torch::rand({1, 1, h + 8, w + 8});
  base = torch::avg_pool2d(base, 3, 1, 1)[0][0];
  auto lf = torch::empty({1, 5, 5, h, w});
  for (int64_t u = 0; u < 5; ++u) {
    for (int64_t v = 0; v < 5; ++v) {
      lf[0][u][v] =
          base.slice(0, 4 + (u - 2), 4 + (u - 2) + h).slice(1, 4 + (v - 2), 4 + (v - 2) + w);
    }
  }
  return lf;
}
}  // namespace

TEST_CASE("pinv with N = 25 recovers the light field from a sensor image", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:25"));
  auto lf = smooth_lf(23, 31);
  auto sensor = optics::simulate_sensor(*phi, lf[0]);
  recon::ReconstructOptions o;
  o.stride = 5;
  auto solver = recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9));
  auto est = recon::reconstruct_sensor(*phi, sensor, solver, o);
  REQUIRE(est.sizes() == lf.sizes());
  // Full rank: only the Tikhonov bias remains; at N = 2 most of the parallax is lost.
  const double full = psnr(est, lf);
  CHECK(full > 30.0);
  auto phi2 = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto est2 =
      recon::reconstruct_sensor(*phi2, optics::simulate_sensor(*phi2, lf[0]),
                                recon::pinv_solver(optics::pinv_matrix_stack(*phi2, 9, 9)), o);
  CHECK(psnr(est2, lf) < full - 5.0);
}

TEST_CASE("streaming in small batches equals one big batch", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("mask:2"));
  auto lf = smooth_lf(30, 26);
  auto sensor = optics::simulate_sensor(*phi, lf[0]);
  auto solver = recon::adjoint_solver(optics::patch_matrix_stack(*phi, 9, 9));
  recon::ReconstructOptions big, small;
  big.stride = small.stride = 3;
  big.batch = 100000;
  small.batch = 7;
  auto a = recon::reconstruct_sensor(*phi, sensor, solver, big);
  auto b = recon::reconstruct_sensor(*phi, sensor, solver, small);
  test::require_close(a, b, 1e-6);
}

TEST_CASE("a reconstruction in 16-bit codes is the float32 one, coded", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto lf = smooth_lf(30, 26);
  auto sensor = optics::simulate_sensor(*phi, lf[0]);
  auto solver = recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9));
  recon::ReconstructOptions plain, coded;
  plain.batch = coded.batch = 40;  // several bands
  coded.coded = true;
  const auto values = recon::reconstruct_sensor(*phi, sensor, solver, plain);
  const auto codes = recon::reconstruct_sensor(*phi, sensor, solver, coded);
  REQUIRE(codes.scalar_type() == torch::kInt16);
  CHECK(torch::equal(codes, encode_codes(values)));
  // The scores read either: PSNR moves by far less than its printed digits.
  CHECK(psnr(LightFieldViews(codes), LightField(lf)) ==
        Approx(psnr(LightField(values), LightField(lf))).margin(1e-3));
  coded.clamp = false;
  CHECK_THROWS_WITH(recon::reconstruct_sensor(*phi, sensor, solver, coded),
                    Catch::Contains("clamped"));
}

TEST_CASE("per-patch and sensor modes agree for a local Phi without noise", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto lf = smooth_lf(20, 20);
  PatchGrid grid(20, 20, 9, 9, 5);
  auto solver = recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9));
  recon::ReconstructOptions o;
  auto source = [&](int64_t r0, int64_t r1) {
    return optics::measure_patches(*phi, lf, grid, optics::SimulationMode::kPerPatch, {}, 0, r0,
                                   r1);
  };
  auto per_patch = recon::reconstruct_patches(*phi, grid, source, solver, o);
  auto sensor = recon::reconstruct_sensor(*phi, optics::simulate_sensor(*phi, lf[0]), solver, o);
  test::require_close(per_patch, sensor, 1e-5);
}

TEST_CASE("a local Phi's per-pixel pseudo-inverses are its patch pseudo-inverses", "[recon]") {
  for (const char* spec : {"asp:2", "mask:2", "aperture:3", "lenslet:4"}) {
    INFO(spec);
    auto phi = optics::make_phi(optics::PhiSpec::parse(spec));
    REQUIRE(phi->local());
    const int64_t h = 6, w = 7, n = phi->measurements(), uv = phi->rows() * phi->cols();
    const auto dense = optics::pinv_matrix_stack(*phi, h, w, 1e-3, torch::kFloat64);
    const auto pixel = optics::pixel_pinv_stack(*phi, h, w, 1e-3, torch::kFloat64);
    REQUIRE(pixel.sizes() == torch::IntArrayRef({dense.size(0), n, uv, h * w}));
    // The dense (P, U V h w, N h w) holds pixel[p, n, k, q] at row (k, q), column (n, q).
    const auto eye = torch::eye(h * w, torch::kFloat64);
    const auto expanded =
        torch::einsum("pnkq,qQ->pkqnQ", {pixel, eye}).reshape({dense.size(0), uv * h * w, -1});
    test::require_close(expanded, dense, 1e-12);
    // So do their solvers, on any measurements.
    const auto y = torch::rand({40, n * h * w});
    const auto phase = torch::randint(dense.size(0), {40}, torch::kLong);
    test::require_close(recon::pixel_pinv_solver(pixel)(y, phase),
                        recon::pinv_solver(dense)(y, phase), 1e-5);
  }
  // Random projections mix pixels: no per-pixel form, and pinv_solver(phi) takes the dense one.
  auto random = optics::make_phi(optics::PhiSpec::parse("random:2"));
  CHECK_THROWS(optics::pixel_pinv_stack(*random, 9, 9));
  const auto y = torch::rand({3, int64_t{2} * 81});
  const auto phase = torch::zeros({3}, torch::kLong);
  test::require_close(recon::pinv_solver(*random, 9, 9)(y, phase),
                      recon::pinv_solver(optics::pinv_matrix_stack(*random, 9, 9))(y, phase), 1e-6);
}

TEST_CASE("random projections refuse patches off the block grid in sensor mode", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("random:2"));
  auto lf = smooth_lf(18, 18);
  auto sensor = optics::simulate_sensor(*phi, lf[0]);
  auto solver = recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9));
  recon::ReconstructOptions o;
  o.stride = 5;
  CHECK_THROWS_AS(recon::reconstruct_sensor(*phi, sensor, solver, o), ConfigError);
  o.stride = 9;
  CHECK(recon::reconstruct_sensor(*phi, sensor, solver, o).sizes() == lf.sizes());
}

TEST_CASE("a solver that returns NaN is reported, not stitched", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto sensor = optics::simulate_sensor(*phi, smooth_lf(18, 18)[0]);
  recon::PatchSolver bad = [](const torch::Tensor& y, const torch::Tensor&) {
    return torch::full({y.size(0), 2025}, std::nan(""));
  };
  CHECK_THROWS_AS(recon::reconstruct_sensor(*phi, sensor, bad, {}), NumericalError);
}

TEST_CASE("mean matching scales measurements linearly", "[recon]") {
  auto y = torch::rand({2, 10, 10}) * 3;
  const double scale = recon::match_mean(y, 0.5);
  CHECK(y.mean().item<double>() == Approx(0.5).epsilon(1e-6));
  CHECK(scale > 0);
  auto zero = torch::zeros({2, 3, 3});
  CHECK_THROWS_AS(recon::match_mean(zero, 0.5), NumericalError);
}

#include "lfnet/dict/sparse_coding.h"

#include <catch2/catch.hpp>

#include <fstream>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::dict::SparseCoder;
using lfnet::dict::SparseCodingOptions;
using lfnet::dict::SparseCodingResult;

namespace {

// A light-field-sized problem: a random dictionary of 2025-value patches and a Gaussian
// patch matrix with 162 = 81 N rows (N = 2), as for 5 x 5 x 9 x 9 patches.
struct Problem {
  torch::Tensor dict;     // (2025, K)
  torch::Tensor a;        // (162, 2025)
  torch::Tensor coef;     // (K, B), `s` non-zeros per column, |value| in [0.5, 1.5]
  torch::Tensor patches;  // (B, 2025) = (D coef)^T
  torch::Tensor y;        // (B, 162) = patches A^T
};

Problem make_problem(int64_t k, int64_t b, int64_t s, uint64_t seed) {
  torch::manual_seed(seed);
  Problem p;
  p.dict = lfnet::test::unit_columns(torch::randn({2025, k}, torch::kFloat64));
  p.a = torch::randn({162, 2025}, torch::kFloat64) / std::sqrt(162.0);
  p.coef = torch::zeros({k, b}, torch::kFloat64);
  for (int64_t i = 0; i < b; ++i) {
    auto idx = torch::randperm(k, torch::kInt64).slice(0, 0, s);
    auto mag = 0.5 + torch::rand({s}, torch::kFloat64);
    p.coef.select(1, i).index_put_({idx}, mag * torch::randn({s}, torch::kFloat64).sign());
  }
  p.patches = p.dict.mm(p.coef).t();
  p.y = p.patches.mm(p.a.t());
  return p;
}

void require_finite(const SparseCodingResult& r) {
  CHECK(torch::isfinite(r.patches).all().item<bool>());
  CHECK(torch::isfinite(r.residual_sq).all().item<bool>());
}

}  // namespace

TEST_CASE("OMP recovers an exactly sparse patch from compressive measurements",
          "[dict][sparse_coding]") {
  const Problem p = make_problem(1000, 24, 5, 41);
  SparseCodingOptions o;
  o.omp.max_atoms = 10;
  SparseCoder coder(p.dict, o);
  auto r = coder.code(p.a, p.y);
  REQUIRE(r.patches.sizes() == p.patches.sizes());
  lfnet::test::require_close(r.patches, p.patches, 1e-6);
  // Five atoms explain the measurements exactly; OMP stops there, not at 10.
  CHECK(r.iterations.eq(5).all().item<bool>());
  CHECK(r.nonzeros.eq(5).all().item<bool>());
  CHECK(r.converged.all().item<bool>());
  CHECK(r.residual_sq.max().item<double>() < 1e-20);
  CHECK(r.unconverged() == 0);
  // Without column normalisation the codes are the same.
  o.normalize_columns = false;
  SparseCoder plain(p.dict, o);
  lfnet::test::require_close(plain.code(p.a, p.y).patches, p.patches, 1e-6);
  // float32 measurements give float32 patches.
  auto r32 = coder.code(p.a, p.y.to(torch::kFloat32));
  CHECK(r32.patches.scalar_type() == torch::kFloat32);
  lfnet::test::require_close(r32.patches, p.patches, 1e-4);
}

TEST_CASE("ADMM-LASSO recovers an exactly sparse patch to its tolerance", "[dict][sparse_coding]") {
  const Problem p = make_problem(1000, 8, 5, 43);
  SparseCodingOptions o;
  o.method = lfnet::dict::CodingMethod::kAdmm;
  o.admm.double_precision = GENERATE(false, true);
  INFO("double precision " << o.admm.double_precision);
  o.admm.lambda = 1e-4;  // relative to ||Theta^T y||_inf
  o.admm.rho = 0.1;
  o.admm.relaxation = 1.6;
  o.admm.abs_tolerance = 1e-7;
  // In float32 this is raised to the precision's floor, 3.8e-5 for K = 1,000: asked for
  // 1e-5, float32 patches stalled above it forever on OpenBLAS's SkylakeX kernel.
  o.admm.rel_tolerance = 1e-5;
  // Why 3,000 suffices: on this problem every patch stops after 195-436 iterations, in both
  // precisions, on OpenBLAS's Haswell and SkylakeX kernels and on 1 and 2 threads
  // (scripts/test-kernels.sh); ADMM converges linearly here, so round-off moves that by tens.
  o.admm.max_iterations = 3000;
  SparseCoder coder(p.dict, o);
  auto r = coder.code(p.a, p.y);
  require_finite(r);
  CHECK(r.converged.all().item<bool>());
  CHECK(r.iterations.max().item<int64_t>() < 1000);
  CHECK(r.nonzeros.eq(5).all().item<bool>());
  // The LASSO's shrinkage biases the estimate by about lambda relative (1.4e-4 here).
  const double rel = ((r.patches - p.patches).norm() / p.patches.norm()).item<double>();
  INFO("relative error " << rel);
  CHECK(rel < 1e-3);
  lfnet::test::require_close(r.patches, p.patches, 1e-4);
}

TEST_CASE("ADMM reports non-convergence rather than a silent answer", "[dict][sparse_coding]") {
  const Problem p = make_problem(300, 6, 5, 47);
  SparseCodingOptions o;
  o.method = lfnet::dict::CodingMethod::kAdmm;
  o.admm.max_iterations = 1;
  SparseCoder coder(p.dict, o);
  auto r = coder.code(p.a, p.y);
  require_finite(r);
  CHECK(r.unconverged() == 6);
  CHECK(r.iterations.eq(1).all().item<bool>());
  // The same problem with room to run converges.
  o.admm.max_iterations = 2000;
  SparseCoder patient(p.dict, o);
  auto ok = patient.code(p.a, p.y);
  CHECK(ok.unconverged() == 0);
  CHECK(ok.iterations.gt(1).all().item<bool>());
  // Patches stop separately: iteration counts differ between patches.
  CHECK(ok.iterations.max().item<int64_t>() > ok.iterations.min().item<int64_t>());
}

TEST_CASE("ADMM solves the LASSO that scikit-learn solves", "[dict][sparse_coding][reference]") {
  const std::string py = lfnet::test::python_with("sklearn");
  if (py.empty()) {
    LFNET_SKIP("python3-sklearn is not installed: no Lasso to compare with");
  }
  // With D = I the patches are the coefficients themselves.
  torch::manual_seed(53);
  const int64_t m = 30, k = 60, b = 5;
  const double lambda = 0.1;
  auto theta = torch::randn({m, k}, torch::kFloat64);
  auto truth = torch::zeros({b, k}, torch::kFloat64);
  truth.slice(1, 0, 4).normal_();
  auto y = truth.mm(theta.t()) + 0.05 * torch::randn({b, m}, torch::kFloat64);
  SparseCodingOptions o;
  o.method = lfnet::dict::CodingMethod::kAdmm;
  o.normalize_columns = false;
  o.admm.lambda = lambda;
  o.admm.relative_lambda = false;
  o.admm.double_precision = true;
  o.admm.abs_tolerance = 1e-11;
  o.admm.rel_tolerance = 1e-11;
  o.admm.max_iterations = 50000;
  o.admm.relaxation = 1.5;
  SparseCoder coder(torch::eye(k, torch::kFloat64), o);
  auto r = coder.code(theta, y);
  CHECK(r.converged.all().item<bool>());

  lfnet::test::TempDir tmp;
  lfnet::test::write_f64(tmp / "theta.f64", theta);
  lfnet::test::write_f64(tmp / "y.f64", y);
  std::ostringstream cmd;
  cmd << py << " " << LFNET_SOURCE_DIR << "/tests/dict/reference_lasso.py " << (tmp / "theta.f64")
      << " " << (tmp / "y.f64") << " " << m << " " << k << " " << b << " " << lambda << " "
      << (tmp / "out.f64");
  std::string out;
  const int rc = lfnet::test::run_command(cmd.str(), out);
  INFO(out);
  REQUIRE(rc == 0);
  auto ref = torch::empty({b, k}, torch::kFloat64);
  std::ifstream in(tmp / "out.f64", std::ios::binary);
  in.read(reinterpret_cast<char*>(ref.data_ptr<double>()),
          static_cast<std::streamsize>(ref.numel() * sizeof(double)));
  REQUIRE(in.good());
  lfnet::test::require_close(r.patches, ref, 1e-6);
  // Sparse, but not trivially: the L1 term zeroed some coefficients and kept others.
  CHECK(r.nonzeros.min().item<int64_t>() > 0);
  CHECK(r.nonzeros.max().item<int64_t>() < k);
  CHECK(ref.ne(0).sum(1).eq(r.nonzeros).all().item<bool>());
}

TEST_CASE("Sparse coding gives finite output on degenerate input", "[dict][sparse_coding]") {
  const Problem p = make_problem(200, 4, 3, 59);
  const std::string method = GENERATE(as<std::string>{}, "omp", "admm");
  {
    INFO("method " << method);
    SparseCodingOptions o;
    o.method = lfnet::dict::from_string(method, o.method);
    SparseCoder coder(p.dict, o);

    SECTION("zero measurements: zero patches, converged") {
      auto r = coder.code(p.a, torch::zeros_like(p.y));
      require_finite(r);
      CHECK(r.patches.eq(0).all().item<bool>());
      CHECK(r.converged.all().item<bool>());
    }
    SECTION("a patch matrix with zero columns") {
      auto a = p.a.clone();
      a.slice(1, 0, 1000).zero_();  // the sensor sees only part of the patch
      auto r = coder.code(a, p.patches.mm(a.t()));
      require_finite(r);
      CHECK(r.residual_sq.le(p.y.pow(2).sum(1) + 1e-9).all().item<bool>());
    }
    SECTION("a patch matrix with duplicated rows") {
      auto a = torch::cat({p.a.slice(0, 0, 81), p.a.slice(0, 0, 81)}, 0);
      auto r = coder.code(a, p.patches.mm(a.t()));
      require_finite(r);
    }
    SECTION("an all-zero patch matrix") {
      auto a = torch::zeros_like(p.a);
      auto r = coder.code(a, torch::zeros_like(p.y));
      require_finite(r);
      CHECK(r.patches.eq(0).all().item<bool>());
    }
    SECTION("a dictionary with zero atoms") {
      auto d = p.dict.clone();
      d.slice(1, 0, 50).zero_();
      SparseCoder zeros(d, o);
      auto r = zeros.code(p.a, p.y);
      require_finite(r);
    }
  }
}

TEST_CASE("Sparse coding shares one factorisation per patch matrix", "[dict][sparse_coding]") {
  const Problem p = make_problem(100, 6, 3, 61);
  SparseCodingOptions o;
  o.cache_size = 1;
  SparseCoder coder(p.dict, o);
  auto first = coder.code(p.a, p.y);
  CHECK(coder.factorizations() == 1);
  auto again = coder.code(p.a.clone(), p.y.slice(0, 0, 3));  // equal content, other storage
  CHECK(coder.factorizations() == 1);
  lfnet::test::require_close(again.patches, first.patches.slice(0, 0, 3), 1e-12);
  auto other = p.a.clone();
  other[0][0] += 1.0;
  coder.code(other, p.y);
  CHECK(coder.factorizations() == 2);
  coder.code(p.a, p.y);  // evicted by the cache of one
  CHECK(coder.factorizations() == 3);
  // Coding patches one at a time gives what coding them together gives.
  for (int64_t i = 0; i < 6; ++i) {
    auto one = coder.code(p.a, p.y.slice(0, i, i + 1));
    lfnet::test::require_close(one.patches, first.patches.slice(0, i, i + 1), 1e-12);
  }
}

TEST_CASE("OMP's residual tolerance stops at the noise level", "[dict][sparse_coding]") {
  Problem p = make_problem(400, 10, 4, 67);
  const double sigma = 0.01;
  auto noisy = p.y + sigma * torch::randn_like(p.y);
  SparseCodingOptions o;
  o.omp.max_atoms = 40;
  o.omp.residual_tolerance = sigma * sigma;  // per measurement
  SparseCoder coder(p.dict, o);
  auto r = coder.code(p.a, noisy);
  CHECK(r.converged.all().item<bool>());
  CHECK(r.residual_sq.le(sigma * sigma * 162 * (1 + 1e-9)).all().item<bool>());
  // It stops well before the atom limit, near the true sparsity.
  CHECK(r.iterations.max().item<int64_t>() < 12);
  CHECK(r.iterations.min().item<int64_t>() >= 3);
}

TEST_CASE("Sparse coding options are strict and input is checked", "[dict][sparse_coding]") {
  SparseCodingOptions o;
  o.method = lfnet::dict::CodingMethod::kAdmm;
  o.admm.rho = 2.5;
  o.omp.residual_tolerance = 1e-4;
  auto back = SparseCodingOptions::from_json(o.to_json());
  CHECK(back.to_json() == o.to_json());
  CHECK_THROWS_WITH(SparseCodingOptions::from_json({{"admm", {{"rho", 1.0}, {"iters", 3}}}}),
                    Catch::Contains("$.admm.iters"));
  CHECK_THROWS_WITH(SparseCodingOptions::from_json({{"method", "fista"}}),
                    Catch::Contains("fista"));
  CHECK_THROWS_AS(SparseCodingOptions::from_json({{"admm", {{"rho", 0.0}}}}), lfnet::ConfigError);
  CHECK_THROWS_AS(SparseCodingOptions::from_json({{"admm", {{"relaxation", 2.0}}}}),
                  lfnet::ConfigError);

  SparseCoder coder(lfnet::test::unit_columns(torch::randn({50, 20}, torch::kFloat64)),
                    SparseCodingOptions{});
  CHECK_THROWS_WITH(coder.code(torch::randn({10, 49}), torch::randn({3, 10})),
                    Catch::Contains("(m, 50)"));
  CHECK_THROWS_WITH(coder.code(torch::randn({10, 50}), torch::randn({3, 11})),
                    Catch::Contains("m = 10"));
  auto nan = torch::randn({3, 10});
  nan[1][1] = std::nan("");
  CHECK_THROWS_AS(coder.code(torch::randn({10, 50}), nan), lfnet::NumericalError);
}

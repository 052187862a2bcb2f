#include "lfnet/dict/omp.h"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <fstream>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::dict::batch_omp;
using lfnet::dict::OmpOptions;
using lfnet::dict::OmpResult;
using lfnet::dict::OmpStop;

namespace {

torch::Tensor read_f64(const std::string& path, const std::vector<int64_t>& shape) {
  auto t = torch::empty(shape, torch::kFloat64);
  std::ifstream in(path, std::ios::binary);
  in.read(reinterpret_cast<char*>(t.data_ptr<double>()),
          static_cast<std::streamsize>(t.numel() * sizeof(double)));
  REQUIRE(in.good());
  return t;
}

// scikit-learn's orthogonal_mp_gram on the same inputs: coefficients (K, B) and atoms used.
struct Reference {
  torch::Tensor coef;
  std::vector<int64_t> n_iter;
};

Reference sklearn_omp(const std::string& py, const torch::Tensor& gram, const torch::Tensor& xy,
                      const std::string& mode, double param, const torch::Tensor& norms = {}) {
  lfnet::test::TempDir tmp;
  const int64_t k = gram.size(0), b = xy.size(1);
  lfnet::test::write_f64(tmp / "gram.f64", gram);
  lfnet::test::write_f64(tmp / "xy.f64", xy);
  std::ostringstream cmd;
  cmd.precision(17);
  cmd << py << " " << LFNET_SOURCE_DIR << "/tests/dict/reference_omp.py " << (tmp / "gram.f64")
      << " " << (tmp / "xy.f64") << " " << k << " " << b << " " << mode << " ";
  if (mode == "n_nonzero") {
    cmd << static_cast<int64_t>(param) << " " << (tmp / "coef.f64");
  } else {
    lfnet::test::write_f64(tmp / "norms.f64", norms);
    cmd << param << " " << (tmp / "norms.f64") << " " << (tmp / "coef.f64");
  }
  std::string out;
  const int rc = lfnet::test::run_command(cmd.str(), out);
  INFO(out);
  REQUIRE(rc == 0);
  Reference ref;
  ref.coef = read_f64(tmp / "coef.f64", {k, b});
  ref.n_iter =
      nlohmann::json::parse(out.substr(out.find('{')))["n_iter"].get<std::vector<int64_t>>();
  return ref;
}

// Signals that are sparse combinations of `atoms` columns plus noise, as rows (B, m).
torch::Tensor sparse_signals(const torch::Tensor& dict, int64_t b, int64_t s, double noise) {
  const int64_t k = dict.size(1);
  auto coef = torch::zeros({k, b}, torch::kFloat64);
  for (int64_t i = 0; i < b; ++i) {
    auto idx = torch::randperm(k, torch::kInt64).slice(0, 0, s);
    coef.select(1, i).index_put_({idx}, torch::randn({s}, torch::kFloat64));
  }
  return (dict.mm(coef) + noise * torch::randn({dict.size(0), b}, torch::kFloat64)).t();
}

struct Case {
  std::string name;
  torch::Tensor dict;  // (m, K)
  torch::Tensor y;     // (B, m)
};

std::vector<Case> reference_cases() {
  torch::manual_seed(11);
  std::vector<Case> cases;
  {
    auto d = lfnet::test::unit_columns(torch::randn({30, 60}, torch::kFloat64));
    cases.push_back({"gaussian unit atoms", d, sparse_signals(d, 40, 4, 0.05)});
  }
  {
    // Strongly correlated atoms: ten clusters of six atoms around shared directions.
    auto base = torch::randn({24, 10}, torch::kFloat64).repeat_interleave(6, 1);
    auto d = lfnet::test::unit_columns(base + 0.3 * torch::randn({24, 60}, torch::kFloat64));
    cases.push_back({"correlated atoms", d, sparse_signals(d, 40, 5, 0.02)});
  }
  {
    // Atoms of very different norms, signals not sparse at all.
    auto d = torch::randn({20, 35}, torch::kFloat64) *
             torch::logspace(-1, 1, 35, 10.0, torch::kFloat64).unsqueeze(0);
    cases.push_back({"unnormalised atoms", d, torch::randn({25, 20}, torch::kFloat64)});
  }
  return cases;
}

}  // namespace

TEST_CASE("Batch-OMP agrees with scikit-learn's orthogonal_mp_gram (n_nonzero)",
          "[dict][omp][reference]") {
  const std::string py = lfnet::test::python_with("sklearn");
  if (py.empty()) {
    LFNET_SKIP("python3-sklearn is not installed: no orthogonal_mp_gram to compare with");
  }
  for (const auto& c : reference_cases()) {
    auto gram = c.dict.t().mm(c.dict);
    auto xy = c.dict.t().mm(c.y.t());
    for (int64_t s : {1, 3, 8}) {
      INFO(c.name << ", n_nonzero " << s);
      OmpOptions o;
      o.max_atoms = s;
      OmpResult ours = batch_omp(gram, xy, o);
      Reference ref = sklearn_omp(py, gram, xy, "n_nonzero", static_cast<double>(s));
      lfnet::test::require_close(ours.dense(), ref.coef, 1e-6, 1e-6);
      for (int64_t i = 0; i < ours.signals(); ++i) {
        CHECK(ours.counts[i].item<int64_t>() == ref.n_iter[i]);
      }
      CHECK(ours.counts.eq(s).all().item<bool>());  // nothing degenerate here
      CHECK(ref.coef.ne(0).sum().item<int64_t>() == s * ours.signals());
    }
  }
}

TEST_CASE("Batch-OMP agrees with scikit-learn's orthogonal_mp_gram (tol)",
          "[dict][omp][reference]") {
  const std::string py = lfnet::test::python_with("sklearn");
  if (py.empty()) {
    LFNET_SKIP("python3-sklearn is not installed: no orthogonal_mp_gram to compare with");
  }
  for (const auto& c : reference_cases()) {
    auto gram = c.dict.t().mm(c.dict);
    auto xy = c.dict.t().mm(c.y.t());
    auto norms = c.y.pow(2).sum(1);
    const double mean_norm = norms.mean().item<double>();
    for (double frac : {0.3, 0.02, 1e-4}) {
      const double tol = frac * mean_norm;
      INFO(c.name << ", tol " << tol);
      OmpOptions o;
      o.max_atoms = 0;  // no limit, like scikit-learn with tol
      o.tolerance = tol;
      OmpResult ours = batch_omp(gram, xy, o, norms);
      Reference ref = sklearn_omp(py, gram, xy, "tol", tol, norms);
      lfnet::test::require_close(ours.dense(), ref.coef, 1e-6, 1e-6);
      for (int64_t i = 0; i < ours.signals(); ++i) {
        CHECK(ours.counts[i].item<int64_t>() == ref.n_iter[i]);
        if (ours.stops[i].item<int8_t>() == static_cast<int8_t>(OmpStop::kTolerance)) {
          CHECK(ours.residual_sq[i].item<double>() <= tol * (1 + 1e-9));
        }
      }
      // The residual of the returned fit is the one reported.
      auto fit = c.dict.mm(ours.dense());
      auto res = (c.y.t() - fit).pow(2).sum(0);
      lfnet::test::require_close(ours.residual_sq, res, 1e-8, 1e-8);
    }
  }
}

// `run()` on one LibTorch thread, then on at least two; the thread count is restored.
template <typename F>
std::pair<OmpResult, OmpResult> on_one_and_two_threads(F run) {
  const int threads = torch::get_num_threads();
  torch::set_num_threads(1);
  OmpResult one = run();
  torch::set_num_threads(std::max(2, threads));
  OmpResult many = run();
  torch::set_num_threads(threads);
  return {one, many};
}

TEST_CASE("Batch-OMP gives the same codes on one thread and on several", "[dict][omp]") {
  // Promise: batch_omp's own arithmetic runs one signal per thread in a fixed order, so the
  // same Gram matrix and correlations give bit-identical codes on any thread count. The
  // inputs are computed once: their BLAS products round differently with the thread count
  // and the CPU's kernel (see the next test).
  torch::manual_seed(3);
  auto d = lfnet::test::unit_columns(torch::randn({40, 120}, torch::kFloat64));
  auto y = sparse_signals(d, 300, 6, 0.01);
  const auto gram = d.t().mm(d), xy = d.t().mm(y.t());
  OmpOptions o;
  o.max_atoms = 9;
  const auto [one, many] = on_one_and_two_threads([&] { return batch_omp(gram, xy, o); });
  CHECK(torch::equal(one.indices, many.indices));
  CHECK(torch::equal(one.values, many.values));
}

TEST_CASE("OMP end to end agrees across thread counts to BLAS round-off", "[dict][omp]") {
  // Promise: omp() computes D^T D and D^T y with BLAS, whose blocking (and so rounding)
  // depends on the thread count and the kernel OpenBLAS picks for the CPU. The codes then
  // agree to round-off: the same atoms (the signals' best and second-best correlations are
  // far apart here) and coefficients within 1e-10 relative, not bit for bit.
  torch::manual_seed(3);
  auto d = lfnet::test::unit_columns(torch::randn({40, 120}, torch::kFloat64));
  auto y = sparse_signals(d, 300, 6, 0.01);
  OmpOptions o;
  o.max_atoms = 6;
  const auto [one, many] = on_one_and_two_threads([&] { return lfnet::dict::omp(d, y, o); });
  CHECK(torch::equal(one.indices, many.indices));
  lfnet::test::require_close(many.values, one.values, 1e-12, 1e-10);
}

TEST_CASE("OMP recovers planted supports and sparse_combine rebuilds the signals", "[dict][omp]") {
  torch::manual_seed(5);
  auto d = lfnet::test::unit_columns(torch::randn({64, 200}, torch::kFloat64));
  auto coef = torch::zeros({200, 50}, torch::kFloat64);
  for (int64_t i = 0; i < 50; ++i) {
    auto idx = torch::randperm(200, torch::kInt64).slice(0, 0, 4);
    coef.select(1, i).index_put_({idx}, torch::randn({4}, torch::kFloat64).sign() *
                                            (1.0 + torch::rand({4}, torch::kFloat64)));
  }
  auto y = d.mm(coef).t();  // (50, 64), noiseless
  OmpOptions o;
  o.max_atoms = 10;
  auto codes = lfnet::dict::omp(d, y, o);
  // Exactly sparse signals stop after their 4 atoms: the residual is orthogonal to all atoms.
  CHECK(codes.counts.eq(4).all().item<bool>());
  CHECK(codes.stops.eq(static_cast<int8_t>(OmpStop::kResidualOrthogonal)).all().item<bool>());
  lfnet::test::require_close(codes.dense(), coef, 1e-9);
  lfnet::test::require_close(lfnet::dict::sparse_combine(d, codes), y, 1e-9);
  // The residual of partial codes: drop every code's last atom.
  auto partial = codes;
  partial.indices = codes.indices.clone();
  partial.indices.select(1, 3).fill_(-1);
  auto dense = partial.dense();
  lfnet::test::require_close(lfnet::dict::sparse_residual(d, partial, y), y - d.mm(dense).t(),
                             1e-12);
  CHECK(lfnet::dict::sparse_residual(d, partial, y).abs().max().item<double>() > 0.1);
  CHECK(codes.premature() == 0);
}

TEST_CASE("Batch-OMP stops early and stays finite on degenerate input", "[dict][omp]") {
  torch::manual_seed(9);
  OmpOptions o;
  o.max_atoms = 6;

  SECTION("all-zero signals") {
    auto d = lfnet::test::unit_columns(torch::randn({10, 20}, torch::kFloat64));
    auto xy = torch::zeros({20, 3}, torch::kFloat64);
    auto r = batch_omp(d.t().mm(d), xy, o, torch::zeros({3}, torch::kFloat64));
    CHECK(r.counts.eq(0).all().item<bool>());
    CHECK(r.stops.eq(static_cast<int8_t>(OmpStop::kResidualOrthogonal)).all().item<bool>());
    CHECK(r.dense().eq(0).all().item<bool>());
    CHECK(r.residual_sq.eq(0).all().item<bool>());
  }
  SECTION("zero atoms") {
    auto d = lfnet::test::unit_columns(torch::randn({10, 20}, torch::kFloat64));
    d.slice(1, 0, 5).zero_();
    auto y = torch::randn({4, 10}, torch::kFloat64);
    auto r = batch_omp(d.t().mm(d), d.t().mm(y.t()), o);
    CHECK(torch::isfinite(r.values).all().item<bool>());
    CHECK(r.indices.ge(5).logical_or(r.indices.eq(-1)).all().item<bool>());
    CHECK(r.counts.eq(6).all().item<bool>());
  }
  SECTION("a Gram matrix with a zero diagonal but non-zero correlation") {
    auto gram = torch::eye(4, torch::kFloat64);
    gram[2][2] = 0.0;
    auto xy = torch::tensor({0.1, 0.2, 5.0, 0.3}, torch::kFloat64).unsqueeze(1);
    auto r = batch_omp(gram, xy, o);
    CHECK(r.counts[0].item<int64_t>() == 0);
    CHECK(r.stops[0].item<int8_t>() == static_cast<int8_t>(OmpStop::kDependentAtom));
    CHECK(r.premature() == 1);
  }
  SECTION("linearly dependent atoms: 12 atoms in 3 dimensions, duplicates included") {
    auto base = torch::randn({3, 6}, torch::kFloat64);
    auto d = lfnet::test::unit_columns(torch::cat({base, base}, 1));
    auto y = torch::randn({5, 3}, torch::kFloat64);
    auto r = batch_omp(d.t().mm(d), d.t().mm(y.t()), o, y.pow(2).sum(1));
    CHECK(torch::isfinite(r.values).all().item<bool>());
    CHECK(r.counts.le(3).all().item<bool>());
    // Three independent atoms span R^3: the fit is exact before the dependent ones are tried.
    CHECK(r.residual_sq.max().item<double>() < 1e-12);
    const std::string py = lfnet::test::python_with("sklearn");
    if (!py.empty()) {
      auto gram = d.t().mm(d);
      auto xy = d.t().mm(y.t());
      Reference ref = sklearn_omp(py, gram, xy, "n_nonzero", 6);
      lfnet::test::require_close(r.dense(), ref.coef, 1e-6, 1e-6);
    }
  }
  SECTION("more atoms asked for than exist") {
    auto d = lfnet::test::unit_columns(torch::randn({8, 4}, torch::kFloat64));
    auto y = torch::randn({2, 8}, torch::kFloat64);
    auto r = batch_omp(d.t().mm(d), d.t().mm(y.t()), o);
    CHECK(r.counts.eq(4).all().item<bool>());
    CHECK(r.stops.eq(static_cast<int8_t>(OmpStop::kAllAtoms)).all().item<bool>());
  }
}

TEST_CASE("Batch-OMP rejects bad input and options", "[dict][omp]") {
  auto gram = torch::eye(5, torch::kFloat64);
  auto xy = torch::ones({5, 2}, torch::kFloat64);
  OmpOptions o;
  auto bad = xy.clone();
  bad[1][1] = std::nan("");
  CHECK_THROWS_AS(batch_omp(gram, bad, o), lfnet::NumericalError);
  CHECK_THROWS_AS(batch_omp(torch::ones({5, 4}), xy, o), lfnet::Error);
  CHECK_THROWS_AS(batch_omp(gram, torch::ones({4, 2}), o), lfnet::Error);
  OmpOptions tol;
  tol.tolerance = 0.1;
  CHECK_THROWS_WITH(batch_omp(gram, xy, tol), Catch::Contains("squared signal norms"));
  OmpOptions none;
  none.max_atoms = 0;
  CHECK_THROWS_AS(none.validate(), lfnet::ConfigError);
  CHECK_THROWS_WITH(OmpOptions::from_json({{"max_atoms", 3}, {"tol", 1.0}}),
                    Catch::Contains("$.tol"));
  auto parsed = OmpOptions::from_json({{"max_atoms", 0}, {"tolerance", 0.5}});
  CHECK(parsed.max_atoms == 0);
  CHECK(parsed.tolerance == 0.5);
  CHECK(OmpOptions::from_json(parsed.to_json()).to_json() == parsed.to_json());
}

TEST_CASE("Batch-OMP in float32 agrees with float64 on well-conditioned input", "[dict][omp]") {
  torch::manual_seed(21);
  auto d = lfnet::test::unit_columns(torch::randn({50, 100}, torch::kFloat64));
  auto y = sparse_signals(d, 30, 3, 0.0);
  OmpOptions o;
  o.max_atoms = 3;
  auto r64 = batch_omp(d.t().mm(d), d.t().mm(y.t()), o);
  o.double_precision = false;
  auto r32 = batch_omp(d.t().mm(d), d.t().mm(y.t()), o);
  CHECK(torch::equal(r64.indices, r32.indices));
  lfnet::test::require_close(r32.values, r64.values, 1e-4, 1e-4);
}

// The method registry (recon/method_registry.h): the built-ins, what each needs, and a method
// added from outside the library with one registration call.
#include "lfnet/recon/method_registry.h"

#include <catch2/catch.hpp>

#include <algorithm>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/methods.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {
// Estimates every patch as the constant 0.5: a method the library does not know.
class HalfGreyMethod : public recon::Method {
 public:
  std::string name() const override { return "half-grey-test"; }
  std::string summary() const override { return "every pixel 0.5 (a test method)"; }
  recon::PatchSolver solver(const recon::MethodResources& r) const override {
    const int64_t d = r.phi->rows() * r.phi->cols() * r.patch_h * r.patch_w;
    return [d](const torch::Tensor& y, const torch::Tensor&) {
      return torch::full({y.size(0), d}, 0.5f);
    };
  }
};
}  // namespace

TEST_CASE("the built-in methods are registered in table order with what they need", "[recon]") {
  const auto names = recon::registered_methods();
  const std::vector<std::string> builtins = {"net",  "ae",       "cnn",     "dict",
                                             "pinv", "pinv-nlm", "adjoint", "no-parallax"};
  REQUIRE(names.size() >= builtins.size());
  CHECK(std::vector<std::string>(names.begin(), names.begin() + 8) == builtins);
  CHECK(recon::find_method("net").needs() == recon::MethodNeeds::kNetwork);
  CHECK(recon::find_method("cnn").needs() == recon::MethodNeeds::kNetwork);
  CHECK(recon::find_method("dict").needs() == recon::MethodNeeds::kDictionary);
  CHECK(recon::find_method("pinv").needs() == recon::MethodNeeds::kNothing);
  CHECK(recon::find_method("adjoint").needs() == recon::MethodNeeds::kNothing);
  CHECK(recon::find_method("pinv-nlm").needs() == recon::MethodNeeds::kNothing);
  CHECK(recon::find_method("no-parallax").needs() == recon::MethodNeeds::kTruth);
  CHECK(recon::needs_network("ae"));
  CHECK_FALSE(recon::needs_network("pinv"));
  CHECK_FALSE(recon::needs_network("nosuch"));
  CHECK_THROWS_WITH(recon::find_method("nosuch"),
                    Catch::Contains("unknown method 'nosuch'") && Catch::Contains("pinv"));
  CHECK(recon::method_list(recon::MethodNeeds::kTruth).find("no-parallax") == std::string::npos);
  // The registry says which are baselines: the report and its figures ask it, not a list.
  for (const auto& name : {"dict", "pinv", "pinv-nlm", "adjoint", "no-parallax"}) {
    INFO(name);
    CHECK(recon::is_baseline(name));
  }
  for (const auto& name : {"net", "ae", "cnn", "nosuch"}) {
    INFO(name);
    CHECK_FALSE(recon::is_baseline(name));
  }
}

TEST_CASE("make_solver names what a method is missing", "[recon]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  recon::MethodResources r;
  r.phi = phi.get();
  CHECK_THROWS_WITH(recon::make_solver("net", r), Catch::Contains("--model"));
  CHECK_THROWS_WITH(recon::make_solver("dict", r), Catch::Contains("--dictionary"));
  CHECK_THROWS_WITH(recon::make_solver("no-parallax", r), Catch::Contains("true light field"));
  // The registry's pinv is the library's pinv solver.
  const auto y = torch::rand({6, phi->measurements() * 81});
  const auto phase = torch::zeros({6}, torch::kInt64);
  const auto direct = recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9))(y, phase);
  CHECK(torch::equal(recon::make_solver("pinv", r)(y, phase), direct));
  // A local Phi's pinv is per pixel: N multiply-adds per value; random projections' dense.
  CHECK(recon::find_method("pinv").patch_flops(r) == 2.0 * 2 * 25 * 81);
  auto random = optics::make_phi(optics::PhiSpec::parse("random:2"));
  r.phi = random.get();
  CHECK(recon::find_method("pinv").patch_flops(r) == 2.0 * (2 * 81) * (25 * 81));
}

TEST_CASE("a method registered from outside is listed and reconstructs", "[recon]") {
  recon::register_method(std::make_unique<HalfGreyMethod>());
  const auto names = recon::registered_methods();
  CHECK(std::find(names.begin(), names.end(), "half-grey-test") != names.end());
  CHECK(recon::method_list().find("half-grey-test") != std::string::npos);
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  recon::MethodResources r;
  r.phi = phi.get();
  const auto sensor = optics::simulate_sensor(*phi, torch::rand({1, 5, 5, 18, 18})[0]);
  recon::ReconstructOptions o;
  const auto est =
      recon::reconstruct_sensor(*phi, sensor, recon::make_solver("half-grey-test", r), o);
  CHECK(est.sizes() == torch::IntArrayRef({1, 5, 5, 18, 18}));
  CHECK(est.min().item<float>() == Approx(0.5f));
  CHECK(est.max().item<float>() == Approx(0.5f));
}

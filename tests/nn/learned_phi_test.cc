// Learnable codes (nn/learned_phi.h): physical by construction, differentiable, and a Phi like
// any other.
#include "lfnet/nn/learned_phi.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <set>

#include "lfnet/core/error.h"
#include "lfnet/optics/phi.h"

using lfnet::nn::LearnedPhi;
using lfnet::nn::LearnedPhiOptions;

namespace {
LearnedPhiOptions family(const std::string& name, int64_t period = 1) {
  LearnedPhiOptions o;
  o.family = name;
  o.period = period;
  o.seed = 3;
  if (name == "asp") o.init = "table";
  return o;
}
}  // namespace

TEST_CASE("learnable codes stay physical and measure white as 1", "[nn][learned_phi]") {
  for (const auto& [name, period] :
       {std::pair<std::string, int64_t>{"mask", 4}, {"aperture", 1}, {"asp", 2}}) {
    INFO(name);
    LearnedPhi phi(family(name, period), 2, 5, 5);
    const auto r = phi->response();
    REQUIRE(r.sizes() == torch::IntArrayRef({2, 5, 5, period, period}));
    CHECK(r.min().item<float>() >= 0.0f);
    CHECK(r.max().item<float>() <= 1.0f);
    // Normalised as every built-in Phi: the mean over measurements and pixels of the views' sum.
    CHECK(phi->weights().sum({1, 2}).mean().item<double>() == Approx(1.0).epsilon(1e-5));
    // Differentiable: a loss on the weights reaches every parameter.
    phi->weights().square().sum().backward();
    for (const auto& p : phi->parameters()) {
      REQUIRE(p.grad().defined());
      CHECK(p.grad().abs().sum().item<double>() > 0);
    }
    // The Phi it makes is a calibrated camera with these weights.
    const auto made = lfnet::optics::make_phi(phi->spec());
    CHECK(made->spec().name == "calibrated");
    CHECK(made->period() == period);
    const auto w = made->pixel_weights(0, 0, period, period);
    CHECK(torch::allclose(w, phi->weights().detach(), 1e-5, 1e-6));
  }
}

TEST_CASE("a learnable ASP starts as the built-in quadrature pair", "[nn][learned_phi]") {
  auto o = family("asp");
  o.init_spread = 0;
  LearnedPhi learned(o, 2, 5, 5);
  lfnet::optics::PhiSpec spec = lfnet::optics::PhiSpec::parse("asp:2");
  spec.params = {{"depth", 0.98}};  // the learnable depth starts just below its ceiling
  const auto fixed = lfnet::optics::make_phi(spec)->pixel_weights(0, 0, 1, 1);
  CHECK(torch::allclose(learned->weights().detach(), fixed, 1e-5, 1e-6));
  // Its physical parameters read back.
  const auto p = learned->physical();
  CHECK(p["family"] == "asp");
  CHECK(p["depth"][0].get<double>() == Approx(0.98));
  CHECK(p["alpha"][0].get<double>() == Approx(std::acos(-1.0) / 2));
}

TEST_CASE("a randomly started learnable ASP draws a grating per pixel from its seed",
          "[nn][learned_phi]") {
  const double pi = std::acos(-1.0);
  LearnedPhiOptions o;
  o.family = "asp";
  o.period = 2;
  o.init = "random";
  o.seed = 5;
  LearnedPhi a(o, 2, 5, 5), b(o, 2, 5, 5);
  // The same seed draws the same code.
  CHECK(torch::equal(a->weights().detach(), b->weights().detach()));
  o.seed = 6;
  LearnedPhi c(o, 2, 5, 5);
  CHECK_FALSE(torch::allclose(a->weights().detach(), c->weights().detach()));
  // Each of the 2 x 2 x 2 gratings in its documented range (docs/acquisition.md): frequency
  // beta in [pi / 2, 2 pi], orientation gamma in [0, pi], phase alpha in [0, 2 pi], depth just
  // below its ceiling.
  const auto p = a->physical();
  REQUIRE(p["beta"].size() == 8);
  std::set<double> betas;
  for (size_t i = 0; i < 8; ++i) {
    const double beta = p["beta"][i], gamma = p["gamma"][i], alpha = p["alpha"][i];
    CHECK(beta >= pi / 2 - 1e-6);
    CHECK(beta <= 2 * pi + 1e-6);
    CHECK(gamma >= 0);
    CHECK(gamma <= pi + 1e-6);
    CHECK(alpha >= 0);
    CHECK(alpha <= 2 * pi + 1e-6);
    CHECK(p["depth"][i].get<double>() == Approx(0.98));
    betas.insert(beta);
  }
  // Not one grating repeated: the pixels of the period measure differently.
  CHECK(betas.size() == 8);
  const auto w = a->weights().detach();  // (N, U, V, T, T)
  CHECK_FALSE(torch::allclose(w.select(3, 0).select(3, 0), w.select(3, 1).select(3, 1)));
}

TEST_CASE("a mask binarises to 0 and 1, and bad options are refused", "[nn][learned_phi]") {
  LearnedPhi mask(family("mask", 3), 2, 5, 5);
  const auto b = mask->binarised_weights();
  const auto values = std::get<0>(at::_unique(b));
  CHECK(values.numel() == 2);
  CHECK(values[0].item<float>() == 0.0f);
  CHECK(torch::equal(b > 0, mask->response() >= 0.5));
  LearnedPhi asp(family("asp"), 2, 5, 5);
  CHECK_THROWS_WITH(asp->binarised_weights(), Catch::Contains("cosine"));
  auto bad = family("lens");
  CHECK_THROWS_WITH(LearnedPhi(bad, 2, 5, 5), Catch::Contains("family"));
  bad = family("aperture", 3);
  CHECK_THROWS_WITH(LearnedPhi(bad, 2, 5, 5), Catch::Contains("period 1"));
  CHECK_THROWS_WITH(LearnedPhi(family("mask"), 30, 5, 5), Catch::Contains("N must"));
}

// Time-coded cameras: specs with sub-frames, their codes, and still cameras over an exposure.
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/core/sequence.h"
#include "lfnet/optics/phi.h"
#include "support/test_support.h"

using lfnet::optics::make_phi;
using lfnet::optics::PhiSpec;

namespace {

PhiSpec time_spec(const std::string& name, int64_t n, int64_t frames) {
  auto spec = PhiSpec::parse(name + ":" + std::to_string(n) + "@" + std::to_string(frames));
  spec.seed = 3;
  return spec;
}

}  // namespace

TEST_CASE("a Phi spec names its sub-frames as @T and keeps still specs as they were",
          "[optics][time]") {
  auto spec = PhiSpec::parse("exposure_aperture:1@4");
  CHECK(spec.name == "exposure_aperture");
  CHECK(spec.n == 1);
  CHECK(spec.frames == 4);
  CHECK(spec.coded_rows() == 20);
  CHECK(spec.label() == "exposure_aperture:1@4");
  CHECK(PhiSpec::from_json(spec.to_json()) == spec);
  CHECK(spec.to_json().at("frames") == 4);
  // A still spec's JSON has no "frames": stored specs and their hashes do not change.
  CHECK_FALSE(PhiSpec::parse("asp:2").to_json().contains("frames"));
  CHECK(PhiSpec::parse("asp:2").label() == "asp:2");
  CHECK(PhiSpec::parse("asp:2") != PhiSpec::parse("asp:2@4"));
  CHECK_THROWS_AS(PhiSpec::parse("asp:2@0"), lfnet::ConfigError);
  CHECK_THROWS_AS(PhiSpec::parse("asp:2@65"), lfnet::ConfigError);
  CHECK_THROWS_AS(PhiSpec::parse("asp@"), lfnet::ConfigError);
  auto j = spec.to_json();
  j["frames"] = 0;
  CHECK_THROWS_AS(PhiSpec::from_json(j), lfnet::ConfigError);
  // N counts against T U V: 100 measurements of 4 frames of 5 x 5 views, not 101.
  j["frames"] = 4;
  j["n"] = 101;
  CHECK_THROWS_AS(PhiSpec::from_json(j), lfnet::ConfigError);
}

TEST_CASE("time-coded models are exact adjoints, measure white as 1 and crop to patches",
          "[optics][time]") {
  torch::manual_seed(11);
  for (const char* name : {"time_aperture", "coded_exposure", "exposure_aperture", "asp", "mask"}) {
    auto phi = make_phi(time_spec(name, 2, 4));
    INFO(name);
    REQUIRE(phi->rows() == 20);
    REQUIRE(phi->frames() == 4);
    auto x = torch::rand({2, 20, 5, 24, 26}, torch::kFloat64);
    auto y = torch::rand({2, 2, 24, 26}, torch::kFloat64);
    auto ax = phi->forward(x);
    REQUIRE(ax.sizes() == y.sizes());
    const double lhs = (ax * y).sum().item<double>(),
                 rhs = (x * phi->adjoint(y)).sum().item<double>();
    CHECK(std::abs(lhs - rhs) < 1e-10 * std::abs(lhs));
    // 72 x 72 holds whole periods of every code (4, 8 and 9).
    auto white = phi->forward(torch::ones({20, 5, 72, 72}, torch::kFloat64));
    CHECK(white.mean().item<double>() == Approx(1.0).epsilon(1e-12));
    auto a = phi->patch_matrix(5, 7, 9, 9, torch::kFloat64);
    REQUIRE(a.sizes() == torch::IntArrayRef({int64_t{2} * 81, int64_t{4} * 25 * 81}));
    auto lf = x[0];
    auto patch = lf.slice(2, 5, 14).slice(3, 7, 16).reshape({-1});
    auto want = ax[0].slice(1, 5, 14).slice(2, 7, 16).reshape({-1});
    lfnet::test::require_close(torch::matmul(a, patch), want, 1e-12);
    // A stale 5-row light field is refused.
    CHECK_THROWS(phi->forward(torch::rand({5, 5, 8, 8})));
  }
}

TEST_CASE("each pixel of a coded exposure integrates its share of the sub-frames",
          "[optics][time]") {
  auto phi = make_phi(time_spec("coded_exposure", 1, 4));
  CHECK(phi->spec().params.at("period") == 4);
  CHECK(phi->period() == 4);
  auto w = phi->pixel_weights(0, 0, 4, 4, torch::kFloat64).view({1, 4, 5, 5, 4, 4});
  // Sub-frame t of pixel (y, x) is on at every view or at none.
  auto on = (w > 0).to(torch::kInt64);
  CHECK(torch::equal(on.amax({2, 3}), on.amin({2, 3})));
  // Half of the 4 sub-frames at every pixel, and the pixels do not all take the same half.
  auto per_pixel = on.select(2, 0).select(2, 0).sum(1);  // (1, 4, 4)
  CHECK(torch::all(per_pixel == 2).item<bool>());
  auto frames_of = on.select(2, 0).select(2, 0)[0];  // (T, 4, 4)
  auto first = frames_of.select(1, 0).select(1, 0).unsqueeze(1).unsqueeze(2);
  CHECK_FALSE(torch::equal(frames_of, first.expand_as(frames_of)));
  // A pixel's measurements share its shutter unless asked otherwise.
  auto spec = time_spec("coded_exposure", 2, 4);
  auto two = make_phi(spec)->pixel_weights(0, 0, 4, 4, torch::kFloat64).view({2, 4, 5, 5, 4, 4});
  CHECK(torch::equal(two[0] > 0, two[1] > 0));
  spec.params = {{"shared", false}};
  two = make_phi(spec)->pixel_weights(0, 0, 4, 4, torch::kFloat64).view({2, 4, 5, 5, 4, 4});
  CHECK_FALSE(torch::equal(two[0] > 0, two[1] > 0));
  // The aperture codes change from sub-frame to sub-frame.
  auto ap = make_phi(time_spec("time_aperture", 1, 4))->pixel_weights(0, 0, 1, 1, torch::kFloat64);
  auto per_frame = ap.view({4, 25});
  CHECK_FALSE(torch::equal(per_frame[0], per_frame[1]));
}

TEST_CASE("a still camera over T sub-frames measures a still scene as the still camera does",
          "[optics][time]") {
  torch::manual_seed(2);
  auto lf = torch::rand({1, 5, 5, 20, 22}, torch::kFloat64);
  lfnet::LightFieldSequence still_scene(lf.unsqueeze(0).expand({4, 1, 5, 5, 20, 22}));
  for (const char* name : {"asp", "mask", "aperture", "lenslet"}) {
    INFO(name);
    auto still = make_phi(time_spec(name, 2, 1));
    auto over = make_phi(time_spec(name, 2, 4));
    CHECK(over->spec().frames == 4);
    CHECK(over->spec().params == still->spec().params);
    lfnet::test::require_close(over->forward(still_scene.stacked().data().to(torch::kFloat64)),
                               still->forward(lf), 1e-6);
  }
  // Random projections mix pixels: they have no form over sub-frames.
  CHECK_THROWS_AS(make_phi(time_spec("random", 2, 4)), lfnet::ConfigError);
}

TEST_CASE("a calibrated time-coded response is read as N x T U x V x P x P values",
          "[optics][time]") {
  auto spec = time_spec("calibrated", 1, 2);
  std::vector<double> weights(static_cast<size_t>(1 * 10 * 5));
  for (size_t i = 0; i < weights.size(); ++i) weights[i] = static_cast<double>(i % 7);
  spec.params = {{"weights", weights}};
  auto phi = make_phi(spec);
  CHECK(phi->rows() == 10);
  auto w = phi->pixel_weights(0, 0, 1, 1, torch::kFloat64).reshape({-1});
  CHECK(w[8].item<double>() / w[1].item<double>() == Approx(1.0));  // 8 % 7 == 1 % 7
  spec.params = {{"weights", std::vector<double>(25, 1.0)}};        // one frame's worth
  CHECK_THROWS_AS(make_phi(spec), lfnet::ConfigError);
}

TEST_CASE("a time-coded camera's still equivalent is what a still scene sees", "[optics][time]") {
  torch::manual_seed(6);
  auto lf = torch::rand({5, 5, 16, 16}, torch::kFloat64);
  const auto still_scene = lf.repeat({4, 1, 1, 1});  // the stacked sequence of 4 equal frames
  for (const char* name : {"exposure_aperture", "time_aperture", "coded_exposure", "mask"}) {
    INFO(name);
    const auto phi = make_phi(time_spec(name, 2, 4));
    const auto still = lfnet::optics::still_equivalent(*phi);
    CHECK(still->frames() == 1);
    CHECK(still->rows() == 5);
    lfnet::test::require_close(still->forward(lf), phi->forward(still_scene), 1e-12);
  }
  // A still model over sub-frames gives the model back, spec and all.
  CHECK(lfnet::optics::still_equivalent(*make_phi(time_spec("asp", 2, 4)))->spec() ==
        make_phi(time_spec("asp", 2, 1))->spec());
  // ASP pixels coded in time: a still scene sees the ASP itself.
  auto spec = time_spec("coded_exposure", 2, 4);
  spec.params = {{"base", "asp"}, {"base_params", {{"pair_alpha", 90}}}};
  const auto asp_exposure = make_phi(spec);
  auto asp = PhiSpec::parse("asp:2");
  asp.params = {{"pair_alpha", 90}};
  const auto still = lfnet::optics::still_equivalent(*asp_exposure);
  CHECK(lfnet::optics::same_response(*still, *make_phi(asp)));
  CHECK_FALSE(lfnet::optics::same_response(*still, *make_phi(PhiSpec::parse("mask:2"))));
  // Its sub-frames differ pixel by pixel: the exposure code.
  const auto w = asp_exposure->pixel_weights(0, 0, 4, 4, torch::kFloat64).view({2, 4, 5, 5, 4, 4});
  CHECK_FALSE(torch::equal(w.select(1, 0), w.select(1, 1)));
  spec.params = {{"base", "exposure_aperture"}};
  CHECK_THROWS_AS(make_phi(spec), lfnet::ConfigError);
}

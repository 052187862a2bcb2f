// A camera whose Phi differs from the nominal one (optics/calibration.h): each error against
// what it should be, computed another way.
#include "lfnet/optics/calibration.h"

#include <catch2/catch.hpp>

#include "lfnet/core/error.h"
#include "lfnet/optics/phi.h"

using lfnet::optics::CalibrationError;
using lfnet::optics::make_phi;
using lfnet::optics::perturbed_forward;
using lfnet::optics::perturbed_pixel_weights;
using lfnet::optics::PhiSpec;
using lfnet::optics::SensorPlacement;

namespace {

std::unique_ptr<lfnet::optics::Phi> coded_by(
    const std::string& text, const nlohmann::json& params = nlohmann::json::object()) {
  auto spec = PhiSpec::parse(text);
  spec.seed = 3;
  spec.params = params;
  return make_phi(spec);
}

CalibrationError error_of(const char* json) {
  return CalibrationError::from_json(nlohmann::json::parse(json));
}

bool same_weights(const torch::Tensor& a, const torch::Tensor& b, double tol = 1e-6) {
  return a.sizes() == b.sizes() && (a - b).abs().max().item<double>() < tol;
}

}  // namespace

TEST_CASE("no calibration error is the nominal Phi", "[optics][calibration]") {
  torch::manual_seed(4);
  const auto lf = torch::rand({5, 5, 23, 31});
  for (const auto* text : {"asp:2", "mask:2", "aperture:3"}) {
    INFO(text);
    const auto phi = coded_by(text);
    CHECK(same_weights(perturbed_forward(*phi, {}, lf), phi->forward(lf)));
    CHECK(same_weights(perturbed_pixel_weights(*phi, {}, 3, 5, 7, 9, {}),
                       phi->pixel_weights(3, 5, 7, 9)));
  }
}

TEST_CASE("a modulation-depth error is the ASP of that depth", "[optics][calibration]") {
  // The ASP's cosines average to zero over the view grid, so scaling the weights about their
  // mean over the views scales m.
  const auto nominal = coded_by("asp:2");
  const auto shallow = coded_by("asp:2", {{"depth", 0.9}});
  const auto weights =
      perturbed_pixel_weights(*nominal, error_of(R"({"depth": -0.1})"), 0, 0, 4, 4, {});
  CHECK(same_weights(weights, shallow->pixel_weights(0, 0, 4, 4), 1e-5));
  CHECK_FALSE(same_weights(weights, nominal->pixel_weights(0, 0, 4, 4), 1e-3));
}

TEST_CASE("a code shift of whole pixels moves the mask; half a pixel averages",
          "[optics][calibration]") {
  const auto phi = coded_by("mask:2");
  REQUIRE(phi->period() > 1);
  const auto shifted =
      perturbed_pixel_weights(*phi, error_of(R"({"shift_y": 1, "shift_x": -2})"), 4, 6, 8, 8, {});
  CHECK(same_weights(shifted, phi->pixel_weights(5, 4, 8, 8)));
  const auto half = perturbed_pixel_weights(*phi, error_of(R"({"shift_x": 0.5})"), 4, 6, 8, 8, {});
  const auto mean = 0.5 * (phi->pixel_weights(4, 6, 8, 8) + phi->pixel_weights(4, 7, 8, 8));
  CHECK(same_weights(half, mean));
  // A code the same at every pixel does not move.
  const auto asp = coded_by("asp:2");
  CHECK(same_weights(perturbed_pixel_weights(*asp, error_of(R"({"shift_x": 0.5, "period": 0.02})"),
                                             0, 0, 4, 4, {}),
                     asp->pixel_weights(0, 0, 4, 4)));
}

TEST_CASE("a period error drifts the code across the sensor", "[optics][calibration]") {
  const auto phi = coded_by("mask:2");
  const int64_t t = phi->period();
  // 1 + 1/t: pixel y reads the code at y + y/t, a whole pixel further every t pixels.
  const auto error =
      error_of(("{\"period\": " + std::to_string(1.0 / static_cast<double>(t)) + "}").c_str());
  const auto weights = perturbed_pixel_weights(*phi, error, 0, 0, 2 * t, 2 * t, {});
  for (int64_t y : {int64_t{0}, t}) {
    const int64_t code = y + y / t;
    CHECK(same_weights(weights.select(3, y).select(3, 0),
                       phi->pixel_weights(code, 0, 1, 1).select(3, 0).select(3, 0), 1e-5));
  }
}

TEST_CASE("an angular shift displaces the response by views, held at the edge",
          "[optics][calibration]") {
  const auto phi = coded_by("asp:2");
  const auto nominal = phi->pixel_weights(0, 0, 1, 1);  // (N, U, V, 1, 1)
  const auto shifted =
      perturbed_pixel_weights(*phi, error_of(R"({"angular_shift_u": 1})"), 0, 0, 1, 1, {});
  CHECK(same_weights(shifted.slice(1, 0, 4), nominal.slice(1, 1, 5)));
  CHECK(same_weights(shifted.select(1, 4), nominal.select(1, 4)));
  const auto half =
      perturbed_pixel_weights(*phi, error_of(R"({"angular_shift_v": -0.5})"), 0, 0, 1, 1, {});
  CHECK(same_weights(half.select(2, 2), 0.5 * (nominal.select(2, 1) + nominal.select(2, 2))));
  CHECK(same_weights(half.select(2, 0), nominal.select(2, 0)));
}

TEST_CASE("vignetting dims the corners by its share and spares the centre",
          "[optics][calibration]") {
  const auto phi = coded_by("asp:2");
  const auto error = error_of(R"({"vignetting": 0.2})");
  const SensorPlacement sensor{0, 0, 101, 101};
  const auto weights = perturbed_pixel_weights(*phi, error, 0, 0, 101, 101, sensor);
  const auto nominal = phi->pixel_weights(0, 0, 101, 101);
  const auto gain = weights.sum({0, 1, 2}) / nominal.sum({0, 1, 2});  // (101, 101)
  CHECK(gain[50][50].item<double>() == Approx(1.0).margin(1e-4));
  CHECK(gain[0][0].item<double>() == Approx(0.8).margin(0.01));
  CHECK(gain[0][50].item<double>() == Approx(0.9).margin(0.01));
  // The forward model vignettes the whole sensor the same way.
  torch::manual_seed(2);
  const auto lf = torch::rand({5, 5, 101, 101});
  const auto y = perturbed_forward(*phi, error, lf);
  const auto direct = (lf.unsqueeze(0) * weights).sum({1, 2});
  CHECK(same_weights(y, direct, 1e-4));
}

TEST_CASE("a white frame's flat field undoes vignetting, whatever the exposure",
          "[optics][calibration]") {
  for (const std::string name : {"asp:2", "mask:2"}) {
    INFO(name);
    const auto phi = coded_by(name);
    const int64_t h = 61, w = 83;
    const auto nominal = lfnet::optics::nominal_white(*phi, h, w);
    // The nominal camera's white frame, computed without the period's tiling.
    CHECK(same_weights(nominal, phi->forward(torch::ones({5, 5, h, w})), 1e-5));
    const auto error = error_of(R"({"vignetting": 0.1})");
    // A white frame at 0.7 of white, through the vignetted camera.
    const auto white = perturbed_forward(*phi, error, torch::full({5, 5, h, w}, 0.7));
    const auto gain = lfnet::optics::flat_field_gain(white, nominal);
    REQUIRE(gain.sizes() == torch::IntArrayRef({h, w}));
    // 1 - 0.1 r^2, r over the half-diagonal: the fitted peak is the centre.
    const double cy = h / 2.0, cx = w / 2.0;
    const auto dy = (torch::arange(h, torch::kFloat64) + 0.5 - cy).square().unsqueeze(1);
    const auto dx = (torch::arange(w, torch::kFloat64) + 0.5 - cx).square().unsqueeze(0);
    const auto expected = 1 - 0.1 * (dy + dx) / (cy * cy + cx * cx);
    CHECK(same_weights(gain.to(torch::kFloat64), expected, 1e-4));
    CHECK(gain[0][0].item<double>() == Approx(0.9).margin(0.01));
    // A scene through the vignetted camera, flat-fielded, is the nominal camera's.
    torch::manual_seed(4);
    const auto lf = torch::rand({5, 5, h, w});
    const auto corrected =
        lfnet::optics::apply_flat_field(perturbed_forward(*phi, error, lf), gain);
    const auto nominal_sensor = phi->forward(lf);
    CHECK((corrected - nominal_sensor).abs().max().item<double>() < 1e-4);
    // Without the correction the corners are 10 % off.
    CHECK((perturbed_forward(*phi, error, lf) - nominal_sensor).abs().max().item<double>() > 0.02);
  }
  const auto phi = coded_by("asp:2");
  const auto nominal = lfnet::optics::nominal_white(*phi, 20, 30);
  CHECK_THROWS_WITH(lfnet::optics::flat_field_gain(torch::ones({2, 20, 31}), nominal),
                    Catch::Contains("white frame"));
  CHECK_THROWS_WITH(lfnet::optics::flat_field_gain(torch::zeros({2, 20, 30}), nominal),
                    Catch::Contains("no light"));
  CHECK_THROWS_WITH(
      lfnet::optics::apply_flat_field(torch::ones({2, 20, 30}), torch::ones({20, 31})),
      Catch::Contains("same size"));
  CHECK_THROWS_AS(lfnet::optics::nominal_white(*coded_by("random:2"), 18, 18), lfnet::ConfigError);
}

TEST_CASE("calibration errors refuse bad values and non-local codes", "[optics][calibration]") {
  CHECK_THROWS_WITH(error_of(R"({"vignetting": 1.5})"), Catch::Contains("vignetting"));
  CHECK_THROWS_WITH(error_of(R"({"depth": -1})"), Catch::Contains("depth"));
  CHECK_THROWS_WITH(error_of(R"({"dpeth": 0.1})"), Catch::Contains("dpeth"));
  const auto random = coded_by("random:2");
  CHECK_THROWS_AS(
      perturbed_forward(*random, error_of(R"({"depth": 0.1})"), torch::rand({5, 5, 9, 9})),
      lfnet::ConfigError);
}

#include "lfnet/io/phi_io.h"

#include <catch2/catch.hpp>

#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/cfa.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
namespace io = lfnet::io;
namespace optics = lfnet::optics;

TEST_CASE("a Phi written as a calibrated folder reads back as the same camera", "[io][phi]") {
  lfnet::test::TempDir tmp;
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(3);
  for (const char* label : {"asp:2", "mask:3", "aperture:2", "lenslet:4"}) {
    INFO(label);
    auto spec = optics::PhiSpec::parse(label);
    const auto phi = optics::make_phi(spec);
    const std::string dir = tmp / spec.name;
    io::write_calibrated_phi(*phi, dir);
    REQUIRE(io::is_calibrated_phi(dir));
    REQUIRE(io::is_calibrated_phi(dir + "/phi.json"));
    const auto back_spec = io::read_calibrated_phi(dir);
    CHECK(back_spec.name == "calibrated");
    CHECK(back_spec.n == phi->measurements());
    CHECK(back_spec.params.at("period") == phi->period());
    const auto back = optics::make_phi(back_spec);
    // Simulations and pseudo-inverses are equal bit for bit, in both precisions.
    for (auto dtype : {torch::kFloat32, torch::kFloat64}) {
      auto lf = torch::rand({5, 5, 23, 31}, gen).to(dtype);
      CHECK(torch::equal(back->forward(lf), phi->forward(lf)));
      auto y = phi->forward(lf);
      CHECK(torch::equal(back->adjoint(y), phi->adjoint(y)));
      CHECK(torch::equal(back->pinv_matrix(2, 3, 9, 9, optics::kDefaultPinvLambda, dtype),
                         phi->pinv_matrix(2, 3, 9, 9, optics::kDefaultPinvLambda, dtype)));
    }
    // The spec survives JSON (checkpoints and sensor.json store it) unchanged.
    CHECK(optics::PhiSpec::from_json(back_spec.to_json()) == back_spec);
  }
}

TEST_CASE("a time-coded Phi is written and read with its sub-frames", "[io][phi][time]") {
  lfnet::test::TempDir tmp;
  const auto phi = optics::make_phi(optics::PhiSpec::parse("exposure_aperture:2@3"));
  const std::string dir = tmp / "video";
  io::write_calibrated_phi(*phi, dir);
  const auto meta = lfnet::read_json_file(dir + "/phi.json");
  CHECK(meta.at("rows") == 5);
  CHECK(meta.at("frames") == 3);
  const auto back_spec = io::read_calibrated_phi(dir);
  CHECK(back_spec.frames == 3);
  const auto back = optics::make_phi(back_spec);
  REQUIRE(back->rows() == 15);
  auto lf = torch::rand({15, 5, 12, 10}, torch::kFloat64);
  CHECK(torch::equal(back->forward(lf), phi->forward(lf)));
}

TEST_CASE("a calibrated folder names its camera's colour filter array", "[io][phi]") {
  lfnet::test::TempDir tmp;
  const auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const std::string dir = tmp / "camera";
  io::write_calibrated_phi(*phi, dir);
  CHECK_FALSE(optics::camera_cfa(io::read_calibrated_phi(dir).to_json()));
  auto meta = lfnet::read_json_file(dir + "/phi.json");
  meta["cfa"] = {{"pattern", "GBRG"}};
  lfnet::write_json_file(dir + "/phi.json", meta);
  const auto spec = io::read_calibrated_phi(dir);
  const auto cfa = optics::camera_cfa(spec.to_json());
  REQUIRE(cfa);
  CHECK(cfa->pattern() == "GBRG");
  // The Phi itself is the grey one's; the spec carries the array through JSON and an export.
  const auto back = optics::make_phi(optics::PhiSpec::from_json(spec.to_json()));
  CHECK(optics::camera_cfa(back->spec().to_json())->pattern() == "GBRG");
  io::write_calibrated_phi(*back, tmp / "again");
  CHECK(lfnet::read_json_file(tmp / "again/phi.json")["cfa"] == cfa->to_json());
  // --cfa agrees with it or is refused; without --cfa the camera's is used.
  CHECK(optics::resolve_cfa("", spec.to_json())->pattern() == "GBRG");
  CHECK(optics::resolve_cfa("GBRG", spec.to_json())->pattern() == "GBRG");
  CHECK_THROWS_WITH(optics::resolve_cfa("RGGB", spec.to_json()),
                    Catch::Contains("not the colour filter array of the camera"));
  CHECK(optics::resolve_cfa("RGGB", phi->spec().to_json())->pattern() == "RGGB");
  // A malformed array is refused naming the sidecar's field.
  meta["cfa"] = {{"pattern", "RGBX"}};
  lfnet::write_json_file(dir + "/phi.json", meta);
  CHECK_THROWS_WITH(io::read_calibrated_phi(dir), Catch::Contains("cfa"));
}

TEST_CASE("a measured response in 16-bit images is scaled and normalised", "[io][phi]") {
  lfnet::test::TempDir tmp;
  const std::string dir = tmp.path().string();
  // Two measurements of a 3 x 3 grid, period 2: pixel (y, x) of measurement n weighs view
  // (u, v) by (1 + n + u + 2 v + y + x) / 20.
  auto code = torch::empty({2, 3, 3, 2, 2}, torch::kFloat64);
  auto acc = code.accessor<double, 5>();
  for (int n = 0; n < 2; ++n)
    for (int u = 0; u < 3; ++u)
      for (int v = 0; v < 3; ++v)
        for (int y = 0; y < 2; ++y)
          for (int x = 0; x < 2; ++x) acc[n][u][v][y][x] = (1 + n + u + 2 * v + y + x) / 20.0;
  for (int n = 0; n < 2; ++n) {
    auto image = code[n].permute({2, 0, 3, 1}).reshape({6, 6});
    io::write_image(dir + "/m" + std::to_string(n) + ".png", image, 16);
  }
  nlohmann::json meta = {{"format", "lfnet-calibrated-phi"},
                         {"version", 1},
                         {"n", 2},
                         {"rows", 3},
                         {"cols", 3},
                         {"period", 2},
                         {"files", {"m0.png", "m1.png"}},
                         {"scale", 4.0}};
  lfnet::write_json_file(dir + "/phi.json", meta);
  const auto phi = optics::make_phi(io::read_calibrated_phi(dir));
  auto w = phi->pixel_weights(0, 0, 2, 2, torch::kFloat64);
  // Normalised: a white light field measures 1 on average over the period.
  CHECK(w.sum({1, 2}).mean().item<double>() == Approx(1.0).epsilon(1e-12));
  // The shape of the response is kept (16-bit quantisation: 1 / 65535 of full scale).
  auto want = code / code.sum({1, 2}).mean();
  lfnet::test::require_close(w, want, 1e-4, 0);
  // Without normalisation the scale applies as given.
  meta["normalise"] = false;
  lfnet::write_json_file(dir + "/phi.json", meta);
  auto raw =
      optics::make_phi(io::read_calibrated_phi(dir))->pixel_weights(0, 0, 2, 2, torch::kFloat64);
  lfnet::test::require_close(raw, code * 4.0, 1e-4, 0);
}

TEST_CASE("a malformed calibrated folder is refused naming the file and field", "[io][phi]") {
  lfnet::test::TempDir tmp;
  const std::string dir = tmp.path().string();
  io::write_calibrated_phi(*optics::make_phi(optics::PhiSpec::parse("asp:2")), dir);
  const auto good = lfnet::read_json_file(dir + "/phi.json");
  auto expect_error = [&](const nlohmann::json& meta, const std::string& fragment) {
    lfnet::write_json_file(dir + "/phi.json", meta);
    REQUIRE_THROWS_WITH(io::read_calibrated_phi(dir), Catch::Contains(fragment));
  };
  auto m = good;
  m["format"] = "something-else";
  expect_error(m, "format is \"something-else\"");
  m = good;
  m["version"] = 2;
  expect_error(m, "version 2 is not supported");
  m = good;
  m["n"] = 3;
  expect_error(m, "files lists 2 images, but n is 3");
  m = good;
  m["rows"] = 4;
  expect_error(m, "must be one channel of 5x4 pixels");
  m = good;
  m["n"] = 2.5;
  expect_error(m, "$.n");
  m = good;
  m["files"] = {"response_1.tif", "../response_2.tif"};
  expect_error(m, "inside the folder");
  m = good;
  m["files"] = {"response_1.tif", "missing.tif"};
  expect_error(m, "missing.tif does not exist");
  m = good;
  m["scale"] = -1;
  expect_error(m, "scale must be a positive number");
  m = good;
  m["extra"] = 1;
  expect_error(m, "$.extra");
  // An all-zero response measures nothing: the file is named.
  lfnet::write_json_file(dir + "/phi.json", good);
  io::write_image(dir + "/zero.png", torch::zeros({5, 5}), 8);
  m = good;
  m["files"] = {"zero.png", "zero.png"};
  m["normalise"] = true;
  expect_error(m, "zero.png is zero everywhere");
  REQUIRE_THROWS_WITH(io::read_calibrated_phi(dir + "/nothing"), Catch::Contains("no phi.json"));
  // A sidecar is known by its format, not its name: a Phi spec file called phi.json is not one,
  // and a sidecar under another name is.
  lfnet::test::TempDir other;
  lfnet::write_json_file(other / "phi.json", {{"name", "asp"}, {"n", 2}});
  CHECK_FALSE(io::is_calibrated_phi(other / "phi.json"));
  CHECK_FALSE(io::is_calibrated_phi(other.path().string()));
  lfnet::write_json_file(dir + "/camera.json", good);
  CHECK(io::is_calibrated_phi(dir + "/camera.json"));
  CHECK(io::read_calibrated_phi(dir + "/camera.json").n == 2);
  // Random projections have no per-pixel response.
  REQUIRE_THROWS_AS(
      io::write_calibrated_phi(*optics::make_phi(optics::PhiSpec::parse("random:2")), dir),
      lfnet::ConfigError);
}

TEST_CASE("a learned mask is exported with the pattern to print", "[io][phi]") {
  lfnet::test::TempDir tmp;
  // A code of period 2 for 2 x 3 views: transmittances 0, 0.25, 0.5, 0.75 and 1, normalised.
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(4);
  const auto open = torch::randint(0, 5, {2, 2, 3, 2, 2}, gen).to(torch::kFloat64) / 4;
  const auto w = open / open.sum({1, 2}).mean();
  optics::PhiSpec spec;
  spec.name = "calibrated";
  spec.n = 2;
  spec.rows = 2;
  spec.cols = 3;
  spec.params = {
      {"period", 2},
      {"weights", std::vector<double>(w.data_ptr<double>(), w.data_ptr<double>() + w.numel())},
      {"normalise", false},
      {"source", "learned mask"}};
  const auto phi = optics::make_phi(spec);
  CHECK(io::is_learned_mask(*phi));
  CHECK_FALSE(io::is_learned_mask(*optics::make_phi(optics::PhiSpec::parse("mask:2"))));
  const auto names = io::write_printable_mask(*phi, tmp / "out");
  REQUIRE(names == std::vector<std::string>{"mask_1.png", "mask_2.png"});
  for (int64_t k = 0; k < 2; ++k) {
    const auto image = io::read_image(tmp / ("out/" + names[k]));  // (1, T U, T V)
    REQUIRE(image.sizes() == torch::IntArrayRef({1, 4, 6}));
    // Pixel (y, x)'s U x V block holds its transmittances over the largest (here 1).
    for (int64_t y = 0; y < 2; ++y) {
      for (int64_t x = 0; x < 2; ++x) {
        const auto block = image[0].slice(0, y * 2, y * 2 + 2).slice(1, x * 3, x * 3 + 3);
        const auto want = open.select(0, k).select(2, y).select(2, x).to(torch::kFloat32) /
                          open.max().item<double>();
        CHECK(torch::allclose(block, want, 0, 0.6 / 255));
      }
    }
  }
  // Random projections have no per-pixel code to print.
  CHECK_THROWS_AS(io::write_printable_mask(*optics::make_phi(optics::PhiSpec::parse("random:2")),
                                           tmp / "random"),
                  lfnet::ConfigError);
}

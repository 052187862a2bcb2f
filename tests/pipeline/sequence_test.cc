// Light-field sequences through simulate, evaluate and reconstruct with time-coded cameras.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/sequence.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/export.h"
#include "lfnet/pipeline/render.h"
#include "lfnet/pipeline/simulate.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/train/checkpoint.h"
#include "lfnet/train/trainer.h"
#include "support/small_nets.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
namespace io = lfnet::io;
namespace pipeline = lfnet::pipeline;
namespace test = lfnet::test;
using lfnet::LightField;
using lfnet::LightFieldSequence;

namespace {
// Four frames of a 7 x 7 light field whose content moves right by 2 px per frame.
LightFieldSequence moving_sequence() {
  const auto lf = test::parallax_light_field(7, 7, 16, 40, 1, -1);
  std::vector<LightField> frames;
  for (int64_t t = 0; t < 4; ++t) frames.emplace_back(torch::roll(lf.data(), {2 * t}, {4}));
  return LightFieldSequence(frames);
}
// The exposure-coded ASP camera of configs/video/asp-exposure.json (4 sub-frames).
std::unique_ptr<lfnet::optics::Phi> exposure_camera() {
  return lfnet::optics::make_phi(lfnet::optics::PhiSpec::from_json(
      lfnet::read_json_file(std::string(LFNET_SOURCE_DIR) + "/configs/video/asp-exposure.json")));
}

// The options of a small lfnet net of that camera: 4 frames of 5 x 5 views, U-Net `image`.
lfnet::nn::NetworkOptions video_options(const nlohmann::json& image) {
  return lfnet::nn::NetworkOptions::from_json(
      {{"architecture", "lfnet"},
       {"measurements", 2},
       {"frames", 4},
       {"patch", {{"rows", 20}, {"cols", 5}, {"height", 16}, {"width", 16}}},
       {"image", image}});
}

// `net` holding one period of `phi`'s per-pixel weights.
void set_camera(lfnet::nn::LightFieldNet& net, const lfnet::optics::Phi& phi) {
  const int64_t p = phi.period();
  net->set_phi(phi.pixel_weights(0, 0, p, p));
}
}  // namespace

TEST_CASE("simulate stacks a sequence's windowed frames for a time-coded camera",
          "[pipeline][sequence]") {
  test::TempDir tmp;
  const auto seq = moving_sequence();
  io::write_light_field_sequence(seq, tmp / "seq", {"exr", 32});
  pipeline::SimulateSource source;
  source.lf = tmp / "seq";
  const auto input = pipeline::load_simulate_input(source, 4);
  REQUIRE(input.lf.rows() == 20);
  CHECK(input.source.at("frames") == 4);
  // Rows 5 t .. 5 t + 4 are frame t's central 5 x 5 views.
  const auto central = seq.central(5);
  CHECK(torch::equal(input.lf.view(5 * 3 + 2, 4), central.frame(3).view(2, 4)));
  CHECK(torch::equal(input.lf.view(5 * 1 + 0, 0), central.frame(1).view(0, 0)));
  // A still camera, or one of other sub-frames, does not code it.
  CHECK_THROWS_WITH(pipeline::load_simulate_input(source, 1), Catch::Contains("NAME:N@4"));
  CHECK_THROWS_WITH(pipeline::load_simulate_input(source, 3), Catch::Contains("@4"));
  // A still folder is the same in every sub-frame.
  io::write_light_field(seq.frame(0), tmp / "still", {"exr", 32});
  source.lf = tmp / "still";
  const auto still = pipeline::load_simulate_input(source, 4);
  CHECK(torch::equal(still.lf.view(5 * 3 + 1, 1), still.lf.view(1, 1)));
}

TEST_CASE("evaluate scores a sequence per frame and writes a folder per frame",
          "[pipeline][sequence]") {
  test::TempDir tmp;
  io::write_light_field_sequence(moving_sequence(), tmp / "seq", {"exr", 32});
  pipeline::EvaluateRequest q;
  q.lf = tmp / "seq";
  q.phi = "exposure_aperture:2@4";
  q.method = "pinv";
  q.keep_estimate = true;
  auto result = pipeline::evaluate_request(q);
  auto& record = result.record;
  CHECK(record.at("frames") == 4);
  const auto per_frame = record.at("per_frame_psnr_db");
  REQUIRE(per_frame.size() == 4);
  REQUIRE(record.at("per_view_psnr_db").size() == 20);
  // The frames' mean squared errors average to the whole sequence's.
  double mse = 0;
  for (const auto& p : per_frame) mse += std::pow(10.0, -p.get<double>() / 10) / 4;
  CHECK(-10 * std::log10(mse) == Approx(record.at("psnr_db").get<double>()).epsilon(1e-6));
  pipeline::write_evaluation(result, record, tmp / "out");
  for (int t = 0; t < 4; ++t) {
    const auto frame = tmp / ("out/frame_" + std::to_string(t));
    CHECK(fs::exists(frame + "/lf_5_5.png"));
    CHECK_FALSE(fs::exists(frame + "/index.html"));
  }
  CHECK(io::sequence_frames(tmp / "out") == 4);
  // One viewer page for the sequence, with a time slider over its 4 frames of 5 x 5 views.
  std::ifstream in(tmp / "out/index.html");
  const std::string page((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  CHECK(page.find("\"frames\":4") != std::string::npos);
  CHECK(page.find("\"rows\":5") != std::string::npos);
  CHECK(page.find("id=\"time\"") != std::string::npos);
  // The sequence in a still camera's evaluation is refused, naming the camera it needs.
  q.phi = "asp:2";
  CHECK_THROWS_WITH(pipeline::evaluate_request(q), Catch::Contains("@4"));
}

TEST_CASE("per-frame PSNR averages the views' errors of each frame", "[pipeline][sequence]") {
  // Two frames of 1 x 2 views: 20 and 30 dB (MSE 0.01 and 0.001) average to 0.0055.
  const nlohmann::json table = {{20.0, 30.0}, {10.0, nullptr}};
  const auto frames = lfnet::eval::per_frame_psnr(table, 2);
  CHECK(frames[0].get<double>() == Approx(-10 * std::log10(0.0055)));
  CHECK(frames[1].get<double>() == Approx(-10 * std::log10(0.05)));
  CHECK_THROWS(lfnet::eval::per_frame_psnr(table, 3));
}

TEST_CASE("the still-scene baseline of a still camera over sub-frames is the still method",
          "[pipeline][sequence]") {
  test::TempDir tmp;
  io::write_light_field(moving_sequence().frame(0), tmp / "still", {"exr", 32});
  pipeline::EvaluateRequest q;
  q.lf = tmp / "still";
  q.phi = "asp:2";
  q.method = "pinv";
  const double still = pipeline::evaluate_request(q).record.at("psnr_db").get<double>();
  q.phi = "asp:2@4";
  q.as_still = true;
  const auto record = pipeline::evaluate_request(q).record;
  CHECK(record.at("as_still") == true);
  CHECK(record.at("still_phi").at("name") == "asp");
  CHECK(record.at("psnr_db").get<double>() == Approx(still).epsilon(1e-5));
  // Without --as-still, pinv of the 100 rays of 4 sub-frames is another estimate.
  q.as_still = false;
  CHECK(pipeline::evaluate_request(q).record.at("psnr_db").get<double>() != Approx(still));
  // A still camera has no still-scene baseline.
  q.phi = "asp:2";
  q.as_still = true;
  CHECK_THROWS_WITH(pipeline::evaluate_request(q), Catch::Contains("time-coded"));
}

TEST_CASE("render --lf gives a real light field synthetic motion, said as such",
          "[pipeline][sequence]") {
  test::TempDir tmp;
  io::write_light_field(moving_sequence().frame(0), tmp / "still", {"png", 16});
  pipeline::RenderRequest r;
  r.lf = tmp / "still";
  r.frames = 3;
  r.shift = {2, 0};
  r.walk = 1;
  r.out = tmp / "seq";
  const auto summary = pipeline::render_to_folder(r);
  CHECK(summary.shape == "3x1x7x5x16x36");
  CHECK(io::sequence_frames(tmp / "seq") == 3);
  const auto meta = lfnet::read_json_file(tmp / "seq/sequence.json");
  CHECK(meta.at("synthetic_motion").at("walk") == 1);
  // Records name the motion their source declares.
  CHECK(pipeline::declared_motion_speed(tmp / "seq") == Approx(2.0));
  CHECK_FALSE(pipeline::declared_motion_speed(tmp / "still").has_value());
  CHECK(pipeline::declared_motion_speed(std::string(LFNET_SOURCE_DIR) +
                                        "/configs/video/scenes/heldout_window-s2.json")
            .value() == Approx(2.0).epsilon(1e-3));
  CHECK(pipeline::declared_motion_speed(std::string(LFNET_SOURCE_DIR) +
                                        "/configs/video/scenes/heldout_window-s0.json")
            .value() == 0.0);
  const auto seq = io::read_light_field_sequence(tmp / "seq");
  const auto lf = io::read_light_field(tmp / "still");
  // Frame 2 is the source's views 3.. moved right by 4 px (crop from 0), frame 0 from 4.
  CHECK(torch::equal(seq.frame(2).view(0, 0), lf.view(0, 2).narrow(2, 0, 36)));
  CHECK(torch::equal(seq.frame(0).view(0, 0), lf.view(0, 0).narrow(2, 4, 36)));
  r.frames = 1;
  r.out = tmp / "seq1";
  CHECK_THROWS_AS(pipeline::render_to_folder(r), lfnet::ConfigError);
  r.lf.clear();
  r.random_seed = 3;
  CHECK_THROWS_WITH(pipeline::render_to_folder(r), Catch::Contains("--lf only"));
}

TEST_CASE("an lfnet net of a time-coded camera starts from the still estimate in every frame",
          "[pipeline][sequence]") {
  const auto phi = exposure_camera();
  auto options = video_options({{"channels", 4}, {"levels", 2}, {"blocks", 1}});
  CHECK(options.to_json().at("frames") == 4);
  lfnet::nn::LightFieldNet net(options);
  set_camera(net, *phi);
  // The base of a still scene is the still camera's pseudo-inverse, the same in every frame.
  const auto lf = test::parallax_light_field(5, 5, 16, 16, 1, -1).data()[0];
  const auto still_scene = lf.repeat({4, 1, 1, 1});
  const auto sensor = phi->forward(still_scene);
  const auto base = net->pixel_hold_image(sensor.unsqueeze(0))[0].view({4, 25, 16, 16});
  // A fresh net's output is that base; what it reads is the minimum-norm pseudo-inverse, dark
  // where a pixel's sub-frame was not exposed.
  {
    torch::NoGradGuard no_grad;
    net->eval();
    const auto out = net->forward_image(sensor.unsqueeze(0))[0].reshape({4, 25, 16, 16});
    CHECK(torch::allclose(out, base, 1e-4, 1e-5));
    const auto read = net->pixel_pinv_image(sensor.unsqueeze(0))[0].view({4, 25, 16, 16});
    CHECK((read.abs().sum(1) < 1e-6).sum().item<int64_t>() > 0);
  }
  CHECK(torch::allclose(base[0], base[3]));
  const auto still = lfnet::optics::still_equivalent(*phi);
  const auto still_pinv = still->pinv_matrix(4, 4, 1, 1, net->options().pinv_lambda);
  const auto pixel = sensor.select(1, 4).select(1, 4).to(torch::kFloat32);  // (N)
  CHECK(
      torch::allclose(base[2].select(1, 4).select(1, 4), torch::mv(still_pinv, pixel), 1e-4, 1e-5));
  // Still nets keep the JSON they had: no "frames".
  options.frames = 1;
  options.patch.rows = 5;
  CHECK_FALSE(options.to_json().contains("frames"));
  auto bad = options.to_json();
  bad["frames"] = 3;
  CHECK_THROWS_AS(lfnet::nn::NetworkOptions::from_json(bad), lfnet::ConfigError);
}

TEST_CASE("an lfnet net of a time-coded camera starts as a still net applied as if still",
          "[pipeline][sequence]") {
  const auto phi = exposure_camera();
  const auto still_phi = lfnet::optics::still_equivalent(*phi);
  const nlohmann::json image = {
      {"channels", 4}, {"levels", 2}, {"blocks", 1}, {"noise_input", true}};
  const auto still_options = lfnet::nn::NetworkOptions::from_json(
      {{"architecture", "lfnet"},
       {"measurements", 2},
       {"patch", {{"rows", 5}, {"cols", 5}, {"height", 16}, {"width", 16}}},
       {"image", image}});
  lfnet::nn::LightFieldNet still(still_options);
  set_camera(still, *still_phi);
  test::randomise_image_net(still, 11);
  lfnet::nn::LightFieldNet video(video_options(image));
  set_camera(video, *phi);
  test::randomise_image_net(video, 12);
  lfnet::nn::WarmStartSource from;
  from.network = still_options.to_json();
  const auto report =
      lfnet::train::warm_start_net(*video, lfnet::train::module_state(*still), from, "", "still");
  CHECK(report.mapped.size() == 3);  // the input's weights, the output's weights and bias
  CHECK(report.widened.empty());
  CHECK(report.reinitialised.empty());
  CHECK(report.copied.size() + 3 == video->parameters().size());
  // On a still scene the video net is the still net, in every frame; on a moving one it is not.
  torch::NoGradGuard no_grad;
  still->eval();
  video->eval();
  const auto sequence = moving_sequence();
  const auto lf = sequence.frame(0).data()[0].slice(0, 1, 6).slice(1, 1, 6).slice(2, 0, 16);
  const auto sensor = phi->forward(lf.repeat({4, 1, 1, 1})).unsqueeze(0);
  const auto want = still->forward_image(sensor, 0, 0.02)[0];
  const auto out = video->forward_image(sensor, 0, 0.02)[0].view({4, 5, 5, 16, 40});
  for (int64_t t = 0; t < 4; ++t) test::require_close(out[t], want, 1e-4);
  // The time-coded pseudo-inverse is read with no weight yet: a moving scene's output is the
  // still net's on its image too.
  std::vector<torch::Tensor> frames;
  for (int64_t t = 0; t < 4; ++t) {
    frames.push_back(sequence.frame(t).data()[0].slice(0, 1, 6).slice(1, 1, 6).slice(2, 0, 16));
  }
  const auto moving = phi->forward(torch::cat(frames, 0)).unsqueeze(0);
  const auto moved = video->forward_image(moving, 0, 0.02)[0].view({4, 5, 5, 16, 40});
  test::require_close(moved[3], still->forward_image(moving, 0, 0.02)[0], 1e-4);
}

TEST_CASE("an lfnet net of a time-coded camera exports: the file reconstructs as the checkpoint",
          "[pipeline][sequence][export]") {
  const auto phi = exposure_camera();
  lfnet::nn::LightFieldNet net(
      video_options({{"channels", 4}, {"levels", 2}, {"blocks", 1}, {"noise_input", true}}));
  set_camera(net, *phi);
  test::randomise_image_net(net, 13);
  test::TempDir tmp;
  test::save_net(net, *phi, "joint_scratch", tmp / "video.ckpt");
  lfnet::pipeline::ExportRequest request;
  request.model = tmp / "video.ckpt";
  request.out = tmp / "video.pt";
  request.check = 1;
  const auto r = lfnet::pipeline::export_model(request);  // compares the two on a sensor image
  CHECK(r.max_difference <= 1e-5);
  // A moving sequence's sensor image: 4 frames of 5 x 5 views come back from the file as from
  // the checkpoint.
  const auto loaded = lfnet::nn::load_script(tmp / "video.pt");
  std::vector<torch::Tensor> frames;
  for (int64_t t = 0; t < 4; ++t) {
    frames.push_back(moving_sequence().frame(t).data()[0].slice(0, 1, 6).slice(1, 1, 6));
  }
  const auto sensor = phi->forward(torch::cat(frames, 0));
  torch::NoGradGuard no_grad;
  net->eval();
  const auto want = lfnet::recon::reconstruct_sensor_tiled(net, sensor, 16, false, 0.02);
  const auto got = loaded.reconstruct_image(sensor, 16, false, 0.02);
  REQUIRE(got.sizes() == torch::IntArrayRef({20, 5, 16, 40}));
  CHECK(want.std().item<double>() > 1e-3);
  test::require_close(got, want.squeeze(0), 1e-5);
}

// pipeline::run_batch: finding the items under a folder, and one record per item and method
// without the program.
#include <catch2/catch.hpp>

#include <filesystem>
#include <utility>
#include <vector>

#include "lfnet/core/json.h"
#include "lfnet/core/sequence.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/batch.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/simulate.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using namespace lfnet;

namespace {
// IN/b: a light field of known parallax; IN/acq: its coded capture with asp:2.
void write_inputs(const std::string& in) {
  const auto lf = test::parallax_light_field(5, 5, 20, 22, 1, -1);
  io::write_light_field(lf, in + "/b");
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  pipeline::SimulateRequest s;
  s.lf = lf;
  s.phi = phi.get();
  fs::create_directories(in + "/acq");
  pipeline::write_acquisition(s, in + "/acq");
}
// A small lfnet net for asp:2 with random U-Net weights (its single pass is not
// mirror-equivariant), saved as a checkpoint.
void save_small_lfnet(const std::string& path) {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  nn::NetworkOptions no;
  no.architecture = nn::kLfnetArchitecture;
  no.measurements = phi->measurements();
  no.patch = {phi->rows(), phi->cols(), 16, 16};
  lfnet::test::edit_image(no, [&](lfnet::nn::ImageNetOptions& no_image) {
    no_image.channels = 6;
    no_image.blocks = 1;
  });
  nn::LightFieldNet net(no);
  net->set_phi(phi->pixel_weights(0, 0, phi->period(), phi->period()));
  test::randomise_image_net(net, 5);
  test::save_net(net, *phi, "joint", path);
}
}  // namespace

TEST_CASE("discover_items finds acquisitions and light fields, and records what it cannot read",
          "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  io::write_light_field(test::parallax_light_field(5, 5, 20, 22, 1, -1), tmp / "in/scenes/a");
  fs::create_directories(tmp / "in/empty");
  fs::create_symlink(tmp / "in/nowhere", tmp / "in/broken");
  const auto items = pipeline::discover_items(tmp / "in");
  REQUIRE(items.size() == 4);  // sorted by name; the empty folder is no item
  CHECK(items[0].name == "acq");
  CHECK(items[0].kind == "reconstruct");
  CHECK(items[1].name == "b");
  CHECK(items[1].kind == "evaluate");
  CHECK(items[2].name == "broken");
  CHECK(items[2].kind == "unreadable");
  CHECK(items[2].error.find("broken link") != std::string::npos);
  CHECK(items[3].name == "scenes/a");
  CHECK(items[3].kind == "evaluate");
  CHECK_THROWS_WITH(pipeline::discover_items(tmp / "in/nowhere"),
                    Catch::Contains("does not exist"));
  CHECK_THROWS_WITH(pipeline::discover_items(tmp / "in/scenes/a/lf_1_1.png"),
                    Catch::Contains("is not a folder"));
}

TEST_CASE("a sequence folder is one item, evaluated per frame", "[pipeline][batch]") {
  test::TempDir tmp;
  const auto lf = test::parallax_light_field(5, 5, 16, 20, 1, -1);
  std::vector<LightField> frames;
  for (int64_t t = 0; t < 4; ++t) frames.emplace_back(torch::roll(lf.data(), {t}, {4}));
  io::write_light_field_sequence(LightFieldSequence(frames), tmp / "in/seq");
  fs::create_directories(tmp / "in/gap/frame_0");
  io::write_light_field(lf, tmp / "in/gap/frame_0");
  io::write_light_field(lf, tmp / "in/gap/frame_2");
  const auto items = pipeline::discover_items(tmp / "in");
  REQUIRE(items.size() == 2);  // no frame_t folder is an item of its own
  CHECK(items[0].name == "gap");
  CHECK(items[0].kind == "unreadable");
  CHECK(items[0].error.find("frame_1") != std::string::npos);
  CHECK(items[1].name == "seq");
  CHECK(items[1].kind == "evaluate");
  pipeline::BatchOptions o;
  o.in = tmp / "in";
  o.out = tmp / "out";
  o.phi = "exposure_aperture:2@4";
  o.methods = {"no-parallax"};
  const auto summary = pipeline::run_batch(o);
  REQUIRE(summary.records.size() == 2);
  CHECK(summary.failures == 1);  // the sequence with a gap
  const auto& record = summary.records[1];
  CHECK(record["item"] == "seq");
  CHECK(record["status"] == "ok");
  const auto full = read_json_file(tmp / "out/records/seq__no-parallax.json");
  CHECK(full.at("frames") == 4);
  CHECK(full.at("per_frame_psnr_db").size() == 4);
}

TEST_CASE("a whole-image net's progress counts the sensor's pixels", "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  save_small_lfnet(tmp / "net.ckpt");
  pipeline::ReconstructRequest request;
  request.sensor = tmp / "in/acq";
  request.model = tmp / "net.ckpt";
  std::vector<std::pair<int64_t, int64_t>> steps;
  const auto r = pipeline::reconstruct_acquisition(
      request, [&](int64_t done, int64_t total) { steps.emplace_back(done, total); });
  const int64_t pixels = r.lf.height() * r.lf.width();  // the sensor's, as the views'
  REQUIRE(steps.size() == 1);
  CHECK((steps[0] == std::pair<int64_t, int64_t>{pixels, pixels}));
}

TEST_CASE("run_batch writes one record per item and method and counts the failures",
          "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  pipeline::BatchOptions o;
  o.in = tmp / "in";
  o.out = tmp / "out";
  o.phi = "asp:2";
  o.methods = {"pinv", "no-parallax"};
  const auto summary = pipeline::run_batch(o);
  REQUIRE(summary.records.size() == 4);
  // The acquisition has no truth: no-parallax fails there and only there.
  CHECK(summary.failures == 1);
  CHECK(summary.records[0]["item"] == "acq");
  CHECK(summary.records[0]["method"] == "pinv");
  CHECK(summary.records[0]["status"] == "ok");
  CHECK(fs::exists(tmp.path() / "out/acq/pinv/reconstruction.json"));
  CHECK(summary.records[1]["status"] == "error");
  CHECK(summary.records[2]["item"] == "b");
  CHECK(summary.records[2]["psnr_db"].get<double>() >
        summary.records[3]["psnr_db"].get<double>());  // pinv beats no-parallax on parallax
  CHECK(fs::exists(tmp.path() / "out/summary.csv"));
  CHECK(read_json_file(tmp / "out/summary.json").size() == 4);
  CHECK(fs::exists(tmp.path() / "out/records/b__pinv.json"));
  // An unknown method is refused before any work, and the output stays as it was.
  o.methods = {"nosuch"};
  o.force = true;
  CHECK_THROWS_WITH(pipeline::run_batch(o), Catch::Contains("--methods"));
  CHECK(read_json_file(tmp / "out/summary.json").size() == 4);
}

TEST_CASE("run_batch --self-ensemble averages the mirror passes of an lfnet checkpoint",
          "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  save_small_lfnet(tmp / "m.ckpt");

  pipeline::BatchOptions o;
  o.in = tmp / "in";
  o.model = tmp / "m.ckpt";
  o.out = tmp / "single";
  const auto single = pipeline::run_batch(o);
  o.self_ensemble = true;
  o.out = tmp / "ensemble";
  const auto ensemble = pipeline::run_batch(o);
  REQUIRE(ensemble.failures == 0);
  REQUIRE(ensemble.records.size() == 2);
  CHECK(fs::exists(tmp.path() / "ensemble/acq/net/reconstruction.json"));
  const auto& scored = ensemble.records[1];
  CHECK(scored["item"] == "b");
  CHECK(scored["self_ensemble"] == true);
  CHECK_FALSE(single.records[1].contains("self_ensemble"));
  CHECK(scored["psnr_db"].get<double>() !=
        Approx(single.records[1]["psnr_db"].get<double>()).margin(1e-3));
  // The same number as lfnet evaluate --self-ensemble on the folder.
  pipeline::EvaluateRequest q;
  q.lf = tmp / "in/b";
  q.model = tmp / "m.ckpt";
  q.self_ensemble = true;
  CHECK(pipeline::evaluate_request(q).record["psnr_db"].get<double>() ==
        Approx(scored["psnr_db"].get<double>()).margin(1e-6));
  CHECK(scored["self_ensemble_passes"] == 4);
  // The first two passes only: another number, the same as evaluate's with two passes.
  o.self_ensemble_passes = 2;
  o.out = tmp / "pair";
  const auto pair = pipeline::run_batch(o);
  REQUIRE(pair.records.size() == 2);
  CHECK(pair.records[1]["self_ensemble_passes"] == 2);
  CHECK(pair.records[1]["psnr_db"].get<double>() !=
        Approx(scored["psnr_db"].get<double>()).margin(1e-6));
  q.self_ensemble_passes = 2;
  CHECK(pipeline::evaluate_request(q).record["psnr_db"].get<double>() ==
        Approx(pair.records[1]["psnr_db"].get<double>()).margin(1e-6));
  // Passes without the self-ensemble are refused.
  q.self_ensemble = false;
  CHECK_THROWS_WITH(pipeline::evaluate_request(q),
                    Catch::Contains("--ensemble-passes applies to --self-ensemble"));
  o.self_ensemble_passes = 0;
  // Another method, or no model, is refused before any output exists.
  o.out = tmp / "refused";
  o.methods = {"net", "pinv"};
  CHECK_THROWS_WITH(pipeline::run_batch(o), Catch::Contains("--self-ensemble applies to"));
  o.methods = {};
  o.model.clear();
  o.phi = "asp:2";
  CHECK_THROWS_WITH(pipeline::run_batch(o), Catch::Contains("pass --model"));
  CHECK_FALSE(fs::exists(tmp.path() / "refused"));
}

TEST_CASE(
    "run_batch takes the shared flags: --tile, --precision, and --phi checked against "
    "the model",
    "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  save_small_lfnet(tmp / "m.ckpt");

  pipeline::BatchOptions o;
  o.in = tmp / "in";
  o.model = tmp / "m.ckpt";
  o.out = tmp / "whole";
  const auto whole = pipeline::run_batch(o);
  REQUIRE(whole.failures == 0);
  // Small tiles give the same light field to float rounding (tiles carry their halo).
  o.tile = 8;
  o.out = tmp / "tiled";
  const auto tiled = pipeline::run_batch(o);
  REQUIRE(tiled.failures == 0);
  CHECK(tiled.records[0]["tile"] == 8);  // the acquisition's reconstruction record
  CHECK(whole.records[0]["tile"] == 0);
  CHECK(tiled.records[1]["psnr_db"].get<double>() ==
        Approx(whole.records[1]["psnr_db"].get<double>()).margin(1e-4));
  // bfloat16 runs the U-Net in lower precision: close, and recorded.
  o.tile = 0;
  o.precision = nn::Precision::kBFloat16;
  o.out = tmp / "bf16";
  const auto bf16 = pipeline::run_batch(o);
  REQUIRE(bf16.failures == 0);
  CHECK(bf16.records[0]["precision"] == "bfloat16");
  CHECK(bf16.records[1]["psnr_db"].get<double>() ==
        Approx(whole.records[1]["psnr_db"].get<double>()).margin(0.5));
  // A --phi that contradicts the model is an error record for every item, never ignored.
  o.precision = nn::Precision::kFloat32;
  o.phi = "mask:2";
  o.out = tmp / "contradiction";
  const auto refused = pipeline::run_batch(o);
  CHECK(refused.failures == 2);
  for (const auto& r : refused.records) {
    CHECK(r["status"] == "error");
    CHECK(r["error"].get<std::string>().find("does not match the model") != std::string::npos);
  }
}

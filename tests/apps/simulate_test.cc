// lfnet simulate: the acquisition folder contract (docs/acquisition.md).
#include <catch2/catch.hpp>

#include <filesystem>
#include <string>
#include <vector>

#include "lfnet/core/json.h"
#include "lfnet/core/patches.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

namespace {

// A 7 x 7-view colour light field of 20 x 24 pixels, written as 16-bit PNGs.
lfnet::LightField write_test_light_field(const std::string& dir) {
  torch::manual_seed(1);
  lfnet::LightField lf(torch::rand({3, 7, 7, 20, 24}));
  lfnet::io::write_light_field(lf, dir, {"png", 16});
  return lfnet::LightField(lfnet::io::read_light_field(dir).data());
}

std::string simulate(const std::string& args) {
  return lfnet_binary() + " --threads 1 --log-level warn simulate " + args;
}

}  // namespace

TEST_CASE("simulate writes a sensor image that is the forward model of the central views",
          "[app][simulate]") {
  lfnet::test::TempDir tmp;
  auto lf = write_test_light_field(tmp / "lf");
  std::string out;
  REQUIRE(run_command(simulate("--lf " + (tmp / "lf") + " --phi mask:3 --out " + (tmp / "acq")),
                      out) == 0);
  auto acq = lfnet::io::read_acquisition(tmp / "acq");
  CHECK(acq.meta.at("mode") == "sensor");
  CHECK(acq.meta.at("phi").at("name") == "mask");
  CHECK(acq.meta.at("phi").at("params").at("period") == 9);
  CHECK(acq.meta.at("views").at("rows") == nlohmann::json({2, 6}));
  CHECK(acq.meta.at("color") == false);
  CHECK(acq.meta.at("noise_sigma") == 0.0);
  CHECK(acq.meta.at("lfnet_version") == "0.1.0");
  CHECK(fs::exists(tmp / "acq/preview.png"));
  REQUIRE(acq.sensor.sizes() == torch::IntArrayRef({1, 3, 20, 24}));
  auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::from_json(acq.meta.at("phi")));
  auto want = phi->forward(lf.central(5).grey().data());
  lfnet::test::require_close(acq.sensor, want, 1e-6);
  // Nothing but the folder itself is left beside it.
  CHECK(std::distance(fs::directory_iterator(tmp.path()), fs::directory_iterator()) == 2);
}

TEST_CASE("simulate in colour, with noise and a Phi spec file", "[app][simulate]") {
  lfnet::test::TempDir tmp;
  auto lf = write_test_light_field(tmp / "lf");
  lfnet::optics::PhiSpec spec;
  spec.name = "aperture";
  spec.n = 2;
  spec.rows = 3;
  spec.cols = 3;
  spec.seed = 4;
  lfnet::write_json_file(tmp / "phi.json", spec.to_json());
  std::string out;
  REQUIRE(
      run_command(simulate("--lf " + (tmp / "lf") + " --phi " + (tmp / "phi.json") +
                           " --views 1:3,2:4 --color --noise 0.1 --seed 3 --out " + (tmp / "acq")),
                  out) == 0);
  auto acq = lfnet::io::read_acquisition(tmp / "acq");
  CHECK(fs::exists(tmp / "acq/sensor_g.tif"));
  CHECK(acq.meta.at("color") == true);
  CHECK(acq.meta.at("effects").at("gaussian").at("sigma") == 0.1);
  CHECK(acq.meta.at("seed") == 3);
  REQUIRE(acq.sensor.sizes() == torch::IntArrayRef({3, 2, 20, 24}));
  auto phi = lfnet::optics::make_phi(spec);
  auto clean = phi->forward(lf.window({0, 3}, {1, 4}).data());
  CHECK((acq.sensor - clean).std().item<double>() == Approx(0.1).epsilon(0.1));
  // The same seed gives the same image.
  REQUIRE(run_command(
              simulate("--lf " + (tmp / "lf") + " --phi " + (tmp / "phi.json") +
                       " --views 1:3,2:4 --color --noise 0.1 --seed 3 --out " + (tmp / "again")),
              out) == 0);
  CHECK(torch::equal(lfnet::io::read_acquisition(tmp / "again").sensor, acq.sensor));
  // A spec for another window is an error.
  CHECK(run_command(simulate("--lf " + (tmp / "lf") + " --phi " + (tmp / "phi.json") + " --out " +
                             (tmp / "bad")),
                    out) != 0);
  CHECK(out.find("3x3 views") != std::string::npos);
}

TEST_CASE("simulate per_patch writes every patch's measurements", "[app][simulate]") {
  lfnet::test::TempDir tmp;
  auto lf = write_test_light_field(tmp / "lf");
  std::string out;
  REQUIRE(run_command(simulate("--lf " + (tmp / "lf") + " --phi random:2 --mode per_patch " +
                               "--stride 4 --out " + (tmp / "acq")),
                      out) == 0);
  auto acq = lfnet::io::read_acquisition(tmp / "acq");
  const lfnet::PatchGrid grid(20, 24, 9, 9, 4);
  CHECK(acq.meta.at("grid").at("stride") == 4);
  CHECK(acq.meta.at("grid").at("patch") == 9);
  REQUIRE(acq.measurements.sizes() == torch::IntArrayRef({1, grid.size(), 162}));
  auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::from_json(acq.meta.at("phi")));
  auto want = lfnet::optics::measure_patches(*phi, lf.central(5).grey().data(), grid,
                                             lfnet::optics::SimulationMode::kPerPatch);
  lfnet::test::require_close(acq.measurements[0], want.values, 1e-5);
}

TEST_CASE("simulate never overwrites a folder unless forced", "[app][simulate]") {
  lfnet::test::TempDir tmp;
  write_test_light_field(tmp / "lf");
  fs::create_directories(tmp / "acq");
  { std::ofstream(tmp / "acq/keep.txt") << "mine"; }
  std::string out;
  const std::string cmd = simulate("--lf " + (tmp / "lf") + " --phi asp:2 --out " + (tmp / "acq"));
  CHECK(run_command(cmd, out) != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find("--force") != std::string::npos);
  CHECK(fs::exists(tmp / "acq/keep.txt"));
  REQUIRE(run_command(cmd + " --force", out) == 0);
  CHECK_FALSE(fs::exists(tmp / "acq/keep.txt"));
  CHECK(fs::exists(tmp / "acq/sensor.json"));
  // A failing simulation leaves neither a folder nor a temporary one behind.
  CHECK(run_command(simulate("--lf " + (tmp / "lf") + " --phi random:2 --effects " +
                             (tmp / "missing.json") + " --out " + (tmp / "none")),
                    out) != 0);
  CHECK_FALSE(fs::exists(tmp / "none"));
  CHECK(std::distance(fs::directory_iterator(tmp.path()), fs::directory_iterator()) == 2);
}

TEST_CASE("simulate describes a Phi and plots its weights", "[app][simulate]") {
  lfnet::test::TempDir tmp;
  std::string out;
  REQUIRE(run_command(simulate("--phi asp:25 --describe"), out) == 0);
  CHECK(out.find("condition:  25.46") != std::string::npos);
  CHECK(out.find("rank 25 of 25") != std::string::npos);
  CHECK(out.find("quadrature") != std::string::npos);
  REQUIRE(run_command(simulate("--phi mask:2 --describe"), out) == 0);
  CHECK(out.find("81 pixel matrices of 2 x 25") != std::string::npos);
  REQUIRE(run_command(simulate("--phi lenslet:4 --plot-weights " + (tmp / "plots")), out) == 0);
  // Drawn by scripts/figures.py: a PNG, its SVG twin and the spec they were drawn from.
  CHECK(fs::file_size(tmp / "plots/lenslet-n4.png") > 1000);
  CHECK(fs::file_size(tmp / "plots/lenslet-n4.svg") > 1000);
  const auto spec = nlohmann::json::parse(lfnet::test::read_bytes(tmp / "plots/lenslet-n4.json"));
  const auto& tiles = spec["figures"][0]["tiles"];  // [pixel][measurement][u][v]
  REQUIRE(tiles.size() == 4);                       // 4 pixels down
  REQUIRE(tiles[0].size() == 4);                    // 4 measurements across
  REQUIRE(tiles[0][0].size() == 5);                 // 5 x 5 views
  // Pixel 0 of the sensor sees view 0 in measurement 0: the top-left view is 1, the next 0.
  CHECK(tiles[0][0][0][0] == 1.0);
  CHECK(tiles[0][0][0][1] == 0.0);
  CHECK(spec["figures"][0]["signed"] == false);
  CHECK(spec["figures"][0]["pixels"] == nlohmann::json::parse("[[0,0],[0,1],[0,2],[0,3]]"));
  // A code of a 2 x 2 period (the learned ASP's tile) shows all four pixels, row by row: its
  // second row measures differently from its first.
  const std::string learned =
      (fs::path(LFNET_SOURCE_DIR) / "models" / "lfnet-learned-asp-n2-full.ckpt").string();
  REQUIRE(run_command(simulate("--phi " + learned + " --plot-weights " + (tmp / "tile")), out) ==
          0);
  const auto tile = nlohmann::json::parse(lfnet::test::read_bytes(tmp / "tile/calibrated-n2.json"));
  const auto& rows = tile["figures"][0]["tiles"];
  REQUIRE(rows.size() == 4);
  CHECK(tile["figures"][0]["pixels"] == nlohmann::json::parse("[[0,0],[0,1],[1,0],[1,1]]"));
  CHECK(rows[0] != rows[2]);
  CHECK(fs::file_size(tmp / "tile/calibrated-n2.png") > 1000);
  CHECK(run_command(simulate("--phi prism:2 --describe"), out) != 0);
  CHECK(out.find("known: aperture, asp, calibrated, coded_exposure, exposure_aperture, lenslet, "
                 "mask, random, time_aperture") != std::string::npos);
  CHECK(run_command(simulate("--phi asp:2"), out) != 0);
  CHECK(out.find("nothing to do") != std::string::npos);
}

TEST_CASE("simulate and evaluate take a camera whose Phi is off", "[app][simulate]") {
  lfnet::test::TempDir tmp;
  write_test_light_field(tmp / "lf");
  std::string out;
  const std::string lf = " --lf " + (tmp / "lf") + " --phi asp:2";
  REQUIRE(run_command(simulate(lf + " --out " + (tmp / "nominal")), out) == 0);
  REQUIRE(
      run_command(simulate(lf + " --out " + (tmp / "off") + " --camera-error '{\"depth\": -0.2}'"),
                  out) == 0);
  const auto nominal = lfnet::io::read_acquisition(tmp / "nominal");
  const auto off = lfnet::io::read_acquisition(tmp / "off");
  CHECK(off.meta["camera_error"]["depth"].get<double>() == Approx(-0.2));
  CHECK_FALSE(nominal.meta.contains("camera_error"));
  // A shallower ASP pair: the same sum of the two channels, less difference between them.
  lfnet::test::require_close(off.sensor.sum(1), nominal.sensor.sum(1), 1e-4, 1e-4);
  const auto diff = [](const torch::Tensor& s) {
    return (s.select(1, 0) - s.select(1, 1)).abs().sum().item<double>();
  };
  CHECK(diff(off.sensor) == Approx(0.8 * diff(nominal.sensor)).epsilon(0.02));

  // A flat grey light field, which pinv recovers well from the nominal camera.
  lfnet::io::write_light_field(lfnet::LightField(torch::full({1, 5, 5, 20, 24}, 0.5)), tmp / "flat",
                               {"png", 16});
  const std::string evaluate = lfnet_binary() + " --threads 1 --log-level warn evaluate --lf " +
                               (tmp / "flat") + " --phi asp:2 --method pinv --stride 3";
  REQUIRE(run_command(evaluate + " --json " + (tmp / "a.json"), out) == 0);
  REQUIRE(run_command(
              evaluate + " --json " + (tmp / "b.json") + " --camera-error '{\"vignetting\": 0.3}'",
              out) == 0);
  const auto a = lfnet::read_json_file(tmp / "a.json");
  const auto b = lfnet::read_json_file(tmp / "b.json");
  CHECK(b["camera_error"]["vignetting"].get<double>() == Approx(0.3));
  CHECK(b["psnr_db"].get<double>() < a["psnr_db"].get<double>() - 3);
  // --json makes the folders it names, and takes them away again when no record comes.
  REQUIRE(run_command(evaluate + " --json " + (tmp / "new/deeper/a.json"), out) == 0);
  CHECK(lfnet::read_json_file(tmp / "new/deeper/a.json")["psnr_db"] == a["psnr_db"]);
  CHECK(run_command(lfnet_binary() + " --threads 1 --log-level warn evaluate --lf " +
                        (tmp / "no-such-lf") + " --phi asp:2 --method pinv --json " +
                        (tmp / "gone/deeper/a.json"),
                    out) != 0);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK_FALSE(fs::exists(tmp / "gone"));
  // Bad errors: one line naming the key, before any work.
  CHECK(run_command(evaluate + " --camera-error '{\"dpeth\": 0.1}'", out) != 0);
  CHECK(out.find("dpeth") != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK(run_command(evaluate + " --mode per_patch --camera-error '{\"depth\": 0.1}'", out) != 0);
  CHECK(out.find("sensor mode") != std::string::npos);
  CHECK(run_command(simulate(lf + " --out " + (tmp / "pp") +
                             " --mode per_patch --camera-error '{\"depth\": 0.1}'"),
                    out) != 0);
  CHECK_FALSE(fs::exists(tmp / "pp"));
}

TEST_CASE("evaluate, reconstruct and batch self-calibrate a camera whose response is displaced",
          "[app][simulate]") {
  lfnet::test::TempDir tmp;
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 1 --log-level warn ";
  REQUIRE(run_command(lfnet +
                          "render --random 93002 --size 96x96 --grey --disparity-range -2:2 "
                          "--bits 16 --out " +
                          (tmp / "lf"),
                      out) == 0);
  const std::string path = (fs::path(LFNET_SOURCE_DIR) / "models" / "lfnet-asp-n2.ckpt").string();
  const std::string model = " --model " + path;
  const std::string shifted = " --camera-error '{\"angular_shift_u\": 0.25}'";
  const std::string evaluate = lfnet + "evaluate --lf " + (tmp / "lf") + model + shifted;
  REQUIRE(run_command(evaluate + " --json " + (tmp / "plain.json"), out) == 0);
  REQUIRE(run_command(evaluate + " --self-calibrate --json " + (tmp / "told.json"), out) == 0);
  const auto plain = lfnet::read_json_file(tmp / "plain.json");
  const auto told = lfnet::read_json_file(tmp / "told.json");
  CHECK_FALSE(plain.contains("camera_error_estimated"));
  CHECK(told["camera_error_estimated"]["angular_shift_u"].get<double>() ==
        Approx(0.25).margin(0.06));
  CHECK(told["psnr_db"].get<double>() > plain["psnr_db"].get<double>() + 2);
  // Told the camera's error itself, as if measured: about as good as the estimate.
  REQUIRE(run_command(evaluate + " --tell-camera-error --json " + (tmp / "known.json"), out) == 0);
  const auto known = lfnet::read_json_file(tmp / "known.json");
  CHECK(known["camera_error_told"].get<bool>());
  CHECK(known["psnr_db"].get<double>() > plain["psnr_db"].get<double>() + 2);
  CHECK(std::abs(known["psnr_db"].get<double>() - told["psnr_db"].get<double>()) < 0.5);
  CHECK(run_command(evaluate + " --tell-camera-error --method pinv --json " + (tmp / "p.json"),
                    out) != 0);
  CHECK(out.find("--tell-camera-error") != std::string::npos);
  CHECK(run_command(lfnet + "evaluate --lf " + (tmp / "lf") + model + " --tell-camera-error",
                    out) != 0);

  // A displaced camera's acquisition, reconstructed with and without the estimate.
  REQUIRE(run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi " + path + shifted +
                          " --out " + (tmp / "acq"),
                      out) == 0);
  const std::string reconstruct = lfnet + "reconstruct --sensor " + (tmp / "acq") + model;
  REQUIRE(run_command(reconstruct + " --self-calibrate --out " + (tmp / "rec"), out) == 0);
  const auto record = lfnet::read_json_file(tmp / "rec/reconstruction.json");
  CHECK(record["camera_error_estimated"]["angular_shift_u"].get<double>() ==
        Approx(0.25).margin(0.06));
  // batch evaluates the light fields under a folder the same way.
  fs::create_directories(tmp / "set");
  fs::rename(tmp / "lf", tmp / "set/lf");
  REQUIRE(run_command(lfnet + "batch --input " + (tmp / "set") + model +
                          " --self-calibrate --out " + (tmp / "batch"),
                      out) == 0);
  const auto item = lfnet::read_json_file(tmp / "batch/records/lf__net.json");
  CHECK(std::abs(item["camera_error_estimated"]["angular_shift_u"].get<double>()) < 0.06);

  // What it cannot do: one line, before any work.
  CHECK(run_command(reconstruct + " --method pinv --self-calibrate --out " + (tmp / "pinv"), out) !=
        0);
  CHECK(out.find("--self-calibrate") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "pinv"));
  CHECK(run_command(reconstruct + " --self-calibrate --self-ensemble --out " + (tmp / "ens"),
                    out) != 0);
  CHECK(out.find("self-ensemble") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "ens"));
}

TEST_CASE("a white frame's flat field undoes vignetting in evaluate and reconstruct",
          "[app][simulate]") {
  lfnet::test::TempDir tmp;
  // A smooth scene without parallax, which pinv recovers well from the nominal camera.
  const auto y = torch::arange(40).unsqueeze(1).to(torch::kFloat32);
  const auto x = torch::arange(48).unsqueeze(0).to(torch::kFloat32);
  const auto image = 0.5 + 0.2 * torch::sin(x / 6) * torch::cos(y / 7);
  lfnet::io::write_light_field(lfnet::LightField(image.expand({1, 5, 5, 40, 48}).contiguous()),
                               tmp / "lf", {"png", 16});
  std::string out;
  const std::string camera_error = " --camera-error '{\"vignetting\": 0.3}'";
  const std::string vignetted = " --phi asp:2" + camera_error;
  // The camera's white frame: a uniform white light field of the sensor's size.
  REQUIRE(run_command(simulate("--white 40x48" + vignetted + " --out " + (tmp / "white")), out) ==
          0);
  const auto white = lfnet::io::read_acquisition(tmp / "white");
  CHECK(white.meta["source"]["kind"] == "white");
  REQUIRE(white.sensor.sizes() == torch::IntArrayRef({1, 2, 40, 48}));
  // Dimmer at the corners than at the centre, by about the vignetting.
  const double corner = white.sensor[0].select(1, 0).select(1, 0).sum().item<double>();
  const double centre = white.sensor[0].select(1, 20).select(1, 24).sum().item<double>();
  CHECK(corner / centre == Approx(0.7).margin(0.04));

  // evaluate on the nominal camera, the vignetted one, and the vignetted one flat-fielded by
  // `white`. Within the white frame's one scale: pinv's small bias here makes PSNR move by
  // 0.1 dB for a change of scale of 1e-4.
  const auto check_flat_field = [&](const std::string& evaluate, const std::string& white,
                                    const std::string& name) {
    std::string flat = camera_error;
    flat += " --flat-field ";
    flat += white;
    std::vector<nlohmann::json> r;
    for (const auto* extra : {"", camera_error.c_str(), flat.c_str()}) {
      const auto json = tmp / (name + std::to_string(r.size()) + ".json");
      std::string command = evaluate;
      command += " --json ";
      command += json;
      command += extra;
      REQUIRE(run_command(command, out) == 0);
      r.push_back(lfnet::read_json_file(json));
    }
    CHECK(r[1]["psnr_db"].get<double>() < r[0]["psnr_db"].get<double>() - 3);
    CHECK(r[2]["psnr_db"].get<double>() == Approx(r[0]["psnr_db"].get<double>()).margin(0.3));
    CHECK(r[2]["flat_field"] == true);
  };
  const std::string evaluate = lfnet_binary() + " --threads 1 --log-level warn evaluate --lf " +
                               (tmp / "lf") + " --phi asp:2 --method pinv --stride 3";
  check_flat_field(evaluate, tmp / "white", "grey");

  // reconstruct: the vignetted camera's sensor image, flat-fielded, is reconstructed as the
  // nominal camera's.
  const std::string lf = " --lf " + (tmp / "lf");
  REQUIRE(run_command(simulate(lf + " --phi asp:2 --out " + (tmp / "acq")), out) == 0);
  REQUIRE(run_command(simulate(lf + vignetted + " --out " + (tmp / "acq-off")), out) == 0);
  const std::string reconstruct =
      lfnet_binary() + " --threads 1 --log-level warn reconstruct --method pinv --stride 3";
  REQUIRE(run_command(reconstruct + " --sensor " + (tmp / "acq") + " --out " + (tmp / "rec"),
                      out) == 0);
  REQUIRE(run_command(reconstruct + " --sensor " + (tmp / "acq-off") + " --out " +
                          (tmp / "rec-flat") + " --flat-field " + (tmp / "white"),
                      out) == 0);
  const auto a = lfnet::io::read_light_field(tmp / "rec").data();
  const auto b = lfnet::io::read_light_field(tmp / "rec-flat").data();
  CHECK((a - b).abs().max().item<double>() < 2e-3);
  CHECK(lfnet::read_json_file(
            (fs::path(tmp / "rec-flat") / "reconstruction.json").string())["flat_field"] == true);
  // batch applies it to every acquisition it finds.
  REQUIRE(run_command(simulate(lf + vignetted + " --out " + (tmp / "items/acq-off")), out) == 0);
  REQUIRE(run_command(lfnet_binary() + " --threads 1 --log-level warn batch --input " +
                          (tmp / "items") + " --out " + (tmp / "batch") +
                          " --methods pinv --stride 3 --flat-field " + (tmp / "white"),
                      out) == 0);
  const auto c = lfnet::io::read_light_field(tmp / "batch/acq-off/pinv").data();
  CHECK(torch::equal(c, b));

  // Behind a Bayer pattern: the white frame of the colour camera, and colour PSNR.
  lfnet::io::write_light_field(lfnet::LightField(torch::stack({image, 1 - image, 0.8 * image})
                                                     .unsqueeze(1)
                                                     .unsqueeze(1)
                                                     .expand({3, 5, 5, 40, 48})
                                                     .contiguous()),
                               tmp / "colour", {"png", 16});
  REQUIRE(run_command(
              simulate("--white 40x48 --cfa RGGB" + vignetted + " --out " + (tmp / "white-rggb")),
              out) == 0);
  check_flat_field(lfnet_binary() + " --threads 1 --log-level warn evaluate --lf " +
                       (tmp / "colour") + " --phi asp:2 --cfa RGGB --method pinv --stride 3",
                   tmp / "white-rggb", "colour");

  // A white frame of another size or camera: one line, nothing written.
  REQUIRE(run_command(simulate("--white 40x49 --phi asp:2 --out " + (tmp / "white-other")), out) ==
          0);
  CHECK(run_command(reconstruct + " --sensor " + (tmp / "acq-off") + " --out " + (tmp / "bad") +
                        " --flat-field " + (tmp / "white-other"),
                    out) != 0);
  CHECK(out.find("--flat-field") != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK_FALSE(fs::exists(tmp / "bad"));
  // A white frame of another camera, or behind another colour filter array (or none).
  REQUIRE(run_command(simulate("--white 40x48 --phi mask:2 --out " + (tmp / "white-mask")), out) ==
          0);
  const std::pair<std::string, std::string> other[] = {
      {reconstruct + " --sensor " + (tmp / "acq-off") + " --flat-field " + (tmp / "white-mask"),
       "is a white frame of the camera mask:2; the sensor image's camera is asp:2"},
      {reconstruct + " --sensor " + (tmp / "acq-off") + " --flat-field " + (tmp / "white-rggb"),
       "was taken behind a colour filter array; the sensor image is grey"},
      {evaluate + " --cfa RGGB --flat-field " + (tmp / "white"),
       "is grey; the sensor image is behind a colour filter array"},
      {evaluate + " --cfa BGGR --flat-field " + (tmp / "white-rggb"),
       "behind another colour filter array"}};
  for (const auto& [command, message] : other) {
    INFO(command);
    CHECK(run_command(command + " --out " + (tmp / "bad"), out) != 0);
    CHECK(out.find(message) != std::string::npos);
    CHECK(std::count(out.begin(), out.end(), '\n') == 1);
    CHECK_FALSE(fs::exists(tmp / "bad"));
  }
  CHECK(run_command(evaluate + " --flat-field " + (tmp / "nothing-here"), out) != 0);
  CHECK(out.find("nothing-here") != std::string::npos);
  CHECK(run_command(simulate("--white 40by48 --phi asp:2 --out " + (tmp / "w2")), out) != 0);
  CHECK(out.find("--white") != std::string::npos);
}

TEST_CASE("a colour filter array: one sensor image, reconstructed and scored in colour",
          "[app][simulate]") {
  lfnet::test::TempDir tmp;
  const auto truth = write_test_light_field(tmp / "lf");  // 3 colours, 7 x 7 views
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 1 --log-level warn ";
  REQUIRE(run_command(
              simulate("--lf " + (tmp / "lf") + " --phi asp:2 --cfa GRBG --out " + (tmp / "acq")),
              out) == 0);
  const auto acq = lfnet::io::read_acquisition(tmp / "acq");
  REQUIRE(acq.sensor.sizes() == torch::IntArrayRef({1, 2, 20, 24}));  // one file of N channels
  CHECK(acq.meta["cfa"]["pattern"] == "GRBG");
  CHECK(acq.meta["light_field"]["channels"] == 3);
  CHECK(fs::exists(tmp / "acq/sensor.tif"));
  CHECK_FALSE(fs::exists(tmp / "acq/sensor_r.tif"));
  // Each pixel measures its own colour of the central views: green at (0, 0), red at (0, 1).
  const auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  const auto central = truth.window({1, 6}, {1, 6});
  const auto colour = phi->forward(central.data());  // (3, N, H, W)
  lfnet::test::require_close(acq.sensor[0].select(1, 0).select(1, 0),
                             colour[1].select(1, 0).select(1, 0), 1e-5, 1e-5);
  lfnet::test::require_close(acq.sensor[0].select(1, 0).select(1, 1),
                             colour[0].select(1, 0).select(1, 1), 1e-5, 1e-5);

  // pinv reconstructs the mosaicked light field and demosaics it: a colour light field.
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq") + " --out " +
                          (tmp / "rec"),
                      out) == 0);
  const auto rec = lfnet::io::read_light_field(tmp / "rec");
  CHECK(rec.channels() == 3);
  const auto record = lfnet::read_json_file(tmp / "rec/reconstruction.json");
  CHECK(record["cfa"]["pattern"] == "GRBG");
  // The same sensor image as a camera writes it, its colour filter array given by --cfa: the
  // same colour light field. An acquisition's --cfa may only repeat what it records.
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq/sensor.tif") +
                          " --phi asp:2 --cfa GRBG --out " + (tmp / "rec-plain"),
                      out) == 0);
  CHECK(torch::equal(lfnet::io::read_light_field(tmp / "rec-plain").data(), rec.data()));
  CHECK(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq") +
                        " --cfa GRBG --out " + (tmp / "rec-same"),
                    out) == 0);
  CHECK(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq") +
                        " --cfa RGGB --out " + (tmp / "rec-other"),
                    out) != 0);
  CHECK(out.find("--cfa RGGB contradicts") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "rec-other"));
  // A grey model refuses it.
  CHECK(run_command(lfnet + "reconstruct --method net --model " +
                        (std::string(LFNET_SOURCE_DIR) + "/models/lfnet-asp-n2.ckpt") +
                        " --sensor " + (tmp / "acq") + " --out " + (tmp / "net"),
                    out) != 0);
  CHECK(out.find("colour filter array") != std::string::npos);

  // evaluate --cfa scores colour and luma; the grey path stays as it was.
  const std::string evaluate = lfnet + "evaluate --lf " + (tmp / "lf") + " --phi asp:2 --stride 3";
  REQUIRE(run_command(evaluate + " --method pinv --cfa GRBG --json " + (tmp / "c.json"), out) == 0);
  REQUIRE(run_command(evaluate + " --method no-parallax --cfa GRBG --json " + (tmp / "n.json"),
                      out) == 0);
  const auto c = lfnet::read_json_file(tmp / "c.json");
  const auto n = lfnet::read_json_file(tmp / "n.json");
  CHECK(c["cfa"]["pattern"] == "GRBG");
  CHECK(c.contains("luma_psnr_db"));
  CHECK(n.contains("luma_psnr_db"));
  CHECK(c["psnr_db"].get<double>() != Approx(c["luma_psnr_db"].get<double>()).margin(1e-6));
  CHECK(run_command(evaluate + " --method pinv --cfa GRBG --mode per_patch", out) != 0);
  CHECK(out.find("sensor mode") != std::string::npos);
  CHECK(run_command(evaluate + " --method pinv --cfa RGBG", out) != 0);
  CHECK(out.find("RGGB") != std::string::npos);
  // A whole-image method of grey images is refused before it runs.
  CHECK(run_command(evaluate + " --method pinv-nlm --noise 0.05 --cfa GRBG", out) != 0);
  CHECK(out.find("method 'pinv-nlm' reconstructs grey sensor images") != std::string::npos);
  // batch evaluates light-field folders behind the same array.
  fs::create_directories(tmp / "in");
  fs::rename(tmp / "lf", tmp / "in/lf");
  REQUIRE(run_command(lfnet + "batch --input " + (tmp / "in") + " --out " + (tmp / "batch") +
                          " --methods pinv --phi asp:2 --stride 3 --cfa GRBG",
                      out) == 0);
  const auto b = lfnet::read_json_file(tmp / "batch/records/lf__pinv.json");
  CHECK(b["cfa"]["pattern"] == "GRBG");
  CHECK(b["psnr_db"].get<double>() == Approx(c["psnr_db"].get<double>()).margin(1e-9));
}

TEST_CASE("pinv-nlm is told the noise estimated from a sensor image of unknown noise",
          "[app][simulate]") {
  lfnet::test::TempDir tmp;
  lfnet::io::write_light_field(lfnet::LightField(torch::full({1, 5, 5, 64, 64}, 0.5)), tmp / "flat",
                               {"png", 16});
  std::string out;
  REQUIRE(run_command(simulate("--lf " + (tmp / "flat") + " --phi asp:2 --noise 0.1 --out " +
                               (tmp / "acq")),
                      out) == 0);
  const std::string lfnet = lfnet_binary() + " --threads 1 --log-level warn ";
  // The plain image, without the sidecar that records the noise: a camera's own.
  const std::string plain = " --phi asp:2 --sensor " + (tmp / "acq/sensor.tif");
  REQUIRE(run_command(lfnet + "reconstruct --method pinv-nlm" + plain + " --out " + (tmp / "nlm"),
                      out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --method pinv" + plain + " --out " + (tmp / "pinv"),
                      out) == 0);
  const auto record = lfnet::read_json_file(tmp / "nlm/reconstruction.json");
  CHECK(record["noise_sigma_estimated"] == true);
  CHECK(record["noise_sigma"][0].get<double>() == Approx(0.1).epsilon(0.1));
  // Told the estimate, the denoiser works: the flat field comes out flatter than pinv's.
  const auto nlm = lfnet::io::read_light_field(tmp / "nlm").data();
  const auto pinv = lfnet::io::read_light_field(tmp / "pinv").data();
  CHECK(nlm.std().item<double>() < 0.5 * pinv.std().item<double>());
  CHECK_FALSE(lfnet::read_json_file(tmp / "pinv/reconstruction.json").contains("noise_sigma"));
}

// A colour model (network.cfa, docs/architectures.md "Colour"): evaluate, reconstruct and batch
// run it on the sensor image of its colour filter array, and refuse what does not fit.
#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <filesystem>

#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/phi.h"
#include "support/small_nets.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

TEST_CASE("a colour model reconstructs the sensor image of its colour filter array",
          "[app][colour]") {
  lfnet::test::TempDir tmp;
  torch::manual_seed(4);
  lfnet::io::write_light_field(lfnet::LightField(torch::rand({3, 5, 5, 32, 36})), tmp / "in/lf",
                               {"png", 16});
  const std::string model = tmp / "colour.ckpt";
  lfnet::test::save_small_image_net("GRBG", 0, model);
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 1 --log-level warn ";
  REQUIRE(run_command(lfnet + "simulate --lf " + (tmp / "in/lf") +
                          " --phi asp:2 --cfa GRBG --out " + (tmp / "acq"),
                      out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --model " + model + " --sensor " + (tmp / "acq") +
                          " --out " + (tmp / "net"),
                      out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq") + " --out " +
                          (tmp / "pinv"),
                      out) == 0);
  // Colour views; untrained, the net is pinv's demosaiced light field but on the outermost
  // pixels, where pinv's demosaicing mirrors the image.
  const auto net = lfnet::io::read_light_field(tmp / "net").data();
  const auto pinv = lfnet::io::read_light_field(tmp / "pinv").data();
  REQUIRE(net.sizes() == torch::IntArrayRef({3, 5, 5, 32, 36}));
  auto inner = [](const torch::Tensor& x) { return x.slice(3, 1, -1).slice(4, 1, -1); };
  CHECK((inner(net) - inner(pinv)).abs().max().item<double>() < 1e-4);
  const auto record = lfnet::read_json_file(tmp / "net/reconstruction.json");
  CHECK(record["cfa"]["pattern"] == "GRBG");
  CHECK_FALSE(record.contains("demosaic"));  // the net's own
  CHECK(lfnet::read_json_file(tmp / "pinv/reconstruction.json")["demosaic"] == "bilinear");
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --demosaic malvar --sensor " +
                          (tmp / "acq") + " --out " + (tmp / "malvar"),
                      out) == 0);
  CHECK(lfnet::read_json_file(tmp / "malvar/reconstruction.json")["demosaic"] == "malvar");
  CHECK((lfnet::io::read_light_field(tmp / "malvar").data() - pinv).abs().max().item<double>() >
        1e-3);

  // evaluate scores it in colour and luma, as a whole image.
  const std::string evaluate = lfnet + "evaluate --lf " + (tmp / "in/lf") + " --model " + model;
  REQUIRE(run_command(evaluate + " --cfa GRBG --json " + (tmp / "e.json"), out) == 0);
  REQUIRE(run_command(lfnet + "evaluate --lf " + (tmp / "in/lf") +
                          " --phi asp:2 --method pinv --cfa GRBG --json " + (tmp / "p.json"),
                      out) == 0);
  const auto e = lfnet::read_json_file(tmp / "e.json");
  const auto p = lfnet::read_json_file(tmp / "p.json");
  CHECK(e["cfa"]["pattern"] == "GRBG");
  CHECK(e["whole_image"] == true);
  CHECK(e.contains("luma_psnr_db"));
  CHECK(e["psnr_db"].get<double>() == Approx(p["psnr_db"].get<double>()).margin(1.0));
  CHECK(p["demosaic"] == "bilinear");
  // pinv's views demosaiced the gradient-corrected way.
  REQUIRE(run_command(lfnet + "evaluate --lf " + (tmp / "in/lf") +
                          " --phi asp:2 --method pinv --cfa GRBG --demosaic malvar --json " +
                          (tmp / "m.json"),
                      out) == 0);
  const auto m = lfnet::read_json_file(tmp / "m.json");
  CHECK(m["demosaic"] == "malvar");
  CHECK(m["psnr_db"].get<double>() != Approx(p["psnr_db"].get<double>()).margin(1e-6));
  // The colour net's self-ensemble: four passes, each mirror image read at its phase, which
  // untrained are each the demosaiced pseudo-inverse (tests/recon/colour_net_test.cc).
  REQUIRE(run_command(evaluate + " --cfa GRBG --self-ensemble --json " + (tmp / "s.json"), out) ==
          0);
  const auto s = lfnet::read_json_file(tmp / "s.json");
  CHECK(s["psnr_db"].get<double>() == Approx(e["psnr_db"].get<double>()).margin(0.01));
  CHECK(s["self_ensemble_passes"] == 4);  // the code's mirrors, not those of the CFA's period

  // batch runs it on light-field folders behind the same array.
  REQUIRE(run_command(lfnet + "batch --input " + (tmp / "in") + " --out " + (tmp / "batch") +
                          " --methods net --model " + model + " --cfa GRBG",
                      out) == 0);
  const auto b = lfnet::read_json_file(tmp / "batch/records/lf__net.json");
  CHECK(b["psnr_db"].get<double>() == Approx(e["psnr_db"].get<double>()).margin(1e-9));

  // What does not fit is one clear error, and writes nothing.
  const std::vector<std::pair<std::string, std::string>> bad = {
      {evaluate + " --json " + (tmp / "x.json"), "give --cfa GRBG"},
      {evaluate + " --cfa RGGB --json " + (tmp / "x.json"), "not RGGB"},
      {evaluate + " --cfa GRBG --demosaic malvar --json " + (tmp / "x.json"),
       "reconstructs the colours itself"},
      {lfnet + "evaluate --lf " + (tmp / "in/lf") +
           " --phi asp:2 --method pinv --demosaic malvar " + "--json " + (tmp / "x.json"),
       "needs a colour filter array"},
      {lfnet + "evaluate --lf " + (tmp / "in/lf") + " --phi asp:2 --method pinv --cfa GRBG " +
           "--demosaic vng --json " + (tmp / "x.json"),
       "bilinear, malvar"},
      {lfnet + "evaluate --lf " + (tmp / "in/lf") + " --model " +
           (std::string(LFNET_SOURCE_DIR) + "/models/lfnet-asp-n2.ckpt") + " --cfa GRBG --json " +
           (tmp / "x.json"),
       "reconstructs grey sensor images"},
      {lfnet + "export --model " + model + " --out " + (tmp / "x.pt"), "colour net"},
  };
  for (const auto& [command, message] : bad) {
    INFO(command);
    CHECK(run_command(command, out) != 0);
    CHECK(out.find(message) != std::string::npos);
    CHECK(out.find("lfnet: error:") != std::string::npos);
  }
  CHECK_FALSE(fs::exists(tmp / "x.json"));
  CHECK_FALSE(fs::exists(tmp / "x.pt"));
}

TEST_CASE("a calibrated Phi that names a colour filter array makes every command colour",
          "[app][colour]") {
  lfnet::test::TempDir tmp;
  torch::manual_seed(6);
  lfnet::io::write_light_field(lfnet::LightField(torch::rand({3, 5, 5, 24, 20})), tmp / "lf",
                               {"png", 16});
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 1 --log-level warn ";
  REQUIRE(run_command(lfnet + "phi export --phi asp:2 --out " + (tmp / "camera"), out) == 0);
  auto meta = lfnet::read_json_file(tmp / "camera/phi.json");
  meta["cfa"] = {{"pattern", "BGGR"}};
  lfnet::write_json_file(tmp / "camera/phi.json", meta);
  const std::string camera = " --phi " + (tmp / "camera");
  // simulate: one sensor image behind the camera's array, without --cfa.
  REQUIRE(run_command(lfnet + "simulate --lf " + (tmp / "lf") + camera + " --out " + (tmp / "acq"),
                      out) == 0);
  CHECK(lfnet::read_json_file(tmp / "acq/sensor.json")["cfa"]["pattern"] == "BGGR");
  // reconstruct: the camera's plain sensor image is read as behind its array.
  REQUIRE(run_command(lfnet + "reconstruct --method pinv" + camera + " --sensor " +
                          (tmp / "acq/sensor.tif") + " --out " + (tmp / "plain"),
                      out) == 0);
  REQUIRE(run_command(lfnet + "reconstruct --method pinv --sensor " + (tmp / "acq") + " --out " +
                          (tmp / "folder"),
                      out) == 0);
  const auto plain = lfnet::io::read_light_field(tmp / "plain").data();
  CHECK(plain.size(0) == 3);
  CHECK(torch::equal(plain, lfnet::io::read_light_field(tmp / "folder").data()));
  // evaluate: scored in colour behind it; a --cfa that differs is refused.
  const std::string evaluate = lfnet + "evaluate --lf " + (tmp / "lf") + camera + " --method pinv";
  REQUIRE(run_command(evaluate + " --json " + (tmp / "e.json"), out) == 0);
  CHECK(lfnet::read_json_file(tmp / "e.json")["cfa"]["pattern"] == "BGGR");
  CHECK(run_command(evaluate + " --cfa RGGB --json " + (tmp / "x.json"), out) != 0);
  CHECK(out.find("not the colour filter array of the camera") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp / "x.json"));
}

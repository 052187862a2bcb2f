// lfnet export, and reconstruct/evaluate with the exported file (docs/export.md): the file
// runs in LibTorch and in Debian's python3-torch with the checkpoint's results.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/nn/auto_precision.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/methods.h"
#include "lfnet/recon/reconstruct.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::run_command;
using lfnet::test::save_net;

namespace {

// A randomly initialised asp:2 net with a pinv residual, saved as a checkpoint.
void write_checkpoint(const std::string& path) {
  auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  lfnet::nn::NetworkOptions o;
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.ae.hidden = {64, 32, 64, 32, 64};
    p.cnn.channels = 4;
    p.cnn.depth = 3;
    p.residual = lfnet::nn::Residual::kPinv;
  });
  torch::manual_seed(3);
  lfnet::nn::LightFieldNet net(o);
  net->set_phi(lfnet::optics::patch_matrix_stack(*phi, 9, 9));
  save_net(net, *phi, "joint", path);
}

void write_raw(const std::string& path, const torch::Tensor& t) {
  auto c = t.contiguous();
  std::ofstream out(path, std::ios::binary);
  out.write(static_cast<const char*>(c.data_ptr()), static_cast<std::streamsize>(c.nbytes()));
}

double max_abs_diff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

nlohmann::json read_json(const std::string& path) {
  return nlohmann::json::parse(std::ifstream(path));
}

// A small noise-aware net of lfnet's architecture for `phi`, with random weights, in eval mode.
lfnet::nn::LightFieldNet noise_aware_image_net(const lfnet::optics::Phi& phi) {
  lfnet::nn::NetworkOptions o;
  o.architecture = lfnet::nn::kLfnetArchitecture;
  o.measurements = phi.measurements();
  o.patch = {phi.rows(), phi.cols(), 16, 16};
  lfnet::test::edit_image(o, [&](lfnet::nn::ImageNetOptions& image) {
    image.channels = 4;
    image.levels = 2;
    image.blocks = 1;
    image.noise_input = true;
  });
  lfnet::nn::LightFieldNet net(o);
  const int64_t t = phi.period();
  net->set_phi(phi.pixel_weights(0, 0, t, t));
  lfnet::test::randomise_image_net(net, 5);
  net->eval();
  return net;
}

}  // namespace

TEST_CASE(
    "precision auto runs bfloat16 only where the CPU and the model allow it; the record "
    "says which ran",
    "[app]") {
  lfnet::test::TempDir tmp;
  const std::string ckpt = tmp / "net.ckpt";
  write_checkpoint(ckpt);
  std::string out;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  REQUIRE(run_command(lfnet + "render --random 7 --size 40x40 --out " + (tmp / "lf"), out) == 0);
  // The precision that ran, with the CPU's bfloat16 as `native` says and more arguments.
  auto ran = [&](const char* native, const std::string& more) {
    std::string command = std::string("LFNET_NATIVE_BFLOAT16=") + native + " " + lfnet;
    for (const std::string& part :
         {std::string("evaluate --model "), ckpt, std::string(" --lf "), tmp / "lf",
          std::string(" --stride 9 --force --json "), tmp / "r.json", more}) {
      command += part;
    }
    REQUIRE(run_command(command, out) == 0);
    return read_json(tmp / "r.json").at("precision").get<std::string>();
  };
  // By default auto; no bfloat16.json beside the model: float32 even on a native CPU.
  CHECK(ran("0", "") == "float32");
  CHECK(ran("1", "") == "float32");
  // Verified in bfloat16.json: bfloat16 on a native CPU only, and never when told float32.
  std::ofstream(tmp / "bfloat16.json")
      << R"({"models": {"net.ckpt": {"fingerprint": ")" << lfnet::nn::file_fingerprint(ckpt)
      << R"(", "verified": true}}})";
  CHECK(ran("1", "") == "bfloat16");
  CHECK(ran("1", " --precision auto") == "bfloat16");
  CHECK(ran("0", " --precision auto") == "float32");
  CHECK(ran("1", " --precision float32") == "float32");
  CHECK(ran("0", " --precision bfloat16") == "bfloat16");
}

TEST_CASE(
    "export writes a TorchScript file that reconstruct, evaluate, LibTorch and Python "
    "run like the checkpoint",
    "[app][export]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  const std::string ckpt = tmp / "net.ckpt", pt = tmp / "net.pt";
  write_checkpoint(ckpt);
  std::string out;
  REQUIRE(run_command(lfnet + "export --model " + ckpt + " --out " + pt, out) == 0);
  CHECK(out.find("max |exported - checkpoint| on 256 patches") != std::string::npos);
  // An existing file is kept unless --force; a TorchScript file is not a checkpoint.
  CHECK(run_command(lfnet + "export --model " + ckpt + " --out " + pt, out) != 0);
  CHECK(out.find("--force") != std::string::npos);
  REQUIRE(run_command(lfnet + "export --model " + ckpt + " --out " + pt + " --force", out) == 0);
  CHECK(run_command(lfnet + "export --model " + pt + " --out " + (tmp / "again.pt"), out) != 0);
  CHECK(out.find("already an exported file") != std::string::npos);

  // LibTorch: the file against the checkpoint's net on realistic patches.
  const auto ck = lfnet::train::load_checkpoint(ckpt);
  auto net = lfnet::train::build_net(ck, ckpt);
  net->eval();
  const auto scripted = lfnet::nn::load_script(pt);
  CHECK(scripted.meta.phi == ck.phi);
  CHECK(scripted.meta.config == ck.config);
  auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::from_json(ck.phi));
  torch::manual_seed(11);
  auto patches = torch::rand({300, 2025});
  auto y = patches.matmul(net->phi[0].t());
  auto phase = torch::zeros({300}, torch::kInt64);
  torch::Tensor want, got;
  {
    torch::NoGradGuard no_grad;
    want = net->forward(y, phase).reshape({300, 5, 5, 9, 9});
    got = scripted.forward(y, phase);
  }
  const double cpp_diff = max_abs_diff(got, want);
  CHECK(cpp_diff <= 1e-5);

  // reconstruct and evaluate take the file as --model and give the checkpoint's results.
  REQUIRE(run_command(lfnet + "render --random 7 --size 40x40 --out " + (tmp / "lf"), out) == 0);
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi asp:2 --out " + (tmp / "acq"),
                  out) == 0);
  for (const auto& [model, name] : {std::pair{ckpt, "rec_ck"}, std::pair{pt, "rec_pt"}}) {
    std::string command = lfnet;
    for (const std::string& part :
         {std::string("reconstruct --model "), std::string(model), std::string(" --sensor "),
          tmp / "acq", std::string(" --stride 4 --out "), tmp / name}) {
      command += part;
    }
    REQUIRE(run_command(command, out) == 0);
  }
  auto rec_ck = lfnet::io::read_light_field(tmp / "rec_ck").data();
  auto rec_pt = lfnet::io::read_light_field(tmp / "rec_pt").data();
  CHECK(rec_ck.std().item<double>() > 1e-3);
  CHECK(max_abs_diff(rec_ck, rec_pt) <= 1.0 / 65535 + 1e-7);  // 16-bit PNGs: at most one step
  CHECK(read_json(tmp / "rec_pt/reconstruction.json").at("model") == pt);
  for (const std::string method : {"net", "ae"}) {
    INFO(method);
    for (const auto& [model, name] : {std::pair{ckpt, "ck.json"}, std::pair{pt, "pt.json"}}) {
      std::string command = lfnet;
      for (const std::string& part :
           {std::string("evaluate --model "), std::string(model), std::string(" --method "), method,
            std::string(" --lf "), tmp / "lf", std::string(" --stride 9 --force --json "),
            tmp / name}) {
        command += part;
      }
      REQUIRE(run_command(command, out) == 0);
    }
    const auto a = read_json(tmp / "ck.json"), b = read_json(tmp / "pt.json");
    CHECK(std::abs(a["psnr_db"].get<double>() - b["psnr_db"].get<double>()) < 1e-4);
    // Patch by patch: the records count the patches and carry no whole_image.
    for (const auto& r : {a, b}) {
      CHECK_FALSE(r.contains("whole_image"));
      CHECK(r["patches"].get<int64_t>() > 0);
    }
    CHECK(std::abs(a["ssim"].get<double>() - b["ssim"].get<double>()) < 1e-6);
  }
  // Another Phi's measurements are refused as for the checkpoint.
  REQUIRE(
      run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi mask:2 --out " + (tmp / "acqm"),
                  out) == 0);
  CHECK(run_command(lfnet + "reconstruct --model " + pt + " --sensor " + (tmp / "acqm") +
                        " --out " + (tmp / "recm"),
                    out) != 0);
  CHECK(out.find("trained for Phi") != std::string::npos);
  CHECK(run_command(lfnet + "evaluate --model " + pt + " --lf " + (tmp / "lf") + " --phi mask:2",
                    out) != 0);
  CHECK(out.find("does not match") != std::string::npos);

  // Python: Debian's python3-torch loads the file and gives the same numbers.
  const std::string python = lfnet::test::python_with("torch");
  const auto file_bytes = fs::file_size(pt);
  std::printf("export: %s is %.3f MB; max |C++ TorchScript - C++ checkpoint| = %.3g\n", pt.c_str(),
              static_cast<double>(file_bytes) / 1e6, cpp_diff);
  if (python.empty()) {
    WARN("python3 with torch not found: the Python half of the export test is skipped");
    return;
  }
  auto lf = lfnet::io::read_light_field(tmp / "lf").central(5).grey().data()[0];
  auto sensor = phi->forward(lf);
  lfnet::recon::ReconstructOptions o;
  o.stride = 4;
  o.clamp = false;
  auto recon = lfnet::recon::reconstruct_sensor(*phi, sensor,
                                                lfnet::recon::network_solver(net, "net"), o)[0];
  const std::string dir = tmp / "reference";
  fs::create_directories(dir);
  write_raw(dir + "/y.f32", y);
  write_raw(dir + "/phase.i64", phase);
  write_raw(dir + "/want.f32", want);
  write_raw(dir + "/sensor.f32", sensor);
  write_raw(dir + "/recon.f32", recon);
  write_raw(dir + "/lf.f32", lf);
  write_raw(dir + "/simulated.f32", sensor);
  lfnet::write_json_file(dir + "/reference.json", {{"stride", 4},
                                                   {"shapes",
                                                    {{"y", y.sizes().vec()},
                                                     {"phase", phase.sizes().vec()},
                                                     {"want", want.sizes().vec()},
                                                     {"sensor", sensor.sizes().vec()},
                                                     {"recon", recon.sizes().vec()},
                                                     {"lf", lf.sizes().vec()},
                                                     {"simulated", sensor.sizes().vec()}}}});
  REQUIRE(
      run_command(python + " " + LFNET_SOURCE_DIR + "/tests/apps/check_export.py " + pt + " " + dir,
                  out) == 0);
  INFO(out);
  const auto result = nlohmann::json::parse(out.substr(out.rfind("\n{") + 1));
  CHECK(result["forward_max_diff"].get<double>() <= 1e-5);
  CHECK(result["reconstruct_max_diff"].get<double>() <= 1e-5);
  CHECK(result["simulate_max_diff"].get<double>() <= 1e-5);
  CHECK(result["output_shape"] == nlohmann::json({300, 5, 5, 9, 9}));
  CHECK(result["phi_spec"] == ck.phi);
  CHECK(result["metadata_phi"] == ck.phi);
  CHECK(result["metadata_matches_attribute"] == true);
  CHECK(result["format_version"] == lfnet::nn::kScriptFormatVersion);
  CHECK(result["patch_shape"] == nlohmann::json({5, 5, 9, 9}));
  // The example of docs/export.md runs as it is.
  std::ifstream doc(std::string(LFNET_SOURCE_DIR) + "/docs/export.md");
  const std::string text((std::istreambuf_iterator<char>(doc)), std::istreambuf_iterator<char>());
  const auto begin = text.find("```python\n");
  REQUIRE(begin != std::string::npos);
  const auto end = text.find("```", begin + 10);
  std::ofstream(tmp / "example.py") << text.substr(begin + 10, end - begin - 10);
  REQUIRE(run_command(python + " " + (tmp / "example.py") + " " + pt, out) == 0);
  INFO(out);
  CHECK(out.find("Phi asp, N = 2, 5x5 views, 9x9 patches, 1 phase(s), trained by net.ckpt") !=
        std::string::npos);
  CHECK(out.find("sensor (2, 64, 64) -> light field (5, 5, 64, 64), PSNR") != std::string::npos);
  CHECK(out.find("one patch -> (1, 5, 5, 9, 9)") != std::string::npos);
  std::printf(
      "export: max |Python TorchScript - C++ checkpoint| = %.3g (forward), %.3g "
      "(reconstruct), %.3g (simulate vs Phi::forward); Python torch %s\n",
      result["forward_max_diff"].get<double>(), result["reconstruct_max_diff"].get<double>(),
      result["simulate_max_diff"].get<double>(),
      result["torch_version"].get<std::string>().c_str());
}

namespace {

// Exports every `shards`-th network checkpoint of the model zoo (sorted by path), from the
// `shard`-th on, and checks the file against its checkpoint. The zoo is split over several test
// cases so that each stays well within CTest's timeout.
void export_shipped_models(size_t shard, size_t shards) {
  const auto models = lfnet::test::zoo_checkpoints();
  if (models.empty()) {
    LFNET_SKIP("no models/zoo.json in the source tree: nothing to export");
  }
  lfnet::test::TempDir tmp;
  for (size_t i = shard; i < models.size(); i += shards) {
    const auto& model = models[i];
    INFO(model.string());
    const std::string pt = tmp / (model.stem().string() + ".pt");
    std::string out;
    const auto network = lfnet::nn::NetworkOptions::from_file_json(
        lfnet::train::load_checkpoint(model.string()).network, "$.network");
    if (!network.cfa.empty()) {
      // A colour net is not exported yet, and says so.
      CHECK(run_command(lfnet_binary() + " --threads 2 --log-level warn export --model " +
                            model.string() + " --out " + pt,
                        out) != 0);
      CHECK(out.find("is a colour net") != std::string::npos);
      CHECK_FALSE(fs::exists(pt));
      continue;
    }
    // export compares the file with the checkpoint on 256 patches (the lfnet architecture: on
    // a sensor image in tiles) and fails above 1e-5.
    REQUIRE(run_command(lfnet_binary() + " --threads 2 --log-level warn export --model " +
                            model.string() + " --out " + pt,
                        out) == 0);
    std::printf("%s", out.c_str());
    CHECK(out.find(network.arch().whole_image()
                       ? "max |exported - checkpoint| on a "
                       : "max |exported - checkpoint| on 256 patches") != std::string::npos);
    const auto loaded = lfnet::nn::load_script(pt);
    CHECK(loaded.meta.phi == lfnet::train::load_checkpoint(model.string()).phi);
  }
}

constexpr size_t kExportShards = 2;

}  // namespace

TEST_CASE("every checkpoint of the zoo exports and matches its checkpoint (1st half)",
          "[app][export]") {
  export_shipped_models(0, kExportShards);
}

TEST_CASE("every checkpoint of the zoo exports and matches its checkpoint (2nd half)",
          "[app][export]") {
  export_shipped_models(1, kExportShards);
}

TEST_CASE(
    "a net of the lfnet architecture exports: the file reconstructs like the checkpoint in "
    "LibTorch, in Python and through lfnet evaluate",
    "[app][export][image]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  std::string out;
  REQUIRE(run_command(lfnet + "render --random 7 --size 45x38 --out " + (tmp / "lf"), out) == 0);
  auto lf = lfnet::io::read_light_field(tmp / "lf").central(5).grey().data()[0];
  // asp (period 1) and mask (period 2: tiles of every phase).
  for (const std::string name : {"asp", "mask"}) {
    INFO(name);
    auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse(name + ":2"));
    auto net = noise_aware_image_net(*phi);
    const int64_t t = phi->period();
    const std::string ckpt = tmp / (name + ".ckpt"), pt = tmp / (name + ".pt");
    save_net(net, *phi, "joint_scratch", ckpt);
    std::string export_command = lfnet;
    export_command += "export --model ";
    export_command += ckpt;
    export_command += " --out ";
    export_command += pt;
    REQUIRE(run_command(export_command, out) == 0);
    std::string summary = "(";
    summary += name;
    summary += ":2, lfnet, ";
    summary += std::to_string(t * t);
    summary += " phases)";
    CHECK(out.find(summary) != std::string::npos);
    CHECK(out.find("max |exported - checkpoint| on a ") != std::string::npos);
    CHECK(out.find(" sensor image in tiles of 4: ") != std::string::npos);

    // LibTorch: whole images, tiles with halos (one tile, and many) and the simulation.
    const auto scripted = lfnet::nn::load_script(pt);
    CHECK(scripted.network.arch().whole_image());
    auto sensor = lfnet::optics::simulate_sensor(*phi, lf);
    const double sigma = 0.1;
    torch::Tensor whole, tiled;
    {
      torch::NoGradGuard no_grad;
      whole = net->forward_image(sensor.unsqueeze(0), 0, sigma);
    }
    for (int64_t tile : {8, 1000}) {
      INFO("tile " << tile);
      tiled = lfnet::recon::reconstruct_sensor_tiled(net, sensor, tile, false, sigma);
      CHECK(max_abs_diff(scripted.reconstruct_image(sensor, tile, false, sigma), tiled[0]) <= 1e-5);
    }
    // A tile of 0 is the automatic one, in the file's own code as in lfnet's.
    CHECK(max_abs_diff(scripted.module.get_method("reconstruct")({sensor, int64_t{0}, false, sigma})
                           .toTensor(),
                       tiled[0]) <= 1e-5);
    // The noise channel is read: another sigma gives another result.
    CHECK(max_abs_diff(scripted.reconstruct_image(sensor, 8, false, 0.0), tiled[0]) > 1e-3);
    CHECK(max_abs_diff(tiled, whole) <= 1e-4);
    auto simulated = scripted.module.get_method("simulate")({lf}).toTensor();
    CHECK(max_abs_diff(simulated, sensor) <= 1e-5);
    CHECK_THROWS_WITH(scripted.forward(torch::zeros({1, phi->measurements() * 81})),
                      Catch::Contains("lfnet architecture"));

    // evaluate with the file gives the checkpoint's PSNR.
    for (const auto& [model, json] : {std::pair{ckpt, "ck.json"}, std::pair{pt, "pt.json"}}) {
      std::string command = lfnet;
      for (const std::string& part :
           {std::string("evaluate --model "), std::string(model), std::string(" --lf "), tmp / "lf",
            std::string(" --force --json "), tmp / json}) {
        command += part;
      }
      REQUIRE(run_command(command, out) == 0);
      // The summary speaks of the whole image, not of a stride it does not have.
      CHECK(out.find("whole image, noise") != std::string::npos);
      CHECK(out.find("stride") == std::string::npos);
    }
    const auto a = read_json(tmp / "ck.json"), b = read_json(tmp / "pt.json");
    CHECK(std::abs(a["psnr_db"].get<double>() - b["psnr_db"].get<double>()) < 1e-4);
    // Both reconstruct the whole image: the records say so, and count no patches.
    for (const auto& r : {a, b}) {
      CHECK(r.value("whole_image", false));
      CHECK(r["patches"] == 0);
      // The command's own time from its start covers the reconstruction and more.
      CHECK(r["end_to_end_seconds"].get<double>() > r["seconds"].get<double>());
      CHECK(r["end_to_end_seconds"].get<double>() < 300);
    }
    // The self-ensemble too: the file's Phi weights give the checkpoint's mirrors.
    CHECK(torch::equal(scripted.pixel_weights(), net->phi));
    for (const auto& [model, json] : {std::pair{ckpt, "cks.json"}, std::pair{pt, "pts.json"}}) {
      std::string command = lfnet;
      for (const std::string& part :
           {std::string("evaluate --self-ensemble --model "), std::string(model),
            std::string(" --lf "), tmp / "lf", std::string(" --force --json "), tmp / json}) {
        command += part;
      }
      REQUIRE(run_command(command, out) == 0);
    }
    const auto as = read_json(tmp / "cks.json"), bs = read_json(tmp / "pts.json");
    CHECK(std::abs(as["psnr_db"].get<double>() - bs["psnr_db"].get<double>()) < 1e-4);
    const int64_t passes = name == "asp" ? 4 : 1;  // a periodic mask has no mirror images
    CHECK(bs["self_ensemble_passes"] == passes);
    CHECK((std::abs(bs["psnr_db"].get<double>() - b["psnr_db"].get<double>()) > 1e-3) ==
          (passes > 1));

    // Python: Debian's python3-torch runs the file with the same numbers.
    const std::string python = lfnet::test::python_with("torch");
    if (python.empty()) {
      WARN("python3 with torch not found: the Python half of the export test is skipped");
      continue;
    }
    const std::string dir = tmp / ("reference-" + name);
    fs::create_directories(dir);
    tiled = lfnet::recon::reconstruct_sensor_tiled(net, sensor, 8, false, sigma);
    write_raw(dir + "/sensor.f32", sensor);
    write_raw(dir + "/whole.f32", whole);
    write_raw(dir + "/tiled.f32", tiled);
    write_raw(dir + "/lf.f32", lf);
    write_raw(dir + "/simulated.f32", sensor);
    lfnet::write_json_file(dir + "/reference.json", {{"tile", 8},
                                                     {"noise_sigma", sigma},
                                                     {"shapes",
                                                      {{"sensor", sensor.sizes().vec()},
                                                       {"whole", whole.sizes().vec()},
                                                       {"tiled", tiled.sizes().vec()},
                                                       {"lf", lf.sizes().vec()},
                                                       {"simulated", sensor.sizes().vec()}}}});
    std::string check_command = python;
    for (const std::string& part :
         {std::string(" ") + LFNET_SOURCE_DIR + "/tests/apps/check_export_image.py ", pt,
          std::string(" "), dir}) {
      check_command += part;
    }
    REQUIRE(run_command(check_command, out) == 0);
    INFO(out);
    const auto result = nlohmann::json::parse(out.substr(out.rfind("\n{") + 1));
    CHECK(result["forward_max_diff"].get<double>() <= 1e-5);
    CHECK(result["reconstruct_max_diff"].get<double>() <= 1e-5);
    CHECK(result["simulate_max_diff"].get<double>() <= 1e-5);
    CHECK(result["output_shape"] == nlohmann::json({5, 5, 45, 38}));
    CHECK(result["noise_input"] == true);
  }
}

// A measurement, not a test (hidden): the sizes of exported default nets next to their
// checkpoints. Run: build/tests/apps/app_tests "[export-sizes]"
TEST_CASE("sizes of exported default nets", "[.][export-sizes]") {
  lfnet::test::TempDir tmp;
  for (const std::string name : {"asp:2", "asp:25", "mask:2", "random:2"}) {
    auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse(name));
    lfnet::nn::NetworkOptions o;  // the defaults: 5 x 5 x 9 x 9 patches, 16-channel CNN
    o.measurements = phi->measurements();
    lfnet::nn::LightFieldNet net(o);
    net->set_phi(lfnet::optics::patch_matrix_stack(*phi, 9, 9));
    lfnet::train::Checkpoint ck;
    ck.network = o.to_json();
    ck.phi = phi->spec().to_json();
    ck.model = lfnet::train::module_state(*net);
    lfnet::train::save_checkpoint(ck, tmp / "m.ckpt");
    lfnet::nn::ScriptMetadata meta;
    meta.phi = ck.phi;
    meta.period = phi->period();
    meta.block = phi->block();
    meta.local = phi->local();
    lfnet::nn::export_network(net, meta, tmp / "m.pt");
    std::printf(
        "%-9s phases %3lld  parameters %lld  checkpoint (weights only) %.2f MB  "
        "exported %.2f MB\n",
        name.c_str(), static_cast<long long>(net->phases()),
        static_cast<long long>(lfnet::nn::parameter_count(*net)),
        static_cast<double>(fs::file_size(tmp / "m.ckpt")) / 1e6,
        static_cast<double>(fs::file_size(tmp / "m.pt")) / 1e6);
  }
}

TEST_CASE(
    "a noise-aware model is told the noise the acquisition records, else the noise "
    "estimated from the sensor image",
    "[app][image]") {
  lfnet::test::TempDir tmp;
  const std::string lfnet = lfnet_binary() + " --threads 2 --log-level warn ";
  std::string out;
  REQUIRE(run_command(lfnet + "render --random 3 --size 120x120 --out " + (tmp / "lf"), out) == 0);
  auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2"));
  auto net = noise_aware_image_net(*phi);
  const std::string ckpt = tmp / "aware.ckpt";
  save_net(net, *phi, "joint_scratch", ckpt);
  REQUIRE(run_command(lfnet + "simulate --lf " + (tmp / "lf") + " --phi asp:2 --noise 0.1 --out " +
                          (tmp / "acq"),
                      out) == 0);
  auto reconstruct = [&](const std::string& name, const std::string& more) {
    std::string command = lfnet + "reconstruct --model ";
    for (const std::string& part :
         {ckpt, std::string(" --sensor "), tmp / "acq", std::string(" --out "), tmp / name, more})
      command += part;
    REQUIRE(run_command(command, out) == 0);
    return read_json(tmp / (name + "/reconstruction.json"));
  };
  // simulate's sensor.json records the noise: the model is told it.
  auto r = reconstruct("told", "");
  CHECK(r.at("noise_sigma").get<double>() == Approx(0.1));
  CHECK_FALSE(r.contains("noise_sigma_estimated"));
  // A sensor image that records no noise (a real camera's): estimated from the image.
  const std::string meta_path = tmp / "acq/sensor.json";
  auto meta = read_json(meta_path);
  REQUIRE(meta.erase("noise_sigma") == 1);
  std::ofstream(meta_path, std::ios::trunc) << meta.dump(2);
  r = reconstruct("estimated", "");
  CHECK(r.at("noise_sigma_estimated") == true);
  REQUIRE(r.at("noise_sigma").size() == 1);
  CHECK(r.at("noise_sigma")[0].get<double>() == Approx(0.1).epsilon(0.1));
  // --noise-sigma overrides both.
  r = reconstruct("given", " --noise-sigma 0.05");
  CHECK(r.at("noise_sigma").get<double>() == Approx(0.05));
  CHECK_FALSE(r.contains("noise_sigma_estimated"));
}

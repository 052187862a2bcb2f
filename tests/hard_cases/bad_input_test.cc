// Bad input to the lfnet program (docs/robustness.md): every case gives exactly one
// `lfnet: error:` line that says what is wrong, a non-zero exit, and leaves every existing file
// as it was.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "lfnet/core/light_field.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::test::lfnet_binary;
using lfnet::test::read_bytes;
using lfnet::test::run_command;
using lfnet::test::write_bytes;

namespace {

// Every file under `dir` with its bytes: a folder is "untouched" when this is unchanged.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    const auto rel = e.path().lexically_relative(dir).string();
    std::error_code ec;  // a link that loops is listed, not followed
    files[rel] = e.is_regular_file(ec) ? read_bytes(e.path().string())
                                       : std::string(ec ? "<link>" : "<dir>");
  }
  return files;
}

int count_lines(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

// The program with quiet logs, so its only output on failure is the error line.
// A command that blocks (a FIFO read) fails after two minutes instead of hanging the suite.
std::string quiet_program(const std::string& args) {
  return "timeout 120 " + lfnet_binary() + " --threads 1 --log-level off " + args;
}

// Runs `args`; requires a non-zero exit, one line "lfnet: error: ..." that contains `what`, and
// no change under `watched`.
void expect_error(const std::string& args, const std::string& what, const fs::path& watched) {
  const auto before = snapshot(watched);
  std::string out;
  const int rc = run_command(quiet_program(args), out);
  INFO("lfnet " << args << "\n-> " << out);
  CHECK(rc != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(count_lines(out) == 1);
  CHECK(out.find(what) != std::string::npos);
  CHECK(snapshot(watched) == before);
}

// A 5 x 5-view grey light field of 18 x 18 pixels, written as 8-bit PNGs.
void write_light_field(const std::string& dir) {
  torch::manual_seed(2);
  lfnet::io::write_light_field(lfnet::LightField(torch::rand({1, 5, 5, 18, 18})), dir, {"png", 8});
}

// A small untrained model for `phi` written as a checkpoint, as `lfnet train` writes it.
void write_model(const std::string& path, const std::string& phi_name) {
  auto phi = lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse(phi_name));
  lfnet::nn::NetworkOptions o;
  o.measurements = phi->measurements();
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.ae.hidden = {16, 8, 16, 8, 16};
    p.cnn.channels = 2;
    p.cnn.depth = 2;
  });
  lfnet::nn::LightFieldNet net(o);
  net->set_phi(lfnet::optics::patch_matrix_stack(*phi, 9, 9));
  lfnet::train::Checkpoint c;
  c.network = o.to_json();
  c.phi = phi->spec().to_json();
  c.config = {{"measurement_mean", 0.5}};
  c.model = lfnet::train::module_state(*net);
  lfnet::train::save_checkpoint(c, path);
}

const char* kTinyConfig = R"({
  "name": "tiny", "phi": "asp:2",
  "data": {"random_scenes": 1, "random_seed": 5, "random_options": {"height": 64, "width": 64}},
  "dataset": {"train_patches": 64, "validation_patches": 32, "seed": 2},
  "network": {"paper": {"ae": {"hidden": [16, 8, 16, 8, 16]}, "cnn": {"channels": 2, "depth": 2}}},
  "training": {"epochs": 1, "batch_size": 32, "progress": false},
  "stages": ["cnn"]
})";

}  // namespace

TEST_CASE("malformed configs and unknown keys name the file and the JSON path",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const auto cfg = tmp / "c.json";
  auto base = nlohmann::json::parse(kTinyConfig);
  struct Case {
    std::string text, what;
  };
  auto with = [&](const std::string& pointer, const nlohmann::json& value) {
    auto j = base;
    j[nlohmann::json::json_pointer(pointer)] = value;
    return j.dump();
  };
  const std::vector<Case> cases = {
      {"{\"name\": \"x\", ", "malformed JSON at byte"},
      {"", "malformed JSON"},
      {"[1, 2]", "JSON object"},
      {"{\"name\": \"x\" \"phi\": 1}", "malformed JSON at byte"},
      {with("/trainng", nlohmann::json::object()), "$.trainng: unknown key"},
      {with("/network/paper/cnn/chanels", 4), "$.network.paper.cnn.chanels: unknown key"},
      {with("/training/epochs", "ten"), "$.training.epochs"},
      {with("/training/lr", -1), "$.training.lr: must lie in (0, 1e+12], got -1"},
      {with("/data/random_scenes", -2), "$.data.random_scenes"},
      {with("/phi", "asp:0"), "N must be"},
      {with("/phi", "nosuchphi:2"), "unknown Phi model 'nosuchphi'"},
      {with("/phi", nlohmann::json{{"name", "asp"}, {"n", 2}, {"colour", 1}}), "$.phi.colour"},
      {with("/stages", nlohmann::json::array({"cnn", "decoder"})), "$.stages[1]"},
      {with("/default_scale", 3), "$.default_scale"},
      {with("/scales", nlohmann::json{{"quick", 5}}), "$.scales.quick"},
      {with("/phi", "asp:99999999999999999999999"), "asp:99999999999999999999999"},
      {with("/phi", nlohmann::json{{"name", "asp"}, {"rows", 100000}, {"cols", 100000}}), "1..64"},
      {with("/phi", nlohmann::json{{"name", "random"}, {"n", 25}, {"params", {{"block", 32}}}}),
       "2^27"},
      {with("/stages", nlohmann::json::array({{{"name", "cnn"}, {"training", 5}}})),
       "$.stages[0].training"},
      {with("/data", nlohmann::json::object()), "no training data"},
      // The evaluations are checked with the config, not after every stage has trained.
      {with("/evaluation", nlohmann::json{{"methods", {"pinv", "pinv-nml"}}}),
       "$.evaluation.methods[1]: unknown method 'pinv-nml'"},
      {with("/evaluation", nlohmann::json{{"strides", {5, 0}}}), "$.evaluation.strides[1]"},
      {with("/evaluation", nlohmann::json{{"method_options", {{"dict", {{"omp", 1}}}}}}),
       "'dict', which this command does not run"},
      // Fractions where whole numbers belong are refused, not rounded.
      {with("/phi", nlohmann::json{{"name", "asp"}, {"n", 2.5}}), "$.phi.n"},
      {with("/training/epochs", 1.7), "$.training.epochs"},
      {with("/training/progress", 1), "$.training.progress"},
      // Data that cannot be loaded: the run folder this command created is removed again.
      {with("/data", nlohmann::json{{"light_fields", {"/nonexistent/lf"}}}), "/nonexistent/lf"},
  };
  for (const auto& c : cases) {
    write_bytes(cfg, c.text);
    expect_error("train " + cfg + " --out " + (tmp / "run"), c.what, tmp.path());
    CHECK_FALSE(fs::exists(tmp / "run"));
  }
}

TEST_CASE("careless input, round 2: run names, resumes, starts, model paths, threads, commands",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const auto cfg = tmp / "c.json";
  auto config = nlohmann::json::parse(kTinyConfig);
  // A run's name is one folder name: out/<name> is what --force replaces.
  for (const std::string name : {"", ".", "..", "../../escape", "a/b"}) {
    config["name"] = name;
    write_bytes(cfg, config.dump());
    expect_error("train " + cfg + " --check", "$.name: a run's name is one folder name",
                 tmp.path());
  }
  config["name"] = "tiny";
  write_bytes(cfg, config.dump());
  // --resume RUN keeps the run's own config; a checkpoint continues one stage only.
  fs::create_directories(tmp / "run");
  expect_error("experiment " + cfg + " --resume " + (tmp / "run"), "give no config file",
               tmp.path());
  write_bytes(tmp / "last.ckpt", "LFNETCKP");
  expect_error("train --resume " + (tmp / "last.ckpt"), "is a checkpoint: it continues one stage",
               tmp.path());
  // What a run starts from is checked before any data is loaded.
  write_bytes(tmp / "weights.pt", "not a checkpoint");
  expect_error("train " + cfg + " --init " + (tmp / "weights.pt"),
               "not an lfnet checkpoint: give a checkpoint", tmp.path());
  config["init"] = tmp / "weights.pt";
  write_bytes(cfg, config.dump());
  expect_error("train " + cfg, "$.init", tmp.path());
  config.erase("init");
  // Every light field a run will read is checked by --check and before training, not after it.
  config["evaluation"] = {{"data", {{"light_fields", {tmp / "no_such_lf"}}}}};
  write_bytes(cfg, config.dump());
  expect_error("train " + cfg + " --check", "$.evaluation.data.light_fields[0]", tmp.path());
  expect_error("experiment " + cfg + " --out " + (tmp / "x"), "no_such_lf", tmp.path());
  config.erase("evaluation");
  write_bytes(cfg, config.dump());
  // A model path that is a folder or a FIFO: one line, and no read that blocks.
  write_light_field(tmp / "lf");
  expect_error("evaluate --model " + tmp.path().string() + " --lf " + (tmp / "lf"),
               "is a folder, not a model file", tmp.path());
  REQUIRE(mkfifo((tmp / "fifo").c_str(), 0600) == 0);
  expect_error("evaluate --model " + (tmp / "fifo") + " --lf " + (tmp / "lf"),
               "is not a regular file", tmp.path());
  // Nor for any other file a command reads: JSON options, a white frame, a sensor image.
  const std::string pinv = "evaluate --phi asp:2 --method pinv --lf " + (tmp / "lf") + " ";
  for (const std::string flag :
       {"--cfa", "--method-options", "--camera-error", "--effects", "--flat-field"}) {
    expect_error(pinv + flag + " " + (tmp / "fifo"), "is not a regular file", tmp.path());
  }
  expect_error("simulate --lf " + (tmp / "lf") + " --phi asp:2 --cfa " + (tmp / "fifo") +
                   " --out " + (tmp / "acq"),
               "--cfa", tmp.path());
  expect_error("reconstruct --phi asp:2 --method pinv --sensor " + (tmp / "fifo") + " --out " +
                   (tmp / "rec"),
               "is not a regular file", tmp.path());
  // --threads has a bound that the message states; an unknown command is named.
  std::string out;
  for (const std::string n : {"10000", "-1"}) {
    CHECK(run_command(lfnet_binary() + " --threads " + n + " info", out) != 0);
    INFO(out);
    CHECK(out.find("--threads") != std::string::npos);
    CHECK(out.find("per core") != std::string::npos);
    CHECK(out.size() < 300);
  }
  expect_error("frobnicate", "unknown command 'frobnicate' (known: info", tmp.path());
}

TEST_CASE("out-of-domain numbers on the command line name the option before any work",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const std::string lf = tmp / "lf";
  write_light_field(lf);
  const std::string eval = "evaluate --phi asp:2 --lf " + lf + " --method pinv ";
  expect_error(eval + "--stride 0", "--stride", tmp.path());
  expect_error(eval + "--cfa ''", "--cfa: may not be empty", tmp.path());
  // Inline JSON that is not an object is read as JSON, not as a file's name.
  {
    expect_error(eval + "--method-options '[1,2]'", "--method-options", tmp.path());
    std::string out;
    CHECK(run_command(quiet_program(eval + "--method-options '[1,2]'"), out) != 0);
    CHECK(out.find("no such file") == std::string::npos);
  }
  expect_error(eval + "--camera-error '{\"angular_shift_u\": 100}'",
               "moves the views beyond the 5-view grid", tmp.path());
  expect_error(eval + "--stride 12", "1..9", tmp.path());
  expect_error(eval + "--noise nan", "--noise", tmp.path());
  expect_error(eval + "--noise inf", "--noise", tmp.path());
  expect_error(eval + "--noise -0.1", "--noise", tmp.path());
  const std::string sim = "simulate --lf " + lf + " --phi asp:2 --out " + (tmp / "acq") + " ";
  expect_error(sim + "--noise nan", "--noise", tmp.path());
  // A size the machine cannot hold is refused before it is allocated, naming the flag.
  expect_error("simulate --white 100000x100000 --phi asp:2 --out " + (tmp / "white"),
               "--white 100000x100000 needs", tmp.path());
  // Overflowing noise would write infinities; seeds beyond 64 bits or negative would wrap or
  // saturate to one seed: each is refused with its flag and its range.
  expect_error(sim + "--noise 1e308", "--noise: must be a noise sigma from 0 to 10", tmp.path());
  expect_error(eval + "--noise 1e39", "--noise: must be a noise sigma from 0 to 10", tmp.path());
  expect_error(sim + "--seed -1", "--seed: must be a whole number from 0 to", tmp.path());
  expect_error(eval + "--seed 18446744073709551616", "(2^64 - 1)", tmp.path());
  expect_error(sim + "--seed 1.5", "--seed", tmp.path());
  expect_error(sim + "--views 1:99999999999999999999,1:5", "99999999999999999999", tmp.path());
  CHECK_FALSE(fs::exists(tmp / "acq"));
  // Options that belong to another method are refused, not ignored.
  expect_error(eval + "--method-options '{\"dict\": {\"omp\": {\"max_atoms\": 5}}}'",
               "which this command does not run", tmp.path());
  expect_error(eval + "--method-options '{\"pinv\": {\"lambda\": 5}}'", "takes no options",
               tmp.path());
  const std::string dict = "evaluate --phi asp:2 --lf " + lf + " --method dict --dictionary " +
                           std::string(LFNET_SOURCE_DIR) + "/models/dictionary.ckpt ";
  expect_error(dict + "--method-options '{\"dict\": {\"admm\": {\"lambda\": -1}}}'",
               "--method-options.dict.admm", tmp.path());
  expect_error(dict + "--method-options " + (tmp / "none.json"), "--method-options", tmp.path());
  // A calibrated Phi that is not one, and phi export's own checks.
  fs::create_directories(tmp / "not_a_camera");
  expect_error(
      "simulate --lf " + lf + " --phi " + (tmp / "not_a_camera") + " --out " + (tmp / "acq"),
      "not a calibrated Phi", tmp.path());
  expect_error("phi export --phi asp:2 --grid 0x5 --out " + (tmp / "cam"), "--grid", tmp.path());
  expect_error("phi export --phi random:2 --out " + (tmp / "cam"), "not local", tmp.path());
  CHECK_FALSE(fs::exists(tmp / "cam"));
  // bench: sizes with domains, and a case that fails in its child process is one error line
  // with the child's reason (not its exit status).
  const std::string bench = "bench --phi asp:2 --methods pinv --reps 1 --strides 9 --skip-kernels ";
  expect_error(bench + "--height 8", "--height", tmp.path());
  expect_error(bench + "--width 100000", "--width", tmp.path());
  expect_error("bench --methods dict --strides 9 --skip-kernels --dict-atoms 100000",
               "--dict-atoms", tmp.path());
  auto spec = nlohmann::json::parse(
      std::ifstream(std::string(LFNET_SOURCE_DIR) + "/configs/scenes/heldout_window.json"));
  spec["height"] = 4;
  spec["width"] = 4;
  std::ofstream(tmp / "tiny_scene.json") << spec.dump();
  std::string out;
  CHECK(run_command(quiet_program(bench + "--scene " + (tmp / "tiny_scene.json")), out) != 0);
  INFO(out);
  size_t errors = 0;
  for (auto at = out.find("lfnet: error: "); at != std::string::npos;
       at = out.find("lfnet: error: ", at + 1)) {
    ++errors;
  }
  CHECK(errors == 1);
  CHECK(out.find("lfnet: error: bench: every case failed (1 of 1); the first: a light field of 4 "
                 "pixels is smaller than one patch of 9") != std::string::npos);
}

TEST_CASE("missing, mismatched, truncated and foreign image files are one-line errors",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const fs::path root = tmp.path();
  auto fresh = [&](const std::string& name) {
    std::string dir = tmp / name;
    write_light_field(dir);
    return dir;
  };
  auto simulate = [&](const std::string& dir) {
    return "simulate --lf " + dir + " --phi asp:2 --out " + (tmp / "acq");
  };
  expect_error(simulate(tmp / "absent"), "absent", root);

  auto gap = fresh("gap");
  fs::remove(gap + "/lf_3_3.png");
  expect_error(simulate(gap), "lf_3_3.png", root);

  auto truncated = fresh("truncated");
  fs::resize_file(truncated + "/lf_2_4.png", 60);
  expect_error(simulate(truncated), "lf_2_4.png", root);

  auto empty_file = fresh("empty_file");
  fs::resize_file(empty_file + "/lf_5_5.png", 0);
  expect_error(simulate(empty_file), "lf_5_5.png", root);

  auto foreign = fresh("foreign");
  write_bytes(foreign + "/lf_1_1.png", "this is not an image\n");
  expect_error(simulate(foreign), "lf_1_1.png", root);

  auto sizes = fresh("sizes");
  lfnet::io::write_image(sizes + "/lf_4_2.png", torch::rand({1, 17, 18}));
  expect_error(simulate(sizes), "lf_4_2.png", root);

  auto channels = fresh("channels");
  lfnet::io::write_image(channels + "/lf_2_2.png", torch::rand({3, 18, 18}));
  expect_error(simulate(channels), "lf_2_2.png", root);

  auto mixed = fresh("mixed");
  lfnet::io::write_image(mixed + "/input_Cam000.png", torch::rand({1, 18, 18}));
  expect_error(simulate(mixed), "mixes", root);

  auto small = tmp / "small";
  lfnet::io::write_light_field(lfnet::LightField(torch::rand({1, 3, 3, 18, 18})), small);
  expect_error(simulate(small), "3x3 views", root);

  // A view that is a folder is named as such, not as missing; two schemes name a file of each.
  auto folder_view = fresh("folder_view");
  fs::remove(folder_view + "/lf_2_3.png");
  fs::create_directories(folder_view + "/lf_2_3.png");
  expect_error(simulate(folder_view), "lf_2_3.png is not a regular file but a folder", root);
  // A view that links to itself is called a link that loops.
  auto looping_view = fresh("looping_view");
  fs::remove(looping_view + "/lf_2_3.png");
  fs::create_symlink("lf_2_3.png", looping_view + "/lf_2_3.png");
  expect_error(simulate(looping_view), "lf_2_3.png is not a regular file but a link that loops",
               root);
  expect_error(simulate(mixed), "such as input_Cam000.png", root);

  // Float views are radiance in [0, 1]: far outside it (another unit) is refused with the file.
  const std::string far = tmp / "far";
  lfnet::io::write_light_field(lfnet::LightField(239 + 412 * torch::rand({1, 5, 5, 18, 18})), far,
                               {"tif", 32});
  expect_error(simulate(far), "lfnet reads views as radiance in [0, 1]", root);
  CHECK_FALSE(fs::exists(tmp / "acq"));
}

TEST_CASE("sensor images, calibrated Phis and export checks name the file and the flag",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const fs::path& root = tmp.path();
  // A camera's plain sensor image with a NaN: the file is named.
  auto sensor = torch::rand({2, 20, 20});
  sensor[1][3][4] = std::nanf("");
  lfnet::io::write_image(tmp / "sensor.tif", sensor, 32);
  expect_error("reconstruct --phi asp:2 --method pinv --sensor " + (tmp / "sensor.tif") +
                   " --out " + (tmp / "rec"),
               "sensor.tif holds NaN", root);
  // A calibrated Phi whose response images are zero: the file is named.
  std::string out;
  REQUIRE(run_command(quiet_program("phi export --phi mask:2 --out " + (tmp / "cam")), out) == 0);
  lfnet::io::write_image(tmp / "cam/response_2.tif", torch::zeros({45, 45}), 32);
  write_light_field(tmp / "lf");
  expect_error(
      "simulate --lf " + (tmp / "lf") + " --phi " + (tmp / "cam") + " --out " + (tmp / "acq"),
      "response_2.tif is zero everywhere", root);
  // export --check is bounded before anything is written.
  write_model(tmp / "asp.ckpt", "asp:2");
  expect_error(
      "export --model " + (tmp / "asp.ckpt") + " --out " + (tmp / "m.pt") + " --check 100000000",
      "--check: must be a whole number of patches from 0 to 65536", root);
  // Other bounds read as ranges, not as 309-digit numbers.
  expect_error("render --random -1 --out " + (tmp / "r"), "--random: must be a whole number >= 0",
               root);
  expect_error("launch -n 2 --grace -1 -- info", "--grace: must be a number of seconds", root);
  // batch --input a link that loops (made outside the watched folder, which is walked).
  lfnet::test::TempDir links;
  fs::create_symlink(links / "self", links / "self");
  expect_error("batch --phi asp:2 --input " + (links / "self") + " --out " + (tmp / "b"),
               "is a link that loops", root);
}

TEST_CASE("truncated and foreign checkpoints, and another Phi's measurements, are refused",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const fs::path root = tmp.path();
  write_light_field(tmp / "lf");
  write_model(tmp / "asp.ckpt", "asp:2");
  std::string out;
  REQUIRE(run_command(quiet_program("simulate --lf " + (tmp / "lf") + " --phi asp:2 --out " +
                                    (tmp / "acq")),
                      out) == 0);
  REQUIRE(run_command(quiet_program("simulate --lf " + (tmp / "lf") + " --phi mask:2 --out " +
                                    (tmp / "acqm")),
                      out) == 0);
  // The model works on its own Phi's measurements (so the failures below are the input's).
  REQUIRE(run_command(quiet_program("reconstruct --model " + (tmp / "asp.ckpt") + " --sensor " +
                                    (tmp / "acq") + " --out " + (tmp / "ok")),
                      out) == 0);
  auto reconstruct = [&](const std::string& model, const std::string& sensor) {
    return "reconstruct --model " + model + " --sensor " + sensor + " --out " + (tmp / "rec");
  };
  const auto bytes = read_bytes(tmp / "asp.ckpt");
  write_bytes(tmp / "half.ckpt", bytes.substr(0, bytes.size() / 2));
  write_bytes(tmp / "stub.ckpt", bytes.substr(0, 12));
  write_bytes(tmp / "png.ckpt", read_bytes(tmp / "lf/lf_1_1.png"));
  write_bytes(tmp / "json.ckpt", "{\"network\": {}}");
  auto flipped = bytes;
  flipped[bytes.size() / 3] = static_cast<char>(flipped[bytes.size() / 3] ^ 0x10);
  write_bytes(tmp / "flipped.ckpt", flipped);

  expect_error(reconstruct(tmp / "half.ckpt", tmp / "acq"), "truncated", root);
  // A noise switch (a JSON model file) cut off is called malformed JSON, not a checkpoint.
  const auto sw = read_bytes(std::string(LFNET_SOURCE_DIR) + "/models/lfnet-asp-n2-auto.json");
  write_bytes(tmp / "switch.json", sw.substr(0, sw.size() / 2));
  expect_error(reconstruct(tmp / "switch.json", tmp / "acq"), "is not valid JSON (truncated", root);
  expect_error(reconstruct(tmp / "stub.ckpt", tmp / "acq"), "stub.ckpt", root);
  expect_error(reconstruct(tmp / "png.ckpt", tmp / "acq"), "not an lfnet checkpoint", root);
  expect_error(reconstruct(tmp / "json.ckpt", tmp / "acq"), "not an lfnet checkpoint", root);
  expect_error(reconstruct(tmp / "flipped.ckpt", tmp / "acq"), "checksum", root);
  expect_error(reconstruct(tmp / "absent.ckpt", tmp / "acq"), "absent.ckpt", root);
  expect_error(reconstruct(tmp / "asp.ckpt", tmp / "acqm"), "trained for Phi", root);
  expect_error("evaluate --model " + (tmp / "asp.ckpt") + " --lf " + (tmp / "lf") + " --phi mask:2",
               "does not match", root);
  expect_error("evaluate --method dict --dictionary " + (tmp / "half.ckpt") + " --lf " +
                   (tmp / "lf") + " --phi asp:2",
               "half.ckpt", root);

  // A broken acquisition folder: truncated sensor image, bad sidecar, unknown version.
  fs::copy(tmp / "acq", tmp / "acq_trunc");
  fs::resize_file(tmp / "acq_trunc/sensor.tif", 100);
  expect_error(reconstruct(tmp / "asp.ckpt", tmp / "acq_trunc"), "sensor.tif", root);
  fs::copy(tmp / "acq", tmp / "acq_json");
  write_bytes(tmp / "acq_json/sensor.json", "{\"format\": ");
  expect_error(reconstruct(tmp / "asp.ckpt", tmp / "acq_json"), "sensor.json", root);
  fs::copy(tmp / "acq", tmp / "acq_version");
  auto meta = nlohmann::json::parse(read_bytes(tmp / "acq_version/sensor.json"));
  meta["format_version"] = 99;
  write_bytes(tmp / "acq_version/sensor.json", meta.dump());
  expect_error(reconstruct(tmp / "asp.ckpt", tmp / "acq_version"), "version", root);
  fs::copy(tmp / "acq", tmp / "acq_shape");
  meta = nlohmann::json::parse(read_bytes(tmp / "acq_shape/sensor.json"));
  meta["light_field"]["width"] = 19;
  write_bytes(tmp / "acq_shape/sensor.json", meta.dump());
  expect_error(reconstruct(tmp / "asp.ckpt", tmp / "acq_shape"), "acq_shape", root);
  CHECK_FALSE(fs::exists(tmp / "rec"));
}

TEST_CASE("existing and unwritable output folders are never overwritten without --force",
          "[app][bad_input]") {
  lfnet::test::TempDir tmp;
  const fs::path& root = tmp.path();
  write_light_field(tmp / "lf");
  write_model(tmp / "asp.ckpt", "asp:2");
  std::string out;
  REQUIRE(run_command(quiet_program("simulate --lf " + (tmp / "lf") + " --phi asp:2 --out " +
                                    (tmp / "acq")),
                      out) == 0);
  fs::create_directories(tmp / "taken");
  write_bytes(tmp / "taken/notes.txt", "keep me");
  write_bytes(tmp / "file", "a file, not a folder");
  write_bytes(tmp / "c.json", kTinyConfig);
  const std::string sim = "simulate --lf " + (tmp / "lf") + " --phi asp:2 --out ";
  const std::string rec =
      "reconstruct --model " + (tmp / "asp.ckpt") + " --sensor " + (tmp / "acq") + " --out ";
  const std::string render = "render --random 3 --size 20x20 --out ";
  const std::string train = "train " + (tmp / "c.json") + " --out ";
  for (const auto& cmd : {sim, rec, render, train}) {
    expect_error(cmd + (tmp / "taken"), "--force", root);
    expect_error(cmd + (tmp / "file"), "not a folder", root);
    expect_error(cmd + (tmp / "file/sub"), "file/sub", root);
  }
  // An existing acquisition is not replaced by a failing run, even with --force.
  expect_error(sim + (tmp / "acq") + " --force --effects " + (tmp / "nosuch.json"), "nosuch.json",
               root);
  expect_error(rec + (tmp / "taken") + " --force --method nosuch", "nosuch", root);
  // With --force the folder is replaced.
  REQUIRE(run_command(quiet_program(sim + (tmp / "taken") + " --force"), out) == 0);
  CHECK_FALSE(fs::exists(tmp / "taken/notes.txt"));
  CHECK(fs::exists(tmp / "taken/sensor.json"));
}

namespace {

// A tmpfs of `kilobytes` mounted on `dir` for the life of the object (root, or a machine that
// lets the tests mount; `mounted()` says whether it worked).
class SmallFileSystem {
 public:
  SmallFileSystem(const fs::path& dir, int kilobytes) : dir_(dir) {
    fs::create_directories(dir);
    std::string out;
    mounted_ = run_command("mount -t tmpfs -o size=" + std::to_string(kilobytes) + "k tmpfs '" +
                               dir.string() + "' 2>&1",
                           out) == 0;
  }
  ~SmallFileSystem() {
    std::string out;
    if (mounted_) run_command("umount '" + dir_.string() + "' 2>&1", out);
  }
  SmallFileSystem(const SmallFileSystem&) = delete;
  SmallFileSystem& operator=(const SmallFileSystem&) = delete;
  bool mounted() const { return mounted_; }

  // Fills what is left with one file, so that the next write of any size fails.
  void fill() const {
    std::ofstream filler(dir_ / "filler", std::ios::binary | std::ios::app);
    const std::string block(4096, '\0');
    while (filler.write(block.data(), static_cast<std::streamsize>(block.size())) &&
           filler.flush()) {
    }
  }

 private:
  fs::path dir_;
  bool mounted_ = false;
};

}  // namespace

TEST_CASE("on a full disk every command that writes fails with the reason and leaves all as it was",
          "[app][bad_input][full_disk]") {
  lfnet::test::TempDir tmp;
  SmallFileSystem disk(tmp.path() / "full", 512);
  if (!disk.mounted()) LFNET_SKIP("cannot mount a tmpfs here (not root?): no full-disk test");
  const fs::path full = tmp.path() / "full";
  const std::string lf = tmp / "lf";
  write_light_field(lf);
  write_model(tmp / "asp.ckpt", "asp:2");
  write_bytes(tmp / "c.json", kTinyConfig);
  std::string out;
  REQUIRE(
      run_command(quiet_program("simulate --lf " + lf + " --phi asp:2 --out " + (tmp / "in/acq")),
                  out) == 0);
  REQUIRE(run_command(quiet_program("train " + (tmp / "c.json") + " --out " + (tmp / "run")),
                      out) == 0);
  // Existing outputs on the full disk, which no failing command may touch: a record, a run, a
  // reconstruction, a model, a report with its figures.
  write_bytes((full / "old.json").string(), "{\"old\": true}\n");
  REQUIRE(run_command(
              quiet_program("train " + (tmp / "c.json") + " --out " + (full / "oldrun").string()),
              out) == 0);
  REQUIRE(run_command(quiet_program("reconstruct --model " + (tmp / "asp.ckpt") + " --sensor " +
                                    (tmp / "in/acq") + " --out " + (full / "oldrec").string()),
                      out) == 0);
  write_bytes((full / "old.pt").string(), "an older export");
  fs::copy(tmp / "run", full / "report_run", fs::copy_options::recursive);
  disk.fill();
  const std::string f = full.string() + "/";
  const std::vector<std::string> commands = {
      "render --random 3 --size 20x20 --out " + f + "r",
      "simulate --lf " + lf + " --phi asp:2 --out " + f + "s",
      "simulate --phi asp:2 --plot-weights " + f + "w",
      "evaluate --lf " + lf + " --phi asp:2 --method pinv --out " + f + "e",
      "evaluate --lf " + lf + " --phi asp:2 --method pinv --json " + f + "old.json --force",
      "reconstruct --model " + (tmp / "asp.ckpt") + " --sensor " + (tmp / "in/acq") + " --out " +
          f + "oldrec --force",
      "batch --input " + (tmp / "in") + " --phi asp:2 --methods pinv --out " + f + "b",
      "train " + (tmp / "c.json") + " --out " + f + "t",
      "train " + (tmp / "c.json") + " --out " + f + "oldrun --force",
      "experiment " + (tmp / "c.json") + " --out " + f + "x",
      "export --model " + (tmp / "asp.ckpt") + " --out " + f + "old.pt --force",
      "phi export --phi mask:2 --out " + f + "cam",
      "blend --model " + (tmp / "asp.ckpt") + " --base " + (tmp / "asp.ckpt") + " --out " + f +
          "blend.ckpt",
      "bench --phi asp:2 --methods pinv --reps 1 --strides 9 --height 24 --width 24 "
      "--skip-kernels --json " +
          f + "bench.json",
      "report " + f + "report_run",
  };
  // Work that ran before the write may have printed its result (evaluate's summary, bench's
  // table); the error is one line with the reason, and nothing changed.
  const auto before = snapshot(full);
  for (const auto& command : commands) {
    const int rc = run_command(quiet_program(command), out);
    INFO("lfnet " << command << "\n-> " << out);
    CHECK(rc != 0);
    const size_t error = out.find("lfnet: error: ");
    REQUIRE(error != std::string::npos);
    CHECK(out.find("lfnet: error: ", error + 1) == std::string::npos);
    const std::string line = out.substr(error, out.find('\n', error) - error);
    CHECK(line.find("No space left on device") != std::string::npos);
    CHECK(line.find(".tmp") == std::string::npos);  // named as the output, not its temporary
    CHECK(snapshot(full) == before);
  }
}

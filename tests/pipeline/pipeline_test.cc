// The pipeline library: experiment configs (scales, --set overrides, run folders), and
// reconstructing and evaluating without the program.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/optics/measure.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/experiment.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/simulate.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/methods.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using namespace lfnet;

namespace {
nlohmann::json small_config() {
  return {{"name", "small"},
          {"phi", "asp:2"},
          {"data", {{"random_scenes", 2}}},
          {"training", {{"epochs", 3}, {"batch_size", 64}}},
          {"stages", {"cnn"}},
          {"scales", {{"quick", {{"training", {{"epochs", 1}}}}}}},
          {"default_scale", "quick"}};
}
}  // namespace

TEST_CASE("a config's scale and --set overrides apply in order and are type-checked",
          "[pipeline]") {
  lfnet::test::TempDir tmp;
  write_json_file(tmp / "c.json", small_config());
  auto config = pipeline::ExperimentConfig::load(tmp / "c.json");
  CHECK(config.scale == "quick");
  CHECK(config.training["epochs"] == 1);
  config = pipeline::ExperimentConfig::load(tmp / "c.json", "quick",
                                            {"training.epochs=2", "dataset.seed=9", "name=other"});
  CHECK(config.training["epochs"] == 2);
  CHECK(config.dataset.seed == 9);
  CHECK(config.name == "other");
  CHECK(config.raw["training"]["epochs"] == 2);  // recorded in the run's config.json
  // Validated like the file: the JSON path and the rule, before any work.
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "c.json", "", {"training.epochs=1.5"}),
                    Catch::Contains("$.training.epochs"));
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "c.json", "", {"training.nosuch=1"}),
                    Catch::Contains("nosuch"));
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "c.json", "", {"training.epochs"}),
                    Catch::Contains("KEY.PATH=VALUE"));
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "c.json", "", {"name.x=1"}),
                    Catch::Contains("not an object"));
}

TEST_CASE("a config extends its base at the same scale, then its own keys, then its own scale",
          "[pipeline][recipes]") {
  lfnet::test::TempDir tmp;
  auto base = small_config();
  base["scales"]["paper"] = {{"training", {{"epochs", 20}}}, {"dataset", {{"seed", 5}}}};
  fs::create_directories(tmp / "models");
  write_json_file(tmp / "models/base.json", base);
  write_text_file(tmp / "start.ckpt", "a checkpoint");
  // The step: relative to itself; keys that hold at every scale, and its own paper patch.
  write_json_file(tmp / "step.json", {{"extends", "models/base.json"},
                                      {"name", "step"},
                                      {"init", tmp / "start.ckpt"},
                                      {"training", {{"lr", 0.0004}}},
                                      {"scales", {{"paper", {{"training", {{"epochs", 30}}}}}}}});
  auto quick = pipeline::ExperimentConfig::load(tmp / "step.json");  // the base's default scale
  CHECK(quick.scale == "quick");
  CHECK(quick.name == "step");
  CHECK(quick.training["epochs"] == 1);
  CHECK(quick.training["lr"] == 0.0004);
  CHECK(quick.training["batch_size"] == 64);
  CHECK(quick.init == tmp / "start.ckpt");
  CHECK(quick.raw["init"] == tmp / "start.ckpt");  // recorded in the run's config.json
  CHECK_FALSE(quick.raw.contains("extends"));
  auto paper = pipeline::ExperimentConfig::load(tmp / "step.json", "paper", {"dataset.seed=8"});
  CHECK(paper.training["epochs"] == 30);  // the step's own patch comes after the base's
  CHECK(paper.training["lr"] == 0.0004);
  CHECK(paper.dataset.seed == 8);  // --set last
  // A chain of two, a scale no file has, a missing base, a cycle, a missing init.
  write_json_file(tmp / "step2.json", {{"extends", "step.json"}, {"training", {{"lr", 0.0001}}}});
  auto second = pipeline::ExperimentConfig::load(tmp / "step2.json", "paper");
  CHECK(second.training["epochs"] == 30);
  CHECK(second.training["lr"] == 0.0001);
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "step2.json", "huge"),
                    Catch::Contains("no scale 'huge'"));
  write_json_file(tmp / "orphan.json", {{"extends", "nowhere.json"}});
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "orphan.json"),
                    Catch::Contains("nowhere.json") && Catch::Contains("does not exist"));
  write_json_file(tmp / "a.json", {{"extends", "b.json"}});
  write_json_file(tmp / "b.json", {{"extends", "a.json"}});
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "a.json"), Catch::Contains("cycle"));
  // $.extends empty, naming a folder or a file that is no config: each said as $.extends.
  write_json_file(tmp / "empty.json", {{"extends", ""}});
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "empty.json"),
                    Catch::Contains("$.extends: expected the path of a config"));
  std::filesystem::create_directories(tmp.path() / "folder");
  write_json_file(tmp / "dir.json", {{"extends", "folder"}});
  CHECK_THROWS_WITH(
      pipeline::ExperimentConfig::load(tmp / "dir.json"),
      Catch::Contains("is a folder, not a config file") && Catch::Contains("($.extends of "));
  std::ofstream(tmp / "view.png") << "not a config";
  write_json_file(tmp / "png.json", {{"extends", "view.png"}});
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "png.json"),
                    Catch::Contains("$.extends of ") && Catch::Contains("view.png"));
  write_json_file(tmp / "lost.json", {{"extends", "step.json"}, {"init", tmp / "gone.ckpt"}});
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "lost.json"),
                    Catch::Contains("$.init") && Catch::Contains("gone.ckpt"));
  // $.init written relative to the config: the error names the file beside it.
  std::filesystem::create_directories(tmp.path() / "sub");
  std::ofstream(tmp / "sub/start.ckpt") << "LFNETCKP";
  write_json_file(tmp / "sub/rel.json", {{"extends", "../step.json"}, {"init", "start.ckpt"}});
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "sub/rel.json"),
                    Catch::Contains("taken from the working folder, not the config's: give ") &&
                        Catch::Contains("sub/start.ckpt"));
}

TEST_CASE("every model in models/ has a recipe, and every recipe's config is valid",
          "[pipeline][recipes][slow]") {
  std::string out;
  const int rc =
      lfnet::test::run_command(std::string("LFNET=") + LFNET_BINARY + " " + LFNET_TEST_PYTHON +
                                   " " + LFNET_SOURCE_DIR + "/scripts/models.py check 2>&1",
                               out);
  INFO(out);
  CHECK(rc == 0);
  // It read every recipe of the list.
  std::ifstream list(std::string(LFNET_SOURCE_DIR) + "/configs/recipes.json");
  const auto recipes = nlohmann::json::parse(list).at("recipes").size();
  REQUIRE(recipes > 90);
  CHECK(out.find(std::to_string(recipes) + " recipes") != std::string::npos);
}

TEST_CASE("train --show-config resolves a config whose inputs are not made yet", "[pipeline]") {
  // scripts/models.py reads every recipe's config so, before the models it starts from exist.
  lfnet::test::TempDir tmp;
  auto base = small_config();
  base["scales"] = {{"paper", {{"training", {{"epochs", 7}}}}}};
  write_json_file(tmp / "base.json", base);
  write_json_file(tmp / "c.json", {{"extends", "base.json"},
                                   {"init", tmp / "not-made.ckpt"},
                                   {"phi", tmp / "code-not-made.ckpt"},
                                   {"training", {{"batch_size", 3}}}});
  const std::string train =
      std::string(LFNET_BINARY) + " --log-level error train " + tmp / "c.json" + " --scale paper ";
  std::string out;
  REQUIRE(lfnet::test::run_command(train + "--show-config 2>&1", out) == 0);
  const auto shown = nlohmann::json::parse(out);
  CHECK(shown.at("scale") == "paper");
  CHECK(shown.at("training").at("epochs") == 7);      // the base's scale
  CHECK(shown.at("training").at("batch_size") == 3);  // the config's own key
  CHECK(shown.at("init") == tmp / "not-made.ckpt");
  CHECK(shown.at("phi") == tmp / "code-not-made.ckpt");  // a model's code, read once made
  CHECK_FALSE(shown.contains("extends"));
  // A run of it (and --check) needs the models, and says which is missing.
  CHECK(lfnet::test::run_command(train + "--check 2>&1", out) != 0);
  CHECK(out.find("$.phi " + tmp / "code-not-made.ckpt" + ": no such file") != std::string::npos);
  write_json_file(tmp / "c.json", {{"extends", "base.json"}, {"init", tmp / "not-made.ckpt"}});
  CHECK(lfnet::test::run_command(train + "--check 2>&1", out) != 0);
  CHECK(out.find("$.init") != std::string::npos);
}

TEST_CASE("network.patch and network.measurements are honoured when they agree, else refused",
          "[pipeline]") {
  lfnet::test::TempDir tmp;
  write_json_file(tmp / "c.json", small_config());
  // They follow from the Phi and the dataset's patches.
  auto config = pipeline::ExperimentConfig::load(tmp / "c.json", "", {"dataset.patch_h=12"});
  CHECK(config.network.patch.height == 12);
  CHECK(config.network.measurements == 2);
  // Given and agreeing: honoured.
  config = pipeline::ExperimentConfig::load(
      tmp / "c.json", "",
      {"dataset.patch_w=12", "network.patch.width=12", "network.measurements=2"});
  CHECK(config.network.patch.width == 12);
  // Given and disagreeing: refused, naming where the value comes from, never silently replaced.
  CHECK_THROWS_WITH(
      pipeline::ExperimentConfig::load(tmp / "c.json", "", {"network.patch.height=64"}),
      Catch::Contains("$.network.patch.height is 64") && Catch::Contains("$.dataset.patch_h"));
  CHECK_THROWS_WITH(
      pipeline::ExperimentConfig::load(tmp / "c.json", "", {"network.measurements=3"}),
      Catch::Contains("$.network.measurements is 3") && Catch::Contains("$.phi"));
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load(tmp / "c.json", "", {"network.patch.rows=7"}),
                    Catch::Contains("$.network.patch.rows is 7"));
}

TEST_CASE("a run folder's config.json reads back as the config it trained", "[pipeline]") {
  lfnet::test::TempDir tmp;
  write_json_file(tmp / "c.json", small_config());
  const auto config = pipeline::ExperimentConfig::load(tmp / "c.json", "", {"training.lr=0.01"});
  fs::create_directories(tmp.path() / "run");
  nlohmann::json recorded = config.raw;
  recorded["scale"] = config.scale;
  write_json_file(tmp / "run/config.json", recorded);
  const auto back = pipeline::ExperimentConfig::load_run(tmp / "run");
  CHECK(back.scale == "quick");
  CHECK(back.raw == config.raw);
  CHECK(back.stage_options(back.stages[0]).lr == Approx(0.01));
  CHECK_THROWS_WITH(pipeline::ExperimentConfig::load_run(tmp.path().string()),
                    Catch::Contains("not a run folder"));
}

TEST_CASE("reconstruct_acquisition with pinv equals the solver run directly", "[pipeline]") {
  lfnet::test::TempDir tmp;
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto lf = torch::rand({1, 5, 5, 27, 36});
  const auto sensor = optics::simulate_sensor(*phi, lf[0]).unsqueeze(0);  // (C, N, H, W)
  const std::string acq = tmp / "acq";
  fs::create_directories(acq);
  io::write_sensor_images(acq, sensor);
  write_json_file(
      (fs::path(acq) / io::kSidecarName).string(),
      {{"format", io::kAcquisitionFormat},
       {"format_version", io::kAcquisitionFormatVersion},
       {"mode", "sensor"},
       {"phi", phi->spec().to_json()},
       {"light_field", {{"channels", 1}, {"rows", 5}, {"cols", 5}, {"height", 27}, {"width", 36}}},
       {"sensor",
        {{"files", io::sensor_file_names(1)}, {"channels_per_file", 2}, {"dtype", "float32"}}}});
  pipeline::ReconstructRequest request;
  request.sensor = acq;
  request.method = "pinv";
  const auto r = pipeline::reconstruct_acquisition(request);
  recon::ReconstructOptions o = request.options;
  const auto direct =
      recon::reconstruct_sensor(*phi, io::read_acquisition(acq).sensor[0],
                                recon::pinv_solver(optics::pinv_matrix_stack(*phi, 9, 9)), o);
  const auto result = r.lf.decode().data();
  REQUIRE(result.sizes() == direct.sizes());
  CHECK(torch::equal(result, direct));
  CHECK(r.record["method"] == "pinv");
  // The method's needs are checked before any work, with the option that supplies them.
  request.method = "dict";
  CHECK_THROWS_WITH(pipeline::reconstruct_acquisition(request), Catch::Contains("--dictionary"));
  request.method = "no-parallax";
  CHECK_THROWS_WITH(pipeline::reconstruct_acquisition(request),
                    Catch::Contains("true light field"));
  // Written by the output policy: never over its own input.
  OutputFolderPolicy policy;
  policy.inputs = {acq};
  CHECK_THROWS_WITH(pipeline::write_reconstruction(r, acq, policy),
                    Catch::Contains("is the input"));
  pipeline::write_reconstruction(r, tmp / "rec", policy);
  CHECK(fs::exists(tmp.path() / "rec/reconstruction.json"));
}

TEST_CASE("evaluate_method scores the registry's methods and the no-parallax baseline",
          "[pipeline]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  pipeline::NamedLightField truth{"noise", LightField(torch::rand({1, 5, 5, 18, 18})), {}};
  pipeline::MethodContext context;
  context.phi = phi.get();
  const auto o = pipeline::make_eval_options(optics::SimulationMode::kSensor, 0.0, 0, 5, 256, false,
                                             std::nullopt);
  const auto pinv = pipeline::evaluate_method(truth, "pinv", context, o, nullptr, false);
  const auto adjoint = pipeline::evaluate_method(truth, "adjoint", context, o, nullptr, false);
  const auto baseline = pipeline::evaluate_method(truth, "no-parallax", context, o, nullptr, false);
  CHECK(pinv["light_field"] == "noise");
  CHECK(pinv["method"] == "pinv");
  CHECK(pinv["psnr_db"].get<double>() > adjoint["psnr_db"].get<double>());
  CHECK(baseline["method"] == "no-parallax");
  CHECK_THROWS_WITH(pipeline::evaluate_method(truth, "net", context, o, nullptr, false),
                    Catch::Contains("--model"));
  CHECK_FALSE(pinv.contains("equivalent_sigma"));
}

TEST_CASE("a truth held in 16-bit codes is simulated in bands and scores as its float32 values",
          "[pipeline]") {
  torch::manual_seed(12);
  // Views wide enough that the simulation takes several bands of rows (about 2^22 values each,
  // starting on the code's period).
  const auto codes = encode_codes(torch::rand({1, 5, 5, 160, 2100}));
  const pipeline::NamedLightField plain{"plain", LightField(decode_codes(codes)), {}};
  const pipeline::NamedLightField coded{"coded", LightField(), codes};
  REQUIRE(coded.views().coded());
  for (const std::string name : {"asp:2", "mask:2"}) {
    INFO(name);
    auto phi = optics::make_phi(optics::PhiSpec::parse(name));
    pipeline::MethodContext context;
    context.phi = phi.get();
    const auto o = pipeline::make_eval_options(optics::SimulationMode::kSensor, 0.01, 3, 5, 4096,
                                               false, std::nullopt);
    const auto a = pipeline::evaluate_method(plain, "pinv", context, o, nullptr, false);
    const auto b = pipeline::evaluate_method(coded, "pinv", context, o, nullptr, false);
    CHECK(b["psnr_db"].get<double>() == Approx(a["psnr_db"].get<double>()).epsilon(1e-9));
    CHECK(b["ssim"].get<double>() == Approx(a["ssim"].get<double>()).epsilon(1e-9));
    const auto np = pipeline::evaluate_method(coded, "no-parallax", context, o, nullptr, false);
    CHECK(np["psnr_db"].get<double>() ==
          pipeline::evaluate_method(plain, "no-parallax", context, o, nullptr, false)["psnr_db"]
              .get<double>());
    // File-backed, as a large light field's: out of memory while the method runs and read back
    // a band at a time, truth and estimate score alike and the truth is unchanged.
    auto oc = o;
    oc.reconstruct.coded = true;  // the estimate in codes too
    const auto ref = pipeline::evaluate_method(coded, "pinv", context, oc, nullptr, false);
    const test::FileBackedEverything everything;
    const pipeline::NamedLightField held{"held", LightField(), file_backed_copy(codes)};
    CHECK(file_backed(held.codes) == test::FileBackedEverything::available());
    torch::Tensor estimate;
    const auto c = pipeline::evaluate_method(held, "pinv", context, oc, &estimate, false);
    CHECK(file_backed(estimate) == test::FileBackedEverything::available());
    CHECK(c["psnr_db"].get<double>() == ref["psnr_db"].get<double>());
    CHECK(c["ssim"].get<double>() == ref["ssim"].get<double>());
    CHECK(torch::equal(held.codes, codes));
  }
}

namespace {

// A method with an option, registered from outside the library: the pseudo-inverse times a
// gain. Its class and the one register_method call are all it takes.
struct GainOptions {
  double gain = 1.0;
  template <typename Fields>
  void fields(Fields& f) {
    f("gain", gain);
  }
  void validate() const { LFNET_CHECK_AS(ConfigError, gain > 0, "gain: must be > 0, got ", gain); }
};

class GainPinvMethod : public recon::MethodWithOptions<GainOptions> {
 public:
  std::string name() const override { return "gain-pinv"; }
  std::string summary() const override { return "the pseudo-inverse times a gain (a test)"; }
  recon::PatchSolver solver(const recon::MethodResources& r) const override {
    const double gain = options(r).gain;
    auto pinv = recon::pinv_solver(optics::pinv_matrix_stack(*r.phi, r.patch_h, r.patch_w));
    return [pinv, gain](const torch::Tensor& y, const torch::Tensor& phase) {
      return pinv(y, phase) * gain;
    };
  }
};

}  // namespace

TEST_CASE("a method with options registered from outside is read and run like the built-ins",
          "[pipeline][method_options]") {
  recon::register_method(std::make_unique<GainPinvMethod>());
  CHECK(recon::methods_with_options() == "dict, pinv-nlm, gain-pinv");
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  pipeline::NamedLightField truth{"flat", LightField(torch::full({1, 5, 5, 18, 18}, 0.4)), {}};
  pipeline::MethodContext context;
  context.phi = phi.get();
  const auto o = pipeline::make_eval_options(optics::SimulationMode::kSensor, 0.0, 0, 9, 256, false,
                                             std::nullopt);
  torch::Tensor plain, halved;
  const auto r1 = pipeline::evaluate_method(truth, "gain-pinv", context, o, &plain, false);
  context.method_options =
      pipeline::method_options_argument(R"({"gain-pinv": {"gain": 0.5}})", {"gain-pinv"});
  const auto r2 = pipeline::evaluate_method(truth, "gain-pinv", context, o, &halved, false);
  CHECK(r1["method_options"] == nlohmann::json({{"gain", 1.0}}));
  CHECK(r2["method_options"] == nlohmann::json({{"gain", 0.5}}));
  CHECK(torch::allclose(halved, plain * 0.5, 1e-5, 1e-6));
  CHECK_THROWS_WITH(
      pipeline::method_options_argument(R"({"gain-pinv": {"gain": -1}})", {"gain-pinv"}),
      Catch::Contains("--method-options.gain-pinv.gain: must be > 0"));
}

TEST_CASE("shot and read noise are recorded as their equivalent Gaussian sigma",
          "[pipeline][simulate]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const LightField lf(torch::rand({1, 5, 5, 20, 20}) * 0.5 + 0.25);
  auto effects = optics::SensorOptions::from_json(
      {{"photons_at_white", 40}, {"shot", {{"model", "gaussian"}}}, {"read", {{"electrons", 4}}}});
  const double mean = optics::simulate_sensor(*phi, lf.data()).mean().item<double>();
  const double want = std::sqrt(mean / 40 + std::pow(4.0 / 40, 2));
  // What a noise-aware net reads from an acquisition, and what an evaluation records.
  test::TempDir tmp;
  pipeline::SimulateRequest r;
  r.lf = lf;
  r.phi = phi.get();
  r.effects = effects;
  fs::create_directories(tmp / "sensor");
  CHECK(pipeline::write_acquisition(r, tmp / "sensor")["noise_sigma"].get<double>() ==
        Approx(want).epsilon(0.02));
  pipeline::MethodContext context;
  context.phi = phi.get();
  for (auto mode : {optics::SimulationMode::kSensor, optics::SimulationMode::kPerPatch}) {
    auto o = pipeline::make_eval_options(mode, 0.0, 0, 5, 256, false, std::nullopt);
    o.effects = effects;
    std::vector<double> sigmas;
    for (const std::string method : {"pinv", "pinv-nlm", "no-parallax"}) {
      if (method == "pinv-nlm" && mode == optics::SimulationMode::kPerPatch) continue;
      INFO(method << " " << optics::to_string(mode));
      const pipeline::NamedLightField truth{"lf", lf, {}};
      const auto record = pipeline::evaluate_method(truth, method, context, o, nullptr, false);
      sigmas.push_back(record.at("equivalent_sigma").get<double>());
      CHECK(sigmas.back() == Approx(want).epsilon(0.05));
      CHECK(record.at("noise_sigma") == 0.0);
    }
    // Every method of one evaluation names the same noise (tables group records by it), to
    // float32 rounding (per patch, the mean is summed band by band).
    for (double sigma : sigmas) CHECK(sigma == Approx(sigmas.front()).epsilon(1e-6));
  }
}

TEST_CASE("evaluate --effects reads the file as simulate does, --noise as its Gaussian sigma",
          "[pipeline]") {
  test::TempDir tmp;
  io::write_light_field(LightField(torch::rand({1, 5, 5, 18, 18}) * 0.5 + 0.25), tmp / "lf");
  write_json_file(tmp / "sensor.json", {{"photons_at_white", 40},
                                        {"shot", {{"model", "gaussian"}}},
                                        {"read", {{"electrons", 4}}},
                                        {"gaussian", {{"sigma", 0.05}}}});
  pipeline::EvaluateRequest q;
  q.lf = tmp / "lf";
  q.phi = "asp:2";
  q.method = "pinv";
  q.effects = tmp / "sensor.json";
  auto effects = pipeline::simulation_effects(q.effects, -1, {}, "");
  const auto with_file = pipeline::evaluate_request(q).record;
  CHECK(with_file.at("effects") == effects.to_json());
  const double sigma = with_file.at("equivalent_sigma").get<double>();
  CHECK(sigma > 0.05);
  q.noise = 0.2;
  const auto with_noise = pipeline::evaluate_request(q).record;
  effects.gaussian->sigma = 0.2;
  CHECK(with_noise.at("effects") == effects.to_json());
  CHECK(with_noise.at("equivalent_sigma").get<double>() > sigma);
  write_json_file(tmp / "bad.json", {{"shot", {{"modle", "gaussian"}}}});
  q.effects = tmp / "bad.json";
  CHECK_THROWS_WITH(pipeline::evaluate_request(q), Catch::Contains("bad.json:$.shot.modle"));
}

TEST_CASE("the dict method codes as its dictionary recommends, unless its options say otherwise",
          "[pipeline][dict][method_options]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  dict::Dictionary d;
  d.atoms = torch::nn::functional::normalize(torch::randn({int64_t{25} * 81, 40}),
                                             torch::nn::functional::NormalizeFuncOptions().dim(0));
  pipeline::MethodContext context;
  context.phi = phi.get();
  context.dictionary_data = &d;
  auto used = [&](const nlohmann::json& options) {
    context.method_options = options;
    return pipeline::prepare_method("dict", context, 9, 9).options;
  };
  // No recommendation: the library's default, OMP.
  CHECK(used(nlohmann::json::object())["method"] == "omp");
  d.training["coding"] = {{"method", "admm"}, {"admm", {{"lambda", 0.001}}}};
  auto c = used(nlohmann::json::object());
  CHECK(c["method"] == "admm");
  CHECK(c["admm"]["lambda"] == 0.001);
  // The options given override field by field.
  c = used({{"dict", {{"admm", {{"rho", 2}}}}}});
  CHECK(c["method"] == "admm");
  CHECK(c["admm"]["lambda"] == 0.001);
  CHECK(c["admm"]["rho"] == 2.0);
  CHECK(used({{"dict", {{"method", "omp"}}}})["method"] == "omp");
  // Errors name the option and the JSON path.
  CHECK_THROWS_WITH(used({{"dict", {{"omp", {{"max_atom", 20}}}}}}),
                    Catch::Contains("--method-options.dict.omp.max_atom"));
  CHECK_THROWS_WITH(
      used({{"dict", {{"method", "lasso"}}}}),
      Catch::Contains("--method-options.dict.method") && Catch::Contains("known: omp, admm"));
}

TEST_CASE("method options are keyed by method, read from JSON or a file, and checked before work",
          "[pipeline][method_options]") {
  test::TempDir tmp;
  const std::vector<std::string> run = {"dict", "pinv", "pinv-nlm"};
  write_json_file(tmp / "options.json", {{"dict", {{"omp", {{"max_atoms", 20}}}}}});
  CHECK(pipeline::method_options_argument(tmp / "options.json", run)["dict"]["omp"]["max_atoms"] ==
        20);
  CHECK(pipeline::method_options_argument("", run).empty());
  CHECK_THROWS_WITH(pipeline::method_options_argument(R"({"dict": )", run),
                    Catch::Contains("--method-options"));
  CHECK_THROWS_WITH(pipeline::method_options_argument(tmp / "none.json", run),
                    Catch::Contains("--method-options"));
  // Not keyed by method: the keys are read as method names.
  CHECK_THROWS_WITH(pipeline::method_options_argument(R"({"omp": {"max_atoms": 20}})", run),
                    Catch::Contains("unknown method 'omp'"));
  CHECK_THROWS_WITH(pipeline::method_options_argument(R"({"dict": {}})", {"pinv"}),
                    Catch::Contains("'dict', which this command does not run (pinv)"));
  CHECK_THROWS_WITH(
      pipeline::method_options_argument(R"({"pinv": {"lambda": 1}})", run),
      Catch::Contains("method 'pinv' takes no options") && Catch::Contains("dict, pinv-nlm"));
  // pinv-nlm: a registered denoiser, and that denoiser's own options.
  CHECK_NOTHROW(pipeline::method_options_argument(
      R"({"pinv-nlm": {"denoiser": "nlm", "options": {"search": 3}}})", run));
  CHECK_THROWS_WITH(pipeline::method_options_argument(R"({"pinv-nlm": {"denoiser": "bm3d"}})", run),
                    Catch::Contains("unknown denoiser 'bm3d'") && Catch::Contains("nlm"));
  CHECK_THROWS_WITH(pipeline::method_options_argument(
                        R"({"pinv-nlm": {"denoiser": "nlm", "options": {"h": -1}}})", run),
                    Catch::Contains("--method-options.pinv-nlm.options") &&
                        Catch::Contains("h: must lie in (0, 100], got -1"));
  // A run's record says which options it ran with, complete.
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  pipeline::MethodContext context;
  context.phi = phi.get();
  context.method_options = {{"pinv-nlm", {{"denoiser", "nlm"}}}};
  const auto p = pipeline::prepare_method("pinv-nlm", context, 9, 9);
  CHECK(p.options["denoiser"] == "nlm");
  CHECK(p.options["options"]["search"] == 5);
  CHECK(pipeline::prepare_method("pinv", context, 9, 9).options.empty());
}

TEST_CASE("write_acquisition writes what the optics simulate, and read_acquisition reads it",
          "[pipeline][simulate]") {
  test::TempDir tmp;
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  pipeline::SimulateRequest r;
  r.lf = LightField(torch::rand({1, 5, 5, 20, 23}));
  r.phi = phi.get();
  r.effects.gaussian = optics::SensorOptions::Gaussian{0.05};
  r.seed = 9;
  r.source = {{"kind", "test"}};
  fs::create_directories(tmp / "sensor");
  const auto meta = pipeline::write_acquisition(r, tmp / "sensor");
  CHECK(meta["noise_sigma"] == 0.05);
  const auto acq = io::read_acquisition(tmp / "sensor");
  CHECK(acq.meta == meta);
  const auto want = optics::simulate_sensor(*phi, r.lf.data(), r.effects, r.seed);
  CHECK(torch::equal(acq.sensor, want));
  // per_patch: every patch measured alone, in the order of the grid.
  r.mode = optics::SimulationMode::kPerPatch;
  r.stride = 7;
  fs::create_directories(tmp / "patches");
  pipeline::write_acquisition(r, tmp / "patches");
  const auto per_patch = io::read_acquisition(tmp / "patches");
  const PatchGrid grid(20, 23, 9, 9, 7);
  const auto direct =
      optics::measure_patches(*phi, r.lf.data(), grid, r.mode, r.effects, r.seed, 0, grid.rows());
  // N h w = 2 x 9 x 9 measurements per patch.
  CHECK(per_patch.measurements.sizes() == torch::IntArrayRef({1, grid.size(), 162}));
  CHECK(torch::equal(per_patch.measurements, direct.values.view({1, grid.size(), -1})));
}

TEST_CASE("simulate's inputs: the window, the Phi on it, the effects, and the Phi described",
          "[pipeline][simulate]") {
  test::TempDir tmp;
  io::write_light_field(test::parallax_light_field(7, 7, 12, 14, 1, -1), tmp / "lf");
  pipeline::SimulateSource source;
  source.lf = tmp / "lf";
  auto input = pipeline::load_simulate_input(source);
  CHECK(input.lf.shape_string() == LightField(torch::zeros({1, 5, 5, 12, 14})).shape_string());
  CHECK((input.views["rows"] == nlohmann::json{2, 6}));  // the central 5 x 5 of 7 x 7
  CHECK(input.source["kind"] == "light_field");
  source.views = "1:3,1:4";
  input = pipeline::load_simulate_input(source);
  CHECK(input.lf.rows() == 3);
  CHECK(input.lf.cols() == 4);
  CHECK((pipeline::window_size("1:3,1:4") == std::pair<int64_t, int64_t>{3, 4}));
  CHECK((pipeline::window_size("") == std::pair<int64_t, int64_t>{5, 5}));
  const auto spec = pipeline::phi_for_window("mask:2", 3, 4);
  CHECK(spec.rows == 3);
  CHECK(spec.cols == 4);
  // A spec file codes its own window: another one is refused.
  write_json_file(tmp / "phi.json", {{"name", "asp"}, {"n", 2}});
  CHECK_THROWS_WITH(pipeline::phi_for_window(tmp / "phi.json", 3, 4), Catch::Contains("--views"));
  // The effects file, then --noise over it.
  write_json_file(tmp / "effects.json",
                  {{"gaussian", {{"sigma", 0.05}}}, {"read", nlohmann::json::object()}});
  auto effects = pipeline::simulation_effects(tmp / "effects.json", -1, input, "");
  REQUIRE(effects.gaussian.has_value());
  CHECK(effects.gaussian->sigma == 0.05);
  CHECK(effects.read.has_value());
  effects = pipeline::simulation_effects(tmp / "effects.json", 0.2, input, "");
  CHECK(effects.gaussian->sigma == 0.2);
  CHECK(pipeline::simulation_effects("", -1, input, "").empty());
  // The description names the spec and, for a single matrix, its condition number.
  const auto text = pipeline::describe_phi(*optics::make_phi(optics::PhiSpec::parse("random:2")));
  CHECK(text.find("random:2") != std::string::npos);
  CHECK(text.find("condition:") != std::string::npos);
  const auto asp = pipeline::describe_phi(*optics::make_phi(optics::PhiSpec::parse("asp:2")));
  CHECK(asp.find("asp table:") != std::string::npos);
  // A periodic mask has one matrix per pixel phase: a table of their condition numbers.
  const auto mask = pipeline::describe_phi(*optics::make_phi(optics::PhiSpec::parse("mask:2")));
  CHECK(mask.find("condition by pixel phase") != std::string::npos);
}

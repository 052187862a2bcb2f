#include "workflow.h"

#include "command.h"

#include <spdlog/spdlog.h>
#include <torch/utils.h>

#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/parallax.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/patches.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/core/runtime.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/post_filter.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/recon/methods.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"
#include "lfnet/train/checkpoint.h"

namespace fs = std::filesystem;

namespace lfnet::app {

void LightFieldSources::read(JsonReader& r) {
  r.get("light_fields", light_fields);
  r.get("scenes", scenes);
  r.get("random_scenes", random_scenes);
  r.get("random_seed", random_seed);
  r.get("random_options", random_options);
  r.get("views", views);
  r.get("orient", orient);
  r.finish();
  if (random_scenes < 0) throw ConfigError(r.path_of("random_scenes") + ": must be >= 0");
  AngularOrientation::parse(orient, r.path_of("orient"));
}

nlohmann::json LightFieldSources::to_json() const {
  return {{"light_fields", light_fields}, {"scenes", scenes},
          {"random_scenes", random_scenes}, {"random_seed", random_seed},
          {"random_options", random_options}, {"views", views}, {"orient", orient}};
}

LightField read_oriented(const std::string& dir, const std::string& orient,
                         const std::string& what) {
  const auto orientation = AngularOrientation::parse(orient, what);
  LightField lf = reorient(io::read_light_field(dir), orientation);
  const auto check = check_parallax(lf);
  if (check.verdict == ParallaxVerdict::kDisagree) {
    static std::mutex mutex;
    static std::set<std::string> warned;
    std::lock_guard<std::mutex> lock(mutex);
    if (warned.insert(fs::absolute(dir).lexically_normal().string()).second) {
      spdlog::warn("{}: {}; if its views are named from the bottom row, load it with {} flip-u "
                   "(docs/conventions.md)",
                   dir, check.summary(), what);
    }
  }
  return lf;
}

namespace {
LightField select_views(const LightField& lf, const std::string& views, int64_t rows,
                        int64_t cols, const std::string& name) {
  LightField out;
  if (views.empty()) {
    LFNET_CHECK_AS(ConfigError, lf.rows() >= rows && lf.cols() >= cols, name, " has ", lf.rows(),
                   "x", lf.cols(), " views, fewer than the ", rows, "x", cols, " the Phi codes");
    const int64_t u0 = central_start(lf.rows(), rows), v0 = central_start(lf.cols(), cols);
    out = lf.window({u0, u0 + rows}, {v0, v0 + cols});
  } else {
    auto [ru, rv] = parse_views(views);
    out = lf.window(ru, rv);
    LFNET_CHECK_AS(ConfigError, out.rows() == rows && out.cols() == cols, "views ", views,
                   " select ", out.rows(), "x", out.cols(), " views but the Phi codes ", rows,
                   "x", cols);
  }
  return out.grey();
}
}  // namespace

std::vector<NamedLightField> load_sources(const LightFieldSources& sources, int64_t rows,
                                          int64_t cols, bool whole_grids) {
  std::vector<NamedLightField> out;
  const int64_t total = static_cast<int64_t>(sources.light_fields.size() + sources.scenes.size()) +
                        sources.random_scenes;
  ProgressBar bar("loading light fields", total);
  for (const auto& dir : sources.light_fields) {
    auto lf = read_oriented(dir, sources.orient, "orient");
    if (whole_grids && sources.views.empty()) {
      LFNET_CHECK_AS(ConfigError, lf.rows() >= rows && lf.cols() >= cols, dir, " has ", lf.rows(),
                     "x", lf.cols(), " views, fewer than the ", rows, "x", cols, " the Phi codes");
      out.push_back({fs::path(dir).filename().string(), lf.grey()});
    } else {
      out.push_back({fs::path(dir).filename().string(),
                     select_views(lf, sources.views, rows, cols, dir)});
    }
    bar.advance();
  }
  for (const auto& path : sources.scenes) {
    scene::SceneSpec spec;
    try {
      spec = scene::load_scene(path);
    } catch (const ConfigError& e) {
      throw ConfigError(path + ": " + e.what());
    }
    spec.color = false;
    auto lf = scene::render_scene(spec, scene_render_options(path)).light_field;
    out.push_back({fs::path(path).stem().string(), select_views(lf, "", rows, cols, path)});
    bar.advance();
  }
  if (sources.random_scenes > 0) {
    JsonReader reader(sources.random_options, "$.random_options");
    auto options = scene::RandomSceneOptions::from_json(reader);
    options.rows = rows;
    options.cols = cols;
    options.color = false;
    for (int64_t i = 0; i < sources.random_scenes; ++i) {
      const uint64_t seed = sources.random_seed + static_cast<uint64_t>(i);
      auto lf = scene::render_scene(scene::random_scene(seed, options), scene_render_options(""))
                    .light_field;
      out.push_back({"random-" + std::to_string(seed), lf.grey()});
      bar.advance();
    }
  }
  return out;
}

void EvaluationConfig::read(JsonReader& r) {
  if (r.has("data")) {
    auto d = r.child("data");
    data.read(d);
  }
  r.get("methods", methods);
  r.get("strides", strides);
  r.get("modes", modes);
  r.get("noise", noise);
  r.get("model_stage", model_stage);
  r.finish();
}

nlohmann::json EvaluationConfig::to_json() const {
  return {{"data", data.to_json()}, {"methods", methods}, {"strides", strides},
          {"modes", modes},         {"noise", noise},     {"model_stage", model_stage}};
}

ExperimentConfig ExperimentConfig::load(const std::string& path, const std::string& scale) {
  auto j = read_json_file(path);
  LFNET_CHECK_AS(ConfigError, j.is_object(), path, ": a config is a JSON object");
  std::string chosen = scale;
  if (chosen.empty() && j.contains("default_scale")) {
    LFNET_CHECK_AS(ConfigError, j["default_scale"].is_string(), path,
                   ": $.default_scale: expected the name of a scale, got ",
                   j["default_scale"].dump());
    chosen = j["default_scale"].get<std::string>();
  }
  if (j.contains("scales")) {
    LFNET_CHECK_AS(ConfigError, j["scales"].is_object(), path,
                   ": $.scales: expected an object of named config patches");
    // Every scale is merged into the config when chosen, so each must be an object.
    for (const auto& [name, patch] : j["scales"].items()) {
      LFNET_CHECK_AS(ConfigError, patch.is_object(), path, ": $.scales.", name,
                     ": expected an object (a patch merged into the config)");
    }
  }
  if (!chosen.empty()) {
    LFNET_CHECK_AS(ConfigError, j.contains("scales") && j["scales"].contains(chosen), path,
                   ": $.scales has no scale '", chosen, "'");
    const nlohmann::json patch = j["scales"][chosen];
    j.merge_patch(patch);
  }
  j.erase("scales");
  j.erase("default_scale");
  auto config = from_json(j, path);
  config.scale = chosen;
  return config;
}

ExperimentConfig ExperimentConfig::from_json(const nlohmann::json& j, const std::string& source) {
  ExperimentConfig c;
  c.raw = j;
  try {
    JsonReader r(j, "$");
    r.get("name", c.name);
    nlohmann::json phi;
    r.require("phi", phi);
    c.phi = phi.is_string() ? optics::PhiSpec::parse(phi.get<std::string>())
                            : optics::PhiSpec::from_json(phi, "$.phi");
    {
      auto d = r.child("data");
      c.train_data.read(d);
    }
    if (r.has("dataset")) {
      auto d = r.child("dataset");
      c.dataset = data::DatasetOptions::from_json(d);
    }
    nlohmann::json network = nlohmann::json::object();
    r.get("network", network);
    c.network = nn::NetworkOptions::from_json(network, "$.network");
    r.get("training", c.training);
    // Parse once so errors in the common options surface before any work.
    (void)train::TrainerOptions::from_json(c.training, "$.training");
    nlohmann::json stages = nlohmann::json::array({"joint"});
    r.get("stages", stages);
    LFNET_CHECK_AS(ConfigError, stages.is_array() && !stages.empty(),
                   "$.stages: a non-empty list of stages (ae, cnn, joint, joint_scratch)");
    for (size_t i = 0; i < stages.size(); ++i) {
      const std::string path = "$.stages[" + std::to_string(i) + "]";
      StageConfig s;
      if (stages[i].is_string()) {
        s.name = stages[i].get<std::string>();
      } else {
        JsonReader sr(stages[i], path);
        sr.require("name", s.name);
        sr.get("training", s.training);
        sr.finish();
        LFNET_CHECK_AS(ConfigError, s.training.is_object(), path,
                       ".training: expected an object of training options");
      }
      LFNET_CHECK_AS(ConfigError,
                     s.name == "ae" || s.name == "cnn" || s.name == "joint" ||
                         s.name == "joint_scratch" || s.name == "dict",
                     path, ": unknown stage '", s.name,
                     "' (known: ae, cnn, joint, joint_scratch, dict)");
      LFNET_CHECK_AS(ConfigError, s.name != "dict" || s.training.empty(), path,
                     ": the dict stage takes its options from $.dictionary, not 'training'");
      c.stages.push_back(s);
      // Values (not only keys and types) are checked before any work starts.
      try {
        if (is_network_stage(s.name)) c.stage_options(s).validate();
      } catch (const ConfigError& e) {
        throw ConfigError("$.training (stage " + s.name + "): " + e.what());
      }
    }
    if (r.has("dictionary")) {
      auto d = r.child("dictionary");
      nlohmann::json sampling = nlohmann::json::object(), ksvd = nlohmann::json::object();
      d.get("sampling", sampling);
      d.get("ksvd", ksvd);
      d.finish();
      c.dictionary_sampling = dict::PatchSamplingOptions::from_json(sampling, "$.dictionary.sampling");
      c.dictionary_ksvd = dict::KsvdOptions::from_json(ksvd, "$.dictionary.ksvd");
    }
    if (r.has("evaluation")) {
      auto e = r.child("evaluation");
      c.evaluation.read(e);
    }
    r.finish();
  } catch (const ConfigError& e) {
    throw ConfigError(source + ": " + e.what());
  }
  // The resolved spec (every parameter filled in) is what models and results record.
  c.phi = optics::make_phi(c.phi)->spec();
  c.network.measurements = c.phi.n;
  c.network.patch.rows = c.phi.rows;
  c.network.patch.cols = c.phi.cols;
  c.network.patch.height = c.dataset.patch_h;
  c.network.patch.width = c.dataset.patch_w;
  return c;
}

train::TrainerOptions ExperimentConfig::stage_options(const StageConfig& stage) const {
  nlohmann::json merged = training;
  if (stage.training.is_object()) merged.merge_patch(stage.training);
  merged["stage"] = stage.name == "joint_scratch" ? "joint" : stage.name;
  return train::TrainerOptions::from_json(merged, "$.stages[" + stage.name + "].training");
}

nn::NetworkOptions ExperimentConfig::stage_network(const StageConfig& stage) const {
  nn::NetworkOptions o = network;
  o.branches = (stage.name == "ae" || stage.name == "cnn") ? stage.name : "net";
  o.validate();
  return o;
}

void prepare_run_dir(const std::string& dir, bool force) {
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    LFNET_CHECK_AS(IoError, fs::is_directory(dir, ec), dir, " exists and is not a folder");
    LFNET_CHECK_AS(IoError, fs::is_empty(dir, ec) || force, "output folder ", dir,
                   " exists and is not empty: choose another --out or pass --force");
  }
  fs::create_directories(fs::path(dir) / "models", ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot create ", dir, ": ", ec.message());
}

std::unique_ptr<data::PatchDataset> make_dataset(const ExperimentConfig& config,
                                                 const optics::Phi& phi) {
  auto named = load_sources(config.train_data, phi.rows(), phi.cols(),
                            config.dataset.needs_whole_grids());
  LFNET_CHECK_AS(ConfigError, !named.empty(), "the config names no training data ($.data)");
  std::vector<LightField> lfs;
  for (auto& n : named) lfs.push_back(n.lf);
  return std::make_unique<data::PatchDataset>(std::move(lfs), phi, config.dataset);
}

std::string train_stage(const ExperimentConfig& config, const StageConfig& stage,
                        data::PatchDataset& dataset, const std::string& run_dir,
                        const std::string& init, const std::string& resume,
                        const std::string& command_line,
                        std::shared_ptr<dist::Communicator> comm) {
  if (!comm) comm = std::make_shared<dist::LocalCommunicator>();
  const bool lead = comm->rank() == 0;
  const auto phi = optics::make_phi(config.phi);
  auto options = config.stage_options(stage);
  const std::string stage_dir = (fs::path(run_dir) / "models" / stage.name).string();
  options.out_dir = stage_dir;
  // LibTorch seeds its default generator from the OS: seed it from the config, so the same
  // config gives the same initial weights and a run is reproducible (docs/robustness.md).
  const uint64_t stage_code = stage.name == "ae" ? 1 : stage.name == "cnn" ? 2 : stage.name == "joint" ? 3 : 4;
  torch::manual_seed(config.dataset.seed * 16 + stage_code);
  nn::LightFieldNet net(config.stage_network(stage));
  net->set_phi(optics::patch_matrix_stack(*phi, config.dataset.patch_h, config.dataset.patch_w));
  train::RunInfo run;
  run.config = config.raw;
  run.config["resolved_stage"] = stage.name;
  run.config["measurement_mean"] = dataset.measurement_mean();
  run.phi = config.phi.to_json();
  run.command_line = command_line;
  train::Trainer trainer(net, options, run);
  trainer.set_communicator(comm);
  const std::string models = (fs::path(run_dir) / "models").string();
  if (!lead) {
    // Rank 0 reads what the stage starts from; fit() hands its state to this rank.
  } else if (!resume.empty()) {
    trainer.resume(resume);
  } else if (!init.empty()) {
    auto report = trainer.init_from(init);
    spdlog::info("initialised from {}: {} copied, {} mapped, {} re-initialised", init,
                 report.copied.size(), report.mapped.size(), report.reinitialised.size());
  } else if (stage.name == "joint") {
    const std::string ae = (fs::path(models) / "ae.ckpt").string();
    const std::string cnn = (fs::path(models) / "cnn.ckpt").string();
    if (fs::exists(ae) && fs::exists(cnn)) {
      trainer.init_branches(ae, cnn);
      spdlog::info("joint stage starts from the pretrained branches {} and {}", ae, cnn);
    } else {
      spdlog::warn("joint stage without pretrained ae.ckpt and cnn.ckpt: training from scratch");
    }
  }
  train::TrainerHooks hooks;
  hooks.on_epoch = [&](const train::EpochRecord& r) {
    if (!lead) return;
    spdlog::info("{} epoch {}: train loss {:.5f}, validation PSNR {:.2f} dB{} ({:.0f} patches/s)",
                 stage.name, r.epoch, r.train_loss, r.val_psnr_db, r.best ? " (best)" : "",
                 r.patches_per_s);
    append_jsonl((fs::path(run_dir) / "training.jsonl").string(),
                 nlohmann::json{{"stage", stage.name}, {"record", r.to_json()}});
  };
  trainer.fit(dataset, hooks);
  const std::string best = train::best_checkpoint_path(stage_dir);
  const std::string target = (fs::path(models) / (stage.name + ".ckpt")).string();
  if (!lead) return target;
  std::error_code ec;
  fs::copy_file(best, target + ".tmp", fs::copy_options::overwrite_existing, ec);
  if (!ec) fs::rename(target + ".tmp", target, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot copy ", best, " to ", target, ": ", ec.message());
  return target;
}

std::string train_dictionary_stage(const ExperimentConfig& config, const std::string& run_dir,
                                   const std::string& command_line) {
  auto sampling = config.dictionary_sampling;
  sampling.views = config.phi.rows;
  sampling.patch_size = config.dataset.patch_h;
  LFNET_CHECK_AS(ConfigError, config.phi.rows == config.phi.cols &&
                                  config.dataset.patch_h == config.dataset.patch_w,
                 "the dict stage needs square views and patches");
  const auto named = load_sources(config.train_data, config.phi.rows, config.phi.cols);
  LFNET_CHECK_AS(ConfigError, !named.empty(), "the config names no training data ($.data)");
  std::vector<LightField> lfs;
  for (const auto& n : named) lfs.push_back(n.lf);
  dict::PatchSamplingStats stats;
  Stopwatch clock;
  const torch::Tensor patches = dict::sample_patches(lfs, sampling, &stats);
  spdlog::info("dict: {} training patches ({} drawn, {} flat ones dropped)", patches.size(0),
               stats.drawn, stats.dropped);
  const auto& ksvd = config.dictionary_ksvd;
  ProgressBar bar("K-SVD", ksvd.iterations, "iterations");
  nlohmann::json history = nlohmann::json::array();
  auto result = dict::ksvd(patches, ksvd, [&](const dict::KsvdIteration& it) {
    bar.advance(1);
    history.push_back({{"iteration", it.iteration}, {"coding_rmse", it.coding_rmse},
                       {"updated_rmse", it.updated_rmse}});
    append_jsonl((fs::path(run_dir) / "training.jsonl").string(),
                 nlohmann::json{{"stage", "dict"}, {"record", history.back()}});
    return true;
  });
  bar.finish();
  dict::Dictionary d;
  d.atoms = result.dictionary.to(torch::kFloat32).contiguous();
  d.patch_shape = {config.phi.rows, config.phi.cols, config.dataset.patch_h, config.dataset.patch_w};
  nlohmann::json sources = nlohmann::json::array();
  for (const auto& n : named) sources.push_back(n.name);
  d.training = {{"ksvd", ksvd.to_json()},     {"sampling", sampling.to_json()},
                {"light_fields", sources},    {"history", history},
                {"command_line", command_line}, {"seconds", clock.seconds()}};
  const std::string target = (fs::path(run_dir) / "models" / "dict.ckpt").string();
  dict::save_dictionary(d, target);
  spdlog::info("dict: {} atoms in {:.0f} s, coding RMSE {:.4f}: {}", d.size(), clock.seconds(),
               history.empty() ? 0.0 : history.back()["coding_rmse"].get<double>(), target);
  return target;
}

void append_jsonl(const std::string& path, const nlohmann::json& record) {
  std::ofstream out(path, std::ios::app);
  LFNET_CHECK_AS(IoError, out, "cannot append to ", path);
  out << record.dump() << "\n";
  LFNET_CHECK_AS(IoError, out.good(), "cannot append to ", path);
}

}  // namespace lfnet::app

namespace lfnet::app {

ModelFile load_model(const std::string& path, bool network) {
  ModelFile model;
  model.path = path;
  model.scripted = nn::is_script_file(path);
  if (model.scripted) {
    model.script = std::make_shared<nn::ScriptedNetwork>(nn::load_script(path));
    model.phi = model.script->meta.phi;
    model.config = model.script->meta.config;
    model.network = model.script->network;
    return model;
  }
  const auto ckpt = train::load_checkpoint(path);
  model.phi = ckpt.phi;
  model.config = ckpt.config;
  try {
    model.network = nn::NetworkOptions::from_json(ckpt.network, "$.network");
  } catch (const ConfigError& e) {
    throw CheckpointError(path + " has invalid network options: " + e.what());
  }
  if (network) model.net = train::build_net(ckpt, path);
  return model;
}

void ModelFile::check_phi(const nlohmann::json& phi_spec) const {
  if (script) return nn::check_script_phi(*script, phi_spec);
  train::Checkpoint ckpt;
  ckpt.phi = phi;
  train::check_phi(ckpt, phi_spec, path);
}

recon::PatchSolver ModelFile::solver(const std::string& method) const {
  if (script) return recon::script_solver(*script, method);
  LFNET_CHECK(!net.is_empty(), "the network of ", path, " was not loaded");
  return recon::network_solver(net, method);
}

double ModelFile::measurement_mean() const {
  return config.contains("measurement_mean") ? config["measurement_mean"].get<double>() : 0.0;
}

eval::EvalOptions make_eval_options(const std::string& mode, double noise, uint64_t seed,
                                    int64_t stride, int64_t batch, bool window,
                                    const std::optional<nn::PatchShape>& patch) {
  eval::EvalOptions o;
  o.mode = optics::parse_simulation_mode(mode);
  if (noise > 0) o.effects.gaussian = optics::SensorOptions::Gaussian{noise};
  o.seed = seed;
  o.reconstruct.stride = stride;
  o.reconstruct.batch = batch;
  o.reconstruct.window = window;
  if (patch) {
    o.reconstruct.patch_h = patch->height;
    o.reconstruct.patch_w = patch->width;
  }
  return o;
}

nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, eval::EvalOptions options,
                               torch::Tensor* estimate, bool show_progress) {
  LFNET_CHECK(context.phi != nullptr, "evaluation without a Phi");
  const auto& phi = *context.phi;
  eval::EvalResult result;
  std::shared_ptr<recon::SolverReport> report;  // iterative methods: non-convergence
  const std::string label = method + " " + truth.name + " stride " +
                            std::to_string(options.reconstruct.stride);
  if (method == "no-parallax") {
    result = eval::evaluate_no_parallax(truth.lf, phi, options);
  } else {
    recon::PatchSolver solver;
    if (recon::needs_network(method)) {
      LFNET_CHECK_AS(ConfigError, context.script || !context.net.is_empty(), "method '", method,
                     "' needs a trained model: give --model");
      solver = context.script ? recon::script_solver(*context.script, method)
                              : recon::network_solver(context.net, method);
    } else if (method == "dict") {
      LFNET_CHECK_AS(ConfigError, !context.dictionary.empty(),
                     "method 'dict' needs a dictionary: give --dictionary FILE (e.g. models/dictionary.ckpt)");
      ModelCache local;
      const auto& dictionary = (context.cache ? *context.cache : local).dictionary(context.dictionary);
      dict::SparseCodingOptions coding;
      coding.method = context.dict_method;
      report = std::make_shared<recon::SolverReport>();
      solver = recon::dictionary_solver(phi, dictionary, coding, options.reconstruct.patch_h,
                                        options.reconstruct.patch_w, report);
    } else if (method == "adjoint" || method == "pinv") {
      solver = recon::linear_solver(phi, method, options.reconstruct.patch_h, options.reconstruct.patch_w);
    } else {
      std::string known;
      for (const auto& m : recon::method_names()) known += (known.empty() ? "" : ", ") + m;
      throw ConfigError("unknown method '" + method + "' (known: " + known + ")");
    }
    std::unique_ptr<ProgressBar> patches_bar;
    if (show_progress) {
      patches_bar = std::make_unique<ProgressBar>(
          label,
          PatchGrid(truth.lf.height(), truth.lf.width(), options.reconstruct.patch_h,
                    options.reconstruct.patch_w, options.reconstruct.stride)
              .size(),
          "patches");
    }
    int64_t shown = 0;
    result = eval::evaluate(truth.lf, phi, method, solver, options, [&](int64_t done, int64_t) {
      if (patches_bar) patches_bar->advance(done - shown);
      shown = done;
    });
  }
  result.record["light_field"] = truth.name;
  if (report) {
    result.record["unconverged_patches"] = report->unconverged.load();
    if (report->unconverged > 0) {
      spdlog::warn("{}: {} of {} patches did not converge (finite, best estimate kept)", label,
                   report->unconverged.load(), report->patches.load());
    }
  }
  if (estimate) *estimate = result.estimate;
  return result.record;
}

}  // namespace lfnet::app

namespace lfnet::app {

namespace {

// A Phi spec from the command line: NAME[:N] or a JSON file holding a spec object.
optics::PhiSpec parse_phi_argument(const std::string& text) {
  if (fs::path(text).extension() == ".json") {
    return optics::PhiSpec::from_json(read_json_file(text), text + ":$");
  }
  return optics::PhiSpec::parse(text);
}

// A camera's own sensor images, one file of N channels per colour channel, as an acquisition.
io::Acquisition plain_sensor_acquisition(const std::string& files, const optics::PhiSpec& spec) {
  std::vector<torch::Tensor> channels;
  std::stringstream list(files);
  for (std::string file; std::getline(list, file, ',');) {
    auto image = io::read_image_channels(file);
    LFNET_CHECK_AS(ConfigError, image.size(0) == spec.n, file, " has ", image.size(0),
                   " channel(s) but the Phi ", spec.label(), " measures N = ", spec.n,
                   " per pixel: give one file of N channels per colour channel");
    LFNET_CHECK_AS(ConfigError, channels.empty() || image.sizes() == channels[0].sizes(), file,
                   " is ", image.size(1), "x", image.size(2), " but the first file is ",
                   channels[0].size(1), "x", channels[0].size(2));
    channels.push_back(image);
  }
  LFNET_CHECK_AS(ConfigError, !channels.empty(), "--sensor names no file");
  io::Acquisition acq;
  acq.sensor = torch::stack(channels);
  acq.meta = {{"phi", spec.to_json()},
              {"mode", "sensor"},
              {"light_field",
               {{"channels", acq.sensor.size(0)}, {"height", acq.sensor.size(2)},
                {"width", acq.sensor.size(3)}}}};
  return acq;
}

}  // namespace

ModelFile& ModelCache::model(const std::string& path) {
  auto it = models_.find(path);
  if (it == models_.end()) {
    it = models_.emplace(path, load_model(path, /*network=*/true)).first;
    ++loads_;
  }
  return it->second;
}

const dict::Dictionary& ModelCache::dictionary(const std::string& path) {
  auto it = dictionaries_.find(path);
  if (it == dictionaries_.end()) {
    it = dictionaries_.emplace(path, dict::load_dictionary(path)).first;
    ++loads_;
  }
  return it->second;
}

Reconstruction reconstruct_acquisition(const ReconstructRequest& a,
                                       const recon::ProgressCallback& progress,
                                       ModelCache* cache) {
  const std::string method = a.method;
  LFNET_CHECK_AS(ConfigError, method != "no-parallax",
                 "no-parallax needs the true light field: it is a method of lfnet evaluate");
  ModelCache local;
  ModelCache& files = cache ? *cache : local;
  // The model first: its Phi is the default for plain sensor images.
  ModelFile* model = nullptr;
  if (recon::needs_network(method)) {
    LFNET_CHECK_AS(ConfigError, !a.model.empty(), "method '", method, "' needs --model");
    model = &files.model(a.model);
  }
  const bool folder = fs::is_directory(a.sensor);
  io::Acquisition acq;
  optics::PhiSpec spec;
  if (folder) {
    acq = io::read_acquisition(a.sensor);
    spec = optics::PhiSpec::from_json(acq.meta.at("phi"), a.sensor + "/sensor.json:$.phi");
    LFNET_CHECK_AS(ConfigError, a.phi.empty() || parse_phi_argument(a.phi).label() == spec.label(),
                   "--phi ", a.phi, " contradicts ", a.sensor, "/sensor.json, which says ",
                   spec.label());
  } else {
    LFNET_CHECK_AS(IoError, fs::exists(a.sensor) || a.sensor.find(',') != std::string::npos,
                   "--sensor ", a.sensor, " does not exist");
    LFNET_CHECK_AS(ConfigError, !a.phi.empty() || model,
                   "a plain sensor image needs --phi (or a --model, whose Phi is then used)");
    spec = a.phi.empty() ? optics::PhiSpec::from_json(model->phi, a.model + ":$.phi")
                         : parse_phi_argument(a.phi);
    spec = optics::make_phi(spec)->spec();
    acq = plain_sensor_acquisition(a.sensor, spec);
  }
  const auto phi = optics::make_phi(spec);
  recon::ReconstructOptions o = a.options;
  recon::PatchSolver solver;
  double train_mean = 0;
  const bool full = recon::parse_cnn_mode(a.cnn_mode) == recon::CnnMode::kFull;
  LFNET_CHECK_AS(ConfigError, !full || method == "net" || method == "cnn",
                 "--cnn-mode full needs --method net or cnn, not '", method, "'");
  if (model) {
    model->check_phi(spec.to_json());
    o.patch_h = model->network.patch.height;
    o.patch_w = model->network.patch.width;
    if (model->net) {
      model->net->to(parse_device(a.device));
      nn::set_cnn_precision(model->net, nn::parse_precision(a.precision));
    } else {
      LFNET_CHECK_AS(ConfigError, a.device == "cpu" && a.precision == "float32" && !full,
                     "--device, --precision and --cnn-mode full apply to checkpoints; ", a.model,
                     " is an exported TorchScript file");
    }
    solver = model->solver(method);
    train_mean = model->measurement_mean();
  } else if (method == "pinv" || method == "adjoint") {
    solver = recon::linear_solver(*phi, method, o.patch_h, o.patch_w);
  } else if (method == "dict") {
    LFNET_CHECK_AS(ConfigError, !a.dictionary.empty(),
                   "method 'dict' needs --dictionary FILE (e.g. models/dictionary.ckpt)");
    const auto& dictionary = files.dictionary(a.dictionary);
    dict::SparseCodingOptions coding;
    coding.method = a.dict_method;
    solver = recon::dictionary_solver(*phi, dictionary, coding, o.patch_h, o.patch_w);
  } else {
    std::string known;
    for (const auto& m : recon::method_names()) {
      if (m != "no-parallax") known += (known.empty() ? "" : ", ") + m;
    }
    throw ConfigError("unknown method '" + method + "' (known: " + known + ")");
  }
  LFNET_CHECK_AS(ConfigError, !a.match_mean || train_mean > 0,
                 "--match-mean needs a model that records its training measurement mean");

  const auto& lf_meta = acq.meta.at("light_field");
  const int64_t c = lf_meta.at("channels").get<int64_t>();
  const int64_t h = lf_meta.at("height").get<int64_t>(), w = lf_meta.at("width").get<int64_t>();
  std::vector<torch::Tensor> channels;
  double scale = 1.0;
  Stopwatch clock;
  if (acq.sensor.defined()) {
    const int64_t per_channel = PatchGrid(h, w, o.patch_h, o.patch_w, o.stride).size();
    for (int64_t ch = 0; ch < c; ++ch) {
      auto sensor = acq.sensor[ch].clone();
      if (a.match_mean) scale = recon::match_mean(sensor, train_mean);
      if (full) {
        channels.push_back(recon::reconstruct_sensor_fully_convolutional(
            model->net, method, *phi, sensor, o, a.tile));
        if (progress) progress((ch + 1) * per_channel, c * per_channel);
        continue;
      }
      channels.push_back(recon::reconstruct_sensor(
          *phi, sensor, solver, o, [&](int64_t done, int64_t total) {
            if (progress) progress(ch * per_channel + done, c * total);
          }));
    }
  } else {
    LFNET_CHECK_AS(ConfigError, !a.match_mean,
                   "--match-mean applies to sensor images, not to per_patch measurements");
    LFNET_CHECK_AS(ConfigError, !full,
                   "--cnn-mode full needs a sensor image, not per-patch measurements");
    const auto& g = acq.meta.at("grid");
    const int64_t patch = g.at("patch").get<int64_t>();
    o.stride = g.at("stride").get<int64_t>();
    LFNET_CHECK_AS(ConfigError, patch == o.patch_h && patch == o.patch_w,
                   "the measurements are of ", patch, "x", patch,
                   " patches but the method reconstructs ", o.patch_h, "x", o.patch_w);
    PatchGrid grid(h, w, patch, patch, o.stride);
    for (int64_t ch = 0; ch < c; ++ch) {
      auto source = [&](int64_t r0, int64_t r1) {
        return optics::PatchMeasurements{
            acq.measurements[ch].slice(0, r0 * grid.cols(), r1 * grid.cols()),
            optics::patch_phases(*phi, grid, r0, r1)};
      };
      channels.push_back(recon::reconstruct_patches(
          *phi, grid, source, solver, o, [&](int64_t done, int64_t total) {
            if (progress) progress(ch * grid.size() + done, c * total);
          }));
    }
  }
  torch::Tensor lf = torch::cat(channels, 0);
  if (a.post_filter) {
    lf = recon::suppress_periodic(lf, o.stride);
    if (o.clamp) lf.clamp_(0.0, 1.0);
  }
  const double seconds = clock.seconds();
  Reconstruction r{LightField(lf), {}};
  r.record = {{"method", method},
              {"model", recon::needs_network(method) ? a.model
                        : method == "dict"            ? a.dictionary
                                                      : ""},
              {"sensor", a.sensor},
              {"stride", o.stride},
              {"seconds", seconds},
              {"phi", spec.to_json()},
              {"mode", acq.meta.value("mode", "sensor")},
              {"shape", r.lf.shape_string()},
              {"match_mean_scale", scale},
              {"post_filter", a.post_filter},
              {"window", o.window},
              {"device", a.device},
              {"cnn_mode", a.cnn_mode},
              {"precision", a.precision},
              {"lfnet_version", kVersion}};
  return r;
}

void write_reconstruction(const Reconstruction& r, const std::string& out, bool force) {
  write_folder(out, force, [&](const std::string& dir) {
    io::write_light_field(r.lf, dir);
    io::write_previews(r.lf, dir);
    write_json_file((fs::path(dir) / "reconstruction.json").string(), r.record);
  });
}

}  // namespace lfnet::app

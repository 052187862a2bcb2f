#include "workflow.h"

#include "command.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/patches.h"
#include "lfnet/io/light_field_io.h"
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
  r.finish();
  if (random_scenes < 0) throw ConfigError(r.path_of("random_scenes") + ": must be >= 0");
}

nlohmann::json LightFieldSources::to_json() const {
  return {{"light_fields", light_fields}, {"scenes", scenes},
          {"random_scenes", random_scenes}, {"random_seed", random_seed},
          {"random_options", random_options}, {"views", views}};
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
                                          int64_t cols) {
  std::vector<NamedLightField> out;
  const int64_t total = static_cast<int64_t>(sources.light_fields.size() + sources.scenes.size()) +
                        sources.random_scenes;
  ProgressBar bar("loading light fields", total);
  for (const auto& dir : sources.light_fields) {
    auto lf = io::read_light_field(dir);
    out.push_back({fs::path(dir).filename().string(), select_views(lf, sources.views, rows, cols, dir)});
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
  if (chosen.empty() && j.contains("default_scale")) chosen = j["default_scale"].get<std::string>();
  if (!chosen.empty()) {
    LFNET_CHECK_AS(ConfigError, j.contains("scales") && j["scales"].contains(chosen), path,
                   ": $.scales has no scale '", chosen, "'");
    j.merge_patch(j["scales"][chosen]);
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
      }
      LFNET_CHECK_AS(ConfigError,
                     s.name == "ae" || s.name == "cnn" || s.name == "joint" || s.name == "joint_scratch",
                     path, ": unknown stage '", s.name, "' (known: ae, cnn, joint, joint_scratch)");
      c.stages.push_back(s);
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
  auto named = load_sources(config.train_data, phi.rows(), phi.cols());
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

void append_jsonl(const std::string& path, const nlohmann::json& record) {
  std::ofstream out(path, std::ios::app);
  LFNET_CHECK_AS(IoError, out, "cannot append to ", path);
  out << record.dump() << "\n";
  LFNET_CHECK_AS(IoError, out.good(), "cannot append to ", path);
}

}  // namespace lfnet::app

namespace lfnet::app {

nlohmann::json evaluate_method(const NamedLightField& truth, const std::string& method,
                               const MethodContext& context, eval::EvalOptions options,
                               torch::Tensor* estimate) {
  LFNET_CHECK(context.phi != nullptr, "evaluation without a Phi");
  const auto& phi = *context.phi;
  eval::EvalResult result;
  const std::string label = method + " " + truth.name + " stride " +
                            std::to_string(options.reconstruct.stride);
  if (method == "no-parallax") {
    result = eval::evaluate_no_parallax(truth.lf, phi, options);
  } else {
    recon::PatchSolver solver;
    if (recon::needs_network(method)) {
      LFNET_CHECK_AS(ConfigError, !context.net.is_empty(), "method '", method,
                     "' needs a trained model: give --model");
      solver = recon::network_solver(context.net, method);
    } else if (method == "dict") {
      LFNET_CHECK_AS(ConfigError, !context.dictionary.empty(),
                     "method 'dict' needs a dictionary: give --dictionary FILE (e.g. models/dictionary.ckpt)");
      const auto dictionary = dict::load_dictionary(context.dictionary);
      dict::SparseCodingOptions coding;
      coding.method = context.dict_method;
      solver = recon::dictionary_solver(phi, dictionary, coding, options.reconstruct.patch_h,
                                        options.reconstruct.patch_w);
    } else if (method == "adjoint" || method == "pinv") {
      solver = recon::linear_solver(phi, method, options.reconstruct.patch_h, options.reconstruct.patch_w);
    } else {
      std::string known;
      for (const auto& m : recon::method_names()) known += (known.empty() ? "" : ", ") + m;
      throw ConfigError("unknown method '" + method + "' (known: " + known + ")");
    }
    ProgressBar patches_bar(label, PatchGrid(truth.lf.height(), truth.lf.width(),
                                             options.reconstruct.patch_h, options.reconstruct.patch_w,
                                             options.reconstruct.stride)
                                       .size(),
                            "patches");
    int64_t shown = 0;
    result = eval::evaluate(truth.lf, phi, method, solver, options, [&](int64_t done, int64_t) {
      patches_bar.advance(done - shown);
      shown = done;
    });
  }
  result.record["light_field"] = truth.name;
  if (estimate) *estimate = result.estimate;
  return result.record;
}

}  // namespace lfnet::app

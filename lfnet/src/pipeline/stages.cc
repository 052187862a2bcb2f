#include "lfnet/pipeline/stages.h"

#include <fcntl.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/optics/measure.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/train/checkpoint.h"
#include "lfnet/train/trainer.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

std::unique_ptr<data::PatchDataset> make_dataset(const ExperimentConfig& config,
                                                 const optics::Phi& phi) {
  const bool colour = !config.network.cfa.empty();
  auto named = load_sources(config.train_data, phi.rows(), phi.cols(),
                            config.dataset.needs_whole_grids(), colour, false, phi.frames());
  LFNET_CHECK_AS(ConfigError, !named.empty(), "the config names no training data ($.data)");
  std::vector<LightField> lfs;
  lfs.reserve(named.size());
  for (auto& n : named) lfs.push_back(n.lf);
  auto options = config.dataset;
  options.cfa = config.network.cfa;  // a colour net's patches keep their colours
  return std::make_unique<data::PatchDataset>(std::move(lfs), phi, options);
}

nn::LightFieldNet load_teacher(const ExperimentConfig& config, const std::string& device) {
  const auto& d = config.distill;
  const std::string what = "$.distill.teacher " + d.teacher;
  LFNET_CHECK_AS(ConfigError, fs::is_regular_file(d.teacher), what, ": no such file");
  LFNET_CHECK_AS(ConfigError, model_file_kind(d.teacher) == ModelFileKind::kCheckpoint, what,
                 ": not an lfnet checkpoint (an exported model or a dictionary cannot teach)");
  auto model = load_model(d.teacher, true);
  LFNET_CHECK_AS(ConfigError, model.network.arch().whole_image(), what,
                 ": the teacher must be of a whole-image architecture such as lfnet (its "
                 "self-ensemble teaches)");
  const auto sensor_of = [](const std::string& cfa) {
    return cfa.empty() ? std::string("grey sensor images")
                       : "sensor images behind a Bayer " + cfa + " filter";
  };
  LFNET_CHECK_AS(ConfigError, model.network.cfa == config.network.cfa, what, ": it reconstructs ",
                 sensor_of(model.network.cfa), ", the net reconstructs ",
                 sensor_of(config.network.cfa));
  try {
    model.check_phi(config.phi.to_json());
  } catch (const Error& e) {
    throw ConfigError(what + ": " + e.what());
  }
  auto net = model.net;
  net->to(parse_device(device));
  nn::set_cnn_precision(net, d.precision);
  net->eval();
  return net;
}

namespace {

// One network stage of a run, as steps: its net seeded from the config, its trainer (with the
// code it learns), where it starts (a checkpoint, the pretrained branches or a learned code),
// the teacher it distils, then the fit and the stage's model file.
class StageTraining {
 public:
  StageTraining(const ExperimentConfig& config, const StageConfig& stage,
                data::PatchDataset& dataset, const std::string& run_dir,
                std::shared_ptr<dist::Communicator> comm)
      : config_(config),
        stage_(stage),
        dataset_(dataset),
        run_dir_(run_dir),
        models_((fs::path(run_dir) / "models").string()),
        comm_(comm ? std::move(comm) : std::make_shared<dist::LocalCommunicator>()),
        lead_(comm_->rank() == 0),
        phi_(optics::make_phi(config.phi)),
        options_(config.stage_options(stage)) {
    options_.out_dir = (fs::path(models_) / stage.name).string();
  }

  std::string run(const std::string& init, const std::string& resume,
                  const std::string& command_line, const std::function<void()>& on_saved) {
    make_trainer(command_line);
    if (lead_) start(init, resume);  // fit() hands rank 0's state to the other ranks
    auto taught = teacher_source();
    trainer_->fit(taught ? static_cast<train::BatchSource&>(*taught) : dataset_, hooks(on_saved));
    std::string target = (fs::path(models_) / (stage_.name + ".ckpt")).string();
    if (lead_) publish(train::best_checkpoint_path(options_.out_dir), target);
    return target;
  }

 private:
  void make_trainer(const std::string& command_line) {
    // LibTorch seeds its default generator from the OS: seed it from the config, so the same
    // config gives the same initial weights and a run is reproducible (docs/robustness.md).
    const uint64_t stage_code = stage_.name == "ae"      ? 1
                                : stage_.name == "cnn"   ? 2
                                : stage_.name == "joint" ? 3
                                                         : 4;
    torch::manual_seed(config_.dataset.seed * 16 + stage_code);
    nn::LightFieldNet net(config_.stage_network(stage_));
    net->set_phi(phi_tensor(*phi_, net->options()));
    train::RunInfo run;
    run.config = config_.raw;
    run.config["resolved_stage"] = stage_.name;
    run.config["measurement_mean"] = dataset_.measurement_mean();
    run.phi = config_.phi.to_json();
    run.command_line = command_line;
    trainer_ = std::make_unique<train::Trainer>(net, options_, run);
    trainer_->set_communicator(comm_);
    if (!config_.code.enabled) return;
    // The code starts as the config's Phi (its start) and is trained with the net.
    const auto& code = config_.code;
    trainer_->set_code(nn::LearnedPhi(code.phi, phi_->measurements(), phi_->rows(), phi_->cols()),
                       code.training);
    if (!lead_) return;
    const int64_t frozen = code.training.freeze_epochs;
    spdlog::info("learning the code with the net: family {}, period {}, learning rate {:g}{}{}",
                 code.phi.family, code.phi.period, code.training.lr,
                 frozen > 0 ? ", fixed for the last " + std::to_string(frozen) +
                                  (frozen == 1 ? " epoch" : " epochs")
                            : "",
                 code.training.binarise ? ", rounded to 0 or 1" : "");
  }

  // A run resumed, a checkpoint to start from, or the joint stage's pretrained branches; and the
  // first stage's code from another model's ($.code.from).
  void start(const std::string& init, const std::string& resume) {
    if (!resume.empty()) {
      trainer_->resume(resume);
    } else if (!init.empty()) {
      auto report = trainer_->init_from(init);
      spdlog::info(
          "initialised from {}: {} copied, {} mapped, {} widened, {} deepened, {} re-initialised",
          init, report.copied.size(), report.mapped.size(), report.widened.size(),
          report.deepened.size(), report.reinitialised.size());
    } else if (stage_.name == "joint") {
      const std::string ae = (fs::path(models_) / "ae.ckpt").string();
      const std::string cnn = (fs::path(models_) / "cnn.ckpt").string();
      if (fs::exists(ae) && fs::exists(cnn)) {
        trainer_->init_branches(ae, cnn);
        spdlog::info("joint stage starts from the pretrained branches {} and {}", ae, cnn);
      } else {
        spdlog::warn("joint stage without pretrained ae.ckpt and cnn.ckpt: training from scratch");
      }
    }
    if (resume.empty() && config_.code.enabled && !config_.code.from.empty() &&
        stage_.name == config_.stages.front().name) {
      trainer_->init_code_from(config_.code.from);
      spdlog::info("the code starts from the learned code of {}", config_.code.from);
    }
  }

  // Each epoch: logged, appended to training.jsonl, and the run's progress note saved.
  train::TrainerHooks hooks(const std::function<void()>& on_saved) {
    train::TrainerHooks hooks;
    hooks.on_epoch = [this, on_saved](const train::EpochRecord& r) {
      if (!lead_) return;
      if (on_saved) on_saved();
      spdlog::info("{} epoch {}: train loss {:.5f}, validation PSNR {:.2f} dB{} ({:.0f} patches/s)",
                   stage_.name, r.epoch, r.train_loss, r.val_psnr_db, r.best ? " (best)" : "",
                   r.patches_per_s);
      const auto& code = trainer_->state().code;
      if (code.contains("binarised") && code["binarised"].value("epoch", int64_t{0}) == r.epoch) {
        spdlog::info(
            "{} epoch {}: the code was rounded to 0 or 1 before it: validation PSNR {:.2f} dB "
            "with the code as learned, {:.2f} dB rounded, {:.2f} dB once the net settled on it",
            stage_.name, r.epoch, code["binarised"]["continuous_psnr_db"].get<double>(),
            code["binarised"]["binary_psnr_db"].get<double>(), r.val_psnr_db);
      }
      append_jsonl((fs::path(run_dir_) / "training.jsonl").string(),
                   nlohmann::json{{"stage", stage_.name}, {"record", r.to_json()}});
    };
    return hooks;
  }

  // $.distill: the batches' targets blended with the teacher's self-ensemble.
  std::unique_ptr<train::TeacherBatchSource> teacher_source() {
    if (!config_.distill.enabled()) return nullptr;
    const auto& distill = config_.distill;
    teacher_ = load_teacher(config_, options_.device);
    auto taught = std::make_unique<train::TeacherBatchSource>(
        dataset_,
        [teacher = teacher_, passes = distill.passes](const train::Batch& b) {
          const auto& o = teacher->options();
          const auto crops = b.y.reshape({b.size(), o.measurements, -1, b.target.size(-1)});
          return recon::reconstruct_crops_mirrored(teacher, crops, b.phase, b.noise, passes);
        },
        distill.weight);
    if (lead_) {
      spdlog::info(
          "distillation: targets {:g} x the self-ensemble of {} ({} passes), {:g} x the truth",
          distill.weight, distill.teacher,
          recon::ensemble_mirrors(recon::mirror_weights(teacher_), distill.passes).size(),
          1.0 - distill.weight);
    }
    return taught;
  }

  // The best checkpoint becomes the stage's model. Trained on a code another model learned
  // ($.phi a checkpoint): the model carries that code's physical parameters, so `phi export`
  // of it needs no other file.
  static void publish(const std::string& best, const std::string& target) {
    auto code = learned_code_of(best);
    if (!code.is_null() && !code.contains("learned_by")) code = nullptr;  // its own code
    write_file_atomically(target, [&](const std::string& tmp) {
      if (!code.is_null()) {
        auto ck = train::load_checkpoint(best);
        ck.training.code["physical"] = code;
        train::save_checkpoint(ck, tmp);
        return;
      }
      std::error_code ec;
      fs::copy_file(best, tmp, fs::copy_options::overwrite_existing, ec);
      LFNET_CHECK_AS(IoError, !ec, "cannot copy ", best, " to ", target, ": ", ec.message());
    });
  }

  const ExperimentConfig& config_;
  const StageConfig& stage_;
  data::PatchDataset& dataset_;
  const std::string run_dir_, models_;
  std::shared_ptr<dist::Communicator> comm_;
  const bool lead_;  // rank 0: reads what the stage starts from, logs and writes
  std::unique_ptr<optics::Phi> phi_;
  train::TrainerOptions options_;
  std::unique_ptr<train::Trainer> trainer_;
  nn::LightFieldNet teacher_{nullptr};
};

}  // namespace

std::string train_stage(const ExperimentConfig& config, const StageConfig& stage,
                        data::PatchDataset& dataset, const std::string& run_dir,
                        const std::string& init, const std::string& resume,
                        const std::string& command_line, std::shared_ptr<dist::Communicator> comm,
                        const std::function<void()>& on_saved) {
  return StageTraining(config, stage, dataset, run_dir, std::move(comm))
      .run(init, resume, command_line, on_saved);
}

std::string train_dictionary_stage(const ExperimentConfig& config, const std::string& run_dir,
                                   const std::string& command_line) {
  LFNET_CHECK_AS(ConfigError, config.phi.frames == 1, "the dict stage learns still light fields; ",
                 config.phi.label(), " codes sequences (docs/video.md)");
  auto sampling = config.dictionary_sampling;
  sampling.views = config.phi.rows;
  sampling.patch_size = config.dataset.patch_h;
  LFNET_CHECK_AS(
      ConfigError,
      config.phi.rows == config.phi.cols && config.dataset.patch_h == config.dataset.patch_w,
      "the dict stage needs square views and patches");
  const auto named = load_sources(config.train_data, config.phi.rows, config.phi.cols);
  LFNET_CHECK_AS(ConfigError, !named.empty(), "the config names no training data ($.data)");
  std::vector<LightField> lfs;
  lfs.reserve(named.size());
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
    history.push_back({{"iteration", it.iteration},
                       {"coding_rmse", it.coding_rmse},
                       {"updated_rmse", it.updated_rmse}});
    append_jsonl((fs::path(run_dir) / "training.jsonl").string(),
                 nlohmann::json{{"stage", "dict"}, {"record", history.back()}});
    return true;
  });
  bar.finish();
  dict::Dictionary d;
  d.atoms = result.dictionary.to(torch::kFloat32).contiguous();
  d.patch_shape = {config.phi.rows, config.phi.cols, config.dataset.patch_h,
                   config.dataset.patch_w};
  nlohmann::json sources = nlohmann::json::array();
  for (const auto& n : named) sources.push_back(n.name);
  d.training = {{"ksvd", ksvd.to_json()},
                {"coding", config.dictionary_coding.to_json()},
                {"sampling", sampling.to_json()},
                {"light_fields", sources},
                {"history", history},
                {"command_line", command_line},
                {"seconds", clock.seconds()}};
  std::string target = (fs::path(run_dir) / "models" / "dict.ckpt").string();
  dict::save_dictionary(d, target);
  spdlog::info("dict: {} atoms in {:.0f} s, coding RMSE {:.4f}: {}", d.size(), clock.seconds(),
               history.empty() ? 0.0 : history.back()["coding_rmse"].get<double>(), target);
  return target;
}

void append_jsonl(const std::string& path, const nlohmann::json& record) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  LFNET_CHECK_AS(IoError, fd >= 0, "cannot append to ", path, ": ", std::strerror(errno));
  try {
    write_all(fd, record.dump() + "\n", path);
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
}

}  // namespace lfnet::pipeline

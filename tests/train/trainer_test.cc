#include "lfnet/train/trainer.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <tuple>
#include <utility>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/train/checkpoint.h"
#include "support/small_nets.h"
#include "support/test_support.h"
#include "synthetic.h"

using lfnet::nn::LightFieldNet;
using lfnet::train::Trainer;
using lfnet::train::TrainerOptions;

namespace {

TrainerOptions quick_options(const std::string& stage, const std::string& out_dir, int64_t epochs) {
  TrainerOptions o;
  o.stage = lfnet::train::from_string(stage, o.stage);
  o.epochs = epochs;
  o.batch_size = 32;
  o.lr = 1e-3;
  o.progress = false;
  o.out_dir = out_dir;
  return o;
}

lfnet::train::RunInfo run_info(const nlohmann::json& phi_spec) {
  return {{{"test", true}}, phi_spec, "trainer_test"};
}

// A net for `branches` seeded with `seed`, holding `phi`.
LightFieldNet make_net(const lfnet::nn::NetworkOptions& o, const torch::Tensor& phi,
                       uint64_t seed) {
  torch::manual_seed(seed);
  LightFieldNet net(o);
  net->set_phi(phi);
  return net;
}

// Wraps a source and poisons one training batch with NaN.
class PoisonedSource : public lfnet::train::BatchSource {
 public:
  PoisonedSource(lfnet::train::BatchSource& inner, int64_t epoch, int64_t batch, bool in_y)
      : inner_(inner), epoch_(epoch), batch_(batch), in_y_(in_y) {}
  void start_epoch(int64_t epoch, int64_t batch_size) override {
    current_ = epoch;
    index_ = 0;
    inner_.start_epoch(epoch, batch_size);
  }
  int64_t train_batches_per_epoch() const override { return inner_.train_batches_per_epoch(); }
  lfnet::train::Batch next_train() override {
    auto b = inner_.next_train();
    if (current_ == epoch_ && index_ == batch_) {
      (in_y_ ? b.y : b.target).view({-1})[3] = std::nan("");
    }
    ++index_;
    return b;
  }
  const std::vector<lfnet::train::Batch>& validation() override { return inner_.validation(); }

 private:
  lfnet::train::BatchSource& inner_;
  int64_t epoch_, batch_, current_ = 0, index_ = 0;
  bool in_y_;
};

void require_same_parameters(const torch::nn::Module& a, const lfnet::train::TensorMap& b) {
  for (const auto& p : a.named_parameters()) {
    INFO(p.key());
    REQUIRE(torch::equal(p.value(), b.at(p.key())));
  }
}

}  // namespace

TEST_CASE("learning-rate schedules", "[train][trainer]") {
  TrainerOptions o;
  o.lr = 0.1;
  o.epochs = 10;
  o.schedule.name = lfnet::train::ScheduleKind::kConstant;
  CHECK(lfnet::train::learning_rate(o, 7, 3, 10) == 0.1);
  o.schedule.name = lfnet::train::ScheduleKind::kStep;
  o.schedule.step_epochs = 3;
  o.schedule.gamma = 0.5;
  CHECK(lfnet::train::learning_rate(o, 2, 9, 10) == Approx(0.1));
  CHECK(lfnet::train::learning_rate(o, 3, 0, 10) == Approx(0.05));
  CHECK(lfnet::train::learning_rate(o, 9, 0, 10) == Approx(0.0125));
  o.schedule.name = lfnet::train::ScheduleKind::kCosine;
  o.schedule.min_factor = 0.01;
  CHECK(lfnet::train::learning_rate(o, 0, 0, 10) == Approx(0.1));
  CHECK(lfnet::train::learning_rate(o, 5, 0, 10) == Approx(0.1 * (0.01 + 0.99 * 0.5)));
  CHECK(lfnet::train::learning_rate(o, 9, 9, 10) < 0.0015);
  o.schedule.warmup_epochs = 1;
  CHECK(lfnet::train::learning_rate(o, 0, 0, 4) == Approx(0.1 * 0.25));
  CHECK(lfnet::train::learning_rate(o, 0, 3, 4) == Approx(lfnet::train::learning_rate(o, 0, 3, 4)));
}

TEST_CASE("trainer options parse strictly and name the bad field", "[train][trainer]") {
  auto o = TrainerOptions::from_json(nlohmann::json::parse(
      R"({"stage": "ae", "epochs": 3, "lr": 0.01, "schedule": {"name": "step", "gamma": 0.5},
          "loss": {"name": "l1"}, "on_nonfinite": "skip"})"));
  CHECK(o.stage == lfnet::train::Stage::kAe);
  CHECK(o.schedule.name == lfnet::train::ScheduleKind::kStep);
  CHECK(o.on_nonfinite == lfnet::train::OnNonFinite::kSkip);
  CHECK(o.to_json()["on_nonfinite"] == "skip");
  CHECK(o.schedule.gamma == 0.5);
  CHECK(o.loss.name == lfnet::nn::LossKind::kL1);
  CHECK(TrainerOptions::from_json(o.to_json()).to_json() == o.to_json());
  CHECK_THROWS_WITH(
      TrainerOptions::from_json(nlohmann::json::parse(R"({"learning_rate": 1})"), "$.train"),
      Catch::Contains("$.train.learning_rate"));
  CHECK_THROWS_WITH(TrainerOptions::from_json(nlohmann::json::parse(R"({"stage": "both"})")),
                    Catch::Contains("$.stage"));
  CHECK_THROWS_WITH(
      TrainerOptions::from_json(nlohmann::json::parse(R"({"schedule": {"name": "linear"}})")),
      Catch::Contains("$.schedule.name"));
  CHECK_THROWS_WITH(TrainerOptions::from_json(nlohmann::json::parse(R"({"lr": -1})")),
                    Catch::Contains("$.lr"));
  CHECK_THROWS_WITH(TrainerOptions::from_json(nlohmann::json::parse(R"({"loss": {"name": "l3"}})")),
                    Catch::Contains("$.loss.name"));
}

TEST_CASE("the stage must match the net's branches", "[train][trainer]") {
  auto o = lfnet::test::small_net_options("ae");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 1);
  auto net = make_net(o, phi, 1);
  CHECK_THROWS_WITH(Trainer(net, quick_options("joint", "", 1),
                            run_info(lfnet::test::synthetic_phi_spec("random", 2, 1))),
                    Catch::Contains("stage 'joint'") && Catch::Contains("'ae'"));
  LightFieldNet unset(o);
  CHECK_THROWS_WITH(Trainer(unset, quick_options("ae", "", 1),
                            run_info(lfnet::test::synthetic_phi_spec("random", 2, 1))),
                    Catch::Contains("set_phi"));
}

TEST_CASE("training on synthetic patches reduces the validation loss", "[train][trainer]") {
  auto o = lfnet::test::small_net_options("net");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 5);
  auto source = lfnet::test::make_source(lfnet::test::smooth_patches(1200, o.patch, 6), phi, 7);
  auto net = make_net(o, phi, 8);
  auto options = quick_options("joint", "", 8);
  Trainer trainer(net, options, run_info(lfnet::test::synthetic_phi_spec("random", 2, 5)));
  const auto before = trainer.evaluate(*source);
  std::vector<lfnet::train::EpochRecord> seen;
  lfnet::train::TrainerHooks hooks;
  hooks.on_epoch = [&](const auto& r) { seen.push_back(r); };
  auto records = trainer.fit(*source, hooks);
  REQUIRE(records.size() == 8);
  REQUIRE(seen.size() == 8);
  const auto& last = records.back();
  INFO("val loss " << before.loss << " -> " << last.val_loss << ", PSNR " << before.psnr_db
                   << " -> " << last.val_psnr_db << " dB");
  CHECK(last.val_loss < 0.3 * before.loss);
  CHECK(last.val_psnr_db > before.psnr_db + 5);
  CHECK(last.train_loss < records.front().train_loss);
  CHECK(last.step == 8 * source->train_batches_per_epoch());
  CHECK(last.patches_per_s > 0);
  CHECK(trainer.state().epoch == 8);
  CHECK(trainer.state().history.size() == 8);
  CHECK(trainer.state().best_metric ==
        Approx(std::max_element(records.begin(), records.end(), [](auto& a, auto& b) {
                 return a.val_psnr_db < b.val_psnr_db;
               })->val_psnr_db));
}

TEST_CASE("two epochs equal one epoch, resume, one epoch, bit for bit", "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto o = lfnet::test::small_net_options("net");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 11);
  auto patches = lfnet::test::smooth_patches(300, o.patch, 12);
  const auto spec = lfnet::test::synthetic_phi_spec("random", 2, 11);
  auto options = quick_options("joint", "", 2);  // cosine over two epochs in both runs

  auto source_a = lfnet::test::make_source(patches, phi, 13);
  Trainer straight(make_net(o, phi, 42), options, run_info(spec));
  straight.fit(*source_a);

  options.out_dir = (dir / "run");
  auto source_b = lfnet::test::make_source(patches, phi, 13);
  {
    Trainer first(make_net(o, phi, 42), options, run_info(spec));
    lfnet::train::TrainerHooks interrupt;
    interrupt.stop_requested = [] { return true; };
    first.fit(*source_b, interrupt);  // interrupted after epoch 1
    REQUIRE(first.state().epoch == 1);
  }
  torch::manual_seed(999);  // the resumed run must not depend on the generator's state
  Trainer resumed(make_net(o, phi, 7), options, run_info(spec));
  resumed.resume(lfnet::train::last_checkpoint_path(options.out_dir));
  CHECK(resumed.state().epoch == 1);
  auto records = resumed.fit(*source_b);
  REQUIRE(records.size() == 1);
  CHECK(records[0].epoch == 2);

  auto a = straight.checkpoint(), b = resumed.checkpoint();
  CHECK(a.training.step == b.training.step);
  require_same_parameters(*resumed.net(), a.model);
  for (const auto& [name, t] : a.optimizer) {
    INFO(name);
    REQUIRE(torch::equal(t, b.optimizer.at(name)));
  }
  CHECK(a.training.history[1]["val_loss"] == b.training.history[1]["val_loss"]);
  CHECK(torch::equal(a.training.rng_state, b.training.rng_state));
}

TEST_CASE("resume refuses another Phi, stage or architecture", "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto o = lfnet::test::small_net_options("cnn");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 1);
  auto source = lfnet::test::make_source(lfnet::test::smooth_patches(60, o.patch, 2), phi);
  const auto spec = lfnet::test::synthetic_phi_spec("random", 2, 1);
  Trainer t(make_net(o, phi, 1), quick_options("cnn", dir.path().string(), 1), run_info(spec));
  t.fit(*source);
  const auto last = lfnet::train::last_checkpoint_path(dir.path().string());

  Trainer other_phi(make_net(o, phi, 1), quick_options("cnn", "", 2),
                    run_info(lfnet::test::synthetic_phi_spec("random", 2, 99)));
  CHECK_THROWS_AS(other_phi.resume(last), lfnet::CheckpointError);
  CHECK_THROWS_WITH(other_phi.resume(last), Catch::Contains("trained for Phi"));

  auto phi2 = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 2);
  Trainer other_matrices(make_net(o, phi2, 1), quick_options("cnn", "", 2), run_info(spec));
  CHECK_THROWS_WITH(other_matrices.resume(last), Catch::Contains("other Phi matrices"));

  auto wide = o;
  lfnet::test::edit_paper(wide, [&](lfnet::nn::PaperOptions& p) { p.cnn.channels = 5; });
  Trainer other_arch(make_net(wide, phi, 1), quick_options("cnn", "", 2), run_info(spec));
  CHECK_THROWS_WITH(other_arch.resume(last), Catch::Contains("another architecture"));

  auto joint = lfnet::test::small_net_options("net");
  Trainer other_stage(make_net(joint, phi, 1), quick_options("joint", "", 2), run_info(spec));
  CHECK_THROWS_WITH(other_stage.resume(last), Catch::Contains("stage 'cnn'"));
}

TEST_CASE("a poisoned batch stops training with a clear message and the last checkpoint loads",
          "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto o = lfnet::test::small_net_options("net");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 3);
  auto inner = lfnet::test::make_source(lfnet::test::smooth_patches(200, o.patch, 4), phi);
  PoisonedSource source(*inner, /*epoch=*/1, /*batch=*/2, /*in_y=*/true);
  const auto spec = lfnet::test::synthetic_phi_spec("random", 2, 3);
  auto options = quick_options("joint", dir.path().string(), 3);
  Trainer trainer(make_net(o, phi, 5), options, run_info(spec));
  lfnet::train::TensorMap after_epoch1;
  lfnet::train::TrainerHooks hooks;
  hooks.on_epoch = [&](const auto&) { after_epoch1 = lfnet::train::module_state(*trainer.net()); };
  try {
    trainer.fit(source, hooks);
    FAIL("a NaN batch was not detected");
  } catch (const lfnet::NumericalError& e) {
    const std::string m = e.what();
    CHECK_THAT(m, Catch::Contains("epoch 2, batch 3") && Catch::Contains("loss is nan") &&
                      Catch::Contains("measurements y contain NaN") &&
                      Catch::Contains("last good checkpoint") && Catch::Contains("last.ckpt"));
  }
  const auto last = lfnet::train::last_checkpoint_path(dir.path().string());
  auto ck = lfnet::train::load_checkpoint(last);
  CHECK(ck.training.epoch == 1);
  require_same_parameters(*lfnet::train::build_net(ck), after_epoch1);
  // And training resumes from it once the data is fixed.
  Trainer again(make_net(o, phi, 6), options, run_info(spec));
  again.resume(last);
  CHECK(again.fit(*inner).size() == 2);
}

TEST_CASE("schedule, validation and saving are hooks that replace the defaults",
          "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto o = lfnet::test::small_net_options("ae");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 3);
  auto source = lfnet::test::make_source(lfnet::test::smooth_patches(200, o.patch, 4), phi);
  const auto spec = lfnet::test::synthetic_phi_spec("random", 2, 3);
  auto options = quick_options("ae", dir.path().string(), 3);
  Trainer trainer(make_net(o, phi, 5), options, run_info(spec));
  std::vector<std::tuple<int64_t, int64_t, int64_t>> asked;
  std::vector<double> used;
  lfnet::train::TrainerHooks hooks;
  hooks.schedule = [&](int64_t epoch, int64_t batch, int64_t batches) {
    asked.emplace_back(epoch, batch, batches);
    return 1e-4 * static_cast<double>(epoch + 1);
  };
  hooks.on_step = [&](const lfnet::train::StepRecord& s) { used.push_back(s.lr); };
  // Validation PSNR that falls every epoch: only the first epoch is a new best.
  int validations = 0;
  hooks.validate = [&](Trainer& t, lfnet::train::BatchSource& s) {
    auto e = t.evaluate(s);
    e.psnr_db = 50.0 - ++validations;
    return e;
  };
  std::vector<std::pair<int64_t, bool>> saved;
  hooks.save = [&](Trainer& t, const lfnet::train::EpochRecord& r) {
    saved.emplace_back(r.epoch, r.best);
    CHECK(t.state().epoch == r.epoch);  // the state already holds the epoch
  };
  const auto records = trainer.fit(*source, hooks);
  REQUIRE(records.size() == 3);
  REQUIRE(!asked.empty());
  CHECK(std::get<0>(asked.front()) == 0);
  CHECK(std::get<0>(asked.back()) == 2);
  CHECK(std::get<1>(asked.back()) == std::get<2>(asked.back()) - 1);
  REQUIRE(used.size() == asked.size());
  CHECK(used.front() == Approx(1e-4));
  CHECK(used.back() == Approx(3e-4));
  CHECK(records[2].lr == Approx(3e-4));
  CHECK(validations == 3);
  CHECK(records[0].val_psnr_db == Approx(49.0));
  CHECK(records[0].best);
  CHECK_FALSE(records[1].best);
  CHECK(trainer.state().best_epoch == 1);
  CHECK(saved == std::vector<std::pair<int64_t, bool>>{{1, true}, {2, false}, {3, false}});
  // The save hook replaced the default: nothing was written to out_dir.
  CHECK_FALSE(std::filesystem::exists(lfnet::train::last_checkpoint_path(dir.path().string())));
  CHECK(trainer.last_written().empty());
  // Without hooks the defaults write last.ckpt and best.ckpt.
  Trainer plain(make_net(o, phi, 5), quick_options("ae", dir.path().string(), 1), run_info(spec));
  plain.fit(*source);
  CHECK(std::filesystem::exists(lfnet::train::last_checkpoint_path(dir.path().string())));
  CHECK(std::filesystem::exists(lfnet::train::best_checkpoint_path(dir.path().string())));
  CHECK(plain.last_written() == lfnet::train::last_checkpoint_path(dir.path().string()));
}

TEST_CASE("with on_nonfinite = skip a poisoned batch is dropped", "[train][trainer]") {
  auto o = lfnet::test::small_net_options("ae");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 3);
  auto inner = lfnet::test::make_source(lfnet::test::smooth_patches(200, o.patch, 4), phi);
  PoisonedSource source(*inner, 0, 1, /*in_y=*/false);
  auto options = quick_options("ae", "", 2);
  options.on_nonfinite = lfnet::train::OnNonFinite::kSkip;
  Trainer trainer(make_net(o, phi, 5), options,
                  run_info(lfnet::test::synthetic_phi_spec("random", 2, 3)));
  auto records = trainer.fit(source);
  REQUIRE(records.size() == 2);
  CHECK(records[0].skipped_batches == 1);
  CHECK(records[1].skipped_batches == 0);
  CHECK(records[0].step == inner->train_batches_per_epoch() - 1);
  CHECK(std::isfinite(records[1].val_loss));
}

TEST_CASE("a far too large learning rate is detected and the last good checkpoint stays intact",
          "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto o = lfnet::test::small_net_options("net");
  auto phi = lfnet::test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 8);
  auto source = lfnet::test::make_source(lfnet::test::smooth_patches(200, o.patch, 9), phi);
  auto options = quick_options("joint", dir.path().string(), 3);
  options.schedule.name =
      lfnet::train::ScheduleKind::kStep;  // a sane first epoch, then lr = 1e-3 * 1e12
  options.schedule.step_epochs = 1;
  options.schedule.gamma = 1e12;
  for (const std::string policy : {"stop", "skip"}) {
    INFO(policy);
    options.on_nonfinite = lfnet::train::from_string(policy, options.on_nonfinite);
    Trainer trainer(make_net(o, phi, 10), options,
                    run_info(lfnet::test::synthetic_phi_spec("random", 2, 8)));
    CHECK_THROWS_WITH(trainer.fit(*source),
                      Catch::Contains("epoch 2") && Catch::Contains("diverged") &&
                          Catch::Contains("learning rate") && Catch::Contains("last.ckpt"));
    auto ck = lfnet::train::load_checkpoint(lfnet::train::last_checkpoint_path(options.out_dir));
    CHECK(ck.training.epoch == 1);
    auto net = lfnet::train::build_net(ck);
    for (const auto& p : net->parameters()) CHECK(torch::isfinite(p).all().item<bool>());
    CHECK(std::filesystem::exists(lfnet::train::best_checkpoint_path(options.out_dir)));
  }
}

TEST_CASE("the joint stage starts from two branch checkpoints", "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto phi_o = lfnet::test::small_net_options();
  auto phi = lfnet::test::gaussian_phi(1, phi_o.measurement_size(), phi_o.patch.size(), 20);
  auto source = lfnet::test::make_source(lfnet::test::smooth_patches(120, phi_o.patch, 21), phi);
  const auto spec = lfnet::test::synthetic_phi_spec("random", 2, 20);
  std::map<std::string, LightFieldNet> branch_nets;
  for (const std::string stage : {"ae", "cnn"}) {
    Trainer t(make_net(lfnet::test::small_net_options(stage), phi, 22),
              quick_options(stage, dir / stage, 1), run_info(spec));
    t.fit(*source);
    branch_nets.emplace(stage, t.net());
  }
  Trainer joint(make_net(lfnet::test::small_net_options("net"), phi, 23),
                quick_options("joint", "", 1), run_info(spec));
  auto report = joint.init_branches(lfnet::train::best_checkpoint_path(dir / "ae"),
                                    lfnet::train::best_checkpoint_path(dir / "cnn"));
  CHECK(report.reinitialised.empty());
  CHECK(report.mapped.empty());
  CHECK(report.copied.size() == joint.net()->parameters().size());
  auto y = torch::rand({5, phi_o.measurement_size()});
  torch::NoGradGuard no_grad;
  auto want = 0.5 * branch_nets.at("ae")->forward(y) + 0.5 * branch_nets.at("cnn")->forward(y);
  lfnet::test::require_close(joint.net()->forward(y), want, 1e-6);
  CHECK(joint.state().epoch == 0);
  CHECK(joint.state().origin.contains("ae"));
  CHECK(joint.state().origin.contains("cnn"));
}

TEST_CASE("Phi switching carries the autoencoder's first layer to the new Phi",
          "[train][trainer]") {
  lfnet::test::TempDir dir;
  auto o2 = lfnet::test::small_net_options("ae");
  auto phi2 = lfnet::test::gaussian_phi(1, o2.measurement_size(), o2.patch.size(), 30);
  auto patches = lfnet::test::smooth_patches(240, o2.patch, 31);
  auto source2 = lfnet::test::make_source(patches, phi2);
  Trainer first(make_net(o2, phi2, 32), quick_options("ae", dir.path().string(), 2),
                run_info(lfnet::test::synthetic_phi_spec("random", 2, 30)));
  first.fit(*source2);

  // Phi B measures everything Phi A does plus a third channel, so W_A Phi_A = W_B Phi_B.
  auto o3 = o2;
  o3.measurements = 3;
  auto extra = lfnet::test::gaussian_phi(1, 25, o2.patch.size(), 33);
  auto phi3 = torch::cat({phi2, extra}, 1);
  auto net3 = make_net(o3, phi3, 34);
  Trainer second(net3, quick_options("ae", "", 1),
                 run_info(lfnet::test::synthetic_phi_spec("random", 3, 30)));
  auto report = second.init_from(lfnet::train::last_checkpoint_path(dir.path().string()));
  CHECK(report.mapped == std::vector<std::string>{"ae.fc1.weight"});
  CHECK(report.reinitialised.empty());
  auto flat = patches.narrow(0, 0, 8).reshape({8, -1});
  torch::NoGradGuard no_grad;
  auto old_out = first.net()->forward(flat.matmul(phi2[0].t()));
  auto new_out = net3->forward(flat.matmul(phi3[0].t()));
  lfnet::test::require_close(new_out, old_out, 2e-3);
  CHECK(second.state().origin["all"]["phi"]["n"] == 2);

  // A Phi of several phases cannot be mapped: fc1 starts afresh.
  auto phi3p = torch::cat({phi3, phi3.flip(2)}, 0);
  Trainer third(make_net(o3, phi3p, 35), quick_options("ae", "", 1),
                run_info(lfnet::test::synthetic_phi_spec("mask", 3, 30)));
  auto report3 = third.init_from(lfnet::train::last_checkpoint_path(dir.path().string()));
  CHECK(report3.reinitialised == std::vector<std::string>{"ae.fc1.weight"});
  CHECK(report3.copied.size() == first.net()->parameters().size() - 1);

  // Finetuning needs the same architecture otherwise.
  auto wide = o3;
  lfnet::test::edit_paper(wide, [&](lfnet::nn::PaperOptions& p) { p.ae.hidden[2] = 70; });
  Trainer fourth(make_net(wide, phi3, 36), quick_options("ae", "", 1),
                 run_info(lfnet::test::synthetic_phi_spec("random", 3, 30)));
  CHECK_THROWS_WITH(fourth.init_from(lfnet::train::last_checkpoint_path(dir.path().string())),
                    Catch::Contains("ae.fc3.weight"));
}

TEST_CASE("finetuning widens a narrower lfnet U-Net and starts from what it computed",
          "[train][trainer]") {
  lfnet::test::TempDir dir;
  // Two measurements per pixel of 3 x 3 views, weights positive like a camera's.
  torch::manual_seed(49);
  const auto weights = torch::rand({2, 3, 3, 1, 1}) + 0.1;
  auto o = lfnet::test::small_image_options(16, 4);
  auto narrow = make_net(o, weights, 50);
  {
    torch::NoGradGuard no_grad;
    for (auto& p : lfnet::nn::image_layers(*narrow)->parameters())
      p.copy_(torch::randn_like(p) * 0.3);
  }
  lfnet::train::Checkpoint ck;
  ck.network = o.to_json();
  ck.phi = {{"name", "asp"}, {"n", 2}};
  ck.model = lfnet::train::module_state(*narrow);
  const auto path = dir / "narrow.ckpt";
  lfnet::train::save_checkpoint(ck, path);

  auto wide_options = o;
  lfnet::test::edit_image(wide_options, [&](lfnet::nn::ImageNetOptions& wide_options_image) {
    wide_options_image.channels = 6;
  });
  auto wide = make_net(wide_options, weights, 51);
  Trainer t(wide, quick_options("joint", "", 1), run_info(ck.phi));
  auto report = t.init_from(path);
  // All but the output's bias (one per view either way), which is copied.
  CHECK(report.widened.size() == lfnet::nn::image_layers(*narrow)->parameters().size() - 1);
  CHECK(std::find(report.copied.begin(), report.copied.end(), "image.output.bias") !=
        report.copied.end());
  CHECK(report.reinitialised.empty());
  CHECK(t.state().origin["all"]["report"]["widened"].size() == report.widened.size());
  auto sensor = torch::rand({1, 2, 16, 24});
  torch::NoGradGuard no_grad;
  lfnet::test::require_close(wide->forward_image(sensor), narrow->forward_image(sensor), 1e-5);

  // A deeper U-Net starts from the shallow one's weights and computes what it did.
  auto deep_options = o;
  lfnet::test::edit_image(deep_options, [&](lfnet::nn::ImageNetOptions& deep_options_image) {
    deep_options_image.levels = 3;
  });
  auto deep = make_net(deep_options, weights, 53);
  Trainer d(deep, quick_options("joint", "", 1), run_info(ck.phi));
  auto deep_report = d.init_from(path);
  CHECK(deep_report.deepened == std::vector<std::string>{"image.up1.weight", "image.up1.bias",
                                                         "image.dec1_0.weight",
                                                         "image.dec1_0.bias"});
  // The new bottom level and the down-sampling to it keep their fresh initialisation.
  CHECK(deep_report.reinitialised ==
        std::vector<std::string>{"image.down1.weight", "image.down1.bias", "image.enc2_0.weight",
                                 "image.enc2_0.bias"});
  lfnet::test::require_close(deep->forward_image(sensor), narrow->forward_image(sensor), 1e-5);

  // Narrowing is not finetuning.
  Trainer back(make_net(o, weights, 52), quick_options("joint", "", 1), run_info(ck.phi));
  auto wide_ck = ck;
  wide_ck.network = wide_options.to_json();
  wide_ck.model = lfnet::train::module_state(*wide);
  lfnet::train::save_checkpoint(wide_ck, dir / "wide.ckpt");
  CHECK_THROWS_WITH(back.init_from(dir / "wide.ckpt"), Catch::Contains("image.input.weight"));
}

// Not run by default: train_tests "[experiment]" prints the validation PSNR of each residual
// base next to the pseudo-inverse alone, on the synthetic patches (docs/training.md).
TEST_CASE("residual bases on synthetic patches", "[.][experiment]") {
  auto patches = lfnet::test::smooth_patches(3000, lfnet::test::small_net_options().patch, 40);
  for (const int64_t n : {1, 2}) {
    auto base = lfnet::test::small_net_options("net");
    base.measurements = n;
    auto phi = lfnet::test::gaussian_phi(1, base.measurement_size(), base.patch.size(), 41);
    auto source = lfnet::test::make_source(patches, phi, 42);
    {
      // The pseudo-inverse alone: a net whose branches output zero, plus the pinv base.
      auto o = lfnet::test::small_net_options("ae");
      o.measurements = n;
      lfnet::test::edit_paper(
          o, [&](lfnet::nn::PaperOptions& p) { p.residual = lfnet::nn::Residual::kPinv; });
      auto net = make_net(o, phi, 43);
      torch::NoGradGuard no_grad;
      for (auto& p : lfnet::nn::ae_branch(*net)->parameters()) p.zero_();
      Trainer t(net, quick_options("ae", "", 1),
                run_info(lfnet::test::synthetic_phi_spec("random", n, 41)));
      WARN("N = " << n << ": pinv alone " << t.evaluate(*source).psnr_db << " dB");
    }
    for (const std::string residual : {"none", "pinv", "adjoint"}) {
      auto o = base;
      lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
        p.residual = lfnet::nn::from_string(residual, p.residual);
      });
      Trainer t(make_net(o, phi, 44), quick_options("joint", "", 12),
                run_info(lfnet::test::synthetic_phi_spec("random", n, 41)));
      auto records = t.fit(*source);
      WARN("N = " << n << ": residual " << residual << ": " << records.back().val_psnr_db
                  << " dB after 12 epochs");
    }
  }
}

TEST_CASE("the lfnet architecture trains on crops, from its pseudo-inverse upward", "[train]") {
  lfnet::test::TempDir dir;
  auto o = lfnet::test::small_image_options(8, 8);
  const int64_t n = 384;
  auto patches = lfnet::test::smooth_patches(n, o.patch, 4);  // (n, 1, 3, 3, 8, 8)
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(5);
  auto weights = torch::rand({2, 3, 3, 1, 1}, gen);
  // Each pixel measures its own views: y[b, k] = sum_uv W[k, u, v] L[b, u, v] per pixel.
  auto y = (weights.unsqueeze(0) * patches).sum({2, 3}).reshape({n, -1});
  lfnet::train::InMemoryBatchSource source(y, {}, patches, 0.15, 0);
  auto net = make_net(o, weights, 6);
  auto options = quick_options("joint", dir / "run", 4);
  options.lr = 3e-3;
  Trainer trainer(net, options, run_info(lfnet::test::synthetic_phi_spec("asp", 2, 0)));
  const double before = trainer.evaluate(source).psnr_db;  // the pseudo-inverse alone
  const auto history = trainer.fit(source);
  REQUIRE(history.size() == 4);
  CHECK(history.back().val_psnr_db > before + 1.0);
  // The checkpoint it wrote builds the same net.
  auto loaded = lfnet::train::build_net(lfnet::train::load_checkpoint(dir / "run/last.ckpt"));
  CHECK(loaded->architecture().whole_image());
  torch::NoGradGuard no_grad;
  CHECK(torch::allclose(loaded->forward(y.slice(0, 0, 4)), net->forward(y.slice(0, 0, 4))));
}

TEST_CASE("a teacher's estimates replace or blend with the training targets, not validation's",
          "[train][trainer]") {
  auto patches = torch::rand({40, 1, 3, 3, 4, 4}, torch::make_generator<at::CPUGeneratorImpl>(3));
  auto y = patches.flatten(1).narrow(1, 0, 32).contiguous();
  lfnet::train::InMemoryBatchSource inner(y, {}, patches, 0.25, 1);
  lfnet::train::InMemoryBatchSource plain(y, {}, patches, 0.25, 1);
  // The teacher says 1 - truth, pushed past 1 where the truth is small (clamped back to 1).
  int64_t calls = 0;
  auto teacher = [&calls](const lfnet::train::Batch& b) {
    ++calls;
    return (1.0 - b.target) * 1.5;
  };
  for (double weight : {1.0, 0.25, 0.0}) {
    INFO("weight " << weight);
    lfnet::train::TeacherBatchSource taught(inner, teacher, weight);
    taught.start_epoch(2, 8);
    plain.start_epoch(2, 8);
    REQUIRE(taught.train_batches_per_epoch() == plain.train_batches_per_epoch());
    for (int64_t i = 0; i < taught.train_batches_per_epoch(); ++i) {
      const auto b = taught.next_train();
      const auto truth = plain.next_train();
      REQUIRE(torch::equal(b.y, truth.y));  // the same batches in the same order
      const auto expected =
          ((1.0 - truth.target) * 1.5).clamp(0, 1) * weight + truth.target * (1 - weight);
      CHECK(torch::allclose(b.target, expected, 1e-6, 1e-6));
    }
    // Validation keeps the truth.
    REQUIRE(taught.validation().size() == plain.validation().size());
    CHECK(torch::equal(taught.validation()[0].target, plain.validation()[0].target));
  }
  CHECK(calls == 2 * plain.train_batches_per_epoch());  // weight 0 never asks the teacher
  CHECK_THROWS_AS(lfnet::train::TeacherBatchSource(inner, teacher, 1.5), lfnet::ConfigError);
  CHECK_THROWS_AS(lfnet::train::TeacherBatchSource(inner, teacher, -0.1), lfnet::ConfigError);
  CHECK_THROWS_AS(lfnet::train::TeacherBatchSource(inner, {}, 1.0), lfnet::ConfigError);
  // A teacher of the wrong shape is an error, not a silent broadcast.
  lfnet::train::TeacherBatchSource wrong(
      inner, [](const lfnet::train::Batch& b) { return b.target.select(1, 0); }, 1.0);
  wrong.start_epoch(0, 8);
  CHECK_THROWS(wrong.next_train());
}

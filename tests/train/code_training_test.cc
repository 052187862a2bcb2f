// Training a code with the net inside the Trainer (Trainer::set_code): the code moves, is held
// fixed (and rounded) for the last epochs, checkpoints record it as their Phi, and a run resumes
// bit for bit.
#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/optics/phi.h"
#include "lfnet/train/checkpoint.h"
#include "lfnet/train/joint_phi.h"
#include "lfnet/train/trainer.h"
#include "support/test_support.h"
#include "synthetic.h"

using namespace lfnet;

namespace {

constexpr int64_t kPeriod = 2;

nn::LearnedPhi mask_code() {
  nn::LearnedPhiOptions o;
  o.family = "mask";
  o.period = kPeriod;
  o.seed = 3;
  return nn::LearnedPhi(o, 2, 3, 3);
}

// 256 crops of 8 x 8 pixels, 3 x 3 views, at random phases of the period, measured by the
// code's start (the Trainer measures them again with the code it has).
std::unique_ptr<train::InMemoryBatchSource> code_source(const nn::LearnedPhi& code) {
  const auto o = test::small_image_options(8, 8);
  auto patches = test::smooth_patches(256, o.patch, 21);
  auto gen = at::detail::createCPUGenerator(22);
  auto phase = at::randint(kPeriod * kPeriod, {256}, gen, torch::kInt64);
  torch::NoGradGuard no_grad;
  auto y = train::simulate_patches(code->weights(), patches, phase);
  return std::make_unique<train::InMemoryBatchSource>(y, phase, patches, 0.15, 23, 64);
}

train::TrainerOptions options(const std::string& out_dir, int64_t epochs) {
  train::TrainerOptions o;
  o.epochs = epochs;
  o.batch_size = 16;
  o.lr = 2e-3;
  o.progress = false;
  o.out_dir = out_dir;
  return o;
}

train::Trainer make_trainer(const nn::LearnedPhi& code, const train::TrainerOptions& o,
                            uint64_t seed) {
  torch::manual_seed(seed);
  nn::LightFieldNet net(test::small_image_options(8, 8));
  {
    torch::NoGradGuard no_grad;
    net->set_phi(code->weights().detach());
  }
  return train::Trainer(net, o, {{{"test", true}}, code->spec().to_json(), "code_training_test"});
}

torch::Tensor logits(const nn::LearnedPhi& code) {
  return code->named_parameters()["logits"].detach().clone();
}

}  // namespace

TEST_CASE("a code trained with the net moves, and its checkpoints hold it as their Phi",
          "[train][code]") {
  test::TempDir dir;
  auto code = mask_code();
  auto source = code_source(code);
  const auto start = logits(code);
  auto trainer = make_trainer(code, options(dir / "run", 3), 31);
  train::CodeTrainingOptions c;
  c.lr = 0.05;
  trainer.set_code(code, c);
  const auto records = trainer.fit(*source);
  REQUIRE(records.size() == 3);
  CHECK(records.back().val_loss < records.front().val_loss);
  CHECK((logits(code) - start).abs().max().item<double>() > 0.01);

  const auto ck = train::load_checkpoint(train::last_checkpoint_path(dir / "run"));
  CHECK(ck.phi["name"] == "calibrated");
  CHECK(ck.phi["params"]["source"] == "learned mask");
  CHECK(ck.model.count("code.logits") == 1);
  CHECK(ck.optimizer.count("code.logits/exp_avg") == 1);
  // The Phi it records is the code's weights, and the net it builds holds them.
  torch::NoGradGuard no_grad;
  const auto weights = code->weights();
  const auto phi = optics::make_phi(optics::PhiSpec::from_json(ck.phi));
  CHECK(torch::equal(phi->pixel_weights(0, 0, kPeriod, kPeriod), weights));
  auto net = train::build_net(ck);
  CHECK(torch::equal(net->phi, weights));
  // The net reconstructs a crop from those weights' measurements as in training.
  const auto& val = source->validation().front();
  const auto y = train::simulate_patches(weights, val.target, val.phase);
  auto trained = trainer.net();
  net->eval();
  trained->eval();
  CHECK(torch::allclose(net->forward(y, val.phase),
                        train::joint_forward(trained, weights, {y, val.phase, val.target, {}}, 0),
                        1e-4, 1e-5));
}

TEST_CASE("the code is held fixed for the last epochs, rounded to 0 or 1 when asked",
          "[train][code]") {
  test::TempDir dir;
  auto code = mask_code();
  auto source = code_source(code);
  auto trainer = make_trainer(code, options(dir / "run", 3), 32);
  train::CodeTrainingOptions c;
  c.lr = 0.05;
  c.freeze_epochs = 1;
  c.binarise = true;
  trainer.set_code(code, c);
  std::vector<torch::Tensor> after;  // the code's parameters after each epoch
  train::TrainerHooks hooks;
  hooks.on_epoch = [&](const train::EpochRecord&) { after.push_back(logits(code)); };
  trainer.fit(*source, hooks);
  REQUIRE(after.size() == 3);
  CHECK(!torch::equal(after[0], after[1]));  // learning
  CHECK(torch::equal(after[1], after[2]));   // held
  // The code in use is binary: zero or one value, the transmittance 1 normalised.
  const auto w = trainer.code_weights();
  const auto values = std::get<0>(at::_unique(w));
  REQUIRE(values.numel() == 2);
  CHECK(values[0].item<double>() == 0.0);
  CHECK(torch::equal(w, optics::normalise_white((code->response() >= 0.5).to(torch::kFloat32))));
  // Its cost is measured, and only the binary epoch counts as best.
  const auto& state = trainer.state();
  REQUIRE(state.code.contains("binarised"));
  CHECK(state.code["binarised"]["epoch"] == 3);
  CHECK(state.code["binarised"]["continuous_psnr_db"].get<double>() > 0);
  CHECK(state.best_epoch == 3);
  const auto best = train::load_checkpoint(train::best_checkpoint_path(dir / "run"));
  CHECK(best.phi["params"]["source"] == "learned mask, binarised");
  CHECK(torch::equal(train::build_net(best)->phi, w));
}

TEST_CASE("a code learns through its rounding before it is held fixed", "[train][code]") {
  test::TempDir dir;
  auto code = mask_code();
  auto source = code_source(code);
  auto trainer = make_trainer(code, options(dir / "run", 3), 36);
  train::CodeTrainingOptions c;
  c.lr = 0.05;
  c.freeze_epochs = 1;
  c.binarise = true;
  c.straight_through_epochs = 1;
  trainer.set_code(code, c);
  std::vector<torch::Tensor> after;
  std::vector<nlohmann::json> phis;  // what each epoch's checkpoint records
  train::TrainerHooks hooks;
  hooks.on_epoch = [&](const train::EpochRecord&) {
    after.push_back(logits(code));
    phis.push_back(train::load_checkpoint(train::last_checkpoint_path(dir / "run")).phi);
  };
  trainer.fit(*source, hooks);
  REQUIRE(after.size() == 3);
  CHECK(!torch::equal(after[0], after[1]));  // the rounded code's gradient reached it
  CHECK(torch::equal(after[1], after[2]));   // then held
  CHECK(phis[0]["params"]["source"] == "learned mask");
  CHECK(phis[1]["params"]["source"] == "learned mask, binarised");
  // The epoch learning through the rounding measured the net with the binary code.
  const auto rounded = optics::make_phi(optics::PhiSpec::from_json(phis[1]));
  CHECK(std::get<0>(at::_unique(rounded->pixel_weights(0, 0, kPeriod, kPeriod))).numel() <= 2);
  // Its values are the rounded code's, its gradient the transmittances': straight through.
  auto fresh = mask_code();
  const auto w = fresh->straight_through_weights();
  CHECK(torch::allclose(w, fresh->binarised_weights(), 0, 1e-6));
  (w * torch::rand_like(w)).sum().backward();
  CHECK(fresh->named_parameters()["logits"].grad().abs().sum().item<double>() > 0);
}

TEST_CASE("a run that learns a code resumes bit for bit", "[train][code]") {
  test::TempDir dir;
  auto straight_code = mask_code();
  auto source_a = code_source(straight_code);
  auto straight = make_trainer(straight_code, options("", 2), 33);
  train::CodeTrainingOptions c;
  c.lr = 0.05;
  straight.set_code(straight_code, c);
  straight.fit(*source_a);

  auto first_code = mask_code();
  auto source_b = code_source(first_code);
  {
    auto first = make_trainer(first_code, options(dir / "run", 2), 33);
    first.set_code(first_code, c);
    train::TrainerHooks interrupt;
    interrupt.stop_requested = [] { return true; };
    first.fit(*source_b, interrupt);
    REQUIRE(first.state().epoch == 1);
  }
  auto resumed_code = mask_code();
  auto resumed = make_trainer(resumed_code, options(dir / "run", 2), 7);
  resumed.set_code(resumed_code, c);
  resumed.resume(train::last_checkpoint_path(dir / "run"));
  resumed.fit(*source_b);
  CHECK(torch::equal(logits(resumed_code), logits(straight_code)));
  const auto a = straight.checkpoint(), b = resumed.checkpoint();
  for (const auto& [name, t] : a.model) {
    INFO(name);
    CHECK(torch::equal(t, b.model.at(name)));
  }
  for (const auto& [name, t] : a.optimizer) {
    INFO(name);
    CHECK(torch::equal(t, b.optimizer.at(name)));
  }
  CHECK(a.phi == b.phi);
}

TEST_CASE("a code starts from another model's learned code, whatever the net starts from",
          "[train][code]") {
  test::TempDir dir;
  auto learned = mask_code();
  auto source = code_source(learned);
  train::CodeTrainingOptions c;
  c.lr = 0.05;
  {
    auto trainer = make_trainer(learned, options(dir / "learned", 2), 36);
    trainer.set_code(learned, c);
    trainer.fit(*source);
  }
  const auto donor = train::last_checkpoint_path(dir / "learned");
  const auto donor_logits = train::load_checkpoint(donor).model.at("code.logits");
  // Another run's net, and a code of another start (seed 4).
  nn::LearnedPhiOptions o;
  o.family = "mask";
  o.period = kPeriod;
  o.seed = 4;
  nn::LearnedPhi code(o, 2, 3, 3);
  REQUIRE_FALSE(torch::equal(logits(code), donor_logits));
  auto trainer = make_trainer(code, options(dir / "next", 1), 37);
  trainer.set_code(code, c);
  const auto taken = trainer.init_code_from(donor);
  CHECK(taken == std::vector<std::string>{"code.logits"});
  CHECK(torch::equal(logits(code), donor_logits));
  {
    // The net measures with that code from the first batch on.
    torch::NoGradGuard no_grad;
    CHECK(torch::equal(trainer.code_weights(), code->weights()));
    CHECK(torch::equal(trainer.net()->phi, code->weights()));
  }
  CHECK(trainer.state().origin.at("code").at("checkpoint") == donor);

  SECTION("a code of another family or shape is refused") {
    nn::LearnedPhiOptions a;
    a.family = "aperture";
    nn::LearnedPhi aperture(a, 2, 3, 3);
    auto other = make_trainer(aperture, options("", 1), 38);
    other.set_code(aperture, c);
    CHECK_THROWS_WITH(other.init_code_from(donor), Catch::Contains("lacks logits"));
  }
  SECTION("a model that learned no code is refused") {
    auto plain = make_trainer(code, options(dir / "plain", 1), 39);
    plain.fit(*source);
    CHECK_THROWS_AS(trainer.init_code_from(train::last_checkpoint_path(dir / "plain")),
                    CheckpointError);
  }
}

TEST_CASE("a code is refused where it cannot train", "[train][code]") {
  test::TempDir dir;
  auto code = mask_code();
  train::CodeTrainingOptions c;
  SECTION("binarising needs freeze epochs; freezing at most every epoch") {
    auto trainer = make_trainer(code, options("", 2), 34);
    c.binarise = true;
    CHECK_THROWS_AS(trainer.set_code(code, c), ConfigError);
    c.freeze_epochs = 3;
    CHECK_THROWS_WITH(trainer.set_code(code, c), Catch::Contains("freeze_epochs"));
    c.freeze_epochs = 1;
    c.straight_through_epochs = 2;
    CHECK_THROWS_WITH(trainer.set_code(code, c), Catch::Contains("straight_through_epochs"));
    c.binarise = false;
    c.straight_through_epochs = 1;
    CHECK_THROWS_WITH(trainer.set_code(code, c), Catch::Contains("set $.code.binarise"));
  }
  SECTION("the code's period must be the data's") {
    nn::LightFieldNet net(test::small_image_options(8, 8));
    net->set_phi(torch::rand({2, 3, 3, 3, 3}));
    train::Trainer trainer(net, options("", 2), {{}, code->spec().to_json(), "test"});
    CHECK_THROWS_WITH(trainer.set_code(code, c), Catch::Contains("period"));
  }
  SECTION("resuming a run that learned no code") {
    auto source = code_source(code);
    auto plain = make_trainer(code, options(dir / "plain", 1), 35);
    plain.fit(*source);
    auto trainer = make_trainer(code, options("", 2), 35);
    trainer.set_code(code, c);
    CHECK_THROWS_WITH(trainer.resume(train::last_checkpoint_path(dir / "plain")),
                      Catch::Contains("holds no learned code"));
  }
}

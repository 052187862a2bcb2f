// Data-parallel training on loopback: 2 ranks as threads of one process, each with its own
// c10d process group, exactly as separate processes would have.
#include "lfnet/dist/communicator.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <chrono>
#include <filesystem>
#include <functional>
#include <future>
#include <thread>

#include "../train/synthetic.h"
#include "lfnet/core/error.h"
#include "lfnet/data/patch_dataset.h"
#include "lfnet/optics/phi.h"
#include "lfnet/train/trainer.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

dist::DistOptions options_for(int64_t rank, int64_t world, int port, double timeout_s = 20) {
  dist::DistOptions o;
  o.rank = rank;
  o.world_size = world;
  o.master = "127.0.0.1:" + std::to_string(port);
  o.timeout_s = timeout_s;
  return o;
}

// Runs fn(rank, communicator) for `world` ranks, each on its own thread, and returns what each
// threw ("" when nothing).
std::vector<std::string> run_ranks(int64_t world,
                                   const std::function<void(int64_t, dist::Communicator&)>& fn,
                                   double timeout_s = 20) {
  const int port = dist::free_loopback_port();
  std::vector<std::future<std::string>> ranks;
  for (int64_t r = 0; r < world; ++r) {
    ranks.push_back(std::async(std::launch::async, [&, r]() -> std::string {
      try {
        auto comm = dist::connect(options_for(r, world, port, timeout_s));
        fn(r, *comm);
        return "";
      } catch (const std::exception& e) {
        return e.what();
      }
    }));
  }
  std::vector<std::string> errors;
  errors.reserve(ranks.size());
  for (auto& f : ranks) errors.push_back(f.get());
  return errors;
}

// A shared_ptr that does not own: the trainer holds the thread's communicator.
std::shared_ptr<dist::Communicator> borrow(dist::Communicator& c) {
  return std::shared_ptr<dist::Communicator>(&c, [](dist::Communicator*) {});
}

train::TrainerOptions quick_options(int64_t epochs, int64_t batch, const std::string& out) {
  train::TrainerOptions o;
  o.stage = lfnet::train::Stage::kJoint;
  o.epochs = epochs;
  o.batch_size = batch;
  o.lr = 1e-3;
  o.progress = false;
  o.out_dir = out;
  return o;
}

nn::LightFieldNet make_net(const torch::Tensor& phi, uint64_t seed) {
  torch::manual_seed(seed);
  nn::LightFieldNet net(test::small_net_options("net"));
  net->set_phi(phi);
  return net;
}

train::RunInfo run_info() {
  return {{{"test", true}}, test::synthetic_phi_spec("random", 2, 1), "dist_test"};
}

double max_difference(const torch::nn::Module& a, const torch::nn::Module& b) {
  double worst = 0;
  const auto pb = b.named_parameters();
  for (const auto& p : a.named_parameters()) {
    worst = std::max(worst, (p.value() - pb[p.key()]).abs().max().item<double>());
  }
  return worst;
}

}  // namespace

TEST_CASE("shard_range splits n items into contiguous parts differing by at most one", "[dist]") {
  CHECK(dist::shard_range(10, 0, 3) == std::pair<int64_t, int64_t>{0, 4});
  CHECK(dist::shard_range(10, 1, 3) == std::pair<int64_t, int64_t>{4, 7});
  CHECK(dist::shard_range(10, 2, 3) == std::pair<int64_t, int64_t>{7, 10});
  CHECK(dist::shard_range(1, 1, 2) == std::pair<int64_t, int64_t>{1, 1});
  CHECK(dist::shard_range(0, 0, 1) == std::pair<int64_t, int64_t>{0, 0});
  CHECK_THROWS(dist::shard_range(5, 2, 2));
}

TEST_CASE("distributed options are checked and name the bad field", "[dist]") {
  dist::DistOptions o;
  CHECK_NOTHROW(o.validate());
  o.world_size = 2;
  o.rank = 2;
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("rank"));
  o.rank = 1;
  o.master = "hostonly";
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("master"));
  o.master = "10.0.0.1:99999";
  CHECK_THROWS_WITH(o.validate(), Catch::Contains("master"));
  o.master = "10.0.0.1:29500";
  CHECK(o.host() == "10.0.0.1");
  CHECK(o.port() == 29500);
  CHECK_NOTHROW(o.validate());
  // One process needs no network at all.
  auto local = dist::connect(dist::DistOptions{});
  CHECK(local->world_size() == 1);
}

TEST_CASE("collectives on loopback: all-reduce, broadcast, all-gather, barrier", "[dist]") {
  if (!dist::available()) {
    WARN("built without c10d: skipped");
    CHECK_THROWS_AS(dist::connect(options_for(0, 2, 29500)), ConfigError);
    return;
  }
  std::vector<torch::Tensor> reduced(3), broadcast(3);
  std::vector<std::vector<std::string>> gathered(3);
  auto errors = run_ranks(3, [&](int64_t r, dist::Communicator& c) {
    CHECK(c.rank() == r);
    auto t = torch::tensor({1.0 + r, 10.0 * r}, torch::kFloat64);
    c.all_reduce_sum(t);
    reduced[r] = t;
    auto b = torch::full({2, 2}, static_cast<float>(r + 5));
    c.broadcast(b, 2);
    broadcast[r] = b;
    gathered[r] = c.all_gather(std::string(static_cast<size_t>(r) * 3, static_cast<char>('a' + r)));
    c.barrier();
  });
  for (int r = 0; r < 3; ++r) {
    INFO("rank " << r);
    CHECK(errors[r].empty());
    CHECK(reduced[r][0].item<double>() == 6.0);
    CHECK(reduced[r][1].item<double>() == 30.0);
    CHECK(broadcast[r].eq(7.0).all().item<bool>());
    CHECK(gathered[r] == std::vector<std::string>{"", "bbb", "cccccc"});
  }
}

TEST_CASE("a rank that never joins is a clear error after the rendezvous timeout", "[dist]") {
  if (!dist::available()) return;
  const auto start = std::chrono::steady_clock::now();
  const int port = dist::free_loopback_port();
  CHECK_THROWS_WITH(dist::connect(options_for(0, 2, port, 1.0)),
                    Catch::Contains("rank 0 of 2: rank 1 did not join within 1 s"));
  CHECK(std::chrono::steady_clock::now() - start < std::chrono::seconds(15));
}

TEST_CASE("patch dataset shards are the parts of the single-process batch", "[dist]") {
  torch::manual_seed(3);
  std::vector<LightField> lfs{LightField(torch::rand({1, 5, 5, 60, 50}))};
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  data::DatasetOptions o;
  o.train_patches = 23;  // a last batch of 3 patches: shards of 2 and 1
  o.validation_patches = 16;
  o.seed = 4;
  for (bool noise : {false, true}) {
    if (noise) o.effects.gaussian = optics::SensorOptions::Gaussian{0.02};
    data::PatchDataset whole(lfs, *phi, o), first(lfs, *phi, o), second(lfs, *phi, o);
    first.set_shard(0, 2);
    second.set_shard(1, 2);
    for (auto* ds : {&whole, &first, &second}) ds->start_epoch(2, 10);
    for (int64_t i = 0; i < whole.train_batches_per_epoch(); ++i) {
      INFO("noise " << noise << ", batch " << i);
      auto w = whole.next_train(), a = first.next_train(), b = second.next_train();
      CHECK(a.size() == (w.size() + 1) / 2);
      CHECK(a.size() + b.size() == w.size());
      CHECK(torch::equal(torch::cat({a.y, b.y}), w.y));
      CHECK(torch::equal(torch::cat({a.target, b.target}), w.target));
      CHECK(torch::equal(torch::cat({a.phase, b.phase}), w.phase));
    }
  }
}

TEST_CASE("2 ranks with batch b take the steps of 1 rank with batch 2b", "[dist][train]") {
  if (!dist::available()) return;
  const auto o = test::small_net_options("net");
  const auto phi = test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 1);
  // 51 patches: 43 for training, so an epoch of batch 8 ends on a batch of 3 (shards 2 and 1).
  const auto patches = test::smooth_patches(51, o.patch, 6);
  test::TempDir dir;
  const std::string out1 = (std::filesystem::path(dir.path()) / "one").string();
  const std::string out2 = (std::filesystem::path(dir.path()) / "two").string();
  const std::string out_rank1 = (std::filesystem::path(dir.path()) / "rank1").string();

  auto single = make_net(phi, 21);
  train::Trainer reference(single, quick_options(2, 8, out1), run_info());
  auto source = test::make_source(patches, phi, 5);
  const auto want = reference.fit(*source);

  // Rank 1 starts from other weights: rank 0's reach it when training starts.
  std::vector<nn::LightFieldNet> nets{make_net(phi, 21), make_net(phi, 99)};
  std::vector<std::vector<train::EpochRecord>> got(2);
  auto errors = run_ranks(2, [&](int64_t r, dist::Communicator& c) {
    train::Trainer trainer(nets[r], quick_options(2, 8, r == 0 ? out2 : out_rank1), run_info());
    trainer.set_communicator(borrow(c));
    auto src = test::make_source(patches, phi, 5);
    got[r] = trainer.fit(*src);
  });
  REQUIRE(errors == std::vector<std::string>{"", ""});
  const double error = max_difference(*single, *nets[0]);
  WARN("2 ranks x 4 vs 1 rank x 8, " << want.back().step << " steps: max |weight difference| "
                                     << error);
  CHECK(want.back().step == 12);  // 6 batches an epoch, the last of 3 patches
  CHECK(error < 1e-5);
  CHECK(max_difference(*nets[0], *nets[1]) == 0.0);  // the ranks agree bit for bit
  // And the steps did move the weights: the comparison is not of two untrained nets.
  CHECK(max_difference(*single, *make_net(phi, 21)) > 1e-3);
  for (int r = 0; r < 2; ++r) {
    REQUIRE(got[r].size() == 2);
    CHECK(got[r][1].train_loss == Approx(want[1].train_loss).epsilon(1e-4));
    CHECK(got[r][1].val_psnr_db == Approx(want[1].val_psnr_db).epsilon(1e-4));
    CHECK(got[r][1].best == want[1].best);
  }
  // Only rank 0 writes checkpoints.
  CHECK(std::filesystem::exists(train::last_checkpoint_path(out2)));
  CHECK(!std::filesystem::exists(out_rank1));
  auto ck = train::load_checkpoint(train::last_checkpoint_path(out2));
  CHECK(ck.training.epoch == 2);
  CHECK(ck.training.step == 12);
}

TEST_CASE("resuming with another world size continues the same run", "[dist][train]") {
  if (!dist::available()) return;
  const auto o = test::small_net_options("net");
  const auto phi = test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 2);
  const auto patches = test::smooth_patches(60, o.patch, 8);
  test::TempDir dir;
  auto path = [&](const char* name) { return (std::filesystem::path(dir.path()) / name).string(); };

  auto straight = make_net(phi, 5);
  train::Trainer reference(straight, quick_options(3, 10, ""), run_info());
  reference.fit(*test::make_source(patches, phi, 1));

  // Epoch 1 on 2 ranks, epoch 2 on 1 rank, epoch 3 on 2 ranks again (only rank 0 resumes).
  // Every part is a 3-epoch run (the schedule spans the run) interrupted after its epoch.
  auto stop_at = [](const train::Trainer& t, int64_t epoch) {
    train::TrainerHooks hooks;
    hooks.stop_requested = [&t, epoch] { return t.state().epoch >= epoch; };
    return hooks;
  };
  std::vector<nn::LightFieldNet> first{make_net(phi, 5), make_net(phi, 6)};
  auto errors = run_ranks(2, [&](int64_t r, dist::Communicator& c) {
    train::Trainer t(first[r], quick_options(3, 10, r == 0 ? path("a") : ""), run_info());
    t.set_communicator(borrow(c));
    t.fit(*test::make_source(patches, phi, 1), stop_at(t, 1));
  });
  REQUIRE(errors == std::vector<std::string>{"", ""});
  train::Trainer middle(make_net(phi, 7), quick_options(3, 10, path("b")), run_info());
  middle.resume(train::last_checkpoint_path(path("a")));
  middle.fit(*test::make_source(patches, phi, 1), stop_at(middle, 2));
  CHECK(middle.state().epoch == 2);
  std::vector<nn::LightFieldNet> last{make_net(phi, 8), make_net(phi, 9)};
  errors = run_ranks(2, [&](int64_t r, dist::Communicator& c) {
    train::Trainer t(last[r], quick_options(3, 10, r == 0 ? path("c") : ""), run_info());
    if (r == 0) t.resume(train::last_checkpoint_path(path("b")));
    t.set_communicator(borrow(c));
    t.fit(*test::make_source(patches, phi, 1));
    CHECK(t.state().epoch == 3);
    CHECK(t.state().step == 18);  // 51 training patches: 6 batches an epoch
  });
  REQUIRE(errors == std::vector<std::string>{"", ""});
  const double error = max_difference(*straight, *last[0]);
  WARN("1-2-1 world sizes vs 1 throughout: max |weight difference| " << error);
  CHECK(error < 1e-5);
  CHECK(max_difference(*last[0], *last[1]) == 0.0);
}

TEST_CASE("a rank that dies or stalls makes the others fail with a clear error", "[dist][train]") {
  if (!dist::available()) return;
  const auto o = test::small_net_options("net");
  const auto phi = test::gaussian_phi(1, o.measurement_size(), o.patch.size(), 1);
  const auto patches = test::smooth_patches(200, o.patch, 3);
  for (bool stall : {false, true}) {
    INFO((stall ? "rank 1 stalls" : "rank 1 dies"));
    std::vector<nn::LightFieldNet> nets{make_net(phi, 1), make_net(phi, 1)};
    const auto start = std::chrono::steady_clock::now();
    auto errors = run_ranks(
        2,
        [&](int64_t r, dist::Communicator& c) {
          train::Trainer t(nets[r], quick_options(50, 8, ""), run_info());
          t.set_communicator(borrow(c));
          train::TrainerHooks hooks;
          hooks.on_step = [&](const train::StepRecord& s) {
            if (r != 1 || s.step != 3) return;
            if (stall) std::this_thread::sleep_for(std::chrono::seconds(6));
            // Leaving the thread destroys the rank's process group, closing its sockets as a
            // dying process would.
            if (!stall) throw std::runtime_error("rank 1 died");
          };
          t.fit(*test::make_source(patches, phi, 2), hooks);
        },
        /*timeout_s=*/2.0);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    WARN((stall ? "stalled" : "died")
         << ": rank 0 failed after " << seconds << " s: " << errors[0]);
    // A dead rank's heartbeat stops, and it is named; a stalled one still beats.
    CHECK_THAT(errors[0], Catch::Contains("rank 0 of 2") &&
                              Catch::Contains(stall ? "another rank failed or stalled"
                                                    : "rank 1 stopped answering"));
    CHECK(seconds < 30);
    if (!stall) CHECK(errors[1] == "rank 1 died");
  }
}

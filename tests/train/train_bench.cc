// Benchmark of the network and training machinery (not a test): GEMM and Conv4d GFLOP/s,
// training throughput of each branch and the joint net at the default sizes, and the size of
// a default checkpoint. Usage:
//   train_bench [--threads 2] [--batch 64] [--conv-batch 256] [--channels 16,64]
//               [--steps 10] [--thin] [--all-algorithms] [--skip-conv] [--skip-train]
//               [--cpu-time] [--reps 2] [--json FILE]
// --thin adds the 1 -> C, C -> 1 and 1 -> 1 layers; --all-algorithms times every Conv4d
// algorithm instead of the default (auto) and the plain stacked one.
#include <torch/torch.h>

#include <time.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "lfnet/nn/conv4d.h"
#include "lfnet/nn/network.h"
#include "lfnet/train/checkpoint.h"
#include "lfnet/train/trainer.h"

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Process CPU seconds: on a shared machine, with one thread, a steadier measure of the work
// than wall time (--cpu-time).
double cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

bool g_cpu_time = false;
int g_reps = 2;
double g_util = 0;  // CPU seconds / (threads x wall seconds) of the best repetition

// Best of g_reps timings of fn() after one warm-up call: wall seconds, or CPU seconds divided
// by the thread count with --cpu-time. g_util below about 0.9 means other processes took
// cores during the timing: the figure is then pessimistic.
template <typename Fn>
double best_time(Fn&& fn) {
  fn();
  double best = 1e30;
  for (int i = 0; i < g_reps; ++i) {
    auto t0 = Clock::now();
    const double c0 = cpu_seconds();
    fn();
    const double wall = seconds_since(t0);
    const double cpu = (cpu_seconds() - c0) / torch::get_num_threads();
    const double t = g_cpu_time ? cpu : wall;
    if (t < best) {
      best = t;
      g_util = cpu / wall;
    }
  }
  return best;
}

double gemm_gflops() {
  auto a = torch::randn({2048, 2048}), b = torch::randn({2048, 2048});
  const double t = best_time([&] { auto c = a.matmul(b); });
  return 2.0 * 2048 * 2048 * 2048 / t / 1e9;
}

std::vector<int64_t> parse_list(const std::string& text) {
  std::vector<int64_t> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) out.push_back(std::stoll(item));
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2;
  int64_t batch = 64, conv_batch = 256, steps = 10;
  std::vector<int64_t> channels = {16, 64};
  bool skip_conv = false, thin = false, all_algorithms = false, skip_train = false;
  std::string json_path;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--threads")
      threads = std::stoi(next());
    else if (arg == "--batch")
      batch = std::stoll(next());
    else if (arg == "--conv-batch")
      conv_batch = std::stoll(next());
    else if (arg == "--channels")
      channels = parse_list(next());
    else if (arg == "--steps")
      steps = std::stoll(next());
    else if (arg == "--skip-conv")
      skip_conv = true;
    else if (arg == "--skip-train")
      skip_train = true;
    else if (arg == "--thin")
      thin = true;
    else if (arg == "--cpu-time")
      g_cpu_time = true;
    else if (arg == "--reps")
      g_reps = std::stoi(next());
    else if (arg == "--all-algorithms")
      all_algorithms = true;
    else if (arg == "--json")
      json_path = next();
    else {
      std::fprintf(stderr, "unknown argument %s\n", arg.c_str());
      return 2;
    }
  }
  torch::set_num_threads(threads);
  torch::manual_seed(0);
  nlohmann::json report;
  report["threads"] = torch::get_num_threads();
  const double gemm = gemm_gflops();
  report["gemm_gflops"] = gemm;
  std::printf("threads %d, GEMM %.1f GFLOP/s (2048^3 sgemm)\n", torch::get_num_threads(), gemm);

  using lfnet::nn::Conv4dAlgorithm;
  if (!skip_conv) {
    std::printf("\nConv4d, %lld patches of 5x5x9x9, kernel 3^4\n",
                static_cast<long long>(conv_batch));
    std::printf("%-8s %-13s %10s %10s %12s %12s %6s\n", "Cin->Cout", "algorithm", "fwd s",
                "fwd GF/s", "fwd+bwd s", "f+b GF/s", "util");
    std::vector<std::pair<int64_t, int64_t>> shapes;
    shapes.reserve(3 * channels.size() + 1);
    for (auto c : channels) shapes.emplace_back(c, c);
    if (thin) {
      for (auto c : channels) {
        shapes.emplace_back(1, c);
        shapes.emplace_back(c, 1);
      }
      shapes.emplace_back(1, 1);
    }
    for (auto [cin, cout] : shapes) {
      auto x = torch::rand({conv_batch, 5, cin, 5, 9, 9}).requires_grad_(true);  // u-major
      auto w = (torch::randn({cout, cin, 3, 3, 3, 3}) * 0.02).requires_grad_(true);
      auto b = torch::zeros({cout}).requires_grad_(true);
      const double flops = lfnet::nn::conv4d_flops(conv_batch, cin, cout, 5, 5, 9, 9, 3);
      for (auto algorithm : {Conv4dAlgorithm::kStacked, Conv4dAlgorithm::kFusedOutput,
                             Conv4dAlgorithm::kFusedInput, Conv4dAlgorithm::kAuto}) {
        if (!all_algorithms && algorithm != Conv4dAlgorithm::kAuto &&
            algorithm != Conv4dAlgorithm::kStacked) {
          continue;
        }
        const double fwd = best_time([&] {
          torch::NoGradGuard no_grad;
          lfnet::nn::conv4d_u_major(x, w, b, algorithm);
        });
        // Backward of a conv: input and weight gradients, twice the forward FLOPs.
        const double both =
            best_time([&] { lfnet::nn::conv4d_u_major(x, w, b, algorithm).sum().backward(); });
        std::printf("%3lld->%-3lld %-13s %10.3f %10.1f %12.3f %12.1f %6.2f\n",
                    static_cast<long long>(cin), static_cast<long long>(cout),
                    lfnet::nn::to_string(algorithm).c_str(), fwd, flops / fwd / 1e9, both,
                    3 * flops / both / 1e9, g_util);
        report["conv4d"].push_back({{"in_channels", cin},
                                    {"out_channels", cout},
                                    {"batch", conv_batch},
                                    {"algorithm", lfnet::nn::to_string(algorithm)},
                                    {"forward_s", fwd},
                                    {"forward_gflops", flops / fwd / 1e9},
                                    {"forward_backward_s", both},
                                    {"forward_backward_gflops", 3 * flops / both / 1e9},
                                    {"util", g_util}});
      }
    }
  }

  if (skip_train) {
    if (!json_path.empty()) std::ofstream(json_path) << report.dump(2) << "\n";
    return 0;
  }
  std::printf(
      "\nTraining steps (forward, weighted L2, backward, Adam), batch %lld, default sizes\n",
      static_cast<long long>(batch));
  std::printf("%-5s %12s %10s %12s %14s %6s\n", "net", "parameters", "step s", "patches/s",
              "CNN GF/s", "util");
  lfnet::nn::NetworkOptions options;
  auto phi = torch::randn({1, options.measurement_size(), options.patch.size()}) / 45.0;
  for (const std::string branches : {"ae", "cnn", "net"}) {
    options.set_branches(lfnet::nn::from_string(branches, lfnet::nn::Branches{}));
    lfnet::nn::LightFieldNet net(options);
    net->set_phi(phi);
    torch::optim::Adam adam(net->parameters(), torch::optim::AdamOptions(1e-3));
    lfnet::nn::ReconstructionLoss loss(lfnet::nn::LossOptions{}, 5, 5);
    auto y = torch::rand({batch, options.measurement_size()});
    auto target = torch::rand({batch, 1, 5, 5, 9, 9});
    auto step = [&] {
      adam.zero_grad();
      loss(net->forward(y), target).backward();
      adam.step();
    };
    const int64_t n = branches == "ae" ? 10 * steps : steps;
    const double per_step = best_time([&] {
                              for (int64_t i = 0; i < n; ++i) step();
                            }) /
                            static_cast<double>(n);
    const int64_t c = lfnet::nn::paper_options(options).cnn.channels;
    const double cnn_flops = branches == "ae"
                                 ? 0.0
                                 : 3 * (lfnet::nn::conv4d_flops(batch, 1, c, 5, 5, 9, 9, 3) +
                                        3 * lfnet::nn::conv4d_flops(batch, c, c, 5, 5, 9, 9, 3) +
                                        lfnet::nn::conv4d_flops(batch, c, 1, 5, 5, 9, 9, 3));
    std::printf("%-5s %12lld %10.4f %12.1f %14.1f %6.2f\n", branches.c_str(),
                static_cast<long long>(lfnet::nn::parameter_count(*net)), per_step,
                static_cast<double>(batch) / per_step, cnn_flops / per_step / 1e9, g_util);
    report["training"].push_back({{"branches", branches},
                                  {"batch", batch},
                                  {"parameters", lfnet::nn::parameter_count(*net)},
                                  {"step_s", per_step},
                                  {"patches_per_s", static_cast<double>(batch) / per_step},
                                  {"util", g_util}});

    if (branches == "net") {
      // Checkpoints of the default net after these steps: full (last.ckpt: model, Adam
      // moments, training state) and model-only (best.ckpt), with the dense Phi used above
      // (like random) and with a per-pixel Phi (like asp, mask, aperture: 1 non-zero in 81).
      auto per_pixel = torch::zeros({1, options.measurement_size(), options.patch.size()});
      const int64_t pixels = options.patch.pixels(), views = 25;
      for (int64_t k = 0; k < options.measurements; ++k) {
        for (int64_t v = 0; v < views; ++v) {
          auto rows = torch::arange(pixels) + k * pixels, cols = torch::arange(pixels) + v * pixels;
          per_pixel[0].index_put_({rows, cols}, torch::rand({pixels}) * (2.0 / views));
        }
      }
      for (const auto& [label, stack] :
           {std::pair<std::string, torch::Tensor>{"dense", phi}, {"per-pixel", per_pixel}}) {
        net->set_phi(stack);
        lfnet::train::Checkpoint ck;
        ck.network = options.to_json();
        ck.phi = {{"name", label}, {"n", options.measurements}};
        ck.model = lfnet::train::module_state(*net);
        ck.optimizer = lfnet::train::adam_state(adam, *net);
        const auto path = (std::filesystem::temp_directory_path() / "lfnet_bench.ckpt").string();
        auto t1 = Clock::now();
        lfnet::train::save_checkpoint(ck, path);
        const double save_s = seconds_since(t1);
        t1 = Clock::now();
        lfnet::train::load_checkpoint(path);
        const double load_s = seconds_since(t1);
        const auto full = std::filesystem::file_size(path);
        ck.optimizer.clear();
        lfnet::train::save_checkpoint(ck, path);
        const auto model_only = std::filesystem::file_size(path);
        std::filesystem::remove(path);
        std::printf(
            "checkpoint, %s Phi: full %.2f MB (save %.3f s, load %.3f s), model only "
            "%.2f MB\n",
            label.c_str(), static_cast<double>(full) / 1e6, save_s, load_s,
            static_cast<double>(model_only) / 1e6);
        report["checkpoint"].push_back(
            {{"phi", label}, {"full_bytes", full}, {"model_only_bytes", model_only}});
      }
    }
  }
  if (!json_path.empty()) {
    std::ofstream(json_path) << report.dump(2) << "\n";
  }
  return 0;
}

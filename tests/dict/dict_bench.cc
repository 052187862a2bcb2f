// Timings of the dictionary baseline: K-SVD iterations and per-patch sparse coding.
//
//   dict_bench [--threads 2] [--atoms 1000] [--sparsity 10] [--train 20000]
//              [--ksvd-iterations 3] [--patches 1000] [--measurements 162]
//              [--data DIR | --synthetic] [--save FILE] [--json FILE]
//
// Training patches are 5 x 5 x 9 x 9 grey patches sampled from the light fields in DIR
// (default ../shared/data when present, else procedural ones); test patches are drawn with
// another seed. The patch matrix is Gaussian with `measurements` rows (162 = 81 x 2, N = 2).
// No timing here is asserted anywhere; this program only reports.
#include <torch/torch.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/dict/patch_sampling.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/io/light_field_io.h"

namespace {

struct Args {
  int threads = 2;
  int64_t atoms = 1000, sparsity = 10, train = 20000, ksvd_iterations = 3, patches = 1000;
  int64_t measurements = 162;
  std::string data, save, json;
  bool synthetic = false;
};

Args parse(int argc, char** argv) {
  Args a;
  const std::filesystem::path shared =
      std::filesystem::path(LFNET_SOURCE_DIR) / ".." / "shared" / "data";
  if (std::filesystem::is_directory(shared)) a.data = shared.string();
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(k + " needs a value");
      return argv[++i];
    };
    if (k == "--threads")
      a.threads = std::stoi(next());
    else if (k == "--atoms")
      a.atoms = std::stoll(next());
    else if (k == "--sparsity")
      a.sparsity = std::stoll(next());
    else if (k == "--train")
      a.train = std::stoll(next());
    else if (k == "--ksvd-iterations")
      a.ksvd_iterations = std::stoll(next());
    else if (k == "--patches")
      a.patches = std::stoll(next());
    else if (k == "--measurements")
      a.measurements = std::stoll(next());
    else if (k == "--data")
      a.data = next();
    else if (k == "--synthetic")
      a.synthetic = true;
    else if (k == "--save")
      a.save = next();
    else if (k == "--json")
      a.json = next();
    else
      throw std::runtime_error("unknown argument " + k + " (see the header of dict_bench.cc)");
  }
  return a;
}

// Light fields with parallax for when no data is at hand: shifted smooth noise per view.
std::vector<lfnet::LightField> synthetic_light_fields() {
  std::vector<lfnet::LightField> out;
  torch::manual_seed(1);
  for (int s = 0; s < 3; ++s) {
    auto base = torch::rand({1, 1, 80, 80});
    base = torch::nn::functional::interpolate(base, torch::nn::functional::InterpolateFuncOptions()
                                                        .size(std::vector<int64_t>{240, 240})
                                                        .mode(torch::kBilinear)
                                                        .align_corners(false));
    auto lf = torch::empty({1, 5, 5, 200, 200});
    const double disparity = 0.5 * (s + 1);
    for (int u = 0; u < 5; ++u) {
      for (int v = 0; v < 5; ++v) {
        const auto dy = static_cast<int64_t>(std::lround(20 + disparity * (u - 2)));
        const auto dx = static_cast<int64_t>(std::lround(20 + disparity * (v - 2)));
        lf[0][u][v].copy_(base[0][0].narrow(0, dy, 200).narrow(1, dx, 200));
      }
    }
    out.emplace_back(lf);
  }
  return out;
}

std::vector<lfnet::LightField> load(const Args& a, std::vector<std::string>& names) {
  if (a.synthetic || a.data.empty()) {
    names = {"synthetic"};
    return synthetic_light_fields();
  }
  std::vector<lfnet::LightField> out;
  for (const auto& e : std::filesystem::directory_iterator(a.data)) {
    if (!e.is_directory()) continue;
    out.push_back(lfnet::io::read_light_field(e.path().string()).grey());
    names.push_back(e.path().filename().string());
  }
  if (out.empty()) throw std::runtime_error("no light-field folders in " + a.data);
  return out;
}

double psnr(const torch::Tensor& est, const torch::Tensor& truth) {
  const double mse =
      (est.to(torch::kFloat64) - truth.to(torch::kFloat64)).pow(2).mean().item<double>();
  return 10.0 * std::log10(1.0 / mse);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Args a = parse(argc, argv);
    lfnet::set_progress_enabled(false);
    const int threads = lfnet::configure_threads(a.threads);
    std::vector<std::string> names;
    const auto lfs = load(a, names);
    nlohmann::json report = {{"threads", threads},
                             {"atoms", a.atoms},
                             {"sparsity", a.sparsity},
                             {"measurements", a.measurements},
                             {"data", names}};

    lfnet::dict::PatchSamplingOptions sampling;
    sampling.count = a.train;
    sampling.seed = 1;
    lfnet::dict::PatchSamplingStats stats;
    lfnet::Stopwatch watch;
    auto train = lfnet::dict::sample_patches(lfs, sampling, &stats);
    std::printf("sampled %lld training patches (%lld dropped as flat) in %.2f s\n",
                static_cast<long long>(a.train), static_cast<long long>(stats.dropped),
                watch.seconds());

    lfnet::dict::KsvdOptions ko;
    ko.atoms = a.atoms;
    ko.sparsity = a.sparsity;
    ko.iterations = a.ksvd_iterations;
    std::vector<double> seconds;
    auto learned = lfnet::dict::ksvd(train, ko, [&](const lfnet::dict::KsvdIteration& it) {
      std::printf("K-SVD iteration %lld: %.2f s, coding RMSE %.5f -> %.5f, replaced %lld\n",
                  static_cast<long long>(it.iteration), it.seconds, it.coding_rmse, it.updated_rmse,
                  static_cast<long long>(it.replaced));
      std::fflush(stdout);
      seconds.push_back(it.seconds);
      return true;
    });
    double mean_s = 0;
    for (double s : seconds) mean_s += s / static_cast<double>(seconds.size());
    std::printf("K-SVD: %.2f s per iteration (%lld patches, K = %lld, sparsity %lld)\n", mean_s,
                static_cast<long long>(a.train), static_cast<long long>(a.atoms),
                static_cast<long long>(a.sparsity));
    report["ksvd_seconds_per_iteration"] = mean_s;
    report["ksvd_training_patches"] = a.train;
    nlohmann::json history = nlohmann::json::array();
    for (const auto& it : learned.history) history.push_back(it.to_json());
    report["ksvd_history"] = history;

    if (!a.save.empty()) {
      lfnet::dict::Dictionary d;
      d.atoms = learned.dictionary.to(torch::kFloat32);
      d.training = {{"ksvd", ko.to_json()},
                    {"sampling", sampling.to_json()},
                    {"sources", names},
                    {"history", history}};
      lfnet::dict::save_dictionary(d, a.save);
      std::printf("saved %s\n", a.save.c_str());
    }

    sampling.count = a.patches;
    sampling.seed = 2;
    auto test = lfnet::dict::sample_patches(lfs, sampling).to(torch::kFloat64);
    torch::manual_seed(3);
    auto phi = torch::randn({a.measurements, test.size(1)}, torch::kFloat64) /
               std::sqrt(static_cast<double>(a.measurements));
    auto y = test.mm(phi.t());
    for (const std::string method : {"omp", "admm"}) {
      lfnet::dict::SparseCodingOptions so;
      so.method = lfnet::dict::from_string(method, so.method);
      so.omp.max_atoms = a.sparsity;
      lfnet::dict::SparseCoder coder(learned.dictionary, so);
      watch.reset();
      auto op = coder.prepare(phi);
      const double prep = watch.seconds();
      watch.reset();
      auto r = coder.code(*op, y);
      const double code = watch.seconds();
      const double per_1000 = code * 1000.0 / static_cast<double>(a.patches);
      const double iters = r.iterations.to(torch::kFloat64).mean().item<double>();
      std::printf(
          "%s: factorisation %.3f s; coding %.3f s per 1000 patches (%.0f patches/s), "
          "mean iterations %.1f, unconverged %lld, patch PSNR %.2f dB\n",
          method.c_str(), prep, per_1000, 1000.0 / per_1000, iters,
          static_cast<long long>(r.unconverged()), psnr(r.patches, test));
      report[method] = {{"factorisation_seconds", prep},
                        {"seconds_per_1000_patches", per_1000},
                        {"mean_iterations", iters},
                        {"unconverged", r.unconverged()},
                        {"patch_psnr_db", psnr(r.patches, test)}};
    }
    if (!a.json.empty()) {
      std::ofstream out(a.json);
      out << report.dump(2) << "\n";
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "dict_bench: error: %s\n", e.what());
    return 1;
  }
}

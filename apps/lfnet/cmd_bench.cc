// lfnet bench: how fast this machine runs lfnet (docs/performance.md). One run measures LibTorch's
// GEMM FLOP/s, Conv4d FLOP/s at the default channel counts, and whole-light-field reconstruction
// of a procedural 593 x 840 x 5 x 5 light field (the paper's test size) for each method and
// stride. Each reconstruction runs in a child process of its own, so its peak resident memory is
// its own and not the high-water mark of the cases before it.
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <torch/torch.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/metrics.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/dict/patch_sampling.h"
#include "lfnet/optics/measure.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/train/checkpoint.h"

namespace lfnet::app {

namespace {

// The paper's times on a Titan X (Table 3, ASP, dragons scene, 593 x 840 x 5 x 5).
constexpr double kPaperNetSeconds = 242.0;
constexpr double kPaperDictSeconds = 3786.0;
constexpr const char* kCaseTag = "LFNET_BENCH_CASE ";

struct BenchArgs {
  std::string json;  // write the report here ("-": standard output)
  std::vector<std::string> methods = {"net", "ae", "cnn", "dict", "pinv"};
  std::vector<int64_t> strides = {9, 5, 2};
  int64_t height = 593, width = 840;
  std::string phi = "asp:2";
  int64_t batch = 1024;
  std::string model;            // trained checkpoint; default an untrained net of the default shape
  std::string dictionary;       // dictionary file; default a small K-SVD dictionary
  std::string save_dictionary;  // write the bench's K-SVD dictionary here
  std::string scene;            // scene spec file; default random_scene(seed) at height x width
  int64_t dict_atoms = 1000;
  uint64_t seed = 7;
  int64_t conv_batch = 256;
  int reps = 3;
  bool in_process = false;
  bool skip_kernels = false;
  std::string device = "cpu";
  std::string cnn_mode = "patches";  // patches or full (recon::CnnMode)
  int64_t tile = recon::kDefaultCnnTile;
  std::string precision = "float32";  // float32 or bfloat16 (the CNN branch's convolutions)
  // Child mode: one case "method:stride", with the parent's GEMM figure.
  std::string one_case;
  double gemm = 0;
};

// CPU seconds of this process so far: (user, system).
std::pair<double, double> cpu_seconds() {
  rusage r{};
  getrusage(RUSAGE_SELF, &r);
  return {r.ru_utime.tv_sec + 1e-6 * r.ru_utime.tv_usec,
          r.ru_stime.tv_sec + 1e-6 * r.ru_stime.tv_usec};
}

// A field of /proc/self/status in MB (VmRSS, VmHWM); -1 where it cannot be read.
double status_mb(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(field + ":", 0) == 0) {
      std::istringstream s(line.substr(field.size() + 1));
      double kb = -1;
      s >> kb;
      return kb / 1024.0;
    }
  }
  return -1;
}

// Resets the peak resident size (VmHWM) to the current one; false where the kernel refuses.
bool reset_peak_rss() {
  std::ofstream out("/proc/self/clear_refs");
  if (!out) return false;
  out << "5";
  out.flush();
  return static_cast<bool>(out);
}

// Best wall time of `reps` runs after one warm-up run.
template <typename Fn>
double best_seconds(int reps, Fn&& fn) {
  fn();
  double best = 1e30;
  for (int i = 0; i < reps; ++i) {
    Stopwatch clock;
    fn();
    best = std::min(best, clock.seconds());
  }
  return best;
}

double gemm_flops(int reps, const torch::Device& device) {
  const int64_t n = 2048;
  auto a = torch::randn({n, n}, torch::TensorOptions().device(device));
  auto b = torch::randn({n, n}, torch::TensorOptions().device(device));
  const double t = best_seconds(reps, [&] {
    auto c = a.matmul(b);
    if (device.is_cuda()) c.cpu();
  });
  return 2.0 * n * n * n / t;
}

LightField bench_light_field(const BenchArgs& a) {
  if (!a.scene.empty()) {
    return scene::render_scene(scene::load_scene(a.scene), pipeline::scene_render_options(a.scene))
        .light_field.grey()
        .central(5);
  }
  scene::RandomSceneOptions so;
  so.height = a.height;
  so.width = a.width;
  so.color = false;
  return scene::render_scene(scene::random_scene(a.seed, so)).light_field.grey();
}

dict::Dictionary bench_dictionary(const BenchArgs& a, int64_t patch) {
  if (!a.dictionary.empty()) return dict::load_dictionary(a.dictionary);
  // Trained on another scene than the one reconstructed; few signals and iterations, since
  // OMP's cost depends on the dictionary's size and the atoms per patch, not on its training.
  scene::RandomSceneOptions so;
  so.height = 256;
  so.width = 256;
  so.color = false;
  std::vector<LightField> lfs{
      scene::render_scene(scene::random_scene(a.seed + 1000, so)).light_field.grey()};
  dict::PatchSamplingOptions sampling;
  sampling.count = 3 * a.dict_atoms;
  sampling.patch_size = patch;
  auto signals = dict::sample_patches(lfs, sampling);
  dict::KsvdOptions ko;
  ko.atoms = a.dict_atoms;
  ko.iterations = 3;
  dict::Dictionary d;
  d.atoms = dict::ksvd(signals, ko).dictionary.to(torch::kFloat32);
  d.patch_shape = {5, 5, patch, patch};
  d.training = {{"bench", true}, {"ksvd", ko.to_json()}, {"signals", signals.size(0)}};
  if (!a.save_dictionary.empty()) dict::save_dictionary(d, a.save_dictionary);
  return d;
}

// One case in this process: reconstructs the bench light field with `method` at `stride`.
nlohmann::json run_case(const BenchArgs& a, const std::string& method, int64_t stride) {
  const torch::Device device = parse_device(a.device);
  Stopwatch setup_clock;
  nn::LightFieldNet net{nullptr};
  optics::PhiSpec spec = optics::PhiSpec::parse(a.phi);
  nlohmann::json model_info = "untrained default network";
  if (recon::needs_network(method)) {
    if (!a.model.empty()) {
      const auto ckpt = train::load_checkpoint(a.model);
      spec = optics::PhiSpec::from_json(ckpt.phi, a.model + ":phi");
      net = train::build_net(ckpt, a.model);
      model_info = a.model;
    } else {
      nn::NetworkOptions no;
      no.measurements = spec.n;
      torch::manual_seed(0);
      net = nn::LightFieldNet(no);
    }
  }
  const auto phi = optics::make_phi(spec);
  if (net && a.model.empty()) {
    net->set_phi(
        optics::patch_matrix_stack(*phi, net->options().patch.height, net->options().patch.width));
  }
  const int64_t patch = net ? net->options().patch.height : 9;
  recon::ReconstructOptions o;
  o.patch_h = o.patch_w = patch;
  o.stride = stride;
  o.batch = a.batch;
  o.validate();
  const LightField truth = bench_light_field(a);
  const auto sensor = optics::simulate_sensor(*phi, truth.data()[0]);

  const auto cnn_mode = recon::parse_cnn_mode(a.cnn_mode);
  const bool full = cnn_mode == recon::CnnMode::kFull && (method == "net" || method == "cnn");
  nlohmann::json extra = nlohmann::json::object();
  recon::MethodResources resources;
  resources.phi = phi.get();
  resources.patch_h = resources.patch_w = patch;
  dict::Dictionary dictionary;
  if (net) {
    net->to(device);
    nn::set_cnn_precision(net, nn::parse_precision(a.precision));
    resources.net = net;
    extra["model"] = model_info;
    extra["cnn_mode"] = full ? "full" : "patches";
    extra["precision"] = a.precision;
    if (full) extra["tile"] = a.tile;
  } else if (recon::find_method(method).needs() == recon::MethodNeeds::kDictionary) {
    dictionary = bench_dictionary(a, patch);
    resources.dictionary = &dictionary;
    extra["dictionary_atoms"] = dictionary.size();
    extra["dictionary"] = a.dictionary.empty() ? "bench K-SVD (3 iterations)" : a.dictionary;
    extra["omp_atoms"] = resources.coding.omp.max_atoms;
  }
  const recon::PatchSolver solver = recon::make_solver(method, resources);
  const double flops_per_patch = recon::find_method(method).patch_flops(resources);
  const double setup_seconds = setup_clock.seconds();
  const double setup_peak = status_mb("VmHWM");
  const bool isolated_peak = reset_peak_rss();
  const double rss_before = status_mb("VmRSS");
  const auto cpu0 = cpu_seconds();
  Stopwatch clock;
  auto est =
      full ? recon::reconstruct_sensor_fully_convolutional(net, method, *phi, sensor, o, a.tile)
           : recon::reconstruct_sensor(*phi, sensor, solver, o);
  const double seconds = clock.seconds();
  const auto cpu1 = cpu_seconds();
  const double user = cpu1.first - cpu0.first, system = cpu1.second - cpu0.second;
  const double cpu = user + system;
  const double peak = status_mb("VmHWM");
  const PatchGrid grid(truth.height(), truth.width(), patch, patch, stride);
  // Patch stitching computes flops_per_patch for every patch; the fully convolutional pass
  // computes the CNN once per tile position instead.
  double flops = flops_per_patch * static_cast<double>(grid.size());
  if (full) {
    flops += nn::cnn_full_flops(net->options(), truth.height(), truth.width(), a.tile) -
             nn::cnn_patch_flops(net->options()) * static_cast<double>(grid.size());
  }
  nlohmann::json r = {{"method", method},
                      {"stride", stride},
                      {"patches", grid.size()},
                      {"seconds", seconds},
                      {"patches_per_second", grid.size() / seconds},
                      {"cpu_utilisation", cpu / seconds / thread_count()},
                      {"cpu_user_seconds", user},
                      {"cpu_system_seconds", system},
                      {"batch", a.batch},
                      {"peak_rss_mb", peak},
                      {"rss_before_mb", rss_before},
                      {"peak_is_reconstruction_only", isolated_peak},
                      {"setup_peak_rss_mb", setup_peak},
                      {"setup_seconds", setup_seconds},
                      {"flops_per_patch", flops_per_patch},
                      {"gflops", flops / seconds / 1e9},
                      {"gemm_fraction", a.gemm > 0 ? flops / seconds / a.gemm : 0.0},
                      {"psnr_db", psnr(LightField(est), truth)},
                      {"phi", spec.label()},
                      {"device", a.device}};
  if (method == "net") r["paper_ratio"] = kPaperNetSeconds / seconds;
  if (method == "dict") r["paper_ratio"] = kPaperDictSeconds / seconds;
  r.update(extra);
  return r;
}

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'')
      out += "'\\''";
    else
      out += c;
  }
  return out + "'";
}

std::string join(const std::vector<std::string>& items, const std::string& sep) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) out += (i ? sep : "") + items[i];
  return out;
}

// Runs one case in a child process of this program and reads back its JSON line.
nlohmann::json run_child(const BenchArgs& a, const std::string& method, int64_t stride) {
  char exe[4096];
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  LFNET_CHECK_AS(IoError, n > 0, "bench: cannot find this program's path (/proc/self/exe)");
  exe[n] = '\0';
  std::vector<std::string> args = {shell_quote(exe),
                                   "--threads",
                                   std::to_string(thread_count()),
                                   "--log-level",
                                   "warn",
                                   "bench",
                                   "--case",
                                   shell_quote(method + ":" + std::to_string(stride)),
                                   "--gemm",
                                   std::to_string(a.gemm),
                                   "--height",
                                   std::to_string(a.height),
                                   "--width",
                                   std::to_string(a.width),
                                   "--phi",
                                   shell_quote(a.phi),
                                   "--batch",
                                   std::to_string(a.batch),
                                   "--seed",
                                   std::to_string(a.seed),
                                   "--dict-atoms",
                                   std::to_string(a.dict_atoms),
                                   "--device",
                                   shell_quote(a.device),
                                   "--cnn-mode",
                                   shell_quote(a.cnn_mode),
                                   "--tile",
                                   std::to_string(a.tile),
                                   "--precision",
                                   shell_quote(a.precision)};
  if (!a.model.empty()) args.insert(args.end(), {"--model", shell_quote(a.model)});
  if (!a.dictionary.empty()) args.insert(args.end(), {"--dictionary", shell_quote(a.dictionary)});
  if (!a.save_dictionary.empty()) {
    args.insert(args.end(), {"--save-dictionary", shell_quote(a.save_dictionary)});
  }
  if (!a.scene.empty()) args.insert(args.end(), {"--scene", shell_quote(a.scene)});
  FILE* pipe = popen(join(args, " ").c_str(), "r");
  LFNET_CHECK_AS(IoError, pipe, "bench: cannot start a child process");
  std::string output;
  char buffer[4096];
  while (size_t got = std::fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, got);
  const int status = pclose(pipe);
  const auto at = output.find(kCaseTag);
  if (status != 0 || at == std::string::npos) {
    return {{"method", method},
            {"stride", stride},
            {"error", "the child process failed (status " + std::to_string(status) + ")"}};
  }
  const auto end = output.find('\n', at);
  return nlohmann::json::parse(
      output.substr(at + std::string(kCaseTag).size(),
                    end == std::string::npos ? end : end - at - std::string(kCaseTag).size()));
}

// GFLOP/s of the Conv4d layers of the default CNN branch and of the whole branch, forward, in
// inference mode, on `batch` patches.
nlohmann::json conv_kernels(const BenchArgs& a, const torch::Device& device) {
  torch::InferenceMode guard;
  nn::NetworkOptions o;
  const auto& p = o.patch;
  const int64_t c = o.cnn.channels, b = a.conv_batch;
  nlohmann::json out = nlohmann::json::array();
  auto run = [&](const std::string& name, int64_t cin, int64_t cout) {
    auto w = torch::randn({cout, cin, 3, 3, 3, 3}, torch::TensorOptions().device(device)) * 0.1;
    auto bias = torch::zeros({cout}, torch::TensorOptions().device(device));
    auto x = torch::rand({b, p.rows, cin, p.cols, p.height, p.width},
                         torch::TensorOptions().device(device));
    const double t = best_seconds(a.reps, [&] {
      auto y = nn::conv4d_u_major(x, w, bias);
      if (device.is_cuda()) y.cpu();
    });
    const double f = nn::conv4d_flops(b, cin, cout, p.rows, p.cols, p.height, p.width, 3);
    out.push_back({{"layer", name},
                   {"batch", b},
                   {"seconds", t},
                   {"gflops", f / t / 1e9},
                   {"gemm_fraction", f / t / a.gemm}});
  };
  run("1->" + std::to_string(c), 1, c);
  run(std::to_string(c) + "->" + std::to_string(c), c, c);
  run(std::to_string(c) + "->1", c, 1);
  nn::CnnBranch cnn(o);
  cnn->eval();
  cnn->to(device);
  auto x =
      torch::rand({b, 1, p.rows, p.cols, p.height, p.width}, torch::TensorOptions().device(device));
  const double t = best_seconds(a.reps, [&] {
    auto y = cnn->forward(x);
    if (device.is_cuda()) y.cpu();
  });
  const double f = b * nn::cnn_patch_flops(o);
  out.push_back({{"layer", "cnn branch (" + std::to_string(o.cnn.depth) + " layers)"},
                 {"batch", b},
                 {"seconds", t},
                 {"gflops", f / t / 1e9},
                 {"gemm_fraction", f / t / a.gemm},
                 {"patches_per_second", b / t}});
  return out;
}

std::string machine_name() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  }
  return "unknown";
}

double load_average() {
  double load[1] = {-1};
  if (getloadavg(load, 1) < 1) return -1;
  return load[0];
}

void print_table(const nlohmann::json& report) {
  std::printf("\n%-6s %-6s %8s %10s %12s %9s %8s %9s %6s %8s\n", "method", "stride", "patches",
              "seconds", "patches/s", "peak MB", "GFLOP/s", "% GEMM", "util", "PSNR dB");
  for (const auto& r : report["cases"]) {
    if (r.contains("error")) {
      std::printf("%-6s %-6lld  %s\n", r["method"].get<std::string>().c_str(),
                  static_cast<long long>(r["stride"].get<int64_t>()),
                  r["error"].get<std::string>().c_str());
      continue;
    }
    std::printf("%-6s %-6lld %8lld %10.2f %12.1f %9.0f %8.1f %8.1f%% %6.2f %8.2f\n",
                r["method"].get<std::string>().c_str(),
                static_cast<long long>(r["stride"].get<int64_t>()),
                static_cast<long long>(r["patches"].get<int64_t>()), r["seconds"].get<double>(),
                r["patches_per_second"].get<double>(), r["peak_rss_mb"].get<double>(),
                r["gflops"].get<double>(), 100 * r["gemm_fraction"].get<double>(),
                r["cpu_utilisation"].get<double>(), r["psnr_db"].get<double>());
  }
}

void run_bench(BenchArgs a) {
  if (!a.json.empty() && a.json != "-" && a.one_case.empty()) {
    // The report is rewritten on each run; it may not be one of the files the bench reads.
    OutputFolderPolicy policy;
    policy.option = "--json";
    policy.force = true;
    policy.inputs = {a.model, a.dictionary, a.scene};
    check_output_file(a.json, policy);
  }
  if (!a.one_case.empty()) {
    const auto colon = a.one_case.find(':');
    LFNET_CHECK_AS(ConfigError, colon != std::string::npos, "--case takes method:stride, got '",
                   a.one_case, "'");
    const auto r =
        run_case(a, a.one_case.substr(0, colon), std::stoll(a.one_case.substr(colon + 1)));
    std::printf("%s%s\n", kCaseTag, r.dump().c_str());
    return;
  }
  const torch::Device device = parse_device(a.device);
  nlohmann::json report;
  report["machine"] = {{"cpu", machine_name()},
                       {"hardware_threads", static_cast<int64_t>(sysconf(_SC_NPROCESSORS_ONLN))},
                       {"threads", thread_count()},
                       {"device", a.device},
                       {"load_average_1min_start", load_average()}};
  report["light_field"] = {{"height", a.height}, {"width", a.width}, {"views", "5x5"},
                           {"seed", a.seed},     {"channels", 1},    {"phi", a.phi}};
  if (!a.scene.empty())
    report["light_field"] = {{"scene", a.scene}, {"channels", 1}, {"phi", a.phi}};
  std::printf("lfnet bench: %s, %d threads, device %s, load %.2f\n", machine_name().c_str(),
              thread_count(), a.device.c_str(), load_average());
  a.gemm = gemm_flops(a.reps, device);
  report["gemm_gflops"] = a.gemm / 1e9;
  std::printf("GEMM (2048^3 sgemm): %.1f GFLOP/s\n", a.gemm / 1e9);
  if (!a.skip_kernels) {
    report["conv4d"] = conv_kernels(a, device);
    for (const auto& k : report["conv4d"]) {
      std::printf("Conv4d %-22s batch %lld: %.4f s, %.1f GFLOP/s (%.0f%% of GEMM)\n",
                  k["layer"].get<std::string>().c_str(),
                  static_cast<long long>(k["batch"].get<int64_t>()), k["seconds"].get<double>(),
                  k["gflops"].get<double>(), 100 * k["gemm_fraction"].get<double>());
    }
  }
  report["cases"] = nlohmann::json::array();
  for (int64_t stride : a.strides) {
    for (const auto& method : a.methods) {
      auto r = a.in_process ? run_case(a, method, stride) : run_child(a, method, stride);
      if (!r.contains("error")) {
        std::printf("%-4s stride %lld: %.2f s, %.0f patches/s, peak %.0f MB, PSNR %.2f dB\n",
                    method.c_str(), static_cast<long long>(stride), r["seconds"].get<double>(),
                    r["patches_per_second"].get<double>(), r["peak_rss_mb"].get<double>(),
                    r["psnr_db"].get<double>());
      } else {
        std::printf("%-4s stride %lld: %s\n", method.c_str(), static_cast<long long>(stride),
                    r["error"].get<std::string>().c_str());
      }
      std::fflush(stdout);
      report["cases"].push_back(r);
    }
  }
  report["machine"]["load_average_1min_end"] = load_average();
  report["paper_seconds"] = {{"net", kPaperNetSeconds}, {"dict", kPaperDictSeconds}};
  print_table(report);
  if (!a.json.empty()) {
    if (a.json == "-") {
      std::printf("%s\n", report.dump(2).c_str());
    } else {
      write_json_file(a.json, report);
      std::printf("wrote %s\n", a.json.c_str());
    }
  }
}

}  // namespace

void add_bench_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "bench", "Measure GEMM and Conv4d FLOP/s and whole-light-field reconstruction speed");
  auto a = std::make_shared<BenchArgs>();
  cmd->add_option("--json", a->json, "also write the report as JSON to this file ('-': stdout)");
  cmd->add_option("--methods", a->methods, "methods to time (net, ae, cnn, dict, pinv, adjoint)")
      ->delimiter(',');
  cmd->add_option("--strides", a->strides, "patch strides (9: non-overlapping 9x9 patches)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  cmd->add_option("--height", a->height, "light-field height (default 593)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--width", a->width, "light-field width (default 840)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--phi", a->phi, "measurement model name[:N] (default asp:2)");
  cmd->add_option("--batch", a->batch, "patches per solver call (default 1024)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--model", a->model,
                  "trained checkpoint (default: an untrained default network)");
  cmd->add_option("--dictionary", a->dictionary,
                  "dictionary file (default: a small K-SVD dictionary)");
  cmd->add_option("--save-dictionary", a->save_dictionary,
                  "write the bench's K-SVD dictionary to this file");
  cmd->add_option("--scene", a->scene,
                  "scene spec to render instead of a random scene (its own size)");
  cmd->add_option("--dict-atoms", a->dict_atoms, "atoms of the bench dictionary (default 1000)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--seed", a->seed, "seed of the procedural scene (default 7)");
  cmd->add_option("--conv-batch", a->conv_batch, "patches per Conv4d timing (default 256)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--reps", a->reps, "repetitions of the kernel timings (best is kept)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--device", a->device, "cpu or cuda (default cpu)");
  cmd->add_option(
         "--cnn-mode", a->cnn_mode,
         "CNN branch per patch ('patches', the default) or once over the light field ('full')")
      ->check(CLI::IsMember({"patches", "full"}));
  cmd->add_option("--tile", a->tile, "tile size of --cnn-mode full (default 128)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--precision", a->precision,
                  "float32 or bfloat16 for the CNN branch's convolutions")
      ->check(CLI::IsMember({"float32", "bfloat16"}));
  cmd->add_flag("--in-process", a->in_process,
                "run every case in this process (peak memory is then a running maximum)");
  cmd->add_flag("--skip-kernels", a->skip_kernels, "skip the Conv4d timings");
  cmd->add_option("--case", a->one_case,
                  "run one case method:stride and print it as JSON (used by the parent run)")
      ->group("");
  cmd->add_option("--gemm", a->gemm, "GEMM FLOP/s measured by the parent run")->group("");
  cmd->callback([a] { run_bench(*a); });
}

}  // namespace lfnet::app

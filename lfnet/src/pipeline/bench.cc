#include "lfnet/pipeline/bench.h"

#include <sys/resource.h>
#include <torch/torch.h>
#include <unistd.h>
#include <filesystem>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/machine.h"
#include "lfnet/core/metrics.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/text.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/dict/patch_sampling.h"
#include "lfnet/nn/auto_precision.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"
#include "lfnet/recon/reconstruct.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"

namespace lfnet::pipeline {

namespace {

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

}  // namespace

double bench_gemm_flops(int reps, const torch::Device& device) {
  const int64_t n = 2048;
  auto a = torch::randn({n, n}, torch::TensorOptions().device(device));
  auto b = torch::randn({n, n}, torch::TensorOptions().device(device));
  const double t = best_seconds(reps, [&] {
    auto c = a.matmul(b);
    if (device.is_cuda()) c.cpu();
  });
  return 2.0 * n * n * n / t;
}

// A random scene's layers' largest speed, px per sub-frame, for a time-coded camera.
constexpr double kBenchSpeed = 2.0;

LightField bench_light_field(const BenchOptions& a, int64_t frames) {
  if (!a.scene.empty()) {
    const auto spec = scene::load_scene(a.scene);
    if (frames > 1) {
      return scene::render_sequence(spec, frames, scene_render_options(a.scene))
          .light_fields.grey()
          .central(5)
          .stacked();
    }
    return scene::render_scene(spec, scene_render_options(a.scene)).light_field.grey().central(5);
  }
  scene::RandomSceneOptions so;
  so.height = a.height;
  so.width = a.width;
  so.color = false;
  if (frames > 1) {
    so.max_speed = kBenchSpeed;
    return scene::render_sequence(scene::random_scene(a.seed, so), frames)
        .light_fields.grey()
        .stacked();
  }
  return scene::render_scene(scene::random_scene(a.seed, so)).light_field.grey();
}

dict::Dictionary bench_dictionary(const BenchOptions& a, int64_t patch) {
  if (!a.dictionary.empty()) {
    ModelCache files;  // refuses a network given as the dictionary, with the fix
    return files.dictionary(a.dictionary);
  }
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

namespace {

// One case of lfnet bench, as steps: the network (a model's, or an untrained one of an
// architecture), the method prepared on the bench light field's sensor image, then one timed
// reconstruction measured in seconds, CPU, memory and operations.
class BenchCase {
 public:
  BenchCase(const BenchOptions& options, const std::string& method, int64_t stride, double gemm)
      : a_(options),
        method_(method),
        stride_(stride),
        gemm_(gemm),
        spec_(phi_from_argument(options.phi)),
        full_(options.cnn_mode == recon::CnnMode::kFull && (method == "net" || method == "cnn")),
        cnn_tile_(options.tile > 0 ? options.tile : recon::kDefaultCnnTile),
        image_tile_(options.tile > 0 ? options.tile : recon::kDefaultImageTile) {}

  nlohmann::json run() {
    const torch::Device device = parse_device(a_.device);
    Stopwatch setup_clock;
    if (recon::needs_network(method_)) read_network();
    has_net_ = net_ || script_;
    phi_ = optics::make_phi(spec_);
    if (net_ && a_.models.empty()) net_->set_phi(phi_tensor(*phi_, net_->options()));
    // The patch grid of patch methods (a whole-image net's crop is no patch).
    const auto net_grid = has_net_ ? network_.patch_grid() : std::nullopt;
    patch_ = net_grid ? net_grid->height : 9;
    o_.patch_h = o_.patch_w = patch_;
    o_.stride = stride_;
    o_.batch = a_.batch;
    o_.validate();
    truth_ = bench_light_field(a_, spec_.frames);
    if (spec_.frames > 1) {
      extra_["frames"] = spec_.frames;
      if (a_.scene.empty()) extra_["max_speed_px_per_frame"] = kBenchSpeed;
    }
    sensor_ = optics::simulate_sensor(*phi_, truth_.data()[0]);
    prepare(device);
    setup_seconds_ = setup_clock.seconds();
    return measure();
  }

 private:
  // A checkpoint's or an exported network, or an untrained one of --architecture.
  void read_network() {
    const std::string model = a_.models.empty() ? "" : a_.models.front();
    if (!model.empty()) {
      const auto file = load_model(model, true);
      spec_ = optics::PhiSpec::from_json(file.phi, model + ":$.phi");
      place_network(file, a_.device, a_.precision);
      LFNET_CHECK_AS(ConfigError, file.net || a_.cnn_mode != recon::CnnMode::kFull,
                     "--cnn-mode full applies to checkpoints; ", model,
                     " is an exported TorchScript file");
      net_ = file.net;
      script_ = file.script;
      network_ = file.network;
      model_info_ = model;
      return;
    }
    network_.measurements = spec_.n;
    network_.architecture =
        a_.architectures.empty() ? nn::kPaperArchitecture : a_.architectures.front();
    if (!network_.patch_grid()) {  // a whole-image architecture
      model_info_ = "untrained " + network_.architecture + " network";
      // A training crop the architecture takes (sides multiples of its tiling's multiple).
      network_.patch.height = network_.patch.width =
          12 * network_.arch().image_tiling(network_).multiple;
    }
    torch::manual_seed(0);
    net_ = nn::LightFieldNet(network_);
  }

  // The method's context: the net on its device, or the dictionary; its options.
  void prepare(const torch::Device& device) {
    MethodContext context;
    context.phi = phi_.get();
    // This method's options (the whole run's were checked by bench_report).
    const auto all_options = a_.method_options.empty()
                                 ? nlohmann::json::object()
                                 : read_json_argument(a_.method_options, "--method-options");
    if (all_options.is_object() && all_options.contains(method_)) {
      context.method_options = {{method_, all_options[method_]}};
    }
    if (has_net_) {
      if (net_) {
        net_->to(device);
        nn::set_cnn_precision(net_, a_.precision);
      }
      context.net = net_;
      context.script = script_;
      extra_["model"] = model_info_;
      extra_["architecture"] = network_.architecture;
      extra_["cnn_mode"] = full_ ? "full" : "patches";
      extra_["precision"] = nn::to_string(a_.precision);
      if (full_) extra_["tile"] = cnn_tile_;
    } else if (recon::find_method(method_).needs() == recon::MethodNeeds::kDictionary) {
      dictionary_ = bench_dictionary(a_, patch_);
      context.dictionary_data = &dictionary_;
      extra_["dictionary_atoms"] = dictionary_.size();
      extra_["dictionary"] = a_.dictionary.empty() ? "bench K-SVD (3 iterations)" : a_.dictionary;
    }
    context.tile = image_tile_;
    if (a_.self_ensemble && has_net_ && recon::whole_image_model(net_, script_.get())) {
      context.self_ensemble = true;
      context.self_ensemble_passes = a_.self_ensemble_passes;
      passes_ = static_cast<int64_t>(
          recon::ensemble_mirrors(net_, script_.get(), a_.self_ensemble_passes).size());
      extra_["self_ensemble_passes"] = passes_;
    }
    prepared_ = prepare_method(method_, context, patch_, patch_);
    if (!prepared_.options.empty()) extra_["method_options"] = prepared_.options;
    if (prepared_.options.contains("omp"))
      extra_["omp_atoms"] = prepared_.options["omp"]["max_atoms"];
    if (prepared_.image) {
      // The sensor image's own size: a --scene is rendered at its own, not --height x --width.
      extra_["tile"] = image_tile_ > 0 ? image_tile_
                                       : nn::auto_image_tile(network_.arch().image_tiling(network_),
                                                             sensor_.size(-2), sensor_.size(-1));
    }
  }

  torch::Tensor reconstruct() const {
    if (prepared_.image) return prepared_.image(sensor_, 0.0);
    if (full_) {
      return recon::reconstruct_sensor_fully_convolutional(net_, method_, *phi_, sensor_, o_,
                                                           cnn_tile_);
    }
    return recon::reconstruct_sensor(*phi_, sensor_, prepared_.solver, o_);
  }

  // Patch stitching computes flops_per_patch for every patch; the fully convolutional pass
  // computes the CNN once per tile position instead.
  double flops(double flops_per_patch, const PatchGrid& grid) const {
    const int64_t h = truth_.height(), w = truth_.width();
    if (prepared_.image) {
      return static_cast<double>(passes_) * nn::image_full_flops(network_, h, w, image_tile_);
    }
    double f = flops_per_patch * static_cast<double>(grid.size());
    if (full_) {
      f += nn::cnn_full_flops(network_, h, w, cnn_tile_) -
           nn::cnn_patch_flops(network_) * static_cast<double>(grid.size());
    }
    return f;
  }

  nlohmann::json measure() const {
    const double flops_per_patch = recon::find_method(method_).patch_flops(prepared_.resources);
    const double setup_peak = status_mb("VmHWM");
    const bool isolated_peak = reset_peak_rss();
    const double rss_before = status_mb("VmRSS");
    const auto cpu0 = cpu_seconds();
    Stopwatch clock;
    const auto est = reconstruct();
    const double seconds = clock.seconds();
    const auto cpu1 = cpu_seconds();
    const double user = cpu1.first - cpu0.first, system = cpu1.second - cpu0.second;
    const double peak = status_mb("VmHWM");
    const PatchGrid grid(truth_.height(), truth_.width(), patch_, patch_, stride_);
    const double total_flops = flops(flops_per_patch, grid);
    // Whole-image models have no stride and no patches: their rate is in sensor megapixels per
    // second, which every case reports so that all compare.
    nlohmann::json r = {{"method", method_},
                        {"seconds", seconds},
                        {"megapixels_per_second",
                         static_cast<double>(truth_.height() * truth_.width()) / seconds / 1e6},
                        {"cpu_utilisation", (user + system) / seconds / thread_count()},
                        {"cpu_user_seconds", user},
                        {"cpu_system_seconds", system},
                        {"batch", a_.batch},
                        {"peak_rss_mb", peak},
                        {"rss_before_mb", rss_before},
                        {"peak_is_reconstruction_only", isolated_peak},
                        {"setup_peak_rss_mb", setup_peak},
                        {"setup_seconds", setup_seconds_},
                        {"flops_per_patch", flops_per_patch},
                        {"gflops", total_flops / seconds / 1e9},
                        {"gemm_fraction", gemm_ > 0 ? total_flops / seconds / gemm_ : 0.0},
                        {"psnr_db", psnr(LightField(est), truth_)},
                        {"phi", spec_.label()},
                        {"device", a_.device}};
    if (prepared_.image) {
      r["whole_image"] = true;
    } else {
      r["stride"] = stride_;
      r["patches"] = grid.size();
      r["patches_per_second"] = static_cast<double>(grid.size()) / seconds;
    }
    if (method_ == "net") r["paper_ratio"] = kPaperNetSeconds / seconds;
    if (method_ == "dict") r["paper_ratio"] = kPaperDictSeconds / seconds;
    r.update(extra_);
    return r;
  }

  const BenchOptions& a_;
  const std::string method_;
  const int64_t stride_;
  const double gemm_;  // the machine's GEMM rate, for gemm_fraction (0: not measured)
  optics::PhiSpec spec_;
  const bool full_;  // --cnn-mode full on a method with a CNN
  const int64_t cnn_tile_, image_tile_;
  nn::LightFieldNet net_{nullptr};               // a checkpoint's or an untrained network,
  std::shared_ptr<nn::ScriptedNetwork> script_;  // or an exported one
  nn::NetworkOptions network_;                   // its options
  nlohmann::json model_info_ = "untrained default network";
  bool has_net_ = false;
  std::shared_ptr<optics::Phi> phi_;
  int64_t patch_ = 9;
  recon::ReconstructOptions o_;
  LightField truth_;
  torch::Tensor sensor_;
  dict::Dictionary dictionary_;
  PreparedMethod prepared_;
  int64_t passes_ = 1;  // of a whole-image pass (the self-ensemble's mirrors)
  double setup_seconds_ = 0;
  nlohmann::json extra_ = nlohmann::json::object();
};

}  // namespace

nlohmann::json bench_case(const BenchOptions& a, const std::string& method, int64_t stride,
                          double gemm) {
  return BenchCase(a, method, stride, gemm).run();
}

nlohmann::json bench_conv_kernels(const BenchOptions& a, double gemm) {
  const torch::Device device = parse_device(a.device);
  torch::InferenceMode guard;
  nn::NetworkOptions o;
  const auto& p = o.patch;
  const auto cnn_options = nn::paper_options(o).cnn;
  const int64_t c = cnn_options.channels, b = a.conv_batch;
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
                   {"gemm_fraction", f / t / gemm}});
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
  out.push_back({{"layer", "cnn branch (" + std::to_string(cnn_options.depth) + " layers)"},
                 {"batch", b},
                 {"seconds", t},
                 {"gflops", f / t / 1e9},
                 {"gemm_fraction", f / t / gemm},
                 {"patches_per_second", b / t}});
  return out;
}

namespace {

std::string machine_name() {
  const auto name = cpu_info("model name");
  return name.empty() ? "unknown" : name;
}

double load_average() {
  double load[1] = {-1};
  if (getloadavg(load, 1) < 1) return -1;
  return load[0];
}

// The nets the network methods run with: one narrowed option set per model or architecture,
// with whether it reconstructs whole images.
std::vector<std::pair<BenchOptions, bool>> bench_nets(const BenchOptions& a) {
  std::vector<std::pair<BenchOptions, bool>> nets;
  const std::vector<std::string> models =
      a.models.empty() ? std::vector<std::string>{""} : a.models;
  for (const auto& model : models) {
    for (const auto& architecture : a.architectures) {
      BenchOptions n = a;
      n.models = model.empty() ? std::vector<std::string>{} : std::vector<std::string>{model};
      n.architectures = {architecture};
      nn::NetworkOptions options;
      if (model.empty()) {
        options.architecture = architecture;
      } else {
        options = load_model(model, false).network;
      }
      // One net per precision of `precisions`, else the one `precision`.
      n.precisions.clear();
      for (const auto precision : a.precisions.empty() ? std::vector{a.precision} : a.precisions) {
        n.precision = precision;
        nets.emplace_back(n, !options.patch_grid());
      }
      if (!model.empty()) break;  // a checkpoint has its own architecture
    }
  }
  return nets;
}

// The line a case prints: its error, or its time, rate, memory and PSNR.
std::string case_line(const std::string& label, const std::string& where, const nlohmann::json& r) {
  if (r.contains("error")) {
    return format_text("%-4s %s: %s\n", label.c_str(), where.c_str(),
                       r["error"].get<std::string>().c_str());
  }
  const bool image = r.value("whole_image", false);
  return format_text(
      "%-4s %s: %.2f s, %.*f %s, peak %.0f MB, PSNR %.2f dB\n", label.c_str(), where.c_str(),
      r["seconds"].get<double>(), image ? 2 : 0,
      image ? r["megapixels_per_second"].get<double>() : r["patches_per_second"].get<double>(),
      image ? "Mpx/s" : "patches/s", r["peak_rss_mb"].get<double>(), r["psnr_db"].get<double>());
}

}  // namespace

std::vector<nn::Precision> ladder_precisions(const std::string& device) {
  std::vector<nn::Precision> precisions = {nn::Precision::kFloat32};
  if (device != "cpu" || nn::cpu_has_native_bfloat16()) {
    precisions.push_back(nn::Precision::kBFloat16);
  }
  return precisions;
}

nlohmann::json bench_report(const BenchOptions& a, const BenchCaseRunner& run_case,
                            const std::function<void(const std::string&)>& print) {
  auto say = [&](const char* format, auto... args) { print(format_text(format, args...)); };
  const torch::Device device = parse_device(a.device);
  method_options_argument(a.method_options, a.methods);  // checked before any work
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
  say("lfnet bench: %s, %d threads, device %s, load %.2f\n", machine_name().c_str(), thread_count(),
      a.device.c_str(), load_average());
  const double gemm = bench_gemm_flops(a.reps, device);
  report["gemm_gflops"] = gemm / 1e9;
  say("GEMM (2048^3 sgemm): %.1f GFLOP/s\n", gemm / 1e9);
  if (!a.skip_kernels) {
    report["conv4d"] = bench_conv_kernels(a, gemm);
    for (const auto& k : report["conv4d"]) {
      say("Conv4d %-22s batch %lld: %.4f s, %.1f GFLOP/s (%.0f%% of GEMM)\n",
          k["layer"].get<std::string>().c_str(), static_cast<long long>(k["batch"].get<int64_t>()),
          k["seconds"].get<double>(), k["gflops"].get<double>(),
          100 * k["gemm_fraction"].get<double>());
    }
  }
  report["cases"] = nlohmann::json::array();
  const auto nets = bench_nets(a);
  for (size_t s = 0; s < a.strides.size(); ++s) {
    const int64_t stride = a.strides[s];
    for (const auto& method : a.methods) {
      const bool network = recon::needs_network(method);
      for (const auto& [narrowed, image_net] : nets) {
        const bool image = network && image_net;  // a whole-image network: no stride applies
        if (image && s > 0) continue;
        auto r = run_case(narrowed, method, stride, gemm);
        const std::string label =
            !network ? method
                     : method + " [" +
                           (narrowed.models.empty() ? narrowed.architectures.front()
                                                    : narrowed.models.front()) +
                           (a.precisions.size() > 1 ? ", " + nn::to_string(narrowed.precision)
                                                    : std::string()) +
                           "]";
        print(case_line(label, image ? "whole image" : "stride " + std::to_string(stride), r));
        report["cases"].push_back(r);
        if (!network) break;  // one case for methods without a net
      }
    }
  }
  report["machine"]["load_average_1min_end"] = load_average();
  report["paper_seconds"] = {{"net", kPaperNetSeconds}, {"dict", kPaperDictSeconds}};
  return report;
}

// ---- the child-process protocol of `lfnet bench` and its table ----

namespace {

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

// The command line of a case's child: this program, `bench --case`, and the options.
std::vector<std::string> child_command(const BenchOptions& a, const std::string& method,
                                       int64_t stride, double gemm) {
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
                                   std::to_string(gemm),
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
                                   recon::to_string(a.cnn_mode),
                                   "--precision",
                                   nn::to_string(a.precision)};
  if (a.tile > 0) args.insert(args.end(), {"--tile", std::to_string(a.tile)});
  if (a.self_ensemble) args.emplace_back("--self-ensemble");
  if (a.self_ensemble_passes > 0) {
    args.insert(args.end(), {"--ensemble-passes", std::to_string(a.self_ensemble_passes)});
  }
  for (const auto& arch : a.architectures) {
    args.insert(args.end(), {"--architecture", arch});
  }
  for (const auto& model : a.models) args.insert(args.end(), {"--model", shell_quote(model)});
  if (!a.dictionary.empty()) args.insert(args.end(), {"--dictionary", shell_quote(a.dictionary)});
  if (!a.save_dictionary.empty()) {
    args.insert(args.end(), {"--save-dictionary", shell_quote(a.save_dictionary)});
  }
  if (!a.scene.empty()) args.insert(args.end(), {"--scene", shell_quote(a.scene)});
  if (!a.method_options.empty()) {
    const auto all = read_json_argument(a.method_options, "--method-options");
    if (all.is_object() && all.contains(method)) {
      args.insert(args.end(),
                  {"--method-options", shell_quote(nlohmann::json{{method, all[method]}}.dump())});
    }
  }
  return args;
}

}  // namespace

nlohmann::json bench_case_in_child(const BenchOptions& a, const std::string& method, int64_t stride,
                                   double gemm) {
  const auto args = child_command(a, method, stride, gemm);
  // The child's messages go to a temporary file, passed on to stderr when it ends, so that its
  // error line (which names the flag it refused) also becomes the case's error in the table.
  char log_path[] = "/tmp/lfnet-bench-XXXXXX";
  const int log_fd = mkstemp(log_path);
  LFNET_CHECK_AS(IoError, log_fd >= 0, "bench: cannot make a temporary file in /tmp");
  close(log_fd);
  // exec: the case is the bench's own child, which it dies with (cmd_bench's --case).
  FILE* pipe = popen(("exec " + join(args, " ") + " 2>" + shell_quote(log_path)).c_str(), "r");
  if (!pipe) std::remove(log_path);
  LFNET_CHECK_AS(IoError, pipe, "bench: cannot start a child process");
  std::string output;
  char buffer[4096];
  while (size_t got = std::fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, got);
  const int status = pclose(pipe);
  std::string log, error;
  {
    std::ifstream in(log_path);
    for (std::string line; std::getline(in, line);) {
      // The child's error becomes the case's (and, if every case fails, the bench's one error
      // line); its other messages pass through.
      const auto said = line.find("lfnet: error: ");
      if (said == std::string::npos) {
        log += line + "\n";
      } else {
        error = line.substr(said + 14);
      }
    }
  }
  std::remove(log_path);
  std::fputs(log.c_str(), stderr);
  const auto at = output.find(kBenchCaseTag);
  if (status != 0 || at == std::string::npos) {
    return {
        {"method", method},
        {"stride", stride},
        {"error", error.empty() ? "the child process failed (status " + std::to_string(status) + ")"
                                : error}};
  }
  const auto end = output.find('\n', at);
  return nlohmann::json::parse(
      output.substr(at + std::string(kBenchCaseTag).size(),
                    end == std::string::npos ? end : end - at - std::string(kBenchCaseTag).size()));
}

std::string bench_table(const nlohmann::json& report) {
  // Whole-image cases have no stride and no patches ("image", "-"); Mpx/s compares every case.
  // Cases of trained models end with the model's file stem, and a precision other than float32.
  bool models = false;
  for (const auto& r : report["cases"]) models = models || r.contains("model");
  std::string out = format_text("%-14s %-6s %8s %10s %12s %8s %9s %8s %9s %6s %8s%s\n", "method",
                                "stride", "patches", "seconds", "patches/s", "Mpx/s", "peak MB",
                                "GFLOP/s", "% GEMM", "util", "PSNR dB", models ? "  model" : "");
  for (const auto& r : report["cases"]) {
    std::string model;
    if (r.contains("model") && r["model"].is_string()) {
      model = "  " + std::filesystem::path(r["model"].get<std::string>()).stem().string();
      const auto precision = r.value("precision", std::string("float32"));
      if (precision != "float32") model += ", " + precision;
    }
    // Network cases name their architecture: both may share a run.
    std::string method = r["method"].get<std::string>();
    if (r.contains("architecture")) method += "/" + r["architecture"].get<std::string>();
    const bool image = r.value("whole_image", false);
    const std::string stride = image ? std::string("image") : std::to_string(r.value("stride", 0));
    if (r.contains("error")) {
      out += format_text("%-14s %-6s  %s\n", method.c_str(), stride.c_str(),
                         r["error"].get<std::string>().c_str());
      continue;
    }
    const std::string patches =
        image ? std::string("-") : std::to_string(r["patches"].get<int64_t>());
    const std::string rate =
        image ? std::string("-") : format_text("%.1f", r["patches_per_second"].get<double>());
    out += format_text("%-14s %-6s %8s %10.2f %12s %8.2f %9.0f %8.1f %8.1f%% %6.2f %8.2f%s\n",
                       method.c_str(), stride.c_str(), patches.c_str(), r["seconds"].get<double>(),
                       rate.c_str(), r.value("megapixels_per_second", 0.0),
                       r["peak_rss_mb"].get<double>(), r["gflops"].get<double>(),
                       100 * r["gemm_fraction"].get<double>(), r["cpu_utilisation"].get<double>(),
                       r["psnr_db"].get<double>(), model.c_str());
  }
  return out;
}

}  // namespace lfnet::pipeline

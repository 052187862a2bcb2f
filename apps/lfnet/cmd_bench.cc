// lfnet bench: how fast this machine runs lfnet (docs/performance.md; pipeline/bench.h measures).
// Each reconstruction runs in a child process of its own, so its peak resident memory is its
// own and not the high-water mark of the cases before it.
#include <unistd.h>

#include <cstdio>
#include <string>
#include <vector>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/runtime.h"
#include "lfnet/pipeline/bench.h"

namespace lfnet::app {

namespace {

constexpr const char* kCaseTag = "LFNET_BENCH_CASE ";

struct BenchArgs {
  pipeline::BenchOptions options;
  std::string json;  // write the report here ("-": standard output)
  bool in_process = false;
  // Child mode: one case "method:stride", with the parent's GEMM figure.
  std::string one_case;
  double gemm = 0;
};

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
nlohmann::json run_child(const pipeline::BenchOptions& a, const std::string& method, int64_t stride,
                         double gemm) {
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
                                   shell_quote(a.cnn_mode),
                                   "--precision",
                                   shell_quote(a.precision)};
  if (a.tile > 0) args.insert(args.end(), {"--tile", std::to_string(a.tile)});
  for (const auto& arch : a.architectures) {
    args.insert(args.end(), {"--architecture", shell_quote(arch)});
  }
  for (const auto& model : a.models) args.insert(args.end(), {"--model", shell_quote(model)});
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

void print_table(const nlohmann::json& report) {
  std::printf("\n%-14s %-6s %8s %10s %12s %9s %8s %9s %6s %8s\n", "method", "stride", "patches",
              "seconds", "patches/s", "peak MB", "GFLOP/s", "% GEMM", "util", "PSNR dB");
  for (const auto& r : report["cases"]) {
    // Network cases name their architecture: both may share a run.
    std::string method = r["method"].get<std::string>();
    if (r.contains("architecture")) method += "/" + r["architecture"].get<std::string>();
    if (r.contains("error")) {
      std::printf("%-14s %-6lld  %s\n", method.c_str(),
                  static_cast<long long>(r["stride"].get<int64_t>()),
                  r["error"].get<std::string>().c_str());
      continue;
    }
    std::printf("%-14s %-6lld %8lld %10.2f %12.1f %9.0f %8.1f %8.1f%% %6.2f %8.2f\n",
                method.c_str(), static_cast<long long>(r["stride"].get<int64_t>()),
                static_cast<long long>(r["patches"].get<int64_t>()), r["seconds"].get<double>(),
                r["patches_per_second"].get<double>(), r["peak_rss_mb"].get<double>(),
                r["gflops"].get<double>(), 100 * r["gemm_fraction"].get<double>(),
                r["cpu_utilisation"].get<double>(), r["psnr_db"].get<double>());
  }
}

void run_bench(const BenchArgs& args) {
  const auto& a = args.options;
  if (!args.json.empty() && args.json != "-" && args.one_case.empty()) {
    // The report is rewritten on each run; it may not be one of the files the bench reads.
    OutputFolderPolicy policy;
    policy.option = "--json";
    policy.force = true;
    policy.inputs = {a.dictionary, a.scene};
    policy.inputs.insert(policy.inputs.end(), a.models.begin(), a.models.end());
    check_output_file(args.json, policy);
  }
  if (!args.one_case.empty()) {
    const auto colon = args.one_case.find(':');
    LFNET_CHECK_AS(ConfigError, colon != std::string::npos, "--case takes method:stride, got '",
                   args.one_case, "'");
    const auto r = pipeline::bench_case(a, args.one_case.substr(0, colon),
                                        std::stoll(args.one_case.substr(colon + 1)), args.gemm);
    std::printf("%s%s\n", kCaseTag, r.dump().c_str());
    return;
  }
  parse_device(a.device);  // a clear error before any work
  const auto report = pipeline::bench_report(
      a,
      [&](const pipeline::BenchOptions& narrowed, const std::string& method, int64_t stride,
          double gemm) {
        return args.in_process ? pipeline::bench_case(narrowed, method, stride, gemm)
                               : run_child(narrowed, method, stride, gemm);
      },
      [](const std::string& line) {
        std::fputs(line.c_str(), stdout);
        std::fflush(stdout);
      });
  print_table(report);
  if (!args.json.empty()) {
    if (args.json == "-") {
      std::printf("%s\n", report.dump(2).c_str());
    } else {
      write_json_file(args.json, report);
      std::printf("wrote %s\n", args.json.c_str());
    }
  }
}

}  // namespace

void add_bench_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "bench", "Measure GEMM and Conv4d FLOP/s and whole-light-field reconstruction speed");
  auto args = std::make_shared<BenchArgs>();
  auto* a = &args->options;
  cmd->add_option("--json", args->json, "also write the report as JSON to this file ('-': stdout)");
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
  cmd->add_option("--model", a->models,
                  "trained checkpoint, repeatable: the network methods run with each (default: "
                  "an untrained network of --architecture)");
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
  cmd->add_option("--tile", a->tile,
                  "tile size of --cnn-mode full (default 128) and of lfnet models (default 256)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--architecture", a->architectures,
                  "untrained networks timed without --model, repeatable: paper (default), lfnet")
      ->check(CLI::IsMember({"paper", "lfnet"}));
  cmd->add_option("--precision", a->precision,
                  "float32 or bfloat16 for the CNN branch's convolutions")
      ->check(CLI::IsMember({"float32", "bfloat16"}));
  cmd->add_flag("--in-process", args->in_process,
                "run every case in this process (peak memory is then a running maximum)");
  cmd->add_flag("--skip-kernels", a->skip_kernels, "skip the Conv4d timings");
  cmd->add_option("--case", args->one_case,
                  "run one case method:stride and print it as JSON (used by the parent run)")
      ->group("");
  cmd->add_option("--gemm", args->gemm, "GEMM FLOP/s measured by the parent run")->group("");
  cmd->callback([args] { run_bench(*args); });
}

}  // namespace lfnet::app

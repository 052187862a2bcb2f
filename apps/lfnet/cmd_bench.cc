// lfnet bench: how fast this machine runs lfnet (docs/performance.md; pipeline/bench.h measures).
// Each reconstruction runs in a child process of its own (pipeline::bench_case_in_child), so its
// peak resident memory is its own and not the high-water mark of the cases before it.
#include <sys/prctl.h>

#include <csignal>
#include <cstdio>
#include <optional>
#include <string>

#include "command.h"
#include "flags.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/runtime.h"
#include "lfnet/pipeline/bench.h"
#include "lfnet/pipeline/budget.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/models.h"

namespace lfnet::app {

namespace {

struct BenchArgs {
  pipeline::BenchOptions options;
  std::string json;        // write the report here ("-": standard output)
  bool force = false;      // replace an existing --json file
  bool phi_given = false;  // --phi on the command line (else the default, for untrained nets)
  bool in_process = false;
  bool calibrate = false;  // time the zoo's models for --budget instead
  bool ladder = false;     // --model: the zoo's ladder for --phi
  // Child mode: one case "method:stride", with the parent's GEMM figure.
  std::string one_case;
  double gemm = 0;
};

// --calibrate: the zoo's models (or those of --model) timed for --budget on this machine.
void run_calibrate(const BenchArgs& args, std::optional<pipeline::Precision> precision) {
  const auto& a = args.options;
  parse_device(a.device);
  pipeline::CalibrateOptions o;
  o.models = a.models;
  o.device = a.device;
  o.precision = precision;
  o.height = a.height;
  o.width = a.width;
  o.seed = a.seed;
  std::printf("timing zoo models for --budget on this machine (%d thread(s)) into %s\n",
              thread_count(), pipeline::calibration_path().c_str());
  std::fflush(stdout);
  const auto timed = pipeline::calibrate_machine(o, [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  });
  std::printf("wrote %s (%zu timing(s))\n", pipeline::calibration_path().c_str(), timed.size());
}

void run_bench(const BenchArgs& args) {
  const auto& a = args.options;
  // The lock makes --json's missing folders (gone again if no report comes) and keeps other
  // writers off.
  std::optional<OutputLock> json_lock;
  if (!args.json.empty() && args.json != "-" && args.one_case.empty()) {
    // The report may not be one of the files the bench reads, nor replace a file unasked.
    OutputFolderPolicy policy;
    policy.option = "--json";
    policy.force = args.force;
    policy.inputs = {a.dictionary, a.scene};
    for (const auto& model : a.models) {
      for (const auto& path : pipeline::model_input_files(model)) policy.inputs.push_back(path);
    }
    check_output_file(args.json, policy);
    json_lock.emplace(args.json, "--json");
  }
  if (!args.one_case.empty()) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a case dies with the bench that started it
    const auto colon = args.one_case.find(':');
    LFNET_CHECK_AS(ConfigError, colon != std::string::npos, "--case takes method:stride, got '",
                   args.one_case, "'");
    const auto r = pipeline::bench_case(a, args.one_case.substr(0, colon),
                                        std::stoll(args.one_case.substr(colon + 1)), args.gemm);
    std::printf("%s%s\n", pipeline::kBenchCaseTag, r.dump().c_str());
    return;
  }
  parse_device(a.device);  // a clear error before any work
  // A --phi that contradicts a model is an error, as in evaluate (a model knows its camera).
  if (args.phi_given) {
    for (const auto& model : a.models) {
      pipeline::check_phi_argument(pipeline::load_model(model, false), a.phi);
    }
  }
  // With the report on standard output (--json -), the progress and the table go to standard
  // error, so that standard output is the JSON alone.
  FILE* text = args.json == "-" ? stderr : stdout;
  const auto report = pipeline::bench_report(
      a,
      [&](const pipeline::BenchOptions& narrowed, const std::string& method, int64_t stride,
          double gemm) {
        return args.in_process ? pipeline::bench_case(narrowed, method, stride, gemm)
                               : pipeline::bench_case_in_child(narrowed, method, stride, gemm);
      },
      [text](const std::string& line) {
        std::fputs(line.c_str(), text);
        std::fflush(text);
      });
  std::fprintf(text, "\n%s", pipeline::bench_table(report).c_str());
  if (!args.json.empty()) {
    if (args.json == "-") {
      std::printf("%s\n", report.dump(2).c_str());
    } else {
      write_json_file(args.json, report);
      std::printf("wrote %s\n", args.json.c_str());
    }
  }
  // A bench in which no case ran is a failure (the report, written above, says why).
  int64_t failed = 0;
  for (const auto& r : report["cases"]) failed += r.contains("error") ? 1 : 0;
  const auto cases = static_cast<int64_t>(report["cases"].size());
  LFNET_CHECK_AS(Error, cases == 0 || failed < cases, "bench: every case failed (", failed, " of ",
                 cases, "); the first: ", report["cases"][0].value("error", std::string()));
}

}  // namespace

void add_bench_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "bench", "Measure GEMM and Conv4d FLOP/s and whole-light-field reconstruction speed");
  auto args = std::make_shared<BenchArgs>();
  auto* a = &args->options;
  add_json_option(cmd, args->json);
  add_force_flag(cmd, args->force);
  cmd->add_option("--methods", a->methods,
                  "methods to time: " + pipeline::method_list(/*reconstruction=*/true))
      ->delimiter(',');
  ReconstructionFlags shared{
      nullptr,           &a->models, &a->phi,     &a->device,        &a->precision,
      &a->tile,          nullptr,    &a->strides, &a->self_ensemble, &a->self_ensemble_passes,
      &a->method_options};
  add_reconstruction_flags(cmd, shared);
  // At least one 9 x 9 patch; at most 8192 x 8192 x 5 x 5 floats (6.7 GB) per light field.
  cmd->add_option("--height", a->height, "light-field height (default 593)")
      ->check(whole_number_in(9, 8192, "pixels"));
  cmd->add_option("--width", a->width, "light-field width (default 840)")
      ->check(whole_number_in(9, 8192, "pixels"));
  add_batch_option(cmd, a->batch);
  add_dictionary_option(cmd, a->dictionary);
  output_file(cmd->add_option("--save-dictionary", a->save_dictionary,
                              "write the bench's K-SVD dictionary to this file"));
  add_scene_option(cmd, a->scene);
  // K-SVD keeps an atoms x atoms Gram matrix in double: 20000 atoms take 3.2 GB.
  cmd->add_option("--dict-atoms", a->dict_atoms, "atoms of the bench dictionary (default 1000)")
      ->check(whole_number_in(1, 20000, "atoms"));
  add_seed_option(cmd, a->seed);
  cmd->add_option("--conv-batch", a->conv_batch, "patches per Conv4d timing (default 256)")
      ->check(kCount);
  cmd->add_option("--reps", a->reps, "repetitions of the kernel timings (best is kept)")
      ->check(kCount);
  add_cnn_mode_option(cmd, a->cnn_mode);
  cmd->add_option_function<std::vector<std::string>>(
      "--architecture",
      [a](const std::vector<std::string>& names) {
        for (const auto& name : names) {
          try {
            pipeline::check_architecture(name);
          } catch (const ConfigError& e) {
            throw CLI::ValidationError("--architecture", e.what());
          }
        }
        a->architectures = names;
      },
      "untrained networks timed without --model, repeatable: " + pipeline::architecture_list() +
          " (default paper)");
  cmd->add_flag("--in-process", args->in_process,
                "run every case in this process (peak memory is then a running maximum)");
  cmd->add_flag("--skip-kernels", a->skip_kernels, "skip the Conv4d timings");
  cmd->add_option("--case", args->one_case,
                  "run one case method:stride and print it as JSON (used by the parent run)")
      ->group("");
  cmd->add_option("--gemm", args->gemm, "GEMM FLOP/s measured by the parent run")->group("");
  cmd->add_flag("--calibrate", args->calibrate,
                "time the zoo's models (or those of --model) and pinv on this machine for "
                "--budget, at --height x --width and a quarter of it, and write them to the "
                "calibration file ($LFNET_CALIBRATION, else ~/.cache/lfnet/calibration.json)");
  cmd->add_flag("--ladder", args->ladder,
                "time the zoo's grey checkpoints for --phi (default asp:2) that --budget chooses "
                "among, most accurate first, as if each were given as --model; without "
                "--precision, each in float32 and, on a CPU with native bfloat16 or a GPU, in "
                "bfloat16");
  cmd->callback([args, cmd] {
    args->phi_given = cmd->count("--phi") > 0;
    if (args->ladder) {
      LFNET_CHECK_AS(ConfigError, args->options.models.empty(),
                     "--ladder times the zoo's models: leave out --model");
      args->options.models =
          pipeline::ladder_models(pipeline::phi_from_argument(args->options.phi).label());
      // Without a --precision, each rung in float32 and, where bfloat16 is native, in it too.
      if (!given_precision(cmd, args->options.precision) && !args->calibrate) {
        args->options.precisions = pipeline::ladder_precisions(args->options.device);
      }
    }
    if (args->calibrate) {
      LFNET_CHECK_AS(ConfigError, args->json.empty() && args->one_case.empty(),
                     "--calibrate writes the calibration file, not --json");
      return run_calibrate(*args, given_precision(cmd, args->options.precision));
    }
    run_bench(*args);
  });
}

}  // namespace lfnet::app

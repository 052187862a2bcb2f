// lfnet: recovers 4D light fields from single coded 2D sensor images.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/text.h"
#include "paths.h"

namespace {

// One error line: without the source locations the library's checks append (" [file.cc:12]"),
// which --log-level debug shows.
int fail(const std::string& what) {
  std::string line = what;
  for (auto& ch : line) {
    if (ch == '\n') ch = ' ';
  }
  spdlog::debug("error with source locations: {}", line);
  line = lfnet::without_source_locations(line);
  std::fprintf(stderr, "lfnet: error: %s\n", line.c_str());
  return 1;
}

// --threads and --log-level, the program's own options, applied once the line is parsed.
void add_global_options(CLI::App& app, lfnet::app::GlobalOptions& global) {
  // At most 4 threads per core: more only wait for each other (300 threads made a 1 s job
  // take 39 s), and a typo such as 10000 would make a job appear to hang.
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int max_threads = 4 * cores;
  app.add_option("--threads", global.threads,
                 "CPU threads (default: OMP_NUM_THREADS, else every core; at most 4 per core)")
      ->check(CLI::Validator(
          [cores, max_threads](std::string& text) -> std::string {
            int v = 0;
            if (!CLI::detail::lexical_cast(text, v) || v < 0 || v > max_threads) {
              return "must be 0 (every core) to " + std::to_string(max_threads) + " (4 per core, " +
                     std::to_string(cores) + " cores here), got " + text;
            }
            return "";
          },
          "0.." + std::to_string(max_threads)));
  app.add_option("--log-level", global.log_level, "trace, debug, info, warn, error or off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));
  app.parse_complete_callback([&global] {
    spdlog::set_level(spdlog::level::from_str(global.log_level));
    // Quiet means quiet: on failure the error line is then the only output.
    lfnet::set_progress_enabled(global.log_level != "off" && global.log_level != "error");
    spdlog::set_pattern("[%H:%M:%S] %^%l%$ %v");
    int n = lfnet::configure_threads(global.threads);
    spdlog::debug("using {} threads", n);
  });
}

// A command that does not exist reads better named than as "a subcommand is required": the
// first word that is no option, when it names no command; "" otherwise.
std::string unknown_command(CLI::App& app, int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const std::string before = i > 1 ? argv[i - 1] : "";
    if (arg.empty() || arg[0] == '-' || before == "--threads" || before == "--log-level") {
      continue;
    }
    std::string known;
    bool found = false;
    for (auto* sub : app.get_subcommands([](CLI::App*) { return true; })) {
      known += (known.empty() ? "" : ", ") + sub->get_name();
      found = found || sub->check_name(arg);
    }
    if (!found) {
      std::string message = "unknown command '" + arg + "' (known: ";
      message += known;
      message += "; run lfnet --help)";
      return message;
    }
    break;
  }
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace lfnet::app;
  lfnet::configure_allocator();
  CLI::App app{"lfnet: compressive light field reconstruction from coded sensor images"};
  app.require_subcommand(1);
  // lfnet's own options (--threads, --log-level) may also follow the command's name.
  app.fallthrough();
  app.set_version_flag("--version", std::string("lfnet ") + lfnet::kVersion);
  GlobalOptions global;
  add_global_options(app, global);
  const std::vector<CommandFactory> commands = {
      add_info_command,       add_render_command,   add_simulate_command,    add_train_command,
      add_experiment_command, add_evaluate_command, add_reconstruct_command, add_batch_command,
      add_report_command,     add_export_command,   add_launch_command,      add_bench_command,
      add_phi_command,        add_blend_command,    add_sets_command,        add_models_command};
  for (const auto& add : commands) add(app, global);

  try {
    // Every path flag is checked before anything is parsed or opened (paths.h).
    check_path_flags(path_flags(app, std::vector<std::string>(argv + 1, argv + argc)));
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    const std::string unknown = unknown_command(app, argc, argv);
    if (!unknown.empty()) return fail(unknown);
    return fail(e.what() + std::string(" (run lfnet --help)"));
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  return 0;
}

// lfnet launch: starts the ranks of a data-parallel job on this host (docs/distributed.md,
// pipeline::launch_job), each rank this program with the job's subcommand and its rank's flags.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <thread>

#include "command.h"
#include "lfnet/pipeline/distributed.h"

namespace lfnet::app {

namespace {

void run_launch(pipeline::LaunchRequest a, const GlobalOptions& global) {
  a.threads = global.threads;
  a.log_level = global.log_level;
  pipeline::launch_job(a);
}

}  // namespace

void add_launch_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "launch", "Run a data-parallel job of N local ranks: lfnet launch -n 2 -- train CONFIG.json");
  auto args = std::make_shared<pipeline::LaunchRequest>();
  // At most 4 ranks per core, as for --threads: more only wait for each other.
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  cmd->add_option("-n,--ranks", args->ranks,
                  "ranks (processes) to start (default 2; at most 4 per core)")
      ->check(CLI::Validator(
          [cores](std::string& text) -> std::string {
            int v = 0;
            if (!CLI::detail::lexical_cast(text, v) || v < 1 || v > 4 * cores) {
              return "must be 1 to " + std::to_string(4 * cores) + " (4 per core, " +
                     std::to_string(cores) + " cores here), got " + text;
            }
            return "";
          },
          "1.." + std::to_string(4 * cores)));
  cmd->add_option("--port", args->port, "loopback port of the rendezvous (default: a free one)")
      ->check(CLI::Range(1, 65535));
  cmd->add_option("--grace", args->grace_s,
                  "seconds the other ranks get to stop after one fails, before SIGKILL (default 5)")
      ->check(kSeconds);
  cmd->add_option("command", args->command, "after --: the subcommand and its arguments")
      ->required();
  cmd->callback([args, &global] { run_launch(*args, global); });
}

}  // namespace lfnet::app

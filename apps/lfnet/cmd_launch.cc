// lfnet launch: starts the ranks of a data-parallel job on this host (docs/distributed.md,
// dist::launch_local), each rank this program with the job's subcommand and its rank's flags.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <thread>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/dist/communicator.h"
#include "lfnet/dist/launch.h"

namespace lfnet::app {

namespace {

struct LaunchArgs {
  int64_t ranks = 2;
  int port = 0;  // 0: a free one
  double grace_s = 5;
  std::vector<std::string> command;
};

void run_launch(const LaunchArgs& a, const GlobalOptions& global) {
  LFNET_CHECK_AS(ConfigError, !a.command.empty(),
                 "name the subcommand to run after --, e.g. lfnet launch -n 2 -- train "
                 "configs/quickstart.json");
  const std::string& verb = a.command.front();
  LFNET_CHECK_AS(ConfigError, verb == "train" || verb == "batch", "lfnet launch runs 'train' or ",
                 "'batch', not '", verb, "'");
  for (const auto& arg : a.command) {
    for (const char* flag : {"--world-size", "--rank", "--master"}) {
      LFNET_CHECK_AS(ConfigError, arg.rfind(flag, 0) != 0, "lfnet launch sets ", flag,
                     " itself: leave it out of the command");
    }
  }
  const int port = a.port > 0 ? a.port : dist::free_loopback_port();
  const std::string master = "127.0.0.1:" + std::to_string(port);
  // Every rank computing with every core would oversubscribe the host: share the cores.
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int threads =
      global.threads > 0 ? global.threads : std::max(1, cores / static_cast<int>(a.ranks));
  spdlog::info("launching {} ranks of 'lfnet {}' on {} with {} thread(s) each", a.ranks, verb,
               master, threads);
  dist::LaunchOptions options;
  options.ranks = a.ranks;
  options.grace_s = a.grace_s;
  dist::launch_local(options, [&](int64_t rank) {
    std::vector<std::string> argv{"lfnet", "--threads", std::to_string(threads), "--log-level",
                                  global.log_level};
    argv.insert(argv.end(), a.command.begin(), a.command.end());
    for (const auto& extra :
         {std::string("--world-size"), std::to_string(a.ranks), std::string("--rank"),
          std::to_string(rank), std::string("--master"), master}) {
      argv.push_back(extra);
    }
    return argv;
  });
  spdlog::info("all {} ranks finished", a.ranks);
}

}  // namespace

void add_launch_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "launch", "Run a data-parallel job of N local ranks: lfnet launch -n 2 -- train CONFIG.json");
  auto args = std::make_shared<LaunchArgs>();
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

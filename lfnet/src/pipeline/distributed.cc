#include "lfnet/pipeline/distributed.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <thread>

#include "lfnet/core/error.h"
#include "lfnet/dist/launch.h"

namespace lfnet::pipeline {

std::shared_ptr<Communicator> join_job(const DistOptions& options) {
  try {
    options.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(std::string("distributed options: ") + e.what());
  }
  if (options.world_size > 1) {
    spdlog::info("rank {} of {}: joining the job at {}", options.rank, options.world_size,
                 options.master);
  }
  if (options.world_size > 1 && options.rank == 0) {
    // Rank 0 waits for the others: say how they join, so a missing --rank is not a silent wait.
    spdlog::info(
        "rank 0 waits up to {:g} s for ranks 1 .. {}: start each with --world-size {} --rank K "
        "--master {}, or run the whole job with lfnet launch -n {} -- ...",
        options.timeout_s, options.world_size - 1, options.world_size, options.master,
        options.world_size);
  }
  auto comm = dist::connect(options);
  if (comm->rank() != 0 && spdlog::get_level() < spdlog::level::warn) {
    spdlog::set_level(spdlog::level::warn);  // rank 0 reports for the job
  }
  return comm;
}

void launch_job(const LaunchRequest& a) {
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
  const int threads = a.threads > 0 ? a.threads : std::max(1, cores / static_cast<int>(a.ranks));
  spdlog::info("launching {} ranks of 'lfnet {}' on {} with {} thread(s) each", a.ranks, verb,
               master, threads);
  dist::LaunchOptions options;
  options.ranks = a.ranks;
  options.grace_s = a.grace_s;
  dist::launch_local(options, [&](int64_t rank) {
    std::vector<std::string> argv{"lfnet", "--threads", std::to_string(threads), "--log-level",
                                  a.log_level};
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

}  // namespace lfnet::pipeline

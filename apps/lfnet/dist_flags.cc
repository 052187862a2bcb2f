#include "dist_flags.h"

#include <spdlog/spdlog.h>

#include "command.h"

namespace lfnet::app {

void add_dist_flags(CLI::App* cmd, dist::DistOptions& o) {
  const std::string group = "Distributed (docs/distributed.md)";
  cmd->add_option("--world-size", o.world_size, "processes in the data-parallel job (default 1)")
      ->check(kCount)
      ->group(group);
  cmd->add_option("--rank", o.rank, "this process's rank, 0 .. world size - 1 (default 0)")
      ->check(kWhole)
      ->group(group);
  cmd->add_option("--master", o.master, "HOST:PORT where rank 0 listens (default " + o.master + ")")
      ->group(group);
  cmd->add_option("--dist-timeout", o.timeout_s,
                  "seconds to wait for the other ranks before failing (default 300)")
      ->check(kTimeout)
      ->group(group);
  cmd->add_option("--dist-interface", o.interface,
                  "network interface for the Gloo transport, e.g. eth0 (default: "
                  "$GLOO_SOCKET_IFNAME, else loopback for a loopback master, else the host "
                  "name's address)")
      ->group(group);
}

std::shared_ptr<dist::Communicator> join_job(const dist::DistOptions& options) {
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

}  // namespace lfnet::app

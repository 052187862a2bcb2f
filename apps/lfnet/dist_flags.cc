#include "dist_flags.h"

#include <spdlog/spdlog.h>

#include "command.h"

namespace lfnet::app {

void add_dist_flags(CLI::App* cmd, pipeline::DistOptions& o) {
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

}  // namespace lfnet::app

// Data-parallel jobs (docs/distributed.md): a process joins one (`lfnet train` and `lfnet batch`
// with --world-size), and `lfnet launch` starts the ranks of one on this host.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lfnet/dist/communicator.h"

namespace lfnet::pipeline {

using dist::Communicator;
using dist::DistOptions;

// Joins the job (a no-op for one process); ranks other than 0 log warnings and errors only.
std::shared_ptr<Communicator> join_job(const DistOptions& options);

struct LaunchRequest {
  int64_t ranks = 2;
  int port = 0;                      // the master's loopback port; 0: a free one
  double grace_s = 5;                // how long the others may run on once one rank has failed
  std::vector<std::string> command;  // the subcommand and its arguments: train or batch
  int threads = 0;                   // per rank; 0: the host's cores shared between the ranks
  std::string log_level = "info";
};

// Runs `ranks` copies of this program with the command and each rank's flags, and waits for
// them all; the first rank to fail stops the job (dist::launch_local).
void launch_job(const LaunchRequest& request);

}  // namespace lfnet::pipeline

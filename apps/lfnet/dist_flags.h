// The flags that place a subcommand in a data-parallel job (docs/distributed.md), shared by
// `lfnet train` and `lfnet batch`, and set by `lfnet launch`.
#pragma once

#include <CLI/CLI.hpp>

#include <memory>

#include "lfnet/dist/communicator.h"

namespace lfnet::app {

// --world-size, --rank, --master, --dist-timeout, --dist-interface.
void add_dist_flags(CLI::App* cmd, dist::DistOptions& options);

// Joins the job (a no-op for one process); ranks other than 0 log warnings and errors only.
std::shared_ptr<dist::Communicator> join_job(const dist::DistOptions& options);

}  // namespace lfnet::app

// The flags that place a subcommand in a data-parallel job (docs/distributed.md), shared by
// `lfnet train` and `lfnet batch`, and set by `lfnet launch`.
#pragma once

#include <CLI/CLI.hpp>

#include "lfnet/pipeline/distributed.h"

namespace lfnet::app {

// --world-size, --rank, --master, --dist-timeout, --dist-interface.
void add_dist_flags(CLI::App* cmd, pipeline::DistOptions& options);

}  // namespace lfnet::app

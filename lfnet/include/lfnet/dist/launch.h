// Starting the ranks of a data-parallel job on this host (`lfnet launch`, docs/distributed.md):
// one process per rank, their output forwarded line by line with a [rank N] prefix, and a job
// that stops as a whole when one rank fails.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace lfnet::dist {

struct LaunchOptions {
  int64_t ranks = 2;                       // processes to start
  double grace_s = 5;                      // after one rank fails: SIGTERM, then SIGKILL after this
  std::string program = "/proc/self/exe";  // what every rank executes
};

// Starts options.ranks processes of options.program, rank r with the arguments argv_of(r)
// (argv[0] included), forwards their standard output and error with a "[rank r] " prefix, and
// waits for all of them. When one fails, the others are stopped (SIGTERM, then SIGKILL after
// the grace period) and an Error names the first failed rank and how it ended.
void launch_local(const LaunchOptions& options,
                  const std::function<std::vector<std::string>(int64_t rank)>& argv_of);

}  // namespace lfnet::dist

// lfnet: the command a user runs. It answers `lfnet --version` itself and runs every other
// command line in lfnet-run, the program beside it that holds the commands (apps/lfnet/main.cc).
// Loading LibTorch and the ~300 shared libraries it pulls in costs about half a second before
// main (docs/performance.md, "Start-up"): a command that needs none of it does not pay it.
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "lfnet/core/version.h"

namespace {

// The folder of this executable, from /proc/self/exe ("" when it cannot be read).
std::string own_folder() {
  std::string path(4096, '\0');
  const ssize_t n = readlink("/proc/self/exe", path.data(), path.size() - 1);
  if (n <= 0) return "";
  path.resize(static_cast<size_t>(n));
  const auto slash = path.rfind('/');
  return slash == std::string::npos ? "" : path.substr(0, slash);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 2 && std::strcmp(argv[1], "--version") == 0) {
    std::printf("lfnet %s\n", lfnet::kVersion);
    return 0;
  }
  const std::string folder = own_folder();
  const std::string program = (folder.empty() ? std::string(".") : folder) + "/lfnet-run";
  execv(program.c_str(), argv);  // returns only when it could not run it
  std::fprintf(stderr, "lfnet: error: cannot run %s: %s (it is built and installed beside lfnet)\n",
               program.c_str(), std::strerror(errno));
  return 127;
}

#include "lfnet/core/process_time.h"

#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <string>

namespace lfnet {

namespace {

// When the library was loaded: the fallback's origin.
const auto kLoaded = std::chrono::steady_clock::now();

// Seconds since the process started, from /proc: its start time in clock ticks since boot
// (field 22 of /proc/self/stat) against the seconds since boot (/proc/uptime); < 0 if unknown.
double proc_seconds() {
  std::ifstream stat("/proc/self/stat");
  std::string text;
  if (!std::getline(stat, text)) return -1;
  const size_t close = text.rfind(')');  // the command name may hold spaces and parentheses
  if (close == std::string::npos || close + 2 > text.size()) return -1;
  std::istringstream fields(text.substr(close + 2));
  std::string skipped;
  for (int field = 3; field < 22; ++field) {
    if (!(fields >> skipped)) return -1;
  }
  unsigned long long start_ticks = 0;
  double uptime = 0;
  std::ifstream up("/proc/uptime");
  const long ticks_per_second = ::sysconf(_SC_CLK_TCK);
  if (!(fields >> start_ticks) || !(up >> uptime) || ticks_per_second <= 0) return -1;
  return uptime - static_cast<double>(start_ticks) / static_cast<double>(ticks_per_second);
}

}  // namespace

double process_seconds() {
  const double from_proc = proc_seconds();
  if (from_proc >= 0) return from_proc;
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - kLoaded).count();
}

}  // namespace lfnet

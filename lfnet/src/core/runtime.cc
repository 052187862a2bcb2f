#include "lfnet/core/runtime.h"

#include <torch/torch.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <thread>

#include "lfnet/core/error.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace lfnet {

int configure_threads(int requested) {
  int n = requested;
  if (n <= 0) {
    // OMP_NUM_THREADS, when set to a positive count, is the default (scripts/test-kernels.sh
    // runs everything on 1 and on 2 threads that way); otherwise every core.
    const char* env = std::getenv("OMP_NUM_THREADS");
    n = env != nullptr ? std::atoi(env) : 0;
    if (n <= 0) n = static_cast<int>(std::thread::hardware_concurrency());
  }
  n = std::max(1, n);
  torch::set_num_threads(n);
  return torch::get_num_threads();
}

int thread_count() { return torch::get_num_threads(); }

bool configure_allocator() {
#if defined(__GLIBC__)
  if (std::getenv("MALLOC_MMAP_THRESHOLD_") != nullptr) return false;
  constexpr int kOneGb = 1 << 30;
  return mallopt(M_MMAP_THRESHOLD, kOneGb) == 1 && mallopt(M_TRIM_THRESHOLD, kOneGb) == 1 &&
         mallopt(M_TOP_PAD, 64 << 20) == 1;
#else
  return false;
#endif
}

void check_fits_in_memory(double bytes, const std::string& what) {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return;
  const double total = static_cast<double>(pages) * static_cast<double>(page);
  LFNET_CHECK_AS(ConfigError, bytes <= total, what, " needs ", std::round(bytes / 1e8) / 10,
                 " GB of memory, more than this machine's ", std::round(total / 1e8) / 10, " GB");
}

void release_free_memory() {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  // Only when much is free: returned pages are faulted in again when reused, which costs more
  // than it saves for a small light field (a tenth of a second of `evaluate` on 593 x 840 views).
  constexpr size_t kWorthReleasing = size_t{256} << 20;
  if (mallinfo2().fordblks >= kWorthReleasing) malloc_trim(0);
#elif defined(__GLIBC__)
  malloc_trim(0);
#endif
}

c10::Device parse_device(const std::string& name) {
  const bool cuda = name == "cuda" || name.rfind("cuda:", 0) == 0;
  LFNET_CHECK_AS(ConfigError, name == "cpu" || cuda, "unknown device '", name,
                 "' (known: cpu, cuda, cuda:K)");
  if (!cuda) return c10::Device(c10::kCPU);
  LFNET_CHECK_AS(ConfigError, torch::cuda::is_available(), "device '", name,
                 "' asked for, but CUDA is not available (this LibTorch was "
                 "built without CUDA or the machine has no GPU); use --device cpu");
  try {
    c10::Device device(name);
    LFNET_CHECK_AS(ConfigError, device.index() < static_cast<int>(torch::cuda::device_count()),
                   "device '", name, "': this machine has ", torch::cuda::device_count(),
                   " CUDA device(s)");
    return device;
  } catch (const c10::Error& e) {
    throw ConfigError("device '" + name + "' is not a valid device name");
  }
}

}  // namespace lfnet

// Dynamic work sharing over std::threads: the dict area's per-signal loops, and file tasks (one
// image to read, encode or write each) in io.
#pragma once

#include <ATen/Parallel.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace lfnet {

// Calls fn(begin, end) on chunks of `grain` indices of [0, n) on `threads` threads (0: LibTorch's
// intra-op thread count), the calling thread among them. Chunks are handed out one at a time and
// idle threads block in join() rather than spin, so a thread that the OS deschedules on a busy
// machine does not hold the others at a barrier (as static OpenMP splits do). The first exception
// is rethrown.
template <typename Fn>
void parallel_chunks(int64_t n, int64_t grain, const Fn& fn, int threads_wanted = 0) {
  if (n <= 0) return;
  grain = std::max<int64_t>(1, grain);
  const int64_t chunks = (n + grain - 1) / grain;
  const int64_t threads =
      std::min<int64_t>(threads_wanted > 0 ? threads_wanted : at::get_num_threads(), chunks);
  if (threads <= 1) {
    fn(int64_t{0}, n);
    return;
  }
  std::atomic<int64_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&]() {
    try {
      for (;;) {
        const int64_t begin = next.fetch_add(grain);
        if (begin >= n) break;
        fn(begin, std::min(n, begin + grain));
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next.store(n);
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(static_cast<size_t>(threads - 1));
  for (int64_t i = 1; i < threads; ++i) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace lfnet

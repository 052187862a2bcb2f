// Independent file tasks (one image to read, encode or write each) on a few threads.
#pragma once

#include <cstdint>
#include <functional>

namespace lfnet::io {

// Runs task(0) .. task(count - 1) on up to `threads` threads (0: LibTorch's thread count), the
// calling thread among them. The first exception stops the tasks not yet started and is passed
// on once every thread has finished.
void for_each_task(int64_t count, int threads, const std::function<void(int64_t)>& task);

}  // namespace lfnet::io

#include "lfnet/core/runtime.h"

#include <torch/torch.h>

#include <algorithm>
#include <thread>

namespace lfnet {

int configure_threads(int requested) {
  int n = requested > 0 ? requested : static_cast<int>(std::thread::hardware_concurrency());
  n = std::max(1, n);
  torch::set_num_threads(n);
  return torch::get_num_threads();
}

int thread_count() { return torch::get_num_threads(); }

}  // namespace lfnet

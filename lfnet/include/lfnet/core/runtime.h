// Process-wide runtime settings: thread counts.
#pragma once

namespace lfnet {

// Sets LibTorch's intra-op threads to `requested`, or to every hardware core when
// `requested` <= 0 (LibTorch here starts with one). Returns the count in effect.
int configure_threads(int requested);

// The intra-op thread count in effect.
int thread_count();

}  // namespace lfnet

// Process-wide runtime settings: thread counts and the compute device.
#pragma once

#include <c10/core/Device.h>

#include <string>

namespace lfnet {

// Sets LibTorch's intra-op threads to `requested`; when `requested` <= 0, to OMP_NUM_THREADS
// if that is a positive count, else to every hardware core (LibTorch here starts with one).
// Returns the count in effect.
int configure_threads(int requested);

// The intra-op thread count in effect.
int thread_count();

// Makes glibc's malloc keep large blocks (up to 1 GB) in its heap and reuse them rather than
// map fresh zero-filled pages for every large tensor and unmap them when freed: batched
// inference allocates the same few tens to hundreds of MB per batch, and the page faults cost
// as much CPU time as the arithmetic (docs/performance.md, section 3). Returns false where
// the C library has no such settings, or MALLOC_MMAP_THRESHOLD_ in the environment already
// chose. Call once, before the work starts; a program's choice, not a library's.
bool configure_allocator();

// Returns the memory malloc holds free to the system (glibc's malloc_trim; nothing elsewhere).
// With configure_allocator's settings freed blocks stay in the heap for reuse, so a command
// that goes from one large phase to another (reconstruct, then write) calls this between them:
// what the last phase freed then does not add to the next one's peak. Does nothing while less
// than 256 MB is free.
void release_free_memory();

// Refuses work whose arrays would not fit in this machine's memory before they are allocated:
// a ConfigError that names `what` (the flag that asked for it), the bytes it needs and the bytes
// the machine has. Where the machine's memory cannot be read, nothing is refused.
void check_fits_in_memory(double bytes, const std::string& what);

// "cpu" or "cuda" (or "cuda:K") as a device. Throws ConfigError for other names and for CUDA
// when this LibTorch has no CUDA or the machine no GPU, saying which.
c10::Device parse_device(const std::string& name);

}  // namespace lfnet

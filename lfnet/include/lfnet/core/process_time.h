// The time a command has taken as its user sees it: from the start of the process, loading
// LibTorch included, to now (records' end_to_end_seconds, docs/reconstruction.md).
#pragma once

namespace lfnet {

// Seconds since this process started (the kernel's start time of the process; where that cannot
// be read, since the library was loaded, which is within milliseconds of it).
double process_seconds();

}  // namespace lfnet

// The library's version, recorded in every output it writes: the project's VERSION in the
// top-level CMakeLists.txt, passed in as LFNET_VERSION.
#pragma once

namespace lfnet {

constexpr const char* kVersion = LFNET_VERSION;

}  // namespace lfnet

// The library's version, recorded in every output it writes.
#pragma once

namespace lfnet {

constexpr const char* kVersion = "0.1.0";

}  // namespace lfnet

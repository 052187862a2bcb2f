// Mathematical constants shared across areas (C++17 has no std::numbers).
#pragma once

namespace lfnet {

inline constexpr double kPi = 3.14159265358979323846;

}  // namespace lfnet

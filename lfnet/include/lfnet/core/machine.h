// What the machine is: the CPU's fields in /proc/cpuinfo.
#pragma once

#include <string>

namespace lfnet {

// The value of the first /proc/cpuinfo line whose field is `field` ("model name", "flags"),
// "" where there is none (or no /proc/cpuinfo).
std::string cpu_info(const std::string& field);

}  // namespace lfnet

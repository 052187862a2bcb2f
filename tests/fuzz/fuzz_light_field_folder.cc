// Fuzz target: the light-field folder loader (io::scan_folder and io::read_light_field). The
// input is one image file's bytes behind a 3-byte header that picks the naming scheme, the
// extension and the grid; every view gets those bytes, and header bits drop or truncate one
// view. Any lfnet::Error is a clean rejection; anything else is a finding.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include "lfnet/core/error.h"
#include "lfnet/io/light_field_io.h"

namespace fs = std::filesystem;

namespace {

std::string view_name(int scheme, int64_t u, int64_t v, int64_t cols, const char* ext) {
  char name[96];
  switch (scheme) {
    case 0:
      std::snprintf(name, sizeof name, "lf_%lld_%lld.%s", (long long)u + 1, (long long)v + 1, ext);
      break;
    case 1:
      std::snprintf(name, sizeof name, "input_Cam%03lld.%s", (long long)(u * cols + v), ext);
      break;
    case 2:
      std::snprintf(name, sizeof name, "TM_%02lld_%02lld.%s", (long long)u + 1, (long long)v + 1,
                    ext);
      break;
    default:
      std::snprintf(name, sizeof name, "scene-%02lld.%s", (long long)(u * cols + v + 1), ext);
      break;
  }
  return name;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 3 || size > 65536) return 0;
  // Headers claiming huge images are refused before allocation either way; a low limit keeps
  // the search from spending its time allocating and filling gigabytes.
  lfnet::io::set_image_value_limit(int64_t{1} << 22);
  static const fs::path dir =
      fs::temp_directory_path() / ("lfnet-fuzz-folder-" + std::to_string(::getpid()));
  std::error_code ec;
  fs::remove_all(dir, ec);
  fs::create_directories(dir);
  static const char* kExt[] = {"png", "tif", "exr", "jpg"};
  const int scheme = data[0] & 3;
  const char* ext = kExt[(data[0] >> 2) & 3];
  const bool drop_one = data[0] & 0x10, truncate_one = data[0] & 0x20;
  const int64_t rows = 1 + (data[1] & 3), cols = 1 + ((data[1] >> 2) & 3);
  const size_t cut = data[2];
  const char* bytes = reinterpret_cast<const char*>(data + 3);
  const size_t n = size - 3;
  for (int64_t u = 0; u < rows; ++u) {
    for (int64_t v = 0; v < cols; ++v) {
      const bool last = u == rows - 1 && v == cols - 1;
      if (last && drop_one && rows * cols > 1) continue;
      std::ofstream out(dir / view_name(scheme, u, v, cols, ext), std::ios::binary);
      out.write(bytes, static_cast<std::streamsize>(last && truncate_one ? std::min(n, cut) : n));
    }
  }
  try {
    auto lf = lfnet::io::read_light_field(dir.string(), 1);
    if (lf.data().numel() == 0) std::abort();  // a light field is never empty
  } catch (const lfnet::Error&) {
    // A clear rejection.
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_light_field_folder: unexpected %s exception: %s\n", typeid(e).name(),
                 e.what());
    std::abort();
  }
  fs::remove_all(dir, ec);
  return 0;
}

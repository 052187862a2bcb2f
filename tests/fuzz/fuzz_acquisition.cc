// Fuzz target: the sensor-image loaders. The first input byte picks what the rest becomes:
// 0: sensor.json of an acquisition folder beside a valid 2 x 4 x 5 sensor.tif
//    (io::read_acquisition); 1: that folder's sensor.tif beside its valid sensor.json;
// 2: a camera's plain sensor image (io::read_image_channels); 3: phi.json of a calibrated-Phi
//    folder beside two valid response images (io::read_calibrated_phi, then make_phi).
// Any lfnet::Error is a clean rejection; anything else is a finding.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>

#include <unistd.h>

#include "lfnet/core/error.h"
#include "lfnet/core/version.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/phi_io.h"
#include "lfnet/io/sensor_io.h"

namespace fs = std::filesystem;

namespace {

void write(const fs::path& path, const uint8_t* data, size_t size) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
}

std::string valid_sidecar() {
  return R"({"format": "lfnet-acquisition", "format_version": 1, "mode": "sensor",
  "phi": {"name": "asp", "n": 2, "rows": 5, "cols": 5, "seed": 0, "params": {}},
  "light_field": {"channels": 1, "rows": 5, "cols": 5, "height": 4, "width": 5},
  "sensor": {"files": ["sensor.tif"], "channels_per_file": 2, "dtype": "float32",
             "shape": [1, 2, 4, 5]}})";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > 65536) return 0;
  lfnet::io::set_image_value_limit(int64_t{1} << 22);
  static const fs::path dir =
      fs::temp_directory_path() / ("lfnet-fuzz-acquisition-" + std::to_string(::getpid()));
  // The valid files, made once and kept in memory: each run writes them with plain writes
  // (a file copy may be interrupted by libFuzzer's timer signal).
  static const std::map<std::string, std::string> good = [] {
    const fs::path g = dir / "good";
    fs::create_directories(g / "phi");
    lfnet::io::write_sensor_images(g.string(), torch::rand({1, 2, 4, 5}));
    lfnet::io::write_calibrated_phi(
        *lfnet::optics::make_phi(lfnet::optics::PhiSpec::parse("asp:2")), (g / "phi").string());
    std::map<std::string, std::string> files;
    for (const char* f : {"sensor.tif", "phi/response_1.tif", "phi/response_2.tif"}) {
      std::ifstream in(g / f, std::ios::binary);
      files[f] = std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    std::error_code removed;
    fs::remove_all(g, removed);
    return files;
  }();
  auto put = [](const fs::path& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary) << bytes;
  };
  const fs::path work = dir / "work";
  std::error_code ec;
  fs::remove_all(work, ec);
  fs::create_directories(work);
  const int mode = data[0] & 3;
  const uint8_t* rest = data + 1;
  const size_t n = size - 1;
  try {
    switch (mode) {
      case 0: {
        put(work / "sensor.tif", good.at("sensor.tif"));
        write(work / "sensor.json", rest, n);
        (void)lfnet::io::read_acquisition(work.string());
        break;
      }
      case 1: {
        write(work / "sensor.tif", rest, n);
        std::ofstream(work / "sensor.json") << valid_sidecar();
        (void)lfnet::io::read_acquisition(work.string());
        break;
      }
      case 2: {
        write(work / "image.tif", rest, n);
        (void)lfnet::io::read_image_channels((work / "image.tif").string());
        break;
      }
      default: {
        for (const char* f : {"response_1.tif", "response_2.tif"}) {
          put(work / f, good.at(std::string("phi/") + f));
        }
        write(work / "phi.json", rest, n);
        const auto spec = lfnet::io::read_calibrated_phi(work.string());
        if (spec.name != "calibrated") std::abort();
        break;
      }
    }
  } catch (const lfnet::Error&) {
    // A clear rejection.
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_acquisition: unexpected %s exception: %s\n", typeid(e).name(),
                 e.what());
    std::abort();
  }
  fs::remove_all(dir, ec);  // nothing left behind in the temporary folder
  return 0;
}

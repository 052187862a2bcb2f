// The acquisition folder: what `lfnet simulate` writes and `lfnet reconstruct` reads. The
// format is described in docs/acquisition.md.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace lfnet::io {

constexpr int kAcquisitionFormatVersion = 1;
constexpr const char* kAcquisitionFormat = "lfnet-acquisition";
constexpr const char* kSidecarName = "sensor.json";
constexpr const char* kMeasurementsName = "measurements.f32";

// One acquisition folder in memory.
struct Acquisition {
  nlohmann::json meta;         // sensor.json: phi, mode, effects, seed, shapes, grid, source ...
  torch::Tensor sensor;        // sensor mode: (C, N, H, W) float32; undefined otherwise
  torch::Tensor measurements;  // per_patch mode: (C, P, N h w) float32; undefined otherwise
};

// The sensor image files of C colour channels: {"sensor.tif"} or {"sensor_r.tif", ...}.
std::vector<std::string> sensor_file_names(int64_t channels);

// Writes a sensor image (C, N, H, W) into `dir`: one float32 TIFF of N channels per colour
// channel, and preview.png (measurement channel 0 of the first colour channel, clipped to
// [0, 1], 8-bit) for people to look at.
void write_sensor_images(const std::string& dir, const torch::Tensor& sensor);

// Reads every channel of an image as stored: (C, H, W) float32 (no alpha is dropped).
torch::Tensor read_image_channels(const std::string& path);

// Decodes a one-channel image straight into `plane`, a contiguous (H, W) float32 tensor of
// its size (e.g. one view of a light field being read: no copy of it is made), and returns its
// (min, max). Returns nothing, having decoded nothing, when the file has other channels or
// another size. Refuses what read_image_channels refuses.
std::optional<std::pair<double, double>> read_grey_image_into(const std::string& path,
                                                              const torch::Tensor& plane);

// A raw little-endian float32 file of shape (C, P, M) written in bands of patches, so per-patch
// measurements never need to be in memory at once.
class MeasurementWriter {
 public:
  MeasurementWriter(const std::string& path, int64_t channels, int64_t patches, int64_t values);
  // Writes patches [patch_begin, patch_begin + p) of every channel from a (C, p, M) tensor.
  void write(const torch::Tensor& band, int64_t patch_begin);
  // Flushes and closes; throws IoError when the file is incomplete.
  void close();

 private:
  std::string path_;
  std::ofstream out_;
  int64_t channels_, patches_, values_;
};

// Reads patches [patch_begin, patch_end) of a raw (C, P, M) float32 measurement file:
// (C, patch_end - patch_begin, M). Checks the file size against the shape.
torch::Tensor read_measurements(const std::string& path, int64_t channels, int64_t patches,
                                int64_t values, int64_t patch_begin = 0, int64_t patch_end = -1);

// Reads an acquisition folder: its sidecar, then the sensor image or the measurements, checking
// the format, version and every shape the sidecar states. Throws IoError naming the file.
Acquisition read_acquisition(const std::string& dir);

}  // namespace lfnet::io

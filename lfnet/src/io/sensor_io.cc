#include "lfnet/io/sensor_io.h"

#include <OpenImageIO/imageio.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/io/light_field_io.h"

namespace fs = std::filesystem;

namespace lfnet::io {

namespace {

bool little_endian() {
  const uint16_t probe = 1;
  return *reinterpret_cast<const uint8_t*>(&probe) == 1;
}

// Reads an integer array field of the sidecar; throws IoError naming the file and field.
std::vector<int64_t> shape_field(const nlohmann::json& meta, const std::string& key,
                                 const std::string& sidecar) {
  try {
    return meta.at(key).at("shape").get<std::vector<int64_t>>();
  } catch (const nlohmann::json::exception& e) {
    throw IoError(sidecar + ": missing or malformed " + key + ".shape (" + e.what() + ")");
  }
}

// libpng reports a PNG cut short on stderr itself before OIIO sees the error, which would add
// a line to lfnet's one-line errors. A PNG ends with its IEND chunk, so a truncated one is
// recognised here first.
void check_png_complete(const std::string& path) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  static const unsigned char kEnd[12] = {0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xae, 0x42, 0x60, 0x82};
  std::ifstream in(path, std::ios::binary);
  unsigned char head[8] = {}, tail[12] = {};
  if (!in.read(reinterpret_cast<char*>(head), 8) || std::memcmp(head, kSignature, 8) != 0) return;
  in.seekg(-12, std::ios::end);
  const bool complete =
      in.read(reinterpret_cast<char*>(tail), 12) && std::memcmp(tail, kEnd, 12) == 0;
  LFNET_CHECK_AS(IoError, complete, "cannot read image ", path,
                 ": the PNG file is truncated (it does not end with an IEND chunk)");
}

std::atomic<int64_t> g_image_value_limit{int64_t{1} << 30};

}  // namespace

void set_image_value_limit(int64_t values) {
  LFNET_CHECK(values > 0, "the image value limit must be positive, got ", values);
  g_image_value_limit = values;
}

int64_t image_value_limit() { return g_image_value_limit; }

std::vector<std::string> sensor_file_names(int64_t channels) {
  if (channels == 1) return {"sensor.tif"};
  LFNET_CHECK(channels == 3, "sensor images have 1 or 3 colour channels, got ", channels);
  return {"sensor_r.tif", "sensor_g.tif", "sensor_b.tif"};
}

void write_sensor_images(const std::string& dir, const torch::Tensor& sensor) {
  LFNET_CHECK(sensor.dim() == 4, "a sensor image is (C, N, H, W)");
  const auto names = sensor_file_names(sensor.size(0));
  for (size_t c = 0; c < names.size(); ++c) {
    write_image((fs::path(dir) / names[c]).string(), sensor[static_cast<int64_t>(c)], 32);
  }
  write_image((fs::path(dir) / "preview.png").string(), sensor[0][0].clamp(0, 1), 8);
}

namespace {

// Opens an image and checks its header: a corrupt one can claim any size, so what no light
// field view needs is refused before anything is allocated.
std::unique_ptr<OIIO::ImageInput> open_image(const std::string& path) {
  // Keep alpha as stored: colour channels are read as they are, never premultiplied.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  check_regular_input(path);
  check_png_complete(path);
  auto input = OIIO::ImageInput::open(path, &config);
  if (!input) throw IoError("cannot read image " + path + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = input->spec();
  const int64_t h = spec.height, w = spec.width, nc = spec.nchannels;
  LFNET_CHECK_AS(IoError, h > 0 && w > 0 && nc > 0, "image ", path, " is empty");
  LFNET_CHECK_AS(IoError, nc <= 64 && h * w <= image_value_limit() / nc, "image ", path, " claims ",
                 w, "x", h, " pixels with ", nc,
                 " channels, more than lfnet reads (corrupt header?)");
  return input;
}

// Decodes every channel of an open image as float32 into `pixels` (H * W * C, interleaved).
void decode(OIIO::ImageInput& input, const std::string& path, float* pixels) {
  if (!input.read_image(0, 0, 0, input.spec().nchannels, OIIO::TypeDesc::FLOAT, pixels)) {
    std::string err = input.geterror();
    throw IoError("cannot decode image " + path + " (truncated or corrupt?): " + err);
  }
  input.close();
}

// Refuses NaN and infinite values; aminmax propagates them, and needs no mask of the image.
std::pair<double, double> finite_range(const torch::Tensor& pixels, const std::string& path) {
  const auto [lo, hi] = torch::aminmax(pixels);
  const double min = lo.item<double>(), max = hi.item<double>();
  LFNET_CHECK_AS(IoError, std::isfinite(min) && std::isfinite(max), "image ", path,
                 " holds NaN or infinite values");
  return {min, max};
}

}  // namespace

torch::Tensor read_image_channels(const std::string& path) {
  auto input = open_image(path);
  const OIIO::ImageSpec& spec = input->spec();
  auto pixels = torch::empty({spec.height, spec.width, spec.nchannels}, torch::kFloat32);
  decode(*input, path, pixels.data_ptr<float>());
  finite_range(pixels, path);
  return pixels.permute({2, 0, 1}).contiguous();
}

std::optional<std::pair<double, double>> read_grey_image_into(const std::string& path,
                                                              const torch::Tensor& plane) {
  LFNET_CHECK(plane.dim() == 2 && plane.is_contiguous() && plane.scalar_type() == torch::kFloat32,
              "read_grey_image_into: expected a contiguous (H, W) float32 plane");
  auto input = open_image(path);
  const OIIO::ImageSpec& spec = input->spec();
  if (spec.nchannels != 1 || spec.height != plane.size(0) || spec.width != plane.size(1)) {
    return std::nullopt;
  }
  decode(*input, path, plane.data_ptr<float>());
  return finite_range(plane, path);
}

MeasurementWriter::MeasurementWriter(const std::string& path, int64_t channels, int64_t patches,
                                     int64_t values)
    : path_(path), channels_(channels), patches_(patches), values_(values) {
  LFNET_CHECK_AS(IoError, little_endian(),
                 "raw measurement files are little-endian; this "
                 "machine is not");
  out_.open(path, std::ios::binary | std::ios::trunc);
  LFNET_CHECK_AS(IoError, out_.good(), "cannot write ", path, ": ", std::strerror(errno));
  // Size the file up front, so bands can be written in place.
  const auto bytes = static_cast<std::streamoff>(channels * patches * values * 4);
  if (bytes > 0) {
    out_.seekp(bytes - 1);
    out_.put('\0');
  }
  LFNET_CHECK_AS(IoError, out_.good(), "cannot write ", path, ": ", std::strerror(errno));
}

void MeasurementWriter::write(const torch::Tensor& band, int64_t patch_begin) {
  LFNET_CHECK(band.dim() == 3 && band.size(0) == channels_ && band.size(2) == values_ &&
                  patch_begin >= 0 && patch_begin + band.size(1) <= patches_,
              "measurement band of shape ", band.sizes(), " at patch ", patch_begin,
              " does not fit a (", channels_, ", ", patches_, ", ", values_, ") file");
  auto data = band.to(torch::kFloat32).contiguous();
  const int64_t p = data.size(1);
  for (int64_t c = 0; c < channels_; ++c) {
    out_.seekp(static_cast<std::streamoff>(((c * patches_) + patch_begin) * values_ * 4));
    out_.write(reinterpret_cast<const char*>(data[c].data_ptr<float>()),
               static_cast<std::streamsize>(p * values_ * 4));
  }
  LFNET_CHECK_AS(IoError, out_.good(), "cannot write ", path_, ": ", std::strerror(errno));
}

void MeasurementWriter::close() {
  out_.close();
  LFNET_CHECK_AS(IoError, !out_.fail(), "cannot write ", path_, ": ", std::strerror(errno));
}

torch::Tensor read_measurements(const std::string& path, int64_t channels, int64_t patches,
                                int64_t values, int64_t patch_begin, int64_t patch_end) {
  if (patch_end < 0) patch_end = patches;
  LFNET_CHECK(patch_begin >= 0 && patch_begin <= patch_end && patch_end <= patches, "patches [",
              patch_begin, ", ", patch_end, ") outside [0, ", patches, ")");
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot read ", path, ": ", ec.message());
  const auto want = static_cast<uintmax_t>(channels * patches * values * 4);
  LFNET_CHECK_AS(IoError, size == want, path, " holds ", size, " bytes, but its shape (", channels,
                 ", ", patches, ", ", values, ") float32 needs ", want,
                 " (truncated or not this acquisition's file?)");
  std::ifstream in(path, std::ios::binary);
  LFNET_CHECK_AS(IoError, in.good(), "cannot read ", path);
  const int64_t p = patch_end - patch_begin;
  auto out = torch::empty({channels, p, values}, torch::kFloat32);
  for (int64_t c = 0; c < channels; ++c) {
    in.seekg(static_cast<std::streamoff>(((c * patches) + patch_begin) * values * 4));
    in.read(reinterpret_cast<char*>(out[c].data_ptr<float>()),
            static_cast<std::streamsize>(p * values * 4));
  }
  LFNET_CHECK_AS(IoError, in.good(), "cannot read ", path);
  return out;
}

Acquisition read_acquisition(const std::string& dir) {
  const std::string sidecar = (fs::path(dir) / kSidecarName).string();
  LFNET_CHECK_AS(IoError, fs::is_regular_file(sidecar), "no ", kSidecarName, " in ", dir,
                 ": not an acquisition folder written by lfnet simulate");
  Acquisition a;
  a.meta = read_json_file(sidecar);
  try {
    const auto format = a.meta.at("format").get<std::string>();
    const int version = a.meta.at("format_version").get<int>();
    LFNET_CHECK_AS(IoError, format == kAcquisitionFormat, sidecar, ": format '", format,
                   "' is not ", kAcquisitionFormat);
    LFNET_CHECK_AS(IoError, version == kAcquisitionFormatVersion, sidecar, ": format version ",
                   version, " is not the supported ", kAcquisitionFormatVersion);
    const auto mode = a.meta.at("mode").get<std::string>();
    const auto& lf = a.meta.at("light_field");
    const int64_t c = lf.at("channels").get<int64_t>(), h = lf.at("height").get<int64_t>(),
                  w = lf.at("width").get<int64_t>();
    const int64_t n = a.meta.at("phi").at("n").get<int64_t>();
    if (mode == "sensor") {
      const auto files = a.meta.at("sensor").at("files").get<std::vector<std::string>>();
      // A colour filter array puts every colour on one sensor: one file.
      const int64_t expected = a.meta.contains("cfa") ? 1 : c;
      LFNET_CHECK_AS(IoError, static_cast<int64_t>(files.size()) == expected, sidecar, ": ", c,
                     " colour channels",
                     a.meta.contains("cfa") ? " behind a colour filter array" : "", " but ",
                     files.size(), " sensor files");
      std::vector<torch::Tensor> images;
      for (const auto& name : files) {
        const std::string path = (fs::path(dir) / name).string();
        auto image = read_image_channels(path);
        LFNET_CHECK_AS(IoError, image.size(0) == n && image.size(1) == h && image.size(2) == w,
                       path, " is ", image.size(0), " x ", image.size(1), " x ", image.size(2),
                       " (N x H x W), but ", kSidecarName, " says ", n, " x ", h, " x ", w);
        images.push_back(image);
      }
      // One colour channel needs no stacked copy.
      a.sensor = images.size() == 1 ? images[0].unsqueeze(0) : torch::stack(images);
    } else if (mode == "per_patch") {
      auto shape = shape_field(a.meta, "measurements", sidecar);
      LFNET_CHECK_AS(IoError, shape.size() == 3 && shape[0] == c, sidecar,
                     ": measurements.shape must be [C, P, N h w]");
      const auto name = a.meta.at("measurements").at("file").get<std::string>();
      a.measurements =
          read_measurements((fs::path(dir) / name).string(), shape[0], shape[1], shape[2]);
    } else {
      throw IoError(sidecar + ": unknown mode '" + mode + "' (known: sensor, per_patch)");
    }
  } catch (const nlohmann::json::exception& e) {
    throw IoError(sidecar + ": missing or malformed field (" + e.what() + ")");
  }
  return a;
}

}  // namespace lfnet::io

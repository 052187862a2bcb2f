#include "lfnet/io/phi_io.h"

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/sequence.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/cfa.h"

namespace fs = std::filesystem;

namespace lfnet::io {

namespace {

std::string response_name(int64_t n) { return "response_" + std::to_string(n + 1) + ".tif"; }

// (H, W) float64 as a one-channel float64 TIFF, written atomically.
void write_double_tiff(const std::string& path, const torch::Tensor& image) {
  auto data = image.to(torch::kFloat64).contiguous();
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw IoError("cannot write " + path + ": no TIFF writer");
  OIIO::ImageSpec spec(static_cast<int>(data.size(1)), static_cast<int>(data.size(0)), 1,
                       OIIO::TypeDesc::DOUBLE);
  write_file_atomically(path, [&](const std::string& tmp) {
    const bool ok = out->open(tmp, spec) &&
                    out->write_image(OIIO::TypeDesc::DOUBLE, data.data_ptr<double>()) &&
                    out->close();
    if (!ok) throw IoError("cannot write " + path + ": " + out->geterror());
  });
}

// One-channel image of exactly (h, w) pixels as float64: float files as stored, integer ones
// scaled to [0, 1] (0 .. 255 or 0 .. 65535 map to 0 .. 1).
torch::Tensor read_response(const std::string& path, int64_t h, int64_t w) {
  std::error_code ec;
  LFNET_CHECK_AS(IoError, fs::is_regular_file(path, ec), path, " does not exist");
  auto input = OIIO::ImageInput::open(path);
  if (!input) throw IoError("cannot read image " + path + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = input->spec();
  LFNET_CHECK_AS(IoError, spec.nchannels == 1 && spec.height == h && spec.width == w, path,
                 " must be one channel of ", w, "x", h, " pixels (T V x T U), got ", spec.width,
                 "x", spec.height, " with ", spec.nchannels, " channels");
  auto pixels = torch::empty({h, w}, torch::kFloat64);
  if (!input->read_image(0, 0, 0, 1, OIIO::TypeDesc::DOUBLE, pixels.data_ptr<double>())) {
    throw IoError("cannot decode image " + path + " (truncated or corrupt?): " + input->geterror());
  }
  input->close();
  return pixels;
}

// The sidecar of a calibrated Phi named by its folder or by the sidecar file itself; the
// response images lie beside it.
fs::path sidecar_of(const std::string& path) {
  std::error_code ec;
  return fs::is_directory(path, ec) ? fs::path(path) / kCalibratedPhiSidecar : fs::path(path);
}

}  // namespace

bool is_calibrated_phi(const std::string& path) {
  std::error_code ec;
  // A JSON file is a calibrated Phi's sidecar when it says so (a Phi spec file may be called
  // phi.json too); a folder is one when its phi.json is.
  const fs::path sidecar = sidecar_of(path);
  if (!fs::is_regular_file(sidecar, ec) || sidecar.extension() != ".json") return false;
  try {
    const auto j = read_json_file(sidecar.string());
    return j.is_object() && j.contains("format") && j["format"].is_string() &&
           j["format"].get<std::string>() == kCalibratedPhiFormat;
  } catch (const Error&) {
    return false;
  }
}

void write_calibrated_phi(const optics::Phi& phi, const std::string& dir) {
  LFNET_CHECK_AS(ConfigError, phi.local(), "Phi '", phi.spec().label(),
                 "' is not local (each measurement mixes a whole block of pixels) and has no "
                 "per-pixel response to write");
  const int64_t t = phi.period(), n = phi.measurements(), u = phi.rows(), v = phi.cols();
  auto code = phi.pixel_weights(0, 0, t, t, torch::kFloat64);  // (N, U, V, T, T)
  nlohmann::json files = nlohmann::json::array();
  fs::create_directories(dir);
  for (int64_t k = 0; k < n; ++k) {
    // (U, V, T, T) -> (T, U, T, V) -> (T U, T V): pixel (y, x)'s views form one U x V block.
    auto image = code[k].permute({2, 0, 3, 1}).reshape({t * u, t * v});
    write_double_tiff((fs::path(dir) / response_name(k)).string(), image);
    files.push_back(response_name(k));
  }
  nlohmann::json meta = {{"format", kCalibratedPhiFormat},
                         {"version", kCalibratedPhiFormatVersion},
                         {"n", n},
                         {"rows", phi.spec().rows},
                         {"cols", v},
                         {"period", t},
                         {"files", files},
                         {"scale", 1.0},
                         {"normalise", false},
                         {"source", phi.spec().label()},
                         {"exported_from", phi.spec().to_json()}};
  // A time-coded camera's response stacks its sub-frames' views along the rows.
  if (phi.frames() > 1) meta["frames"] = phi.frames();
  if (const auto cfa = optics::camera_cfa(phi.spec().to_json())) meta["cfa"] = cfa->to_json();
  write_json_file((fs::path(dir) / kCalibratedPhiSidecar).string(), meta);
}

std::vector<std::string> write_printable_mask(const optics::Phi& phi, const std::string& dir) {
  LFNET_CHECK_AS(ConfigError, phi.local(), "Phi '", phi.spec().label(),
                 "' is not local and has no mask to print");
  const int64_t t = phi.period(), n = phi.measurements(), u = phi.rows(), v = phi.cols();
  const auto code = phi.pixel_weights(0, 0, t, t, torch::kFloat64);  // (N, U, V, T, T)
  LFNET_CHECK_AS(ConfigError, code.min().item<double>() >= 0, "Phi '", phi.spec().label(),
                 "' has negative weights: no transmittance makes them, so there is no mask to "
                 "print");
  const double top = code.max().item<double>();
  LFNET_CHECK_AS(ConfigError, top > 0, "Phi '", phi.spec().label(), "' measures nothing");
  std::vector<std::string> names;
  fs::create_directories(dir);
  for (int64_t k = 0; k < n; ++k) {
    const auto image = (code[k] / top).permute({2, 0, 3, 1}).reshape({t * u, t * v});
    names.push_back("mask_" + std::to_string(k + 1) + ".png");
    write_image((fs::path(dir) / names.back()).string(), image.to(torch::kFloat32), 8);
  }
  return names;
}

bool is_learned_mask(const optics::Phi& phi) {
  const auto& spec = phi.spec();
  if (spec.name != "calibrated" || !spec.params.contains("source")) return false;
  const auto& source = spec.params["source"];
  if (!source.is_string()) return false;
  const auto text = source.get<std::string>();
  return text.rfind("learned mask", 0) == 0 || text.rfind("learned aperture", 0) == 0;
}

optics::PhiSpec read_calibrated_phi(const std::string& path) {
  const std::string sidecar = sidecar_of(path).string();
  const fs::path dir = fs::path(sidecar).parent_path();
  std::error_code ec;
  LFNET_CHECK_AS(IoError, fs::is_regular_file(sidecar, ec), path,
                 " is not a calibrated Phi (no phi.json)");
  const auto meta = read_json_file(sidecar);
  LFNET_CHECK_AS(IoError, meta.is_object(), sidecar, ": expected a JSON object");
  std::string format;
  int64_t version = 0, n = 0, rows = 0, cols = 0, period = 1, frames = 1;
  std::vector<std::string> file_names;
  double scale = 1.0;
  bool normalise = true;
  std::string source;
  nlohmann::json exported_from, cfa;
  try {
    JsonReader r(meta, sidecar + ":$");
    r.require("format", format);
    r.require("version", version);
    r.require("n", n);
    r.require("rows", rows);
    r.require("cols", cols);
    r.get("frames", frames);
    r.get("period", period);
    r.require("files", file_names);
    r.get("scale", scale);
    r.get("normalise", normalise);
    r.get("source", source);
    r.get("exported_from", exported_from);
    r.get("cfa", cfa);
    r.finish();
    if (!cfa.is_null())
      cfa = optics::ColourFilterArray::from_json(cfa, sidecar + ":$.cfa").to_json();
  } catch (const ConfigError& e) {
    throw IoError(e.what());
  }
  LFNET_CHECK_AS(IoError, format == kCalibratedPhiFormat, sidecar, ": format is \"", format,
                 "\", expected \"", kCalibratedPhiFormat, "\"");
  LFNET_CHECK_AS(IoError, version == kCalibratedPhiFormatVersion, sidecar, ": version ", version,
                 " is not supported (this lfnet reads version ", kCalibratedPhiFormatVersion, ")");
  LFNET_CHECK_AS(
      IoError, rows >= 1 && cols >= 1 && rows <= optics::kMaxViews && cols <= optics::kMaxViews,
      sidecar, ": rows and cols must be in 1..", optics::kMaxViews, ", got ", rows, "x", cols);
  LFNET_CHECK_AS(IoError, frames >= 1 && frames <= kMaxFrames, sidecar, ": frames must be in 1..",
                 kMaxFrames, ", got ", frames);
  LFNET_CHECK_AS(IoError, n >= 1 && n <= frames * rows * cols, sidecar, ": n must be in 1..",
                 frames * rows * cols, ", got ", n);
  LFNET_CHECK_AS(IoError, period >= 1 && period <= 64, sidecar, ": period must be in 1..64, got ",
                 period);
  LFNET_CHECK_AS(IoError, static_cast<int64_t>(file_names.size()) == n, sidecar, ": files lists ",
                 file_names.size(), " images, but n is ", n, " (one image per measurement)");
  LFNET_CHECK_AS(IoError, std::isfinite(scale) && scale > 0, sidecar,
                 ": scale must be a positive number, got ", scale);
  std::vector<torch::Tensor> responses;
  for (const auto& name : file_names) {
    LFNET_CHECK_AS(IoError, !name.empty() && fs::path(name).filename() == fs::path(name), sidecar,
                   ": files must name images inside the folder, got \"", name, "\"");
    auto image = read_response((dir / name).string(), period * frames * rows, period * cols);
    // A measurement that responds to no ray records nothing: a failed or unexposed capture.
    LFNET_CHECK_AS(IoError, image.ne(0).any().item<bool>(), (dir / name).string(),
                   " is zero everywhere: its measurement would record nothing (recalibrate, or "
                   "leave the measurement out and lower n in ",
                   sidecar, ")");
    // (T U, T V) -> (T, U, T, V) -> (U, V, T, T)
    responses.push_back(image.view({period, frames * rows, period, cols}).permute({1, 3, 0, 2}) *
                        scale);
  }
  auto code = torch::stack(responses).contiguous();
  optics::PhiSpec spec;
  spec.name = "calibrated";
  spec.n = n;
  spec.rows = rows;
  spec.cols = cols;
  spec.frames = frames;
  spec.params = {{"period", period},
                 {"weights", std::vector<double>(code.data_ptr<double>(),
                                                 code.data_ptr<double>() + code.numel())},
                 {"normalise", normalise}};
  if (!source.empty()) spec.params["source"] = source;
  if (!cfa.is_null()) spec.params["cfa"] = cfa;
  try {
    return optics::make_phi(spec)->spec();
  } catch (const Error& e) {  // a code the Phi refuses, named by its folder
    throw IoError(dir.string() + ": " + e.what());
  }
}

}  // namespace lfnet::io

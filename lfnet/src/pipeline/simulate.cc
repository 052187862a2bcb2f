#include "lfnet/pipeline/simulate.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/patches.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/core/version.h"
#include "lfnet/io/sensor_io.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

nlohmann::json write_acquisition(const SimulateRequest& r, const std::string& dir) {
  LFNET_CHECK(r.phi != nullptr, "write_acquisition needs a Phi");
  LFNET_CHECK_AS(ConfigError, r.patch >= 1 && r.stride >= 1, "the patch and stride must be >= 1");
  const auto& lf = r.lf;
  const auto& phi = *r.phi;
  nlohmann::json meta = {
      {"format", io::kAcquisitionFormat},
      {"format_version", io::kAcquisitionFormatVersion},
      {"lfnet_version", kVersion},
      {"mode", optics::to_string(r.mode)},
      {"phi", phi.spec().to_json()},
      {"effects", r.effects.to_json()},
      {"noise_sigma", r.effects.gaussian ? r.effects.gaussian->sigma : 0.0},
      {"seed", r.seed},
      {"light_field",
       {{"channels", lf.channels()},
        {"rows", lf.rows()},
        {"cols", lf.cols()},
        {"height", lf.height()},
        {"width", lf.width()}}},
      {"views", r.views},
      {"color", lf.channels() == 3},
      {"source", r.source},
  };
  const int64_t n = phi.measurements();
  Stopwatch clock;
  if (r.mode == optics::SimulationMode::kSensor) {
    auto sensor = optics::simulate_sensor(phi, lf.data(), r.effects, r.seed);  // (C, N, H, W)
    meta["seconds"] = clock.seconds();
    io::write_sensor_images(dir, sensor);
    meta["sensor"] = {{"files", io::sensor_file_names(lf.channels())},
                      {"channels_per_file", n},
                      {"dtype", "float32"},
                      {"shape", {lf.channels(), n, lf.height(), lf.width()}}};
    spdlog::info("simulated a {}x{}x{} sensor image with {} in {:.3f} s", n, lf.height(),
                 lf.width(), phi.spec().label(), clock.seconds());
  } else {
    const PatchGrid grid(lf.height(), lf.width(), r.patch, r.patch, r.stride);
    const int64_t m = n * r.patch * r.patch, c = lf.channels();
    io::MeasurementWriter writer((fs::path(dir) / io::kMeasurementsName).string(), c, grid.size(),
                                 m);
    const int64_t band = std::max<int64_t>(1, 4096 / std::max<int64_t>(1, grid.cols()));
    ProgressBar bar("simulate", grid.rows(), "rows");
    for (int64_t row = 0; row < grid.rows(); row += band) {
      const int64_t row_end = std::min(grid.rows(), row + band);
      auto values =
          optics::measure_patches(phi, lf.data(), grid, r.mode, r.effects, r.seed, row, row_end)
              .values;
      writer.write(values.view({c, -1, m}), row * grid.cols());
      bar.advance(row_end - row);
    }
    bar.finish();
    writer.close();
    meta["seconds"] = clock.seconds();
    meta["measurements"] = {{"file", io::kMeasurementsName},
                            {"dtype", "float32"},
                            {"byte_order", "little"},
                            {"shape", {c, grid.size(), m}}};
    meta["grid"] = {{"patch", r.patch},      {"stride", r.stride},  {"height", grid.height()},
                    {"width", grid.width()}, {"rows", grid.rows()}, {"cols", grid.cols()}};
    spdlog::info("simulated {} patches of {} measurements with {} ({}) in {:.3f} s",
                 c * grid.size(), m, phi.spec().label(), optics::to_string(r.mode),
                 clock.seconds());
  }
  write_json_file((fs::path(dir) / io::kSidecarName).string(), meta);
  return meta;
}

}  // namespace lfnet::pipeline

// lfnet reconstruct: a light field from the folder `lfnet simulate` writes (or a camera's own
// sensor images with a sidecar of the same format).
#include <spdlog/spdlog.h>

#include <filesystem>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/progress.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/core/runtime.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/methods.h"
#include "lfnet/train/checkpoint.h"
#include "workflow.h"

namespace fs = std::filesystem;

namespace lfnet::app {

namespace {
struct ReconstructArgs {
  std::string model, sensor, out, method = "net", dictionary;
  int64_t stride = 5;
  int64_t batch = 1024;
  bool window = false;
  bool match_mean = false;
  bool force = false;
  std::string device = "cpu";
  std::string cnn_mode = "patches";
  int64_t tile = recon::kDefaultCnnTile;
  std::string precision = "float32";
};

void run_reconstruct(const ReconstructArgs& a) {
  const io::Acquisition acq = io::read_acquisition(a.sensor);
  const auto spec = optics::PhiSpec::from_json(acq.meta.at("phi"), a.sensor + "/sensor.json:$.phi");
  const auto phi = optics::make_phi(spec);
  MethodContext context;
  context.phi = phi.get();
  recon::ReconstructOptions o;
  o.stride = a.stride;
  o.batch = a.batch;
  o.window = a.window;
  recon::PatchSolver solver;
  nn::LightFieldNet net{nullptr};
  const auto device = parse_device(a.device);
  const auto cnn_mode = recon::parse_cnn_mode(a.cnn_mode);
  double train_mean = 0;
  if (recon::needs_network(a.method)) {
    LFNET_CHECK_AS(ConfigError, !a.model.empty(), "method '", a.method, "' needs --model");
    const auto ckpt = train::load_checkpoint(a.model);
    train::check_phi(ckpt, spec.to_json(), a.model);
    net = train::build_net(ckpt, a.model);
    net->to(device);
    nn::set_cnn_precision(net, nn::parse_precision(a.precision));
    o.patch_h = net->options().patch.height;
    o.patch_w = net->options().patch.width;
    solver = recon::network_solver(net, a.method);
    if (ckpt.config.contains("measurement_mean")) train_mean = ckpt.config["measurement_mean"].get<double>();
  } else if (a.method == "pinv" || a.method == "adjoint") {
    solver = recon::linear_solver(*phi, a.method, o.patch_h, o.patch_w);
  } else {
    throw ConfigError("lfnet reconstruct takes --method net, ae, cnn, pinv or adjoint, not '" +
                      a.method + "'");
  }
  const bool full = cnn_mode == recon::CnnMode::kFull;
  LFNET_CHECK_AS(ConfigError, !full || a.method == "net" || a.method == "cnn",
                 "--cnn-mode full needs --method net or cnn, not '", a.method, "'");
  const auto& lf_meta = acq.meta.at("light_field");
  const int64_t c = lf_meta.at("channels").get<int64_t>();
  const int64_t h = lf_meta.at("height").get<int64_t>(), w = lf_meta.at("width").get<int64_t>();
  std::vector<torch::Tensor> channels;
  Stopwatch clock;
  if (acq.sensor.defined()) {
    PatchGrid grid(h, w, o.patch_h, o.patch_w, o.stride);
    ProgressBar bar("reconstruct", c * grid.size(), "patches");
    for (int64_t ch = 0; ch < c; ++ch) {
      auto sensor = acq.sensor[ch].clone();
      if (a.match_mean) {
        LFNET_CHECK_AS(ConfigError, train_mean > 0, "--match-mean needs a model that records its training measurement mean");
        recon::match_mean(sensor, train_mean);
      }
      if (full) {
        channels.push_back(
            recon::reconstruct_sensor_fully_convolutional(net, a.method, *phi, sensor, o, a.tile));
        bar.advance(grid.size());
        continue;
      }
      int64_t shown = 0;
      channels.push_back(recon::reconstruct_sensor(*phi, sensor, solver, o, [&](int64_t done, int64_t) {
        bar.advance(done - shown);
        shown = done;
      }));
    }
  } else {
    const auto& g = acq.meta.at("grid");
    const int64_t patch = g.at("patch").get<int64_t>();
    o.stride = g.at("stride").get<int64_t>();
    LFNET_CHECK_AS(ConfigError, patch == o.patch_h && patch == o.patch_w, "the measurements are of ",
                   patch, "x", patch, " patches but the method reconstructs ", o.patch_h, "x", o.patch_w);
    PatchGrid grid(h, w, patch, patch, o.stride);
    LFNET_CHECK_AS(ConfigError, !full, "--cnn-mode full needs a sensor image, not per-patch measurements");
    spdlog::info("per_patch measurements at stride {} (from {})", o.stride, a.sensor);
    for (int64_t ch = 0; ch < c; ++ch) {
      auto source = [&](int64_t r0, int64_t r1) {
        return optics::PatchMeasurements{
            acq.measurements[ch].slice(0, r0 * grid.cols(), r1 * grid.cols()),
            optics::patch_phases(*phi, grid, r0, r1)};
      };
      channels.push_back(recon::reconstruct_patches(*phi, grid, source, solver, o));
    }
  }
  const double seconds = clock.seconds();
  LightField lf(torch::cat(channels, 0));
  write_folder(a.out, a.force, [&](const std::string& dir) {
    io::write_light_field(lf, dir);
    io::write_previews(lf, dir);
    write_json_file((fs::path(dir) / "reconstruction.json").string(),
                    {{"method", a.method}, {"model", a.model}, {"sensor", a.sensor},
                     {"stride", o.stride}, {"seconds", seconds}, {"phi", spec.to_json()},
                     {"device", a.device}, {"cnn_mode", a.cnn_mode}, {"precision", a.precision},
                     {"mode", acq.meta.value("mode", "sensor")}, {"shape", lf.shape_string()}});
  });
  spdlog::info("reconstructed {} with {} in {:.2f} s into {}", lf.shape_string(), a.method, seconds, a.out);
}
}  // namespace

void add_reconstruct_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand("reconstruct", "Reconstruct a light field from coded measurements (the folder lfnet simulate writes)");
  auto a = std::make_shared<ReconstructArgs>();
  cmd->add_option("--model", a->model, "trained model (checkpoint)");
  cmd->add_option("--sensor", a->sensor, "acquisition folder: sensor.json with sensor.tif or measurements.f32")->required();
  cmd->add_option("--out", a->out, "output light-field folder (views, grid.png, EPIs)")->required();
  cmd->add_option("--stride", a->stride, "patch stride (sensor mode; default 5)")->check(CLI::PositiveNumber);
  cmd->add_option("--method", a->method, "net, ae, cnn, pinv or adjoint (default net)");
  cmd->add_option("--batch", a->batch, "patches per forward pass")->check(CLI::PositiveNumber);
  cmd->add_flag("--window", a->window, "weight patch estimates by a smooth window when stitching");
  cmd->add_flag("--match-mean", a->match_mean, "scale real measurements to the training data's mean (the paper's step)");
  cmd->add_flag("--force", a->force, "replace an existing output folder");
  cmd->add_option("--device", a->device, "cpu or cuda[:K] (default cpu)");
  cmd->add_option("--cnn-mode", a->cnn_mode, "CNN branch per patch ('patches', default) or once over the light field in tiles ('full'; docs/performance.md)")
      ->check(CLI::IsMember({"patches", "full"}));
  cmd->add_option("--tile", a->tile, "tile size of --cnn-mode full (default 128)")->check(CLI::PositiveNumber);
  cmd->add_option("--precision", a->precision, "float32 (default) or bfloat16 for the CNN branch")
      ->check(CLI::IsMember({"float32", "bfloat16"}));
  cmd->callback([a] { run_reconstruct(*a); });
}

}  // namespace lfnet::app

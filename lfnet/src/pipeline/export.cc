#include "lfnet/pipeline/export.h"

#include <torch/torch.h>

#include <cmath>
#include <filesystem>
#include <regex>
#include <utility>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/version.h"
#include "lfnet/io/phi_io.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/train/checkpoint.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// Measurements of random light-field patches in [0, 1] through the net's own patch matrices,
// one phase after another: inputs like those reconstruction gives the net.
std::pair<torch::Tensor, torch::Tensor> check_inputs(const nn::LightFieldNet& net, int64_t count) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(7);
  const int64_t phases = net->phases();
  auto phase = torch::arange(count, torch::kInt64).remainder(phases);
  auto patches = torch::rand({count, net->options().patch.size()}, gen);
  auto y = torch::empty({count, net->options().measurement_size()});
  for (int64_t i = 0; i < count; ++i) y[i] = net->phi[i % phases].matmul(patches[i]);
  return {y, phase};
}

// What the exported file records of the checkpoint and its camera.
nn::ScriptMetadata script_metadata(const train::Checkpoint& ckpt, const optics::Phi& phi,
                                   const std::string& model) {
  nn::ScriptMetadata meta;
  meta.phi = ckpt.phi;
  meta.config = ckpt.config;
  meta.period = phi.period();
  meta.block = phi.block();
  meta.local = phi.local();
  meta.source = {{"checkpoint", fs::path(model).filename().string()},
                 {"stage", ckpt.training.stage},
                 {"epoch", ckpt.training.epoch},
                 {"step", ckpt.training.step},
                 {"lfnet_version", kVersion}};
  if (std::isfinite(ckpt.training.best_metric))
    meta.source["best_psnr_db"] = ckpt.training.best_metric;
  return meta;
}

// The exported net against the checkpoint's: a whole-image net on a sensor image wider than two
// halos, with sides that are no multiples of its tiling's, in many tiles; a patch net on
// `count` patches. Returns the largest difference and sets `compared`.
double compare_exported(nn::LightFieldNet net, const nn::ScriptedNetwork& loaded, int64_t count,
                        std::string& compared) {
  const auto& o = net->options();
  double diff = 0;
  if (!o.patch_grid()) {
    auto gen = torch::make_generator<at::CPUGeneratorImpl>(7);
    const auto tiling = o.arch().image_tiling(o);
    const int64_t m = tiling.multiple, halo = tiling.receptive_radius;
    auto sensor = torch::rand({o.measurements, 2 * halo + m + 3, 3 * halo + 1}, gen);
    const double sigma = 0.05;  // read by noise-aware nets only
    const int64_t tile = 2 * m;
    auto want = recon::reconstruct_sensor_tiled(net, sensor, tile, false, sigma);
    auto got = loaded.reconstruct_image(sensor, tile, false, sigma);
    diff = (got - want.squeeze(0)).abs().max().item<double>();
    compared = "a " + std::to_string(sensor.size(1)) + " x " + std::to_string(sensor.size(2)) +
               " sensor image in tiles of " + std::to_string(tile);
  } else {
    auto [y, phase] = check_inputs(net, count);
    torch::NoGradGuard no_grad;
    auto want = net->forward(y, phase).reshape({count, -1});
    auto got = loaded.forward(y, phase).reshape({count, -1});
    diff = (got - want).abs().max().item<double>();
    compared = std::to_string(count) + " patches";
  }
  LFNET_CHECK_AS(NumericalError, diff <= 1e-5, "the exported net differs from the checkpoint by ",
                 diff, " on ", compared, " (more than 1e-5): please report this");
  return diff;
}

}  // namespace

ExportResult export_model(const ExportRequest& a) {
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = {a.model};
  check_output_file(a.out, policy);
  OutputLock lock(a.out);
  LFNET_CHECK_AS(ConfigError, !nn::is_script_file(a.model), "--model ", a.model,
                 " is already an exported file; export takes a checkpoint");
  LFNET_CHECK_AS(ConfigError, model_file_kind(a.model) != ModelFileKind::kNoiseSwitch, "--model ",
                 a.model,
                 " is a noise switch of two checkpoints: export each of them (its \"quiet\" and "
                 "\"noisy\" files)");
  const auto ckpt = train::load_checkpoint(a.model);
  auto net = train::build_net(ckpt, a.model);
  net->eval();
  const auto spec = optics::PhiSpec::from_json(ckpt.phi, a.model + ":$.phi");
  const auto phi = optics::make_phi(spec);
  const auto& o = net->options();
  LFNET_CHECK_AS(ConfigError, o.cfa.empty(), "--model ", a.model, " is a colour net (cfa ", o.cfa,
                 "), which cannot be exported to TorchScript yet: use the checkpoint");
  LFNET_CHECK_AS(CheckpointError,
                 phi->measurements() == o.measurements && phi->rows() == o.patch.rows &&
                     phi->cols() == o.patch.cols,
                 a.model, ": its Phi ", spec.label(), " (", phi->rows(), "x", phi->cols(),
                 " views) does not fit its network (N = ", o.measurements, ", ", o.patch.rows, "x",
                 o.patch.cols, " views)");
  const auto meta = script_metadata(ckpt, *phi, a.model);
  // Written to a temporary, read back and compared with the checkpoint's net on realistic
  // inputs, and only then moved into place: a failed comparison leaves no exported file.
  double diff = 0;
  ExportResult r;
  write_file_atomically(a.out, [&](const std::string& tmp) {
    nn::export_network(net, meta, tmp);
    const auto loaded = nn::load_script(tmp);
    if (a.check > 0) diff = compare_exported(net, loaded, a.check, r.compared);
  });
  r.phi = spec.label();
  r.branches = o.patch_grid() ? nn::to_string(o.branches()) : o.architecture;
  r.phases = net->phases();
  r.megabytes = static_cast<double>(fs::file_size(a.out)) / 1e6;
  r.max_difference = diff;
  return r;
}

namespace {

// "UxV" -> (U, V).
std::pair<int64_t, int64_t> parse_grid(const std::string& text) {
  static const std::regex kGrid(R"(^(\d{1,3})x(\d{1,3})$)");
  std::smatch m;
  const bool matched = std::regex_match(text, m, kGrid);
  const int64_t u = matched ? std::stoll(m[1]) : 0, v = matched ? std::stoll(m[2]) : 0;
  LFNET_CHECK_AS(ConfigError, u >= 1 && v >= 1 && u <= optics::kMaxViews && v <= optics::kMaxViews,
                 "--grid must be UxV with U and V in 1..", optics::kMaxViews, ", got ", text);
  return {u, v};
}

}  // namespace

PhiExportResult export_phi(const PhiExportRequest& a) {
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = model_input_files(a.phi);  // a switch's members too
  check_output_folder(a.out, policy);
  const bool file = phi_argument_is_file(a.phi);
  optics::PhiSpec spec;
  if (file) {
    spec = phi_from_argument(a.phi);
  } else {
    spec = optics::PhiSpec::parse(a.phi);
    std::tie(spec.rows, spec.cols) = parse_grid(a.grid);
  }
  const auto phi = optics::make_phi(spec);
  PhiExportResult r;
  r.printable = a.printable || io::is_learned_mask(*phi);
  // A model that learned its code: the code's physical parameters too.
  const auto code = file ? learned_code_of(a.phi) : nlohmann::json();
  write_folder(a.out, policy, [&](const std::string& dir) {
    io::write_calibrated_phi(*phi, dir);
    if (r.printable) io::write_printable_mask(*phi, dir);
    if (!code.is_null()) write_json_file((fs::path(dir) / "code.json").string(), code);
    // Read it back: the folder must give the same camera, weight for weight.
    const auto back = optics::make_phi(io::read_calibrated_phi(dir));
    const int64_t t = phi->period();
    const double diff = (back->pixel_weights(0, 0, t, t, torch::kFloat64) -
                         phi->pixel_weights(0, 0, t, t, torch::kFloat64))
                            .abs()
                            .max()
                            .item<double>();
    LFNET_CHECK_AS(NumericalError, diff == 0, "the written Phi differs from ", spec.label(), " by ",
                   diff, " when read back: please report this");
  });
  r.label = spec.label();
  r.measurements = phi->measurements();
  r.rows = phi->rows();
  r.cols = phi->cols();
  r.period = phi->period();
  r.code_file = !code.is_null();
  const std::string source = spec.params.is_object() ? spec.params.value("source", "") : "";
  if (!r.code_file && spec.name == "calibrated" && source.rfind("learned", 0) == 0) {
    r.missing_code = source;  // a learned code whose parameters this file does not hold
  }
  return r;
}

}  // namespace lfnet::pipeline

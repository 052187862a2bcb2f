#include "lfnet/recon/fully_convolutional.h"

#include <torch/torch.h>

#include <algorithm>
#include <vector>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/core/file_backed.h"
#include "lfnet/core/light_field.h"
#include "lfnet/nn/image_net.h"
#include "lfnet/recon/methods.h"

namespace lfnet::recon {

namespace {
constexpr EnumName<CnnMode> kCnnModes[] = {{CnnMode::kPatches, "patches"},
                                           {CnnMode::kFull, "full"}};
}  // namespace

CnnMode parse_cnn_mode(const std::string& name) { return value_of(name, kCnnModes); }

std::string to_string(CnnMode mode) { return name_of(mode, kCnnModes); }

torch::Tensor cnn_over_light_field(nn::CnnBranch cnn, const torch::Tensor& x, int64_t tile) {
  LFNET_CHECK_AS(ConfigError, tile >= 1, "the CNN tile must be at least 1 pixel, got ", tile);
  LFNET_CHECK(x.dim() == 4, "cnn_over_light_field: expected (U, V, H, W), got ", x.sizes());
  LFNET_CHECK(!cnn->convs.empty(), "cnn_over_light_field: the CNN branch has no layers");
  torch::InferenceMode guard;
  const auto device = cnn->convs.front()->weight.device();
  const auto dtype = cnn->convs.front()->weight.scalar_type();  // set_cnn_precision
  const int64_t u = x.size(0), v = x.size(1), height = x.size(2), width = x.size(3);
  int64_t halo = 0;
  for (const auto& conv : cnn->convs) halo += conv->options().kernel / 2;
  // Zero-pad by the halo: a tile then always reads a full (tile + 2 halo)^2 window.
  auto padded = torch::constant_pad_nd(x.to(torch::kFloat32), {halo, halo, halo, halo});
  auto inside = torch::constant_pad_nd(torch::ones({height, width}), {halo, halo, halo, halo});
  auto out = torch::empty({u, v, height, width});
  for (int64_t y0 = 0; y0 < height; y0 += tile) {
    const int64_t th = std::min(tile, height - y0);
    for (int64_t x0 = 0; x0 < width; x0 += tile) {
      const int64_t tw = std::min(tile, width - x0);
      const int64_t ph = th + 2 * halo, pw = tw + 2 * halo;
      // u-major (1, U, C = 1, V, h, w)
      auto z =
          padded.narrow(2, y0, ph).narrow(3, x0, pw).unsqueeze(0).unsqueeze(2).to(device, dtype);
      // 1 inside the light field, 0 outside: activations there must act as zero padding.
      auto mask =
          inside.narrow(0, y0, ph).narrow(1, x0, pw).to(device, dtype).view({1, 1, 1, 1, ph, pw});
      const bool at_border =
          y0 < halo || x0 < halo || y0 + th + halo > height || x0 + tw + halo > width;
      for (size_t i = 0; i < cnn->convs.size(); ++i) {
        z = cnn->convs[i]->forward_u_major(z);
        if (i + 1 < cnn->convs.size()) {
          z = torch::relu_(z);
          if (at_border) z.mul_(mask);
        }
      }
      out.narrow(2, y0, th).narrow(3, x0, tw).copy_(
          z.squeeze(2).squeeze(0).narrow(2, halo, th).narrow(3, halo, tw));
    }
  }
  return out;
}

torch::Tensor reconstruct_sensor_fully_convolutional(
    nn::LightFieldNet net, const std::string& method, const optics::Phi& phi,
    const torch::Tensor& sensor, const ReconstructOptions& options, int64_t tile) {
  options.validate();
  LFNET_CHECK_AS(ConfigError, method == "net" || method == "cnn",
                 "a fully convolutional CNN pass needs the method net or cnn, not '", method, "'");
  LFNET_CHECK_AS(ConfigError, net->options().has_cnn(), "the model was trained as '",
                 nn::to_string(net->options().branches()),
                 "' and has no CNN branch to run fully convolutionally");
  const auto o = nn::paper_options(net->options());
  LFNET_CHECK_AS(ConfigError, method == "net" || o.branches != nn::Branches::kAe,
                 "the model has no '", method, "' branch");
  net->eval();
  // Everything here is inference: the tensors made under the guard are updated in place.
  torch::InferenceMode inference;
  const auto device = net->phi.device();
  ReconstructOptions raw = options;
  raw.clamp = false;
  raw.coded = false;  // the pieces are summed in float32
  // The CNN's input: the stitched scaled adjoint of the patches.
  PatchSolver adjoint = [&](const torch::Tensor& y, const torch::Tensor& phase) {
    torch::InferenceMode guard;
    return net->adjoint(y.to(device), phase.defined() ? phase.to(device) : phase).to(torch::kCPU);
  };
  auto x0 = reconstruct_sensor(phi, sensor, adjoint, raw);  // (1, U, V, H, W)
  const double cnn_weight =
      method == "net" && o.branches == nn::Branches::kNet ? o.head_weights[1] : 1.0;
  auto out = cnn_over_light_field(nn::CnnBranch(nn::cnn_branch(*net)), x0[0], tile)
                 .mul_(cnn_weight)
                 .unsqueeze(0);
  // The rest per patch: the weighted autoencoder branch and the residual base.
  const bool ae = method == "net" && o.has_ae();
  if (ae || o.residual != nn::Residual::kNone) {
    nn::BranchSelection run;
    run.ae = ae;
    run.cnn = false;
    const double ae_weight = o.branches == nn::Branches::kNet ? o.head_weights[0] : 1.0;
    PatchSolver rest = [&](const torch::Tensor& y, const torch::Tensor& phase) {
      torch::InferenceMode guard;
      auto r = net->forward_all(y.to(device), phase.defined() ? phase.to(device) : phase, run);
      torch::Tensor patch = r.ae.defined() ? r.ae * ae_weight : torch::Tensor();
      if (r.base.defined()) patch = patch.defined() ? patch + r.base : r.base;
      return patch.reshape({y.size(0), -1}).to(torch::kCPU);
    };
    out.add_(reconstruct_sensor(phi, sensor, rest, raw));
  }
  LFNET_CHECK_AS(NumericalError, torch::isfinite(out).all().item<bool>(),
                 "the fully convolutional reconstruction produced NaN or infinite values");
  return options.clamp ? out.clamp_(0, 1) : out;
}

torch::Tensor reconstruct_sensor_tiled(nn::LightFieldNet net, const torch::Tensor& sensor,
                                       int64_t tile, bool clamp, double noise_sigma,
                                       const ProgressCallback& progress, bool coded,
                                       int64_t origin) {
  const auto& o = net->options();
  const auto& arch = net->architecture();
  LFNET_CHECK_AS(ConfigError, arch.whole_image(), "whole-image reconstruction needs a model of ",
                 "a whole-image architecture, not ", arch.name());
  LFNET_CHECK_AS(ConfigError, sensor.dim() == 3 && sensor.size(0) == o.measurements,
                 "the sensor image must be (", o.measurements, ", H, W), got ", sensor.sizes());
  LFNET_CHECK_AS(ConfigError, tile >= 0, "the tile must be positive (0: automatic), got ", tile);
  LFNET_CHECK(clamp || !coded, "a result in 16-bit codes is clamped to [0, 1]");
  torch::NoGradGuard no_grad;
  net->eval();
  const auto tiling = arch.image_tiling(o);
  const int64_t m = tiling.multiple, h = sensor.size(1), w = sensor.size(2);
  const int64_t hp = nn::round_up(h, m), wp = nn::round_up(w, m), t = net->period();
  LFNET_CHECK(origin >= 0 && origin < t * t, "reconstruct_sensor_tiled: origin ", origin,
              " outside the net's period of ", t, " x ", t);
  const int64_t oy = origin / t, ox = origin % t;
  const auto device = net->phi.device();
  // The image is zero-padded to (hp, wp) tile by tile: crops that reach past it are padded by
  // forward_image, the image itself is not copied.
  const auto image = sensor.to(torch::kFloat32);
  const int64_t colours = o.colours();
  // Codes of a large light field are file-backed, and each finished row of tiles leaves memory
  // (core/file_backed.h).
  auto out = coded ? file_backed_empty({colours, o.patch.rows, o.patch.cols, h, w}, torch::kInt16)
                   : torch::empty({colours, o.patch.rows, o.patch.cols, h, w});
  int64_t step = 0, done = 0;
  const auto tiles = nn::image_tiles(tiling, h, w, tile, &step);
  for (const auto& c : tiles) {
    LFNET_CHECK(c.a1 <= hp && c.b1 <= wp, "internal: a tile reaches past the padded image");
    // forward_image pads the crop to the multiple itself, as it pads a whole image (a colour
    // net demosaics before padding, so the padding is no measurement).
    auto crop = image.slice(1, c.a0, std::min(c.a1, h))
                    .slice(2, c.b0, std::min(c.b1, w))
                    .unsqueeze(0)
                    .to(device);
    auto est = net->forward_image(crop, ((c.a0 + oy) % t) * t + (c.b0 + ox) % t, noise_sigma)
                   .to(torch::kCPU)
                   .reshape({colours, o.patch.rows, o.patch.cols, crop.size(2), crop.size(3)});
    const int64_t th = std::min(c.y0 + step, h) - c.y0, tw = std::min(c.x0 + step, w) - c.x0;
    if (th > 0 && tw > 0) {
      auto part =
          est.slice(3, c.y0 - c.a0, c.y0 - c.a0 + th).slice(4, c.x0 - c.b0, c.x0 - c.b0 + tw);
      out.slice(3, c.y0, c.y0 + th)
          .slice(4, c.x0, c.x0 + tw)
          .copy_(coded ? encode_codes(part) : part);
    }
    if (c.x0 + step >= wp) page_out(out);  // the rows of tiles so far are final
    if (progress) progress(++done, static_cast<int64_t>(tiles.size()));
  }
  if (clamp && !coded) out.clamp_(0.0, 1.0);
  return out;
}

std::vector<SensorMirror> phi_mirrors(const torch::Tensor& pixel_weights) {
  LFNET_CHECK(pixel_weights.dim() == 5, "phi_mirrors: pixel weights must be (N, U, V, T, T), got ",
              pixel_weights.sizes());
  std::vector<SensorMirror> mirrors;
  const int64_t n = pixel_weights.size(0);
  SensorMirror identity;
  for (int64_t k = 0; k < n; ++k) identity.measurements.push_back(k);
  mirrors.push_back(identity);
  if (pixel_weights.size(3) != 1 || pixel_weights.size(4) != 1) return mirrors;
  const auto w = pixel_weights.detach().to(torch::kCPU, torch::kFloat64);
  const double tolerance = 1e-5 * std::max(w.abs().max().item<double>(), 1e-30);
  for (const auto& [flip_x, flip_y] : {std::pair{true, false}, {false, true}, {true, true}}) {
    std::vector<int64_t> dims;
    if (flip_y) dims.push_back(1);  // u
    if (flip_x) dims.push_back(2);  // v
    const auto flipped = w.flip(dims);
    SensorMirror m{flip_x, flip_y, {}};
    std::vector<bool> used(static_cast<size_t>(n), false);
    for (int64_t k = 0; k < n; ++k) {
      for (int64_t j = 0; j < n; ++j) {
        if (used[static_cast<size_t>(j)]) continue;
        if ((flipped[k] - w[j]).abs().max().item<double>() <= tolerance) {
          used[static_cast<size_t>(j)] = true;
          m.measurements.push_back(j);
          break;
        }
      }
    }
    if (static_cast<int64_t>(m.measurements.size()) == n) mirrors.push_back(m);
  }
  return mirrors;
}

torch::Tensor mirror_weights(const nn::LightFieldNet& net) {
  const auto& w = net->phi;
  if (net->options().colours() == 1 || w.dim() != 5) return w;
  const auto first = w.narrow(3, 0, 1).narrow(4, 0, 1);
  const bool period_one = (w - first).abs().max().item<double>() <=
                          1e-6 * std::max(w.abs().max().item<double>(), 1e-30);
  return period_one ? first : w;
}

int64_t mirrored_origin(const nn::LightFieldNet& net, const SensorMirror& m, int64_t height,
                        int64_t width, int64_t origin) {
  if (net->options().colours() == 1) return origin;
  // Pixel (y, x) of the image mirrored top to bottom is pixel (H - 1 - y, x) of the sensor
  // image, of phase (oy + H - 1 - y) mod T, which over a period T that divides 2 is
  // (oy + H - 1 + y) mod T.
  const int64_t t = net->period();
  LFNET_CHECK(t <= 2 || (!m.flip_x && !m.flip_y), "mirrored_origin: a colour net of period ", t,
              " has no mirrors");
  const int64_t oy = origin / t, ox = origin % t;
  return ((oy + (m.flip_y ? height - 1 : 0)) % t) * t + (ox + (m.flip_x ? width - 1 : 0)) % t;
}

bool whole_image_model(const nn::LightFieldNet& net, const nn::ScriptedNetwork* script) {
  return (!net.is_empty() && net->architecture().whole_image()) ||
         (script != nullptr && script->network.arch().whole_image());
}

void check_self_ensemble(const std::string& method, const nn::LightFieldNet& net,
                         const nn::ScriptedNetwork* script) {
  LFNET_CHECK_AS(ConfigError, method == "net" && whole_image_model(net, script),
                 "--self-ensemble applies to --method net with a model of a whole-image "
                 "architecture (lfnet)");
}

void check_ensemble_passes(bool self_ensemble, int64_t passes) {
  LFNET_CHECK_AS(ConfigError, self_ensemble || passes == 0,
                 "--ensemble-passes applies to --self-ensemble");
}

std::vector<SensorMirror> ensemble_mirrors(const torch::Tensor& pixel_weights, int64_t max_passes) {
  LFNET_CHECK_AS(ConfigError, max_passes >= 0,
                 "the self-ensemble's passes must be positive (0: every mirror image), not " +
                     std::to_string(max_passes));
  auto mirrors = phi_mirrors(pixel_weights);
  if (max_passes > 0 && static_cast<size_t>(max_passes) < mirrors.size()) {
    mirrors.resize(static_cast<size_t>(max_passes));
  }
  return mirrors;
}

std::vector<SensorMirror> ensemble_mirrors(const nn::LightFieldNet& net,
                                           const nn::ScriptedNetwork* script, int64_t max_passes) {
  LFNET_CHECK(!net.is_empty() || script != nullptr, "ensemble_mirrors: no network");
  return ensemble_mirrors(net.is_empty() ? script->pixel_weights() : mirror_weights(net),
                          max_passes);
}

torch::Tensor reconstruct_mirrored(const std::vector<SensorMirror>& mirrors,
                                   const torch::Tensor& sensor, const SensorPass& pass, bool clamp,
                                   const ProgressCallback& progress) {
  LFNET_CHECK(!mirrors.empty(), "reconstruct_mirrored: no mirrors (the identity comes first)");
  const auto count = static_cast<int64_t>(mirrors.size());
  torch::Tensor sum;
  for (int64_t i = 0; i < count; ++i) {
    const auto& m = mirrors[static_cast<size_t>(i)];
    // Sensor (N, H, W); light field (1, U, V, H, W).
    auto mirrored = sensor.index_select(0, torch::tensor(m.measurements, torch::kInt64));
    if (m.flip_y) mirrored = mirrored.flip({1});
    if (m.flip_x) mirrored = mirrored.flip({2});
    ProgressCallback part;
    if (progress) {
      part = [&progress, i, count](int64_t done, int64_t total) {
        progress(i * total + done, count * total);
      };
    }
    auto est = pass(mirrored, m, part);
    if (m.flip_y) est = est.flip({1, 3});
    if (m.flip_x) est = est.flip({2, 4});
    sum = sum.defined() ? sum.add_(est) : est;
  }
  sum.div_(static_cast<double>(count));
  if (clamp) sum.clamp_(0.0, 1.0);
  return sum;
}

torch::Tensor reconstruct_sensor_mirrored(nn::LightFieldNet net, const torch::Tensor& sensor,
                                          int64_t tile, bool clamp, double noise_sigma,
                                          const ProgressCallback& progress, int64_t max_passes) {
  LFNET_CHECK_AS(ConfigError, net->architecture().whole_image(),
                 "the self-ensemble needs a model of a whole-image architecture (lfnet)");
  return reconstruct_mirrored(
      ensemble_mirrors(mirror_weights(net), max_passes), sensor,
      [&](const torch::Tensor& mirrored, const SensorMirror& m, const ProgressCallback& part) {
        const auto origin = mirrored_origin(net, m, sensor.size(1), sensor.size(2));
        return reconstruct_sensor_tiled(net, mirrored, tile, false, noise_sigma, part, false,
                                        origin);
      },
      clamp, progress);
}

torch::Tensor reconstruct_crops_mirrored(nn::LightFieldNet net, const torch::Tensor& sensor,
                                         const torch::Tensor& phase, const torch::Tensor& noise,
                                         int64_t max_passes) {
  LFNET_CHECK_AS(ConfigError, net->architecture().whole_image(),
                 "the self-ensemble needs a model of a whole-image architecture (lfnet)");
  LFNET_CHECK(sensor.dim() == 4 && sensor.size(1) == net->options().measurements,
              "reconstruct_crops_mirrored: expected sensor crops (B, ", net->options().measurements,
              ", h, w), got ", sensor.sizes());
  const int64_t batch = sensor.size(0);
  LFNET_CHECK(!phase.defined() || phase.numel() == batch,
              "reconstruct_crops_mirrored: one phase per crop");
  LFNET_CHECK(!noise.defined() || noise.numel() == batch,
              "reconstruct_crops_mirrored: one noise sigma per crop");
  torch::NoGradGuard no_grad;
  net->eval();
  const auto device = net->phi.device();
  const auto phases = phase.defined() ? phase.to(torch::kCPU, torch::kInt64) : torch::Tensor();
  const auto sigmas = noise.defined() ? noise.to(torch::kCPU, torch::kFloat64) : torch::Tensor();
  // forward_image takes one phase and one sigma per call: crops that share both run together.
  const bool uniform = (!phases.defined() || (phases == phases[0]).all().item<bool>()) &&
                       (!sigmas.defined() || (sigmas == sigmas[0]).all().item<bool>());
  const int64_t h = sensor.size(2), w = sensor.size(3);
  // A crop's phase in the mirror image `m` (a colour net's CFA moves with it).
  const auto phase_of = [&](const SensorMirror& m, int64_t b) {
    return mirrored_origin(net, m, h, w, phases.defined() ? phases[b].item<int64_t>() : 0);
  };
  auto run = [&](const torch::Tensor& crops, const SensorMirror& m) {
    if (uniform) {
      return net->forward_image(crops, phase_of(m, 0),
                                sigmas.defined() ? sigmas[0].item<double>() : 0.0);
    }
    std::vector<torch::Tensor> parts;
    parts.reserve(static_cast<size_t>(batch));
    for (int64_t b = 0; b < batch; ++b) {
      parts.push_back(net->forward_image(crops.narrow(0, b, 1), phase_of(m, b),
                                         sigmas.defined() ? sigmas[b].item<double>() : 0.0));
    }
    return torch::cat(parts, 0);
  };
  const auto mirrors = ensemble_mirrors(mirror_weights(net), max_passes);
  const auto input = sensor.to(device, torch::kFloat32);
  // Light fields (B, U, V, h, w), or (B, 3, U, V, h, w) of a colour net: their u and y, v and x.
  const int64_t c = net->options().colours() == 1 ? 0 : 1;
  torch::Tensor sum;
  for (const auto& m : mirrors) {
    // Crops (B, N, h, w).
    auto mirrored = input.index_select(1, torch::tensor(m.measurements, torch::kInt64).to(device));
    if (m.flip_y) mirrored = mirrored.flip({2});
    if (m.flip_x) mirrored = mirrored.flip({3});
    auto est = run(mirrored, m).to(torch::kFloat32);
    if (m.flip_y) est = est.flip({1 + c, 3 + c});
    if (m.flip_x) est = est.flip({2 + c, 4 + c});
    sum = sum.defined() ? sum.add_(est) : est;
  }
  sum.div_(static_cast<double>(mirrors.size()));
  return c == 0 ? sum.unsqueeze(1) : sum;
}

}  // namespace lfnet::recon

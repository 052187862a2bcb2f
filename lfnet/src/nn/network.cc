#include "lfnet/nn/network.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"

namespace lfnet::nn {

// ---- options -------------------------------------------------------------------------------

namespace {
constexpr EnumName<Architecture> kArchitectures[] = {{Architecture::kPaper, "paper"},
                                                     {Architecture::kLfnet, "lfnet"}};
constexpr EnumName<Branches> kBranches[] = {
    {Branches::kNet, "net"}, {Branches::kAe, "ae"}, {Branches::kCnn, "cnn"}};
constexpr EnumName<Residual> kResiduals[] = {
    {Residual::kNone, "none"}, {Residual::kPinv, "pinv"}, {Residual::kAdjoint, "adjoint"}};
constexpr EnumName<AeInput> kAeInputs[] = {{AeInput::kMeasurements, "measurements"},
                                           {AeInput::kAdjoint, "adjoint"}};
}  // namespace

std::string to_string(Architecture value) { return name_of(value, kArchitectures); }
std::string to_string(Branches value) { return name_of(value, kBranches); }
std::string to_string(Residual value) { return name_of(value, kResiduals); }
std::string to_string(AeInput value) { return name_of(value, kAeInputs); }
Architecture from_string(const std::string& name, Architecture) {
  return value_of(name, kArchitectures);
}
Branches from_string(const std::string& name, Branches) { return value_of(name, kBranches); }
Residual from_string(const std::string& name, Residual) { return value_of(name, kResiduals); }
AeInput from_string(const std::string& name, AeInput) { return value_of(name, kAeInputs); }

void PatchShape::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json PatchShape::to_json() const { return fields_to_json(*this); }
void AutoencoderOptions::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json AutoencoderOptions::to_json() const { return fields_to_json(*this); }
void CnnOptions::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json CnnOptions::to_json() const { return fields_to_json(*this); }

NetworkOptions NetworkOptions::from_json(const nlohmann::json& j, const std::string& path) {
  NetworkOptions options;
  JsonReader reader(j, path);
  options.read(reader);
  reader.finish();
  return options;
}

void NetworkOptions::read(JsonReader& reader) {
  read_fields(reader, *this);
  with_path(reader, [&] { validate(); });
}

nlohmann::json NetworkOptions::to_json() const { return fields_to_json(*this); }

void NetworkOptions::validate() const {
  auto fail = [](const std::string& field, const std::string& what) {
    throw ConfigError(field + ": " + what);
  };
  if (patch.rows < 1 || patch.cols < 1 || patch.height < 1 || patch.width < 1) {
    fail("patch", "every size must be positive, got " + patch.to_json().dump());
  }
  if (is_image()) {
    image.validate();
    const int64_t m = image.multiple();
    if (patch.height % m != 0 || patch.width % m != 0) {
      fail("patch", "the lfnet architecture's training crops need sides that are multiples of " +
                        std::to_string(m) + ", got " + patch.to_json().dump());
    }
  }
  if (measurements < 1) fail("measurements", "must be >= 1, got " + std::to_string(measurements));
  if (kernel < 1 || kernel % 2 == 0) {
    fail("kernel", "must be odd and positive, got " + std::to_string(kernel));
  }
  if (ae.hidden.size() != 5) {
    fail("ae.hidden", "needs the 5 widths of fc1 .. fc5, got " + std::to_string(ae.hidden.size()));
  }
  for (auto w : ae.hidden) {
    if (w < 1) fail("ae.hidden", "widths must be positive, got " + std::to_string(w));
  }
  if (cnn.channels < 1) fail("cnn.channels", "must be positive");
  if (cnn.depth < 1) fail("cnn.depth", "must be >= 1");
  if (head_weights.size() != 2 || !std::isfinite(head_weights[0]) ||
      !std::isfinite(head_weights[1])) {
    fail("head_weights", "needs two finite weights (ae, cnn)");
  }
  if (!(pinv_lambda > 0) || !std::isfinite(pinv_lambda)) {
    fail("pinv_lambda", "must be positive and finite");
  }
}

int64_t NetworkOptions::ae_input_size() const {
  return ae.input == AeInput::kAdjoint ? patch.size() : measurement_size();
}

// ---- branches ------------------------------------------------------------------------------

AutoencoderBranchImpl::AutoencoderBranchImpl(const NetworkOptions& options)
    : patch_(options.patch) {
  std::vector<int64_t> widths{options.ae_input_size()};
  widths.insert(widths.end(), options.ae.hidden.begin(), options.ae.hidden.end());
  widths.push_back(options.patch.size());
  for (size_t i = 0; i + 1 < widths.size(); ++i) {
    fc.push_back(
        register_module("fc" + std::to_string(i + 1), torch::nn::Linear(widths[i], widths[i + 1])));
  }
  Conv4dOptions conv_options;
  conv_options.kernel = options.kernel;
  conv_options.algorithm = options.conv_algorithm;
  conv = register_module("conv", Conv4d(conv_options));
}

torch::Tensor AutoencoderBranchImpl::forward(const torch::Tensor& input) {
  auto x = input;
  for (size_t i = 0; i < fc.size(); ++i) {
    x = fc[i]->forward(x);
    if (i + 1 < fc.size()) x = torch::relu(x);
  }
  // (B, R C h w) -> (B, 1, R, C, h, w), with no batch size a trace would keep (nn/script.cc)
  x = x.unsqueeze(1).unflatten(2, {patch_.rows, patch_.cols, patch_.height, patch_.width});
  return conv->forward(x);
}

CnnBranchImpl::CnnBranchImpl(const NetworkOptions& options) {
  const auto algorithm = options.conv_algorithm;
  for (int64_t i = 0; i < options.cnn.depth; ++i) {
    Conv4dOptions conv_options;
    conv_options.in_channels = i == 0 ? 1 : options.cnn.channels;
    conv_options.out_channels = i + 1 == options.cnn.depth ? 1 : options.cnn.channels;
    conv_options.kernel = options.kernel;
    conv_options.algorithm = algorithm;
    convs.push_back(register_module("conv" + std::to_string(i + 1), Conv4d(conv_options)));
  }
}

torch::Tensor CnnBranchImpl::forward(const torch::Tensor& x) {
  LFNET_CHECK(x.dim() == 6 && x.size(1) == 1, "CNN branch: expected (B, 1, U, V, h, w), got ",
              x.sizes());
  // (B, U, 1, V, h, w): u-major, free for one channel; in the weights' type (set_cnn_precision)
  auto z = x.transpose(1, 2).to(convs.front()->weight.scalar_type());
  for (size_t i = 0; i < convs.size(); ++i) {
    z = convs[i]->forward_u_major(z);
    if (i + 1 < convs.size()) z = torch::relu_(z);
  }
  return z.transpose(1, 2).to(x.scalar_type()).contiguous();
}

// ---- Phi stacks ----------------------------------------------------------------------------

torch::Tensor apply_phase_stack(const torch::Tensor& y, const torch::Tensor& phase,
                                const torch::Tensor& stack) {
  const int64_t p = stack.size(0);
  if (p == 1) return y.matmul(stack[0]);
  LFNET_CHECK(phase.defined(), "a Phi with ", p, " phases needs the phase of every patch");
  // Sort the batch by phase, multiply each run by its matrix, and undo the sort.
  auto order = std::get<1>(phase.sort(/*stable=*/true, /*dim=*/0, /*descending=*/false));
  auto counts = torch::bincount(phase, {}, p).to(torch::kCPU);
  auto sorted = y.index_select(0, order);
  std::vector<torch::Tensor> parts;
  int64_t offset = 0;
  auto count = counts.accessor<int64_t, 1>();
  for (int64_t i = 0; i < p; ++i) {
    if (count[i] == 0) continue;
    parts.push_back(sorted.narrow(0, offset, count[i]).matmul(stack[i]));
    offset += count[i];
  }
  auto inverse = torch::empty_like(order);
  inverse.index_put_({order}, torch::arange(order.size(0), order.options()));
  return torch::cat(parts, 0).index_select(0, inverse);
}

torch::Tensor pinv_stack(const torch::Tensor& stack, double lambda) {
  LFNET_CHECK(stack.dim() == 3, "pinv_stack: expected (P, M, D), got ", stack.sizes());
  auto a = stack.to(torch::kFloat64);
  auto gram = torch::matmul(a, a.transpose(1, 2));
  gram = gram + lambda * torch::eye(a.size(1), a.options()).unsqueeze(0);
  return at::linalg_solve(gram, a).to(stack.scalar_type());
}

torch::Tensor map_measurement_weights(const torch::Tensor& weight, const torch::Tensor& phi_a,
                                      const torch::Tensor& phi_b, double lambda) {
  LFNET_CHECK(weight.dim() == 2 && phi_a.dim() == 2 && phi_b.dim() == 2 &&
                  weight.size(1) == phi_a.size(0) && phi_a.size(1) == phi_b.size(1),
              "map_measurement_weights: shapes do not chain: weight ", weight.sizes(), ", Phi A ",
              phi_a.sizes(), ", Phi B ", phi_b.sizes());
  auto b = phi_b.to(torch::kFloat64);
  auto gram = b.matmul(b.t()) + lambda * torch::eye(b.size(0), b.options());
  auto pinv_t = at::linalg_solve(gram, b);  // (M_B, D) = (Phi_B^+)^T
  auto mapped = weight.to(torch::kFloat64).matmul(phi_a.to(torch::kFloat64)).matmul(pinv_t.t());
  return mapped.to(weight.scalar_type());
}

namespace {
constexpr EnumName<Precision> kPrecisions[] = {{Precision::kFloat32, "float32"},
                                               {Precision::kBFloat16, "bfloat16"}};
}  // namespace

Precision parse_precision(const std::string& name) { return value_of(name, kPrecisions); }

std::string to_string(Precision precision) { return name_of(precision, kPrecisions); }

void set_cnn_precision(LightFieldNet& net, Precision precision) {
  const auto dtype = precision == Precision::kBFloat16 ? torch::kBFloat16 : torch::kFloat32;
  if (net->options().is_image()) {
    net->image->set_precision(dtype);
  } else if (net->options().has_cnn()) {
    net->cnn->to(dtype);
  }
}

int64_t parameter_count(const torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

// ---- the network ---------------------------------------------------------------------------

LightFieldNetImpl::LightFieldNetImpl(NetworkOptions options) : options_(std::move(options)) {
  options_.validate();
  const auto& p = options_.patch;
  if (options_.is_image()) {
    const int64_t views = p.rows * p.cols;
    phi = register_buffer("phi", torch::zeros({options_.measurements, p.rows, p.cols, 1, 1}));
    pixel_pinv = register_buffer("pixel_pinv", torch::zeros({1, 1, options_.measurements, views}));
    const int64_t in = views + (options_.image.noise_input ? 1 : 0);
    image = register_module("image", ImageNet(options_.image, in, views));
    return;
  }
  const int64_t m = options_.measurement_size(), d = options_.patch.size();
  phi = register_buffer("phi", torch::zeros({1, m, d}));
  adjoint_scale = register_buffer("adjoint_scale", torch::ones({1}));
  if (options_.residual == Residual::kPinv) base = register_buffer("base", torch::zeros({1, m, d}));
  if (options_.has_ae()) ae = register_module("ae", AutoencoderBranch(options_));
  if (options_.has_cnn()) cnn = register_module("cnn", CnnBranch(options_));
}

void LightFieldNetImpl::set_phi(const torch::Tensor& stack) {
  if (options_.is_image()) {
    const auto& p = options_.patch;
    LFNET_CHECK(stack.dim() == 5 && stack.size(0) == options_.measurements &&
                    stack.size(1) == p.rows && stack.size(2) == p.cols && stack.size(3) >= 1 &&
                    stack.size(3) == stack.size(4),
                "set_phi: the lfnet architecture expects the pixel weights of one period (",
                options_.measurements, ", ", p.rows, ", ", p.cols, ", T, T), got ", stack.sizes());
    LFNET_CHECK_AS(NumericalError, torch::isfinite(stack).all().item<bool>(),
                   "set_phi: the pixel weights contain NaN or inf");
    torch::NoGradGuard no_grad;
    // Per pixel, A (N, U V) -> A^T (A A^T + lambda I)^-1, stored transposed as (N, U V).
    const int64_t n = options_.measurements, t = stack.size(3);
    auto a = stack.to(torch::kFloat64).reshape({n, p.rows * p.cols, t, t}).permute({2, 3, 0, 1});
    auto gram =
        torch::matmul(a, a.transpose(2, 3)) + options_.pinv_lambda * torch::eye(n, a.options());
    auto inverse = at::linalg_solve(gram, a);  // (T, T, N, U V)
    phi.set_(stack.to(phi.options()).contiguous().clone());
    pixel_pinv.set_(inverse.to(phi.options()).contiguous());
    return;
  }
  const int64_t m = options_.measurement_size(), d = options_.patch.size();
  LFNET_CHECK(stack.dim() == 3 && stack.size(0) >= 1 && stack.size(1) == m && stack.size(2) == d,
              "set_phi: expected patch matrices (P, ", m, ", ", d,
              ") for N = ", options_.measurements, " and a ", options_.patch.rows, "x",
              options_.patch.cols, "x", options_.patch.height, "x", options_.patch.width,
              " patch, got ", stack.sizes());
  LFNET_CHECK_AS(NumericalError, torch::isfinite(stack).all().item<bool>(),
                 "set_phi: the patch matrices contain NaN or inf");
  torch::NoGradGuard no_grad;
  auto a = stack.to(torch::kFloat64).contiguous();
  // s_p = <t, 1> / <t, t> with t = Phi_p^T Phi_p 1: least squares for s t ~ 1.
  auto t = torch::matmul(a.sum(2).unsqueeze(1), a).squeeze(1);
  auto tt = t.square().sum(1);
  auto scale = torch::where(tt > 0, t.sum(1) / tt, torch::ones_like(tt));
  auto opts = phi.options();
  phi.set_(stack.to(opts).contiguous().clone());
  adjoint_scale.set_(scale.to(opts).contiguous());
  if (base.defined()) base.set_(pinv_stack(a, options_.pinv_lambda).to(opts).contiguous());
}

torch::Tensor LightFieldNetImpl::check_phase(const torch::Tensor& y,
                                             const torch::Tensor& phase) const {
  const int64_t m = options_.measurement_size();
  LFNET_CHECK(y.dim() == 2 && y.size(1) == m, "LightFieldNet: expected measurements (B, ", m,
              ") (N = ", options_.measurements, " times ", options_.patch.pixels(),
              " pixels), got ", y.sizes());
  if (!phase.defined()) {
    LFNET_CHECK(phases() == 1, "LightFieldNet: this net's Phi has ", phases(),
                " phases; give the phase of every patch");
    return {};
  }
  LFNET_CHECK(
      phase.dim() == 1 && phase.size(0) == y.size(0) && phase.scalar_type() == torch::kInt64,
      "LightFieldNet: phase must be (", y.size(0), ") int64, got ", phase.sizes(), " ",
      phase.scalar_type());
  if (phase.numel() > 0) {
    const auto lo = phase.min().item<int64_t>(), hi = phase.max().item<int64_t>();
    LFNET_CHECK(lo >= 0 && hi < phases(), "LightFieldNet: phases must lie in [0, ", phases(),
                "), got [", lo, ", ", hi, "]");
  }
  return phase;
}

torch::Tensor LightFieldNetImpl::adjoint(const torch::Tensor& y, const torch::Tensor& phase) const {
  return scaled_adjoint(y, check_phase(y, phase));
}

torch::Tensor LightFieldNetImpl::scaled_adjoint(const torch::Tensor& y,
                                                const torch::Tensor& phase) const {
  LFNET_CHECK(!options_.is_image(), "the lfnet architecture has no scaled adjoint");
  auto x = apply_phase_stack(y, phase, phi);
  if (phases() == 1) return x * adjoint_scale[0];
  return x * adjoint_scale.index_select(0, phase).unsqueeze(1);
}

NetworkOutputs LightFieldNetImpl::forward_all(const torch::Tensor& y, const torch::Tensor& phase) {
  return forward_all(y, phase, BranchSelection{});
}

torch::Tensor LightFieldNetImpl::pixel_pinv_image(const torch::Tensor& sensor,
                                                  const torch::Tensor& phase) const {
  LFNET_CHECK(options_.is_image(), "pixel_pinv_image: only the lfnet architecture has it");
  LFNET_CHECK(sensor.dim() == 4 && sensor.size(1) == options_.measurements,
              "pixel_pinv_image: expected sensor crops (B, ", options_.measurements,
              ", h, w), got ", sensor.sizes());
  const int64_t t = pixel_pinv.size(0), h = sensor.size(2), w = sensor.size(3);
  const auto x = sensor.to(pixel_pinv.scalar_type());
  if (t == 1) return torch::einsum("nk,bnij->bkij", {pixel_pinv[0][0], x});
  // The map of pixel (i, j) of a crop of phase (py, px) is the tile's entry
  // ((py + i) mod T, (px + j) mod T).
  auto ph = phase.defined() ? phase.to(torch::kCPU) : torch::zeros({x.size(0)}, torch::kInt64);
  auto out = torch::empty({x.size(0), pixel_pinv.size(3), h, w}, x.options());
  auto iota = [&](int64_t n) { return torch::arange(n, torch::kInt64).to(x.device()); };
  const auto values = std::get<0>(at::_unique(ph));
  for (int64_t k = 0; k < values.size(0); ++k) {
    const int64_t v = values[k].item<int64_t>();
    auto rows = (iota(h) + v / t) % t, cols = (iota(w) + v % t) % t;
    auto map = pixel_pinv.index_select(0, rows).index_select(1, cols);  // (h, w, N, U V)
    auto index = torch::nonzero(ph == v).squeeze(1).to(x.device());
    out.index_copy_(0, index, torch::einsum("ijnk,bnij->bkij", {map, x.index_select(0, index)}));
  }
  return out;
}

torch::Tensor LightFieldNetImpl::refine(const torch::Tensor& base, const torch::Tensor& noise) {
  if (!options_.image.noise_input) return base + image->forward(base);
  auto sigma =
      noise.defined() ? noise.to(base.options()) : torch::zeros({base.size(0)}, base.options());
  auto channel = sigma.view({-1, 1, 1, 1}).expand({base.size(0), 1, base.size(2), base.size(3)});
  return base + image->forward(torch::cat({base, channel}, 1));
}

torch::Tensor LightFieldNetImpl::forward_image(const torch::Tensor& sensor, int64_t phase,
                                               double noise_sigma) {
  LFNET_CHECK(options_.is_image(), "forward_image: only the lfnet architecture has it");
  LFNET_CHECK(sensor.dim() == 4, "forward_image: expected (B, N, H, W), got ", sensor.sizes());
  const auto& p = options_.patch;
  const int64_t m = options_.image.multiple(), h = sensor.size(2), w = sensor.size(3);
  const int64_t ph = (m - h % m) % m, pw = (m - w % m) % m;
  LFNET_CHECK(phase >= 0 && phase < phases(), "forward_image: phase ", phase, " outside [0, ",
              phases(), ")");
  auto base = pixel_pinv_image(
      sensor, phase == 0 ? torch::Tensor() : torch::full({sensor.size(0)}, phase, torch::kInt64));
  if (ph > 0 || pw > 0) base = torch::constant_pad_nd(base, {0, pw, 0, ph});
  auto out = refine(base, torch::full({sensor.size(0)}, noise_sigma, base.options()));
  return out.slice(2, 0, h).slice(3, 0, w).reshape({sensor.size(0), p.rows, p.cols, h, w});
}

NetworkOutputs LightFieldNetImpl::forward_all(const torch::Tensor& y, const torch::Tensor& phase,
                                              BranchSelection run) {
  auto ph = check_phase(y, phase);
  const auto& p = options_.patch;
  const std::vector<int64_t> shape{y.size(0), 1, p.rows, p.cols, p.height, p.width};
  if (options_.is_image()) {
    // A crop: its pixel (0, 0) has the crop's phase.
    NetworkOutputs out;
    auto sensor = y.reshape({y.size(0), options_.measurements, p.height, p.width});
    auto base = pixel_pinv_image(sensor, ph);
    out.base = base.view(shape);
    out.output = refine(base, {}).view(shape);
    return out;
  }
  const bool run_ae = run.ae && options_.has_ae(), run_cnn = run.cnn && options_.has_cnn();
  const bool need_adjoint = run_cnn || (run_ae && options_.ae.input == AeInput::kAdjoint) ||
                            options_.residual == Residual::kAdjoint;
  torch::Tensor x0 = need_adjoint ? scaled_adjoint(y, ph) : torch::Tensor();

  NetworkOutputs out;
  if (run_ae) out.ae = ae->forward(options_.ae.input == AeInput::kAdjoint ? x0 : y);
  if (run_cnn) out.cnn = cnn->forward(x0.view(shape));
  if (out.ae.defined() && out.cnn.defined()) {
    const double a = options_.head_weights[0], b = options_.head_weights[1];
    // One fused kernel: lerp(cnn, ae, a) = (1 - a) cnn + a ae when the weights sum to 1.
    out.output =
        a + b == 1.0 ? torch::lerp(out.cnn, out.ae, a) : torch::add(out.cnn * b, out.ae, a);
  } else {
    out.output = out.ae.defined() ? out.ae : out.cnn;
  }
  if (options_.residual == Residual::kPinv) out.base = apply_phase_stack(y, ph, base).view(shape);
  if (options_.residual == Residual::kAdjoint) out.base = x0.view(shape);
  // With no branch run (a selection that leaves none), the output is the base alone.
  if (out.base.defined()) out.output = out.output.defined() ? out.output + out.base : out.base;
  return out;
}

torch::Tensor LightFieldNetImpl::forward(const torch::Tensor& y, const torch::Tensor& phase,
                                         const torch::Tensor& noise) {
  if (!options_.is_image()) return forward_all(y, phase).output;
  const auto& p = options_.patch;
  auto ph = check_phase(y, phase);
  auto sensor = y.reshape({y.size(0), options_.measurements, p.height, p.width});
  return refine(pixel_pinv_image(sensor, ph), noise)
      .view({y.size(0), 1, p.rows, p.cols, p.height, p.width});
}

double cnn_patch_flops(const NetworkOptions& o) {
  const auto& p = o.patch;
  const int64_t c = o.cnn.channels;
  double flops = 0;
  for (int64_t i = 0; i < o.cnn.depth; ++i) {
    flops += conv4d_flops(1, i == 0 ? 1 : c, i + 1 == o.cnn.depth ? 1 : c, p.rows, p.cols, p.height,
                          p.width, o.kernel);
  }
  return flops;
}

double cnn_full_flops(const NetworkOptions& o, int64_t height, int64_t width, int64_t tile) {
  const double per_position = cnn_patch_flops(o) / static_cast<double>(o.patch.size());
  const int64_t halo = o.cnn.depth * (o.kernel / 2);
  double positions = 0;
  for (int64_t y0 = 0; y0 < height; y0 += tile) {
    for (int64_t x0 = 0; x0 < width; x0 += tile) {
      positions += static_cast<double>((std::min(tile, height - y0) + 2 * halo) *
                                       (std::min(tile, width - x0) + 2 * halo));
    }
  }
  return per_position * positions * static_cast<double>(o.patch.rows * o.patch.cols);
}

double image_pixel_flops(const NetworkOptions& o) {
  const int64_t views = o.patch.rows * o.patch.cols;
  return 2.0 * static_cast<double>(o.measurements * views) + o.image.pixel_flops(views, views);
}

double image_full_flops(const NetworkOptions& o, int64_t height, int64_t width, int64_t tile) {
  double pixels = 0;
  for (const auto& t : image_tiles(o.image, height, width, tile)) {
    pixels += static_cast<double>((t.a1 - t.a0) * (t.b1 - t.b0));
  }
  return image_pixel_flops(o) * pixels;
}

double patch_flops(const NetworkOptions& o, const BranchSelection& run) {
  if (o.is_image()) return image_pixel_flops(o) * static_cast<double>(o.patch.pixels());
  const auto& p = o.patch;
  const double d = static_cast<double>(p.size()), m = static_cast<double>(o.measurement_size());
  auto conv = [&](int64_t cin, int64_t cout) {
    return conv4d_flops(1, cin, cout, p.rows, p.cols, p.height, p.width, o.kernel);
  };
  const bool ae = run.ae && o.has_ae(), cnn = run.cnn && o.has_cnn();
  double flops = 0;
  if (cnn || (ae && o.ae.input == AeInput::kAdjoint)) flops += 2 * m * d;
  if (ae) {
    double in = static_cast<double>(o.ae_input_size());
    std::vector<int64_t> widths = o.ae.hidden;
    widths.push_back(p.size());
    for (auto w : widths) {
      flops += 2 * in * static_cast<double>(w);
      in = static_cast<double>(w);
    }
    flops += conv(1, 1);
  }
  if (cnn) flops += cnn_patch_flops(o);
  if (o.residual == Residual::kPinv) flops += 2 * m * d;
  return flops;
}

}  // namespace lfnet::nn

#include "lfnet/nn/network.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/optics/cfa.h"

namespace lfnet::nn {

// ---- options -------------------------------------------------------------------------------

namespace {
constexpr EnumName<Branches> kBranches[] = {
    {Branches::kNet, "net"}, {Branches::kAe, "ae"}, {Branches::kCnn, "cnn"}};
constexpr EnumName<Residual> kResiduals[] = {
    {Residual::kNone, "none"}, {Residual::kPinv, "pinv"}, {Residual::kAdjoint, "adjoint"}};
constexpr EnumName<AeInput> kAeInputs[] = {{AeInput::kMeasurements, "measurements"},
                                           {AeInput::kAdjoint, "adjoint"}};
}  // namespace

std::string to_string(Branches value) { return name_of(value, kBranches); }
std::string to_string(Residual value) { return name_of(value, kResiduals); }
std::string to_string(AeInput value) { return name_of(value, kAeInputs); }
Branches from_string(const std::string& name, Branches) { return value_of(name, kBranches); }
Residual from_string(const std::string& name, Residual) { return value_of(name, kResiduals); }
AeInput from_string(const std::string& name, AeInput) { return value_of(name, kAeInputs); }

void PatchShape::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json PatchShape::to_json() const { return fields_to_json(*this); }
void AutoencoderOptions::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json AutoencoderOptions::to_json() const { return fields_to_json(*this); }
void CnnOptions::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json CnnOptions::to_json() const { return fields_to_json(*this); }

namespace {
// The keys of the paper's section, from its fields (the keys files held at the top level).
std::vector<std::string> paper_section_keys() {
  const PaperOptions defaults;  // named: GCC 12 warns of a temporary's vectors
  const auto fields = fields_to_json(defaults);
  std::vector<std::string> keys;
  for (const auto& item : fields.items()) keys.push_back(item.key());
  return keys;
}
}  // namespace

NetworkOptions NetworkOptions::from_json(const nlohmann::json& j, const std::string& path) {
  NetworkOptions options;
  JsonReader reader(j, path);
  options.read(reader);
  reader.finish();
  return options;
}

NetworkOptions NetworkOptions::from_file_json(const nlohmann::json& j, const std::string& path) {
  auto own = j;
  if (own.is_object()) {
    const auto it = own.find("architecture");
    const std::string architecture = it != own.end() && it->is_string()
                                         ? it->get<std::string>()
                                         : std::string(kPaperArchitecture);
    // The paper options at the top level: into the paper's section, dropped for the others.
    nlohmann::json paper = nlohmann::json::object();
    for (const auto& key : paper_section_keys()) {
      if (!own.contains(key)) continue;
      paper[key] = own[key];
      own.erase(key);
    }
    if (architecture == kPaperArchitecture && !paper.empty() && !own.contains(kPaperSection)) {
      own[kPaperSection] = paper;
    }
    std::string kept;  // an unknown architecture is refused by from_json, naming it
    for (const auto& name : registered_architectures()) {
      if (name == architecture) kept = find_architecture(name).options_section();
    }
    for (const auto& name : registered_architectures()) {
      const auto key = find_architecture(name).options_section();
      if (!key.empty() && key != kept) own.erase(key);
    }
  }
  return from_json(own, path);
}

void NetworkOptions::read(JsonReader& reader) {
  for (const auto& key : paper_section_keys()) {
    LFNET_CHECK_AS(ConfigError, !reader.has(key), reader.path_of(key),
                   ": the paper architecture's options are its section \"paper\": write ",
                   reader.path_of(std::string(kPaperSection) + "." + key));
  }
  read_fields(reader, *this);
  reader.get("frames", frames);
  // The sections of the architectures that own theirs, kept as read (validate parses them).
  sections = nlohmann::json::object();
  for (const auto& name : registered_architectures()) {
    const auto key = find_architecture(name).options_section();
    if (!key.empty() && reader.has(key)) sections[key] = reader.child(key).object();
  }
  with_path(reader, [&] { validate(); });
}

nlohmann::json NetworkOptions::to_json() const {
  auto j = fields_to_json(*this);
  if (frames != 1) j["frames"] = frames;  // still nets keep the JSON they always had
  for (const auto& [key, value] : sections.items()) j[key] = value;
  // The architecture's own section in full, so a file keeps the values it was built with (an
  // unknown architecture's is left as read: validate names it).
  for (const auto& name : registered_architectures()) {
    const auto& a = find_architecture(name);
    const auto key = a.options_section();
    if (name != architecture || key.empty()) continue;
    auto full = a.default_options();
    if (sections.contains(key)) full.merge_patch(sections[key]);
    j[key] = full;
  }
  return j;
}

void NetworkOptions::validate() const {
  auto fail = [](const std::string& field, const std::string& what) {
    throw ConfigError(field + ": " + what);
  };
  const NetworkArchitecture* a = nullptr;
  try {
    a = &arch();
  } catch (const ConfigError& e) {
    fail("architecture", e.what());
  }
  if (patch.rows < 1 || patch.cols < 1 || patch.height < 1 || patch.width < 1) {
    fail("patch", "every size must be positive, got " + patch.to_json().dump());
  }
  if (measurements < 1) fail("measurements", "must be >= 1, got " + std::to_string(measurements));
  if (frames < 1 || frames > 64 || patch.rows % frames != 0) {
    fail("frames", "must be in 1..64 and divide patch.rows (" + std::to_string(patch.rows) +
                       "), got " + std::to_string(frames));
  }
  if (!(pinv_lambda > 0) || !std::isfinite(pinv_lambda)) {
    fail("pinv_lambda", "must be positive and finite");
  }
  for (const auto& [key, value] : sections.items()) {
    if (key != a->options_section()) {
      fail(key, "these options belong to another architecture than '" + architecture + "'");
    }
  }
  if (!cfa.empty()) {
    if (!a->colour()) {
      fail("cfa", "a colour net needs an architecture that reconstructs colour (lfnet), not '" +
                      architecture + "'");
    }
    try {
      optics::ColourFilterArray::bayer(cfa);
    } catch (const ConfigError& e) {
      fail("cfa", e.what());
    }
  }
  a->validate(*this);
}

Branches NetworkOptions::branches() const {
  return architecture == kPaperArchitecture ? paper_options(*this).branches : Branches::kNet;
}

void NetworkOptions::set_branches(Branches value) {
  if (architecture == kPaperArchitecture) {
    auto paper = paper_options(*this);
    paper.branches = value;
    set_paper_options(*this, paper);
    return;
  }
  LFNET_CHECK_AS(ConfigError, value == Branches::kNet, "the ", architecture,
                 " architecture has no branches to train or run alone (branches '",
                 to_string(value), "')");
}

PaperOptions paper_options(const NetworkOptions& o) {
  return o.unchecked_section<PaperOptions>(kPaperSection);
}

void set_paper_options(NetworkOptions& o, const PaperOptions& paper) {
  o.set_section(kPaperSection, paper);
}

int64_t ae_input_size(const NetworkOptions& o, const PaperOptions& paper) {
  return paper.ae.input == AeInput::kAdjoint ? o.patch.size() : o.measurement_size();
}

// ---- branches ------------------------------------------------------------------------------

AutoencoderBranchImpl::AutoencoderBranchImpl(const NetworkOptions& options)
    : patch_(options.patch) {
  const auto paper = paper_options(options);
  std::vector<int64_t> widths{ae_input_size(options, paper)};
  widths.insert(widths.end(), paper.ae.hidden.begin(), paper.ae.hidden.end());
  widths.push_back(options.patch.size());
  for (size_t i = 0; i + 1 < widths.size(); ++i) {
    fc.push_back(
        register_module("fc" + std::to_string(i + 1), torch::nn::Linear(widths[i], widths[i + 1])));
  }
  Conv4dOptions conv_options;
  conv_options.kernel = paper.kernel;
  conv_options.algorithm = paper.conv_algorithm;
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
  const auto paper = paper_options(options);
  const auto& cnn = paper.cnn;
  for (int64_t i = 0; i < cnn.depth; ++i) {
    Conv4dOptions conv_options;
    conv_options.in_channels = i == 0 ? 1 : cnn.channels;
    conv_options.out_channels = i + 1 == cnn.depth ? 1 : cnn.channels;
    conv_options.kernel = paper.kernel;
    conv_options.algorithm = paper.conv_algorithm;
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
  net->architecture().set_precision(*net, dtype);
}

void emulate_precision(LightFieldNet& net, Precision precision) {
  const auto dtype = precision == Precision::kBFloat16 ? torch::kBFloat16 : torch::kFloat32;
  net->architecture().emulate_precision(*net, dtype);
}

int64_t parameter_count(const torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

// ---- the network ---------------------------------------------------------------------------

LightFieldNetImpl::LightFieldNetImpl(NetworkOptions options) : options_(std::move(options)) {
  options_.validate();
  arch_ = &options_.arch();
  arch_->build(*this);
}

void LightFieldNetImpl::set_phi(const torch::Tensor& stack) { arch_->set_phi(*this, stack); }

int64_t LightFieldNetImpl::period() const {
  const int64_t p = phases();
  auto t = static_cast<int64_t>(std::lround(std::sqrt(static_cast<double>(p))));
  LFNET_CHECK(t * t == p, "the net's Phi has ", p, " phases, which is no period squared");
  return t;
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

NetworkOutputs LightFieldNetImpl::forward_all(const torch::Tensor& y, const torch::Tensor& phase) {
  return forward_all(y, phase, BranchSelection{});
}

NetworkOutputs LightFieldNetImpl::forward_all(const torch::Tensor& y, const torch::Tensor& phase,
                                              BranchSelection run) {
  return arch_->forward_all(*this, y, phase, {}, run);
}

torch::Tensor LightFieldNetImpl::forward(const torch::Tensor& y, const torch::Tensor& phase,
                                         const torch::Tensor& noise) {
  return arch_->forward_all(*this, y, phase, noise, BranchSelection{}).output;
}

torch::Tensor LightFieldNetImpl::forward_image(const torch::Tensor& sensor, int64_t phase,
                                               double noise_sigma) {
  return arch_->forward_image(*this, sensor, phase, noise_sigma);
}

double cnn_patch_flops(const NetworkOptions& o) {
  const auto& p = o.patch;
  const auto paper = paper_options(o);
  const int64_t c = paper.cnn.channels, depth = paper.cnn.depth;
  double flops = 0;
  for (int64_t i = 0; i < depth; ++i) {
    flops += conv4d_flops(1, i == 0 ? 1 : c, i + 1 == depth ? 1 : c, p.rows, p.cols, p.height,
                          p.width, paper.kernel);
  }
  return flops;
}

double cnn_full_flops(const NetworkOptions& o, int64_t height, int64_t width, int64_t tile) {
  const double per_position = cnn_patch_flops(o) / static_cast<double>(o.patch.size());
  const auto paper = paper_options(o);
  const int64_t halo = paper.cnn.depth * (paper.kernel / 2);
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
  const int64_t views = o.patch.rows * o.patch.cols, channels = o.colours() * views;
  // A time-coded camera's net also forms and reads the held still estimate.
  const int64_t estimates = o.frames > 1 ? 2 : 1;
  return 2.0 * static_cast<double>(estimates * o.measurements * views) +
         image_options(o).pixel_flops(estimates * channels, channels);
}

double image_full_flops(const NetworkOptions& o, int64_t height, int64_t width, int64_t tile) {
  return o.arch().image_flops(o, height, width, tile);
}

double patch_flops(const NetworkOptions& o, const BranchSelection& run) {
  return o.arch().patch_flops(o, run);
}

}  // namespace lfnet::nn

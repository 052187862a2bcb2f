// Hard cases (docs/robustness.md): extreme scenes, extreme noise, degenerate codes and badly
// scaled measurements, simulated and then reconstructed with every method. Every output must
// be finite, the clamped output must lie in [0, 1], and the sparse solvers must stop within
// their bounds and say when they did not converge.
#include <catch2/catch.hpp>

#include <cmath>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/light_field.h"
#include "lfnet/core/metrics.h"
#include "lfnet/dict/dictionary.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"
#include "lfnet/recon/methods.h"
#include "lfnet/recon/reconstruct.h"
#include "support/small_nets.h"

using namespace lfnet;

namespace {

constexpr int64_t kU = 5, kV = 5, kSize = 23, kPatch = 9, kStride = 7;

// A local Phi given by its weights M_n(u, v, y mod T, x mod T): lets the tests build codes no
// built-in model makes (duplicated rows, a closed exposure).
class CodePhi : public optics::Phi {
 public:
  // `code` (N, U, V, T, T) float64.
  CodePhi(const std::string& name, torch::Tensor code)
      : Phi(make_spec(name, code)), code_(std::move(code)) {}

  torch::Tensor forward(const torch::Tensor& lf) const override {
    auto w = tile(0, 0, lf.size(-2), lf.size(-1)).to(lf.scalar_type());
    return (lf.unsqueeze(-5) * w).sum({-4, -3});
  }
  torch::Tensor adjoint(const torch::Tensor& y) const override {
    auto w = tile(0, 0, y.size(-2), y.size(-1)).to(y.scalar_type());
    return (y.unsqueeze(-3).unsqueeze(-3) * w).sum(-5);
  }
  torch::Tensor patch_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w,
                             torch::ScalarType dtype) const override {
    // A[(n, y, x), (u, v, y', x')] = M_n(u, v, y, x) when (y, x) = (y', x').
    auto m = tile(y0, x0, h, w).permute({0, 3, 4, 1, 2});  // (N, h, w, U, V)
    auto eye = torch::eye(h * w, torch::kFloat64).view({1, h, w, 1, 1, h, w});
    auto a = m.unsqueeze(-1).unsqueeze(-1) * eye;
    return a.reshape({code_.size(0) * h * w, code_.size(1) * code_.size(2) * h * w}).to(dtype);
  }
  int64_t period() const override { return code_.size(3); }
  torch::Tensor pixel_weights(int64_t y0, int64_t x0, int64_t h, int64_t w,
                              torch::ScalarType dtype) const override {
    return tile(y0, x0, h, w).to(dtype);
  }

 private:
  static optics::PhiSpec make_spec(const std::string& name, const torch::Tensor& code) {
    optics::PhiSpec s;
    s.name = name;
    s.n = code.size(0);
    s.rows = code.size(1);
    s.cols = code.size(2);
    return s;
  }
  torch::Tensor tile(int64_t y0, int64_t x0, int64_t h, int64_t w) const {
    const int64_t t = code_.size(3);
    auto iy = (torch::arange(h, torch::kInt64) + y0).remainder(t);
    auto ix = (torch::arange(w, torch::kInt64) + x0).remainder(t);
    return code_.index_select(3, iy).index_select(4, ix);
  }
  torch::Tensor code_;
};

// asp:4 with its second row replaced by the first: rank 3 where the shape promises 4.
std::unique_ptr<optics::Phi> duplicated_asp() {
  auto asp = optics::make_phi(optics::PhiSpec::parse("asp:4"));
  auto w = asp->pixel_weights(0, 0, 1, 1, torch::kFloat64).clone();  // (4, U, V, 1, 1)
  w[1] = w[0];
  return std::make_unique<CodePhi>("asp-duplicated", w);
}

// mask:2 (period 3) with its second exposure fully closed: half the measurements are zero.
std::unique_ptr<optics::Phi> closed_exposure_mask() {
  auto spec = optics::PhiSpec::parse("mask:2");
  spec.params = {{"period", 3}};
  auto mask = optics::make_phi(spec);
  const int64_t t = mask->period();
  auto w = mask->pixel_weights(0, 0, t, t, torch::kFloat64).clone();  // (2, U, V, T, T)
  w[1].zero_();
  return std::make_unique<CodePhi>("mask-closed", w);
}

// A mask whose only exposure is closed: the measurements carry nothing at all.
std::unique_ptr<optics::Phi> blind_mask() {
  return std::make_unique<CodePhi>("mask-blind", torch::zeros({1, kU, kV, 3, 3}, torch::kFloat64));
}

// A light field (1, U, V, H, W) whose views are `texture` (H + 2 pad, W + 2 pad) shifted by
// `disparity` pixels per view step (integer shifts, wrapped).
torch::Tensor shifted_views(const torch::Tensor& texture, int64_t disparity) {
  auto lf = torch::empty({1, kU, kV, kSize, kSize});
  for (int64_t u = 0; u < kU; ++u) {
    for (int64_t v = 0; v < kV; ++v) {
      lf[0][u][v] =
          torch::roll(texture, {disparity * (u - kU / 2), disparity * (v - kV / 2)}, {0, 1});
    }
  }
  return lf;
}

// The hard scenes, by name.
std::map<std::string, torch::Tensor> hard_scenes() {
  torch::manual_seed(7);
  std::map<std::string, torch::Tensor> s;
  s["black"] = torch::zeros({1, kU, kV, kSize, kSize});
  s["white"] = torch::ones({1, kU, kV, kSize, kSize});
  s["grey"] = torch::full({1, kU, kV, kSize, kSize}, 0.5);
  auto y = torch::arange(kSize).view({kSize, 1}), x = torch::arange(kSize).view({1, kSize});
  s["checker"] = shifted_views((y + x).remainder(2).to(torch::kFloat32), 0);
  s["nyquist_rows"] = shifted_views(y.remainder(2).expand({kSize, kSize}).to(torch::kFloat32), 0);
  s["nyquist_cols"] = shifted_views(x.remainder(2).expand({kSize, kSize}).to(torch::kFloat32), 0);
  // 7 pixels per view step: 28 pixels across the 5 views, more than a 9-pixel patch.
  s["disparity_7"] = shifted_views(torch::rand({kSize, kSize}), 7);
  s["disparity_-4_checker"] =
      shifted_views((y.floor_divide(2) + x.floor_divide(2)).remainder(2).to(torch::kFloat32), -4);
  s["random"] = torch::rand({1, kU, kV, kSize, kSize});
  return s;
}

// A small random dictionary over 5 x 5 x 9 x 9 patches: a flat atom and random unit atoms.
dict::Dictionary small_dictionary() {
  torch::manual_seed(3);
  auto atoms = torch::randn({kU * kV * kPatch * kPatch, 48});
  atoms.select(1, 0).fill_(1.0);
  atoms = atoms / atoms.norm(2, 0, /*keepdim=*/true);
  dict::Dictionary d;
  d.atoms = atoms.contiguous();
  d.patch_shape = {kU, kV, kPatch, kPatch};
  return d;
}

// A small randomly initialised two-branch net for `phi`.
nn::LightFieldNet small_net(const optics::Phi& phi) {
  torch::manual_seed(11);
  nn::NetworkOptions o;
  o.measurements = phi.measurements();
  lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
    p.ae.hidden = {32, 16, 32, 16, 32};
    p.cnn.channels = 2;
    p.cnn.depth = 2;
  });
  nn::LightFieldNet net(o);
  net->set_phi(optics::patch_matrix_stack(phi, kPatch, kPatch));
  return net;
}

// Every patch method (no-parallax needs the truth and is checked apart), as solvers for `phi`.
std::vector<std::pair<std::string, recon::PatchSolver>> solvers(const optics::Phi& phi,
                                                                int64_t admm_iterations = 500) {
  std::vector<std::pair<std::string, recon::PatchSolver>> out;
  auto net = small_net(phi);
  for (const char* m : {"net", "ae", "cnn"}) out.emplace_back(m, recon::network_solver(net, m));
  out.emplace_back("pinv", recon::pinv_solver(optics::pinv_matrix_stack(phi, kPatch, kPatch)));
  out.emplace_back("adjoint",
                   recon::adjoint_solver(optics::patch_matrix_stack(phi, kPatch, kPatch)));
  const auto d = small_dictionary();
  dict::SparseCodingOptions omp;
  omp.omp.max_atoms = 6;
  out.emplace_back("dict-omp", recon::dictionary_solver(phi, d, omp, kPatch, kPatch));
  dict::SparseCodingOptions admm;
  admm.method = lfnet::dict::CodingMethod::kAdmm;
  admm.admm.max_iterations = admm_iterations;
  out.emplace_back("dict-admm", recon::dictionary_solver(phi, d, admm, kPatch, kPatch));
  return out;
}

recon::ReconstructOptions raw_options() {
  recon::ReconstructOptions o;
  o.stride = kStride;
  o.clamp = false;  // look at what the solvers return, not what clamping hides
  return o;
}

bool finite(const torch::Tensor& t) { return torch::isfinite(t).all().item<bool>(); }

// Reconstructs `sensor` (N, H, W) with every method; checks every raw output is finite and
// every clamped output lies in [0, 1]; returns the raw outputs by method.
using Solvers = std::vector<std::pair<std::string, recon::PatchSolver>>;

std::map<std::string, torch::Tensor> reconstruct_all(const optics::Phi& phi, const Solvers& methods,
                                                     const torch::Tensor& sensor,
                                                     const std::string& label,
                                                     int64_t* cases = nullptr) {
  std::map<std::string, torch::Tensor> out;
  for (const auto& [method, solver] : methods) {
    INFO(label << " / " << method);
    torch::Tensor raw;
    REQUIRE_NOTHROW(raw = recon::reconstruct_sensor(phi, sensor, solver, raw_options()));
    REQUIRE(raw.sizes() == torch::IntArrayRef({1, kU, kV, sensor.size(1), sensor.size(2)}));
    CHECK(finite(raw));
    auto clamped = raw.clamp(0, 1);
    CHECK(clamped.min().item<double>() >= 0.0);
    CHECK(clamped.max().item<double>() <= 1.0);
    out[method] = raw;
    if (cases) ++*cases;
  }
  return out;
}

double max_abs(const torch::Tensor& t) { return t.abs().max().item<double>(); }

}  // namespace

TEST_CASE("every method stays finite on black, white, grey, Nyquist and extreme-disparity scenes",
          "[hard_cases]") {
  int64_t cases = 0;
  for (const char* name : {"asp:2", "mask:2"}) {
    auto phi = optics::make_phi(optics::PhiSpec::parse(name));
    const auto methods = solvers(*phi);
    for (const auto& [scene, lf] : hard_scenes()) {
      const std::string label = std::string(name) + " " + scene;
      auto sensor = optics::simulate_sensor(*phi, lf[0]);
      REQUIRE(finite(sensor));
      auto raw = reconstruct_all(*phi, methods, sensor, label, &cases);
      // The no-parallax baseline is the truth's angular mean: exact for constant scenes.
      auto flat = LightField(lf).angular_mean().data();
      CHECK(finite(flat));
      if (scene == "black") {
        // Zero measurements: every non-network method returns exactly zero.
        for (const char* m : {"pinv", "adjoint", "dict-omp", "dict-admm"}) {
          INFO(label << " / " << m);
          CHECK(max_abs(raw[m]) < 1e-6);
        }
      }
      if ((scene == "grey" || scene == "white") && std::string(name) == "asp:2") {
        // A flat patch is in the row space of asp's complementary pair: the adjoint (normalised
        // by A^T A 1) returns it exactly, pinv up to its Tikhonov shrinkage. (A mask never sees
        // the rays its exposures all block; those come back 0.)
        const double level = lf.mean().item<double>();
        INFO(label);
        CHECK(max_abs(raw["adjoint"] - level) < 1e-4);
        CHECK(max_abs(raw["pinv"] - level) < 0.05);
      }
    }
  }
  CHECK(cases == int64_t{2} * 9 * 7);
}

TEST_CASE("saturated highlights: a clipped, quantised white sensor reconstructs finitely",
          "[hard_cases]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  optics::SensorOptions effects;
  effects.saturation = optics::SensorOptions::Saturation{500.0};  // a white scene is over full well
  effects.adc = optics::SensorOptions::Adc{8, 0.5};               // and over the ADC's top code
  effects.shot = optics::SensorOptions::Shot{};
  auto lf = torch::ones({1, kU, kV, kSize, kSize});
  auto sensor = optics::simulate_sensor(*phi, lf[0], effects, 5);
  REQUIRE(finite(sensor));
  // Every pixel is clipped to the ADC's top code.
  CHECK(sensor.max().item<double>() <= 0.5 + 1e-6);
  CHECK(sensor.min().item<double>() >= 0.45);
  auto raw = reconstruct_all(*phi, solvers(*phi), sensor, "saturated white");
  // Clipping at half of white: the linear methods see a half-grey scene.
  CHECK(std::abs(raw["adjoint"].mean().item<double>() - 0.5) < 0.03);
}

TEST_CASE("noise up to sigma 1 gives finite reconstructions", "[hard_cases]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto lf = hard_scenes()["random"];
  const auto methods = solvers(*phi);
  for (double sigma : {0.1, 0.5, 1.0}) {
    optics::SensorOptions effects;
    effects.gaussian = optics::SensorOptions::Gaussian{sigma};
    auto sensor = optics::simulate_sensor(*phi, lf[0], effects, 9);
    REQUIRE(finite(sensor));
    // The noise is what was asked for (the noiseless sensor is the reference).
    const double measured = (sensor - optics::simulate_sensor(*phi, lf[0])).std().item<double>();
    CHECK(measured == Approx(sigma).epsilon(0.1));
    reconstruct_all(*phi, methods, sensor, "noise " + std::to_string(sigma));
  }
}

TEST_CASE("N = 1, N = 25 and rank-deficient codes reconstruct finitely", "[hard_cases]") {
  auto lf = hard_scenes()["random"];
  std::vector<std::unique_ptr<optics::Phi>> phis;
  for (const char* name : {"asp:1", "asp:25", "mask:1", "aperture:1", "aperture:25", "lenslet:1"}) {
    phis.push_back(optics::make_phi(optics::PhiSpec::parse(name)));
  }
  phis.push_back(duplicated_asp());
  phis.push_back(closed_exposure_mask());
  phis.push_back(blind_mask());
  for (const auto& phi : phis) {
    auto sensor = optics::simulate_sensor(*phi, lf[0]);
    REQUIRE(finite(sensor));
    auto raw = reconstruct_all(*phi, solvers(*phi), sensor,
                               phi->spec().name + ":" + std::to_string(phi->measurements()));
    if (phi->spec().name == "mask-blind") {
      // Nothing was measured: the linear and sparse methods have nothing to return but zero.
      for (const char* m : {"pinv", "adjoint", "dict-omp", "dict-admm"}) {
        INFO(m);
        CHECK(max_abs(raw[m]) < 1e-6);
      }
    }
    if (phi->spec().name == "asp" && phi->measurements() == 25) {
      // Full rank: pinv is close to the truth even for a random light field.
      CHECK(psnr(raw["pinv"].clamp(0, 1), lf) > 25.0);
    }
  }
  // The duplicated row adds nothing: pinv gives what asp with three distinct rows gives.
  auto dup = duplicated_asp();
  auto sensor = optics::simulate_sensor(*dup, lf[0]);
  auto est = recon::reconstruct_sensor(
      *dup, sensor, recon::pinv_solver(optics::pinv_matrix_stack(*dup, 9, 9)), raw_options());
  CHECK(finite(est));
  auto c = optics::conditioning(*dup);
  CHECK(c.rank[0].item<int64_t>() == 3);
  CHECK(std::isinf(c.condition[0].item<double>()));
}

TEST_CASE("measurements scaled by 1e-6 and 1e6 stay finite and scale the linear methods",
          "[hard_cases]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto lf = hard_scenes()["random"];
  auto sensor = optics::simulate_sensor(*phi, lf[0]);
  const auto methods = solvers(*phi);
  auto reference = reconstruct_all(*phi, methods, sensor, "scale 1");
  for (double scale : {1e-6, 1e6}) {
    auto raw = reconstruct_all(*phi, methods, sensor * scale, "scale " + std::to_string(scale));
    // Linear methods and OMP (no tolerance) are homogeneous: the output scales with y.
    for (const char* m : {"pinv", "adjoint", "dict-omp"}) {
      INFO(m << " at scale " << scale);
      const double err = max_abs(raw[m] / scale - reference[m]);
      CHECK(err <= 1e-3 * std::max(1.0, max_abs(reference[m])));
    }
  }
}

TEST_CASE("non-finite measurements are a NumericalError, never a NaN light field", "[hard_cases]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto sensor = optics::simulate_sensor(*phi, hard_scenes()["random"][0]);
  for (double bad : {NAN, INFINITY}) {
    auto broken = sensor.clone();
    broken[1][12][12] = bad;
    for (auto& [method, solver] : solvers(*phi)) {
      INFO(method << " with " << bad);
      CHECK_THROWS_AS(recon::reconstruct_sensor(*phi, broken, solver, raw_options()),
                      NumericalError);
    }
  }
}

TEST_CASE("OMP and ADMM stop within their bounds and report non-convergence", "[hard_cases]") {
  const auto d = small_dictionary();
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  auto closed = closed_exposure_mask();
  auto blind = blind_mask();
  auto lf = hard_scenes()["random"];
  auto patches = lf[0].slice(2, 0, 9).slice(3, 0, 9).reshape({1, -1}).to(torch::kFloat64);
  struct Case {
    std::string name;
    torch::Tensor a;  // (m, d)
    torch::Tensor y;  // (B, m)
  };
  std::vector<Case> cases;
  for (auto* p : {phi.get(), closed.get(), blind.get()}) {
    auto a = p->patch_matrix(0, 0, 9, 9, torch::kFloat64);
    auto y = patches.mm(a.t());
    cases.push_back({p->spec().name + " y", a, y});
    cases.push_back({p->spec().name + " zero", a, torch::zeros_like(y)});
    cases.push_back({p->spec().name + " 1e-6", a, y * 1e-6});
    cases.push_back({p->spec().name + " 1e6", a, y * 1e6});
    cases.push_back({p->spec().name + " noise 1", a, y + torch::randn_like(y)});
  }
  for (const auto& c : cases) {
    INFO(c.name);
    dict::SparseCodingOptions omp;
    omp.omp.max_atoms = 6;
    auto r = dict::SparseCoder(d.atoms, omp).code(c.a, c.y);
    CHECK(finite(r.patches));
    CHECK(r.iterations.max().item<int64_t>() <= 6);
    CHECK(r.nonzeros.max().item<int64_t>() <= 6);
    for (int64_t limit : {3, 2000}) {
      dict::SparseCodingOptions admm;
      admm.method = lfnet::dict::CodingMethod::kAdmm;
      admm.admm.max_iterations = limit;
      auto a = dict::SparseCoder(d.atoms, admm).code(c.a, c.y);
      CHECK(finite(a.patches));
      CHECK(a.iterations.max().item<int64_t>() <= limit);
      if (limit == 3 && c.y.abs().max().item<double>() > 0 &&
          c.name.find("blind") == std::string::npos) {
        // Three iterations are far too few for a real patch: reported, not hidden.
        CHECK(a.unconverged() == 1);
      }
    }
  }
}

TEST_CASE("the dict method reports patches that did not converge", "[hard_cases]") {
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  const auto d = small_dictionary();
  auto sensor = optics::simulate_sensor(*phi, hard_scenes()["random"][0]);
  const int64_t patches = 9;  // 3 x 3 at stride 7 on 23 x 23
  dict::SparseCodingOptions admm;
  admm.method = lfnet::dict::CodingMethod::kAdmm;
  admm.admm.max_iterations = 3;
  auto report = std::make_shared<recon::SolverReport>();
  auto est = recon::reconstruct_sensor(
      *phi, sensor, recon::dictionary_solver(*phi, d, admm, kPatch, kPatch, report), raw_options());
  CHECK(finite(est));
  CHECK(report->patches == patches);
  CHECK(report->unconverged == patches);
  // With room to converge, ADMM does; OMP on a black scene ends normally (nothing to explain).
  admm.admm.max_iterations = 5000;
  auto enough = std::make_shared<recon::SolverReport>();
  recon::reconstruct_sensor(
      *phi, sensor, recon::dictionary_solver(*phi, d, admm, kPatch, kPatch, enough), raw_options());
  CHECK(enough->patches == patches);
  CHECK(enough->unconverged == 0);
  dict::SparseCodingOptions omp;
  auto black = std::make_shared<recon::SolverReport>();
  auto zero = recon::reconstruct_sensor(
      *phi, torch::zeros_like(sensor),
      recon::dictionary_solver(*phi, d, omp, kPatch, kPatch, black), raw_options());
  CHECK(max_abs(zero) == 0.0);
  CHECK(black->unconverged == 0);
}

#include "lfnet/nn/learned_phi.h"

#include <cmath>
#include <vector>

#include "lfnet/core/constants.h"
#include "lfnet/core/error.h"
#include "lfnet/optics/asp.h"

namespace lfnet::nn {

namespace {
// The starting modulation depth of an ASP, as a share of max_depth (a sigmoid never reaches 1).
constexpr double kStartDepth = 0.98;
}  // namespace

void LearnedPhiOptions::validate() const {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw ConfigError("learned_phi: " + what);
  };
  check(family == "mask" || family == "aperture" || family == "asp",
        "family must be mask, aperture or asp, got \"" + family + "\"");
  check(period >= 1 && period <= 64, "period must be in 1..64");
  check(family != "aperture" || period == 1, "an aperture is the same at every pixel: period 1");
  check(max_depth > 0 && max_depth <= 1, "max_depth must lie in (0, 1]");
  check(init == "random" || (family == "asp" && init == "table"),
        "init must be \"random\"" + std::string(family == "asp" ? " or \"table\"" : ""));
  check(init_spread >= 0 && std::isfinite(init_spread), "init_spread must be >= 0");
}

LearnedPhiImpl::LearnedPhiImpl(const LearnedPhiOptions& options, int64_t n, int64_t rows,
                               int64_t cols)
    : options_(options), n_(n), rows_(rows), cols_(cols) {
  options_.validate();
  LFNET_CHECK_AS(ConfigError, n >= 1 && rows >= 1 && cols >= 1 && n <= rows * cols,
                 "learned_phi: N must be in 1..U V, got N = ", n, " for ", rows, " x ", cols,
                 " views");
  const int64_t t = options_.period;
  auto gen = at::detail::createCPUGenerator(options_.seed);
  auto uniform = [&](const std::vector<int64_t>& shape) {
    return at::rand(shape, gen, torch::TensorOptions().dtype(torch::kFloat32));
  };
  if (options_.family == "mask") {
    // Transmittances uniform in [0.1, 0.9], as logits.
    logits_ =
        register_parameter("logits", torch::logit(0.1 + 0.8 * uniform({n, rows, cols, t, t})));
  } else if (options_.family == "aperture") {
    logits_ = register_parameter("logits", torch::logit(0.1 + 0.8 * uniform({n, rows, cols})));
  } else {
    auto beta = torch::empty({n, t, t}), gamma = torch::empty({n, t, t});
    auto alpha = torch::empty({n, t, t});
    if (options_.init == "table") {
      // The built-in ASP's rows (its complementary pair first, at 90 degrees: the quadrature
      // pair), every pixel of the period alike, plus a random spread.
      const auto table = optics::asp_table(rows, cols, n, false, 0.0, 90.0);
      for (int64_t k = 0; k < n; ++k) {
        beta[k].fill_(table[static_cast<size_t>(k)].beta);
        gamma[k].fill_(table[static_cast<size_t>(k)].gamma);
        alpha[k].fill_(table[static_cast<size_t>(k)].alpha);
      }
      const double spread = options_.init_spread;
      alpha = alpha + spread * (2 * uniform({n, t, t}) - 1);
      gamma = gamma + spread * (2 * uniform({n, t, t}) - 1);
    } else {
      beta = kPi * (0.5 + 1.5 * uniform({n, t, t}));
      gamma = kPi * uniform({n, t, t});
      alpha = 2 * kPi * uniform({n, t, t});
    }
    beta_ = register_parameter("beta", beta);
    gamma_ = register_parameter("gamma", gamma);
    alpha_ = register_parameter("alpha", alpha);
    depth_ = register_parameter("depth",
                                torch::full({n, t, t}, std::log(kStartDepth / (1 - kStartDepth))));
    auto angle = [](int64_t count) {
      return count > 1 ? torch::linspace(-1.0, 1.0, count) : torch::zeros({1});
    };
    theta_ = register_buffer("theta", angle(rows).view({rows, 1}));
    phi_ = register_buffer("phi", angle(cols).view({1, cols}));
  }
}

torch::Tensor LearnedPhiImpl::response() const {
  if (options_.family == "mask") return torch::sigmoid(logits_);
  if (options_.family == "aperture") return torch::sigmoid(logits_).view({n_, rows_, cols_, 1, 1});
  // (N, T, T, 1, 1) parameters against (U, V) angles: (N, T, T, U, V), then (N, U, V, T, T).
  auto at = [](const torch::Tensor& p) { return p.unsqueeze(-1).unsqueeze(-1); };
  const auto phase =
      at(beta_) * (at(torch::cos(gamma_)) * theta_ + at(torch::sin(gamma_)) * phi_) + at(alpha_);
  const auto m = options_.max_depth * torch::sigmoid(at(depth_));
  return ((1 + m * torch::cos(phase)) / 2).permute({0, 3, 4, 1, 2});
}

torch::Tensor LearnedPhiImpl::weights() const { return optics::normalise_white(response()); }

optics::PhiSpec calibrated_spec(const torch::Tensor& weights, const std::string& source) {
  LFNET_CHECK_AS(ConfigError, weights.dim() == 5 && weights.size(3) == weights.size(4),
                 "calibrated_spec: pixel weights are (N, U, V, T, T), got ", weights.sizes());
  const auto w = weights.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  optics::PhiSpec spec;
  spec.name = "calibrated";
  spec.n = w.size(0);
  spec.rows = w.size(1);
  spec.cols = w.size(2);
  spec.params = {
      {"period", w.size(3)},
      {"weights", std::vector<double>(w.data_ptr<double>(), w.data_ptr<double>() + w.numel())},
      {"normalise", false},
      {"source", source}};
  return spec;
}

optics::PhiSpec LearnedPhiImpl::spec() const {
  torch::NoGradGuard no_grad;
  return calibrated_spec(weights(), "learned " + options_.family);
}

nlohmann::json LearnedPhiImpl::physical() const {
  torch::NoGradGuard no_grad;
  auto list = [](const torch::Tensor& x) {
    const auto d = x.to(torch::kFloat64).contiguous();
    return std::vector<double>(d.data_ptr<double>(), d.data_ptr<double>() + d.numel());
  };
  if (options_.family != "asp") {
    return {{"family", options_.family},
            {"shape", response().sizes().vec()},
            {"transmittance", list(response())}};
  }
  return {{"family", "asp"},       {"shape", beta_.sizes().vec()},
          {"beta", list(beta_)},   {"gamma", list(gamma_)},
          {"alpha", list(alpha_)}, {"depth", list(options_.max_depth * torch::sigmoid(depth_))}};
}

torch::Tensor LearnedPhiImpl::straight_through_weights() const {
  LFNET_CHECK_AS(ConfigError, options_.family != "asp",
                 "an ASP's response is a cosine: it has no binary form");
  const auto open = response();
  const auto rounded = (open >= 0.5).to(open.scalar_type());
  return optics::normalise_white(rounded + open - open.detach());
}

torch::Tensor LearnedPhiImpl::binarised_weights() const {
  LFNET_CHECK_AS(ConfigError, options_.family != "asp",
                 "an ASP's response is a cosine: it has no binary form");
  torch::NoGradGuard no_grad;
  return optics::normalise_white((response() >= 0.5).to(torch::kFloat32));
}

}  // namespace lfnet::nn

// Angle Sensitive Pixels: oriented sinusoidal angular responses (Wang & Molnar; Hirsch et al.).
#include "lfnet/optics/asp.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "lfnet/core/constants.h"
#include "lfnet/core/error.h"
#include "models.h"

namespace lfnet::optics {

namespace {

// The representative of k modulo n in (-n/2, n/2].
int64_t centred(int64_t k, int64_t n) {
  int64_t m = ((k % n) + n) % n;
  if (2 * m > n) m -= n;
  return m;
}

struct Frequency {
  int64_t kt = 0, kp = 0;
  double beta = 0, gamma = 0;
  int64_t ring = 0;
  bool principal = false;
  bool self_conjugate = false;  // cos only: the sine vanishes on the grid
};

Frequency make_frequency(int64_t kt, int64_t kp, int64_t rows, int64_t cols) {
  Frequency f;
  f.kt = kt;
  f.kp = kp;
  // beta (cos, sin)(gamma) = (pi k_theta (U-1)/U, pi k_phi (V-1)/V): the DFT frequencies of
  // views at theta_u = -1 + 2u / (U - 1).
  const double wt = rows > 1 ? kPi * static_cast<double>(kt * (rows - 1)) / rows : 0.0;
  const double wp = cols > 1 ? kPi * static_cast<double>(kp * (cols - 1)) / cols : 0.0;
  f.beta = std::hypot(wt, wp);
  f.gamma = std::atan2(wp, wt);
  f.ring = std::max(std::abs(kt), std::abs(kp));
  f.principal = kt == 0 || kp == 0 || std::abs(kt) == std::abs(kp);
  f.self_conjugate = centred(-kt, rows) == kt && centred(-kp, cols) == kp;
  return f;
}

// One of each conjugate pair of non-zero DFT frequencies, orientation gamma in [0, pi).
std::vector<Frequency> half_plane(int64_t rows, int64_t cols) {
  auto upper = [](int64_t kt, int64_t kp) { return kp > 0 || (kp == 0 && kt > 0); };
  std::vector<Frequency> out;
  for (int64_t i = 0; i < rows; ++i) {
    for (int64_t j = 0; j < cols; ++j) {
      const int64_t kt = centred(i, rows), kp = centred(j, cols);
      if (kt == 0 && kp == 0) continue;
      Frequency f = make_frequency(kt, kp, rows, cols);
      if (!upper(kt, kp)) continue;
      if (!f.self_conjugate) {
        const int64_t ct = centred(-kt, rows), cp = centred(-kp, cols);
        // Aliased conjugates at the Nyquist frequency can both lie in the upper half plane:
        // keep the one of smaller orientation.
        if (upper(ct, cp) && make_frequency(ct, cp, rows, cols).gamma < f.gamma) continue;
      }
      out.push_back(f);
    }
  }
  return out;
}

AspRow row_of(const Frequency& f, double alpha, const char* role) {
  AspRow r;
  r.beta = f.beta;
  r.gamma = f.gamma;
  r.alpha = alpha;
  r.k_theta = f.kt;
  r.k_phi = f.kp;
  r.role = role;
  return r;
}

}  // namespace

std::vector<AspRow> asp_table(int64_t rows, int64_t cols, int64_t n, bool pairs, double pair_gamma,
                              double pair_alpha) {
  LFNET_CHECK_AS(ConfigError, rows >= 1 && cols >= 1, "asp needs at least one view, got ", rows,
                 "x", cols);
  LFNET_CHECK_AS(ConfigError, n >= 1 && n <= rows * cols, "asp on ", rows, "x", cols,
                 " views takes N from 1 to ", rows * cols, ", got ", n);
  auto freqs = half_plane(rows, cols);
  std::stable_sort(freqs.begin(), freqs.end(), [](const Frequency& a, const Frequency& b) {
    if (a.ring != b.ring) return a.ring < b.ring;
    if (a.principal != b.principal) return a.principal;
    return a.gamma < b.gamma;
  });
  // Rows group by group (ring, principal first): in-phase by gamma, then quadrature by gamma.
  std::vector<AspRow> sequence;
  for (size_t g = 0; g < freqs.size();) {
    size_t end = g;
    while (end < freqs.size() && freqs[end].ring == freqs[g].ring &&
           freqs[end].principal == freqs[g].principal) {
      ++end;
    }
    for (size_t i = g; i < end; ++i) sequence.push_back(row_of(freqs[i], 0.0, "in-phase"));
    for (size_t i = g; i < end; ++i) {
      if (!freqs[i].self_conjugate) sequence.push_back(row_of(freqs[i], kPi / 2, "quadrature"));
    }
    g = end;
  }
  std::vector<AspRow> table;
  if (sequence.empty()) {  // a single view: a conventional pixel
    AspRow r;
    r.role = "pair";
    table.push_back(r);
    return table;
  }
  // The pair's row: the first row of the sequence at the requested orientation and phase.
  size_t first = sequence.size();
  for (size_t i = 0; i < sequence.size() && first == sequence.size(); ++i) {
    if (std::abs(sequence[i].gamma * 180.0 / kPi - pair_gamma) < 1e-6 &&
        std::abs(sequence[i].alpha * 180.0 / kPi - pair_alpha) < 1e-6) {
      first = i;
    }
  }
  LFNET_CHECK_AS(ConfigError, first < sequence.size(), "asp on ", rows, "x", cols,
                 " views has no row at orientation ", pair_gamma, " and phase ", pair_alpha,
                 " degrees for its complementary pair (orientations 0/45/90/135..., phases 0/90)");
  std::rotate(sequence.begin(), sequence.begin() + static_cast<std::ptrdiff_t>(first),
              sequence.begin() + static_cast<std::ptrdiff_t>(first) + 1);
  sequence[0].role = "pair";
  AspRow partner = sequence[0];
  partner.alpha += kPi;
  table.push_back(sequence[0]);
  table.push_back(partner);
  for (size_t i = 1; i < sequence.size() && static_cast<int64_t>(table.size()) < n; ++i) {
    table.push_back(sequence[i]);
    if (pairs) {
      AspRow complement = sequence[i];
      complement.alpha += kPi;
      complement.role = "complement";
      table.push_back(complement);
    }
  }
  table.resize(static_cast<size_t>(n));
  return table;
}

namespace detail {

AspParams AspParams::read(JsonReader& r) {
  AspParams p;
  r.get("depth", p.depth);
  r.get("aperture", p.aperture);
  r.get("radius", p.radius);
  r.get("edge", p.edge);
  r.get("layout", p.layout);
  r.get("pair_gamma", p.pair_gamma);
  r.get("pair_alpha", p.pair_alpha);
  r.finish();
  LFNET_CHECK_AS(ConfigError, p.depth > 0 && p.depth <= 1, r.path_of("depth"),
                 ": the modulation depth m must be in (0, 1], got ", p.depth);
  LFNET_CHECK_AS(ConfigError, p.aperture == "full" || p.aperture == "disk", r.path_of("aperture"),
                 ": expected \"full\" or \"disk\", got \"", p.aperture, "\"");
  // Both relative to the aperture's radius: 10 is already far outside it.
  LFNET_CHECK_AS(ConfigError, p.radius > 0 && p.radius <= 10, r.path_of("radius"),
                 ": must lie in (0, 10], got ", p.radius);
  LFNET_CHECK_AS(ConfigError, p.edge > 0 && p.edge <= 10, r.path_of("edge"),
                 ": must lie in (0, 10], got ", p.edge);
  LFNET_CHECK_AS(ConfigError, p.layout == "independent" || p.layout == "pairs", r.path_of("layout"),
                 ": expected \"independent\" or \"pairs\", got \"", p.layout, "\"");
  return p;
}

nlohmann::json AspParams::to_json() const {
  return {{"depth", depth},   {"aperture", aperture},     {"radius", radius},        {"edge", edge},
          {"layout", layout}, {"pair_gamma", pair_gamma}, {"pair_alpha", pair_alpha}};
}

torch::Tensor asp_weights(const PhiSpec& spec, const AspParams& params) {
  const int64_t u_n = spec.rows, v_n = spec.cols;
  const auto table =
      asp_table(u_n, v_n, spec.n, params.layout == "pairs", params.pair_gamma, params.pair_alpha);
  auto angle = [](int64_t i, int64_t count) {
    return count > 1 ? -1.0 + 2.0 * static_cast<double>(i) / static_cast<double>(count - 1) : 0.0;
  };
  auto m = torch::empty({spec.n, u_n, v_n}, torch::kFloat64);
  auto acc = m.accessor<double, 3>();
  for (int64_t u = 0; u < u_n; ++u) {
    for (int64_t v = 0; v < v_n; ++v) {
      const double theta = angle(u, u_n), phi = angle(v, v_n);
      double a = 1.0;
      if (params.aperture == "disk") {
        const double r = std::hypot(theta, phi);
        a = std::clamp((params.radius - r) / params.edge + 0.5, 0.0, 1.0);
      }
      for (int64_t n = 0; n < spec.n; ++n) {
        const auto& row = table[static_cast<size_t>(n)];
        const double phase =
            row.beta * (std::cos(row.gamma) * theta + std::sin(row.gamma) * phi) + row.alpha;
        acc[n][u][v] = a * (1.0 + params.depth * std::cos(phase)) / 2.0;
      }
    }
  }
  return normalise_white(m.view({spec.n, u_n, v_n, 1, 1})).view({spec.n, u_n, v_n});
}

std::unique_ptr<Phi> make_asp(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  AspParams params = AspParams::read(r);
  // Grids without a quadrature row at the pair's orientation (a single row or column of
  // views: the odd frequencies vanish) take the phase-0 pair unless a phase was asked for.
  if (!r.has("pair_alpha")) {
    try {
      (void)asp_table(spec.rows, spec.cols, spec.n, params.layout == "pairs", params.pair_gamma,
                      params.pair_alpha);
    } catch (const ConfigError&) {
      params.pair_alpha = 0.0;
    }
  }
  PhiSpec resolved = spec;
  resolved.params = params.to_json();
  auto weights = asp_weights(resolved, params);
  return std::make_unique<LocalPhi>(resolved, weights.view({spec.n, spec.rows, spec.cols, 1, 1}));
}

}  // namespace detail
}  // namespace lfnet::optics

#include "lfnet/dict/ksvd.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/progress.h"
#include "lfnet/dict/omp.h"

namespace lfnet::dict {

std::string to_string(AtomUpdate update) {
  return update == AtomUpdate::kExact ? "exact" : "approximate";
}

AtomUpdate parse_atom_update(const std::string& name) {
  if (name == "approximate") return AtomUpdate::kApproximate;
  if (name == "exact") return AtomUpdate::kExact;
  throw ConfigError("unknown atom update \"" + name + "\" (known: approximate, exact)");
}

void KsvdOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, atoms >= 1, "ksvd.atoms must be >= 1, got ", atoms);
  LFNET_CHECK_AS(ConfigError, sparsity >= 1 && sparsity <= atoms,
                 "ksvd.sparsity must be in [1, atoms = ", atoms, "], got ", sparsity);
  LFNET_CHECK_AS(ConfigError, std::isfinite(target_error) && target_error >= 0.0,
                 "ksvd.target_error must be >= 0, got ", target_error);
  LFNET_CHECK_AS(ConfigError, iterations >= 1, "ksvd.iterations must be >= 1, got ", iterations);
  LFNET_CHECK_AS(ConfigError, std::isfinite(tolerance) && tolerance >= 0.0,
                 "ksvd.tolerance must be >= 0, got ", tolerance);
  LFNET_CHECK_AS(ConfigError, min_uses >= 0, "ksvd.min_uses must be >= 0, got ", min_uses);
  LFNET_CHECK_AS(ConfigError, max_coherence > 0.0 && max_coherence <= 1.0,
                 "ksvd.max_coherence must be in (0, 1], got ", max_coherence);
}

nlohmann::json KsvdOptions::to_json() const { return fields_to_json(*this); }

KsvdOptions KsvdOptions::from_json(const nlohmann::json& j, const std::string& path) {
  KsvdOptions o;
  JsonReader r(j, path);
  read_fields(r, o);
  r.finish();
  try {
    o.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(path + ": " + e.what());
  }
  return o;
}

nlohmann::json KsvdIteration::to_json() const {
  return {{"iteration", iteration},       {"coding_rmse", coding_rmse},
          {"updated_rmse", updated_rmse}, {"relative_error", relative_error},
          {"mean_atoms", mean_atoms},     {"unused", unused},
          {"replaced", replaced},         {"premature", premature},
          {"kept_codes", kept_codes},     {"seconds", seconds}};
}

namespace {

// Squared norms of the rows of a float64 matrix, without a temporary of its size.
torch::Tensor row_sq_norms(const torch::Tensor& t) {
  return torch::linalg_vector_norm(t, 2, torch::IntArrayRef{1}, false, c10::nullopt).square();
}

// A seeded permutation of 0..n-1 (Fisher-Yates on mt19937_64 draws, the same on every
// platform, unlike std::shuffle).
std::vector<int64_t> permutation(int64_t n, std::mt19937_64& rng) {
  std::vector<int64_t> p(n);
  std::iota(p.begin(), p.end(), 0);
  for (int64_t i = n - 1; i > 0; --i) {
    const auto j = static_cast<int64_t>(rng() % static_cast<uint64_t>(i + 1));
    std::swap(p[i], p[j]);
  }
  return p;
}

// Atoms as rows (K, d): K distinct non-zero training signals, normalised.
torch::Tensor initial_atoms(const torch::Tensor& x, int64_t k, std::mt19937_64& rng) {
  auto norms = x.norm(2, 1);
  auto nonzero = norms.gt(0).nonzero().reshape({-1});
  const int64_t available = nonzero.size(0);
  LFNET_CHECK_AS(ConfigError, available >= k, "ksvd: ", k, " atoms need as many non-zero ",
                 "training signals, but only ", available, " of ", x.size(0), " are non-zero");
  const auto order = permutation(available, rng);
  auto pick = torch::tensor(std::vector<int64_t>(order.begin(), order.begin() + k));
  auto rows = nonzero.index_select(0, pick);
  return x.index_select(0, rows) / norms.index_select(0, rows).unsqueeze(1);
}

// Signals using each atom, as flat positions i * S + slot into the (N, S) code arrays.
struct Users {
  std::vector<int64_t> offsets;    // K + 1
  std::vector<int64_t> positions;  // grouped by atom
};

Users users_of_atoms(const torch::Tensor& indices, int64_t k) {
  const int64_t total = indices.numel();
  const int64_t* idx = indices.data_ptr<int64_t>();
  Users u;
  u.offsets.assign(k + 1, 0);
  for (int64_t p = 0; p < total; ++p) {
    if (idx[p] >= 0) ++u.offsets[idx[p] + 1];
  }
  for (int64_t a = 0; a < k; ++a) u.offsets[a + 1] += u.offsets[a];
  u.positions.resize(u.offsets[k]);
  std::vector<int64_t> fill(u.offsets.begin(), u.offsets.end() - 1);
  for (int64_t p = 0; p < total; ++p) {
    if (idx[p] >= 0) u.positions[fill[idx[p]]++] = p;
  }
  return u;
}

// Refits atom row `atom` of `dt` and the coefficients of its users against the residual `r`,
// keeping r = X - D Gamma.
void update_atom_exact(int64_t atom, const std::vector<int64_t>& positions, int64_t width,
                       torch::Tensor& dt, torch::Tensor& r, torch::Tensor& values) {
  auto pos = torch::tensor(positions, torch::kInt64);
  auto sig = torch::div(pos, width, "trunc");
  auto flat_values = values.view({-1});
  auto g = flat_values.index_select(0, pos);
  auto d_old = dt[atom];
  auto e = r.index_select(0, sig).addr_(g, d_old);  // E_k = R_I + g d_k^T
  auto [u, s, vh] = torch::linalg_svd(e, /*full_matrices=*/false, c10::nullopt);
  torch::Tensor d_new = vh[0], g_new = u.select(1, 0) * s[0];
  if (s[0].item<double>() <= 0.0) {
    d_new = d_old.clone();
    g_new = e.mv(d_new);
  } else if (d_new.dot(d_old).item<double>() < 0.0) {
    d_new = -d_new;
    g_new = -g_new;
  }
  r.index_copy_(0, sig, e.addr_(g_new, d_new, 1.0, -1.0));
  flat_values.index_copy_(0, pos, g_new);
  dt[atom].copy_(d_new);
}

// The approximate update without forming E_k = R_I + g d^T: E_k^T g = R_I^T g + d (g.g) and
// E_k d' = R_I d' + g (d.d'), then R_I += g d^T - g' d'^T. Three passes over the users' rows
// of r, no allocation (this runs K times per iteration).
void update_atom_approximate(int64_t atom, const std::vector<int64_t>& positions, int64_t width,
                             torch::Tensor& dt, torch::Tensor& r, torch::Tensor& values,
                             std::vector<double>& scratch) {
  const int64_t d = dt.size(1), n = static_cast<int64_t>(positions.size());
  double* pr = r.data_ptr<double>();
  double* val = values.data_ptr<double>();
  double* d_old = dt.data_ptr<double>() + atom * d;
  scratch.assign(static_cast<size_t>(d + n), 0.0);
  double* d_new = scratch.data();
  double* g_new = scratch.data() + d;
  double gg = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    const double g = val[positions[i]];
    const double* ri = pr + (positions[i] / width) * d;
    gg += g * g;
    for (int64_t t = 0; t < d; ++t) d_new[t] += g * ri[t];
  }
  double norm = 0.0;
  for (int64_t t = 0; t < d; ++t) {
    d_new[t] += gg * d_old[t];
    norm += d_new[t] * d_new[t];
  }
  norm = std::sqrt(norm);
  // g = 0 for every user (all coefficients dropped): keep the atom.
  if (norm > 0.0) {
    for (int64_t t = 0; t < d; ++t) d_new[t] /= norm;
  } else {
    std::copy(d_old, d_old + d, d_new);
  }
  double overlap = 0.0;
  for (int64_t t = 0; t < d; ++t) overlap += d_old[t] * d_new[t];
  for (int64_t i = 0; i < n; ++i) {
    const double g = val[positions[i]];
    double* ri = pr + (positions[i] / width) * d;
    double dot = 0.0;
    for (int64_t t = 0; t < d; ++t) dot += ri[t] * d_new[t];
    const double gn = dot + g * overlap;
    for (int64_t t = 0; t < d; ++t) ri[t] += g * d_old[t] - gn * d_new[t];
    g_new[i] = gn;
  }
  for (int64_t i = 0; i < n; ++i) val[positions[i]] = g_new[i];
  std::copy(d_new, d_new + d, d_old);
}

// Replaces atoms used by fewer than `min_uses` signals or nearly duplicating another with the
// training signals represented worst, each signal at most once (Rubinstein's cleardict). The
// old atom's coefficients are dropped (the next sparse coding step re-codes its users).
// Keeps r = X - D Gamma. Returns the number of atoms replaced.
int64_t replace_atoms(const KsvdOptions& options, const Users& users, const torch::Tensor& x,
                      const torch::Tensor& x_norms_sq, torch::Tensor& dt, torch::Tensor& r,
                      torch::Tensor& values) {
  const int64_t k = dt.size(0), d = dt.size(1);
  double* val = values.data_ptr<double>();
  double* pr = r.data_ptr<double>();
  const int64_t width = values.size(1);
  std::vector<int64_t> use_count(k, 0);
  for (int64_t a = 0; a < k; ++a) {
    for (int64_t p = users.offsets[a]; p < users.offsets[a + 1]; ++p) {
      if (std::abs(val[users.positions[p]]) > 1e-7) ++use_count[a];
    }
  }
  // Candidates: non-zero signals with a non-zero residual, worst first.
  auto err = row_sq_norms(r);
  auto order = std::get<1>(err.sort(0, /*descending=*/true));
  auto usable =
      x_norms_sq.index_select(0, order).gt(0).logical_and(err.index_select(0, order).gt(0));
  auto cand_t = order.masked_select(usable).contiguous();
  const int64_t* cand = cand_t.data_ptr<int64_t>();
  const int64_t available = cand_t.size(0);
  auto coherence = dt.mm(dt.t());
  coherence.fill_diagonal_(0.0);
  int64_t next = 0, replaced = 0;
  for (int64_t a = 0; a < k && next < available; ++a) {
    // Atoms replaced earlier in this pass changed the coherences: recompute this row's.
    const bool duplicate = coherence[a].abs().max().item<double>() > options.max_coherence;
    if (use_count[a] >= options.min_uses && !duplicate) continue;
    const double* da = dt.data_ptr<double>() + a * d;
    for (int64_t p = users.offsets[a]; p < users.offsets[a + 1]; ++p) {
      const int64_t pos = users.positions[p];
      double* rs = pr + (pos / width) * d;
      for (int64_t t = 0; t < d; ++t) rs[t] += val[pos] * da[t];
      val[pos] = 0.0;
    }
    const int64_t s = cand[next++];
    dt[a].copy_(x[s] / x_norms_sq[s].sqrt());
    auto column = dt.mv(dt[a]);
    column[a] = 0.0;
    coherence[a].copy_(column);
    coherence.select(1, a).copy_(column);
    ++replaced;
  }
  return replaced;
}

}  // namespace

KsvdResult ksvd(const torch::Tensor& signals, const KsvdOptions& options,
                const KsvdCallback& callback, const torch::Tensor& initial) {
  options.validate();
  LFNET_CHECK(signals.defined() && signals.dim() == 2, "ksvd: signals must be (N, d), got ",
              signals.defined() ? signals.sizes() : c10::IntArrayRef{});
  const int64_t n = signals.size(0), d = signals.size(1), k = options.atoms;
  LFNET_CHECK_AS(ConfigError, n >= k, "ksvd: ", n, " training signals for ", k,
                 " atoms; K-SVD needs at least as many signals as atoms");
  auto x = signals.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  LFNET_CHECK_AS(NumericalError, torch::isfinite(x).all().item<bool>(),
                 "ksvd: the training signals have NaN or inf entries");
  std::mt19937_64 rng(options.seed);
  torch::Tensor dt;  // atoms as rows (K, d)
  if (initial.defined()) {
    LFNET_CHECK(initial.dim() == 2 && initial.size(0) == d && initial.size(1) == k,
                "ksvd: the initial dictionary must be (", d, ", ", k, "), got ", initial.sizes());
    dt = initial.detach().to(torch::kCPU, torch::kFloat64).t().contiguous();
    auto norms = dt.norm(2, 1);
    LFNET_CHECK_AS(NumericalError, torch::isfinite(dt).all().item<bool>(),
                   "ksvd: the initial dictionary has NaN or inf entries");
    LFNET_CHECK_AS(NumericalError, norms.gt(0).all().item<bool>(),
                   "ksvd: the initial dictionary has a zero atom");
    dt = dt / norms.unsqueeze(1);
  } else {
    dt = initial_atoms(x, k, rng);
  }
  auto x_norms_sq = row_sq_norms(x);
  const double total_sq = x_norms_sq.sum().item<double>();
  const double entries = static_cast<double>(n) * static_cast<double>(d);

  OmpOptions omp_options;
  omp_options.max_atoms = options.sparsity;
  omp_options.tolerance = options.target_error > 0.0 ? options.target_error * d : -1.0;

  KsvdResult result;
  double previous = -1.0;
  torch::Tensor prev_indices, prev_values, prev_r;  // the last iteration's codes and residual
  for (int64_t it = 1; it <= options.iterations; ++it) {
    Stopwatch watch;
    KsvdIteration report;
    report.iteration = it;
    // Sparse coding with the current atoms.
    auto dict = dt.t();  // (d, K) view
    auto gram = dt.mm(dict);
    auto xy = x.mm(dict).t();  // (K, N) view of an (N, K) product: no copy in batch_omp
    OmpResult codes = batch_omp(gram, xy, omp_options, x_norms_sq);
    report.premature = codes.premature();
    auto r = sparse_residual(dict, codes, x);
    torch::Tensor indices = codes.indices, values = codes.values;
    if (options.keep_better_codes && prev_r.defined()) {
      // OMP is greedy: its new code can fit a signal worse than the previous code, which is
      // still valid for the updated atoms. Keep whichever is better, signal by signal.
      auto keep_old = row_sq_norms(prev_r).lt(row_sq_norms(r));
      report.kept_codes = keep_old.sum().item<int64_t>();
      if (report.kept_codes > 0) {
        const int64_t w = std::max(indices.size(1), prev_indices.size(1));
        auto pad = [w](const torch::Tensor& t, double fill) {
          return torch::constant_pad_nd(t, {0, w - t.size(1)}, fill);
        };
        auto old_rows = keep_old.unsqueeze(1);
        indices = torch::where(old_rows, pad(prev_indices, -1), pad(indices, -1));
        values = torch::where(old_rows, pad(prev_values, 0), pad(values, 0));
        r = torch::where(old_rows, prev_r, r);
      }
    }
    report.mean_atoms = indices.ge(0).sum().item<double>() / static_cast<double>(n);
    const double coding_sq = row_sq_norms(r).sum().item<double>();
    report.coding_rmse = std::sqrt(coding_sq / entries);
    report.relative_error = total_sq > 0.0 ? std::sqrt(coding_sq / total_sq) : 0.0;

    // Atom updates in a random order; supports stay fixed, values change.
    const int64_t width = indices.size(1);
    const Users users = users_of_atoms(indices, k);
    std::vector<double> scratch;
    for (int64_t atom : permutation(k, rng)) {
      const int64_t begin = users.offsets[atom], end = users.offsets[atom + 1];
      if (begin == end) {
        ++report.unused;
        continue;
      }
      std::vector<int64_t> positions(users.positions.begin() + begin,
                                     users.positions.begin() + end);
      if (options.atom_update == AtomUpdate::kExact) {
        update_atom_exact(atom, positions, width, dt, r, values);
      } else {
        update_atom_approximate(atom, positions, width, dt, r, values, scratch);
      }
    }

    report.updated_rmse = std::sqrt(row_sq_norms(r).sum().item<double>() / entries);
    if (options.replace_atoms && width > 0) {
      report.replaced = replace_atoms(options, users, x, x_norms_sq, dt, r, values);
    }
    if (options.keep_better_codes) {
      prev_indices = indices;
      prev_values = values;
      prev_r = r;
    }
    report.seconds = watch.seconds();
    result.history.push_back(report);
    const bool go_on = callback ? callback(report) : true;
    if (options.tolerance > 0.0 &&
        (report.coding_rmse == 0.0 ||
         (previous > 0.0 && (previous - report.coding_rmse) / previous < options.tolerance))) {
      result.converged = true;
      break;
    }
    previous = report.coding_rmse;
    if (!go_on) break;
  }
  result.dictionary = dt.t().contiguous();
  return result;
}

}  // namespace lfnet::dict

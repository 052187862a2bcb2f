#include "lfnet/dict/omp.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/parallel.h"

namespace lfnet::dict {

void OmpOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, max_atoms >= 0, "omp.max_atoms must be >= 0, got ", max_atoms);
  LFNET_CHECK_AS(ConfigError, max_atoms > 0 || tolerance >= 0.0,
                 "omp: max_atoms = 0 (no limit) needs a tolerance >= 0");
  LFNET_CHECK_AS(ConfigError, std::isfinite(tolerance), "omp.tolerance must be finite");
}

nlohmann::json OmpOptions::to_json() const { return fields_to_json(*this); }

OmpOptions OmpOptions::from_json(const nlohmann::json& j, const std::string& path) {
  OmpOptions o;
  JsonReader r(j, path);
  read_fields(r, o);
  r.finish();
  o.validate();
  return o;
}

std::string to_string(OmpStop stop) {
  switch (stop) {
    case OmpStop::kMaxAtoms:
      return "max_atoms";
    case OmpStop::kTolerance:
      return "tolerance";
    case OmpStop::kResidualOrthogonal:
      return "residual_orthogonal";
    case OmpStop::kRepeatedAtom:
      return "repeated_atom";
    case OmpStop::kDependentAtom:
      return "dependent_atom";
    case OmpStop::kAllAtoms:
      return "all_atoms";
  }
  return "unknown";
}

torch::Tensor OmpResult::dense() const {
  const int64_t b = signals();
  auto out = torch::zeros({atoms, b}, torch::kFloat64);
  if (b == 0 || indices.size(1) == 0) return out;
  auto cols = torch::arange(b, torch::kInt64).unsqueeze(1).expand_as(indices);
  auto valid = indices.ge(0);
  out.index_put_({indices.masked_select(valid), cols.masked_select(valid)},
                 values.masked_select(valid));
  return out;
}

int64_t OmpResult::premature() const {
  auto s = stops.to(torch::kInt64);
  return (s.eq(static_cast<int64_t>(OmpStop::kRepeatedAtom)) |
          s.eq(static_cast<int64_t>(OmpStop::kDependentAtom)))
      .sum()
      .item<int64_t>();
}

namespace {

// The support and coefficients found for one signal.
struct Code {
  std::vector<int64_t> atoms;
  std::vector<double> values;
  OmpStop stop = OmpStop::kMaxAtoms;
  double residual_sq = 0.0;
};

// Per-thread scratch space, reused across the columns of a chunk.
template <typename T>
struct Workspace {
  std::vector<int64_t> perm;  // position -> atom, swapped as scikit-learn swaps Gram rows
  std::vector<T> beta;        // G[:, chosen] * gamma, indexed by atom
  std::vector<T> alpha;       // xy - beta, indexed by atom
  std::vector<T> chol;        // packed lower Cholesky factor of G[chosen, chosen], row-major
  std::vector<T> gamma, xy_chosen, w;
};

// One column of Batch-OMP. The positions 0..n-1 of `perm` hold the chosen atoms, exactly as
// scikit-learn's _gram_omp keeps them after its row/column swaps, so the argmax visits the
// atoms in the same order and ties resolve the same way.
template <typename T>
void omp_column(const T* g, const T* xy, int64_t k, int64_t max_atoms, double tol, double norm_sq,
                bool have_norm, Workspace<T>& ws, Code& code) {
  const T eps = std::numeric_limits<T>::epsilon();
  auto& perm = ws.perm;
  perm.resize(k);
  for (int64_t i = 0; i < k; ++i) perm[i] = i;
  ws.beta.assign(k, T(0));
  ws.alpha.assign(xy, xy + k);
  ws.chol.clear();
  ws.gamma.clear();
  ws.xy_chosen.clear();
  code.atoms.clear();
  code.values.clear();
  T tol_curr = static_cast<T>(norm_sq), delta = 0;
  int64_t n = 0;
  OmpStop stop = OmpStop::kMaxAtoms;
  while (true) {
    // argmax over positions |alpha|, first maximum wins (numpy's argmax).
    int64_t lam = 0;
    T best = -1;
    for (int64_t p = 0; p < k; ++p) {
      const T a = std::abs(ws.alpha[perm[p]]);
      if (a > best) {
        best = a;
        lam = p;
      }
    }
    const int64_t atom = perm[lam];
    const T a_lam = ws.alpha[atom];
    // scikit-learn stops on either condition; a negligible correlation is named first since
    // round-off then decides which atom looks best.
    if (a_lam * a_lam < eps) {
      stop = OmpStop::kResidualOrthogonal;
      break;
    }
    if (lam < n) {
      stop = OmpStop::kRepeatedAtom;
      break;
    }
    const T g_kk = g[atom * k + atom];
    if (n > 0) {
      // Row n of the factor: solve L w = G[atom, chosen].
      ws.w.resize(n);
      T v = 0;
      for (int64_t i = 0; i < n; ++i) {
        T s = g[atom * k + perm[i]];
        const T* li = ws.chol.data() + i * (i + 1) / 2;
        for (int64_t j = 0; j < i; ++j) s -= li[j] * ws.w[j];
        s /= li[i];
        ws.w[i] = s;
        v += s * s;
      }
      const T lkk = g_kk - v;
      if (!(lkk > eps)) {
        stop = OmpStop::kDependentAtom;
        break;
      }
      ws.chol.insert(ws.chol.end(), ws.w.begin(), ws.w.end());
      ws.chol.push_back(std::sqrt(lkk));
    } else {
      // scikit-learn has no check here and divides by zero on a zero atom.
      if (!(g_kk > eps)) {
        stop = OmpStop::kDependentAtom;
        break;
      }
      ws.chol.push_back(std::sqrt(g_kk));
    }
    std::swap(perm[n], perm[lam]);
    ws.xy_chosen.push_back(xy[atom]);
    ++n;
    // gamma = (L L^T)^-1 xy[chosen]: forward, then backward substitution.
    ws.gamma.assign(ws.xy_chosen.begin(), ws.xy_chosen.end());
    for (int64_t i = 0; i < n; ++i) {
      const T* li = ws.chol.data() + i * (i + 1) / 2;
      T s = ws.gamma[i];
      for (int64_t j = 0; j < i; ++j) s -= li[j] * ws.gamma[j];
      ws.gamma[i] = s / li[i];
    }
    for (int64_t i = n - 1; i >= 0; --i) {
      T s = ws.gamma[i];
      for (int64_t j = i + 1; j < n; ++j) s -= ws.chol[j * (j + 1) / 2 + i] * ws.gamma[j];
      ws.gamma[i] = s / ws.chol[i * (i + 1) / 2 + i];
    }
    // beta = G[:, chosen] gamma (G is symmetric: rows of the chosen atoms are contiguous).
    std::fill(ws.beta.begin(), ws.beta.end(), T(0));
    for (int64_t j = 0; j < n; ++j) {
      const T* row = g + perm[j] * k;
      const T c = ws.gamma[j];
      T* beta = ws.beta.data();
      for (int64_t i = 0; i < k; ++i) beta[i] += c * row[i];
    }
    for (int64_t i = 0; i < k; ++i) ws.alpha[i] = xy[i] - ws.beta[i];
    if (tol >= 0.0) {
      tol_curr += delta;
      delta = 0;
      for (int64_t j = 0; j < n; ++j) delta += ws.gamma[j] * ws.beta[perm[j]];
      tol_curr -= delta;
      if (std::abs(tol_curr) <= tol) {
        stop = OmpStop::kTolerance;
        break;
      }
    }
    if (n == max_atoms) {
      stop = OmpStop::kMaxAtoms;
      break;
    }
    if (n == k) {
      stop = OmpStop::kAllAtoms;
      break;
    }
  }
  code.stop = stop;
  code.atoms.assign(perm.begin(), perm.begin() + n);
  code.values.assign(ws.gamma.begin(), ws.gamma.begin() + (n > 0 ? n : 0));
  if (have_norm) {
    // ||y - D_I gamma||^2 = ||y||^2 - gamma^T G_II gamma, with G_II gamma = beta[chosen].
    double fit = 0;
    for (int64_t j = 0; j < n; ++j) fit += double(ws.gamma[j]) * double(ws.beta[perm[j]]);
    code.residual_sq = std::max(0.0, norm_sq - fit);
  }
}

template <typename T>
OmpResult run_batch(const torch::Tensor& gram, const torch::Tensor& xy_rows, int64_t max_atoms,
                    double tol, const torch::Tensor& norms) {
  const int64_t k = gram.size(0), b = xy_rows.size(0);
  const T* g = gram.data_ptr<T>();
  const T* xy = xy_rows.data_ptr<T>();
  const double* nrm = norms.defined() ? norms.data_ptr<double>() : nullptr;
  std::vector<Code> codes(b);
  parallel_chunks(b, 16, [&](int64_t begin, int64_t end) {
    Workspace<T> ws;
    for (int64_t i = begin; i < end; ++i) {
      omp_column<T>(g, xy + i * k, k, max_atoms, tol, nrm ? nrm[i] : 0.0, nrm != nullptr, ws,
                    codes[i]);
    }
  });
  int64_t width = 0;
  for (const auto& c : codes) width = std::max<int64_t>(width, c.atoms.size());
  OmpResult r;
  r.atoms = k;
  r.indices = torch::full({b, width}, -1, torch::kInt64);
  r.values = torch::zeros({b, width}, torch::kFloat64);
  r.counts = torch::empty({b}, torch::kInt64);
  r.stops = torch::empty({b}, torch::kInt8);
  if (nrm) r.residual_sq = torch::empty({b}, torch::kFloat64);
  auto* idx = r.indices.data_ptr<int64_t>();
  auto* val = r.values.data_ptr<double>();
  auto* cnt = r.counts.data_ptr<int64_t>();
  auto* stp = r.stops.data_ptr<int8_t>();
  for (int64_t i = 0; i < b; ++i) {
    const auto& c = codes[i];
    std::copy(c.atoms.begin(), c.atoms.end(), idx + i * width);
    std::copy(c.values.begin(), c.values.end(), val + i * width);
    cnt[i] = static_cast<int64_t>(c.atoms.size());
    stp[i] = static_cast<int8_t>(c.stop);
    if (nrm) r.residual_sq.data_ptr<double>()[i] = c.residual_sq;
  }
  return r;
}

}  // namespace

OmpResult batch_omp(const torch::Tensor& gram, const torch::Tensor& xy, const OmpOptions& options,
                    const torch::Tensor& norms_sq) {
  options.validate();
  LFNET_CHECK(gram.defined() && gram.dim() == 2 && gram.size(0) == gram.size(1),
              "batch_omp: the Gram matrix must be square (K, K), got ",
              gram.defined() ? gram.sizes() : c10::IntArrayRef{});
  const int64_t k = gram.size(0);
  LFNET_CHECK(k > 0, "batch_omp: empty dictionary");
  LFNET_CHECK(xy.defined() && xy.dim() == 2 && xy.size(0) == k,
              "batch_omp: correlations must be (K, B) with K = ", k, ", got ",
              xy.defined() ? xy.sizes() : c10::IntArrayRef{});
  const int64_t b = xy.size(1);
  LFNET_CHECK(options.tolerance < 0.0 || norms_sq.defined(),
              "batch_omp: a residual tolerance needs the squared signal norms");
  const auto dtype = options.double_precision ? torch::kFloat64 : torch::kFloat32;
  auto g = gram.detach().to(torch::kCPU, dtype).contiguous();
  // (B, K) rows: a transposed view of a (B, K) product becomes contiguous without a copy.
  auto rows = xy.detach().to(torch::kCPU, dtype).t().contiguous();
  LFNET_CHECK_AS(NumericalError, torch::isfinite(g).all().item<bool>(),
                 "batch_omp: the Gram matrix has NaN or inf entries");
  LFNET_CHECK_AS(NumericalError, torch::isfinite(rows).all().item<bool>(),
                 "batch_omp: the correlations have NaN or inf entries");
  torch::Tensor norms;
  if (norms_sq.defined()) {
    LFNET_CHECK(norms_sq.numel() == b, "batch_omp: ", norms_sq.numel(), " squared norms for ", b,
                " signals");
    norms = norms_sq.detach().to(torch::kCPU, torch::kFloat64).reshape({b}).contiguous();
    LFNET_CHECK_AS(NumericalError, torch::isfinite(norms).all().item<bool>(),
                   "batch_omp: the squared norms have NaN or inf entries");
  }
  if (dtype == torch::kFloat64) {
    return run_batch<double>(g, rows, options.max_atoms, options.tolerance, norms);
  }
  return run_batch<float>(g, rows, options.max_atoms, options.tolerance, norms);
}

OmpResult omp(const torch::Tensor& dictionary, const torch::Tensor& signals,
              const OmpOptions& options) {
  LFNET_CHECK(dictionary.dim() == 2, "omp: the dictionary must be (d, K), got ",
              dictionary.sizes());
  LFNET_CHECK(signals.dim() == 2 && signals.size(1) == dictionary.size(0),
              "omp: signals must be (N, d) with d = ", dictionary.size(0), ", got ",
              signals.sizes());
  auto d = dictionary.to(torch::kFloat64);
  auto y = signals.to(torch::kFloat64);
  auto gram = d.t().mm(d);
  auto xy = y.mm(d).t();  // (K, N) view of an (N, K) product
  torch::Tensor norms;
  if (options.tolerance >= 0.0) norms = y.pow(2).sum(1);
  return batch_omp(gram, xy, options, norms);
}

namespace {

// out[i] += sign * sum_j values[i, j] * D[:, indices[i, j]] for every signal i, in float64.
void accumulate_codes(const torch::Tensor& dictionary, const OmpResult& codes, double sign,
                      torch::Tensor& out) {
  LFNET_CHECK(dictionary.dim() == 2 && dictionary.size(1) == codes.atoms, "sparse codes over ",
              codes.atoms, " atoms need a (d, ", codes.atoms, ") dictionary, got ",
              dictionary.sizes());
  const int64_t d = dictionary.size(0), b = codes.signals(), width = codes.indices.size(1);
  auto atoms = dictionary.to(torch::kFloat64).t().contiguous();  // (K, d): atoms as rows
  const double* a = atoms.data_ptr<double>();
  const int64_t* idx = codes.indices.data_ptr<int64_t>();
  const double* val = codes.values.data_ptr<double>();
  double* o = out.data_ptr<double>();
  parallel_chunks(b, 64, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      double* row = o + i * d;
      for (int64_t j = 0; j < width; ++j) {
        const int64_t atom = idx[i * width + j];
        if (atom < 0) break;
        const double c = sign * val[i * width + j];
        const double* src = a + atom * d;
        for (int64_t t = 0; t < d; ++t) row[t] += c * src[t];
      }
    }
  });
}

}  // namespace

torch::Tensor sparse_combine(const torch::Tensor& dictionary, const OmpResult& codes) {
  auto out = torch::zeros({codes.signals(), dictionary.size(0)}, torch::kFloat64);
  accumulate_codes(dictionary, codes, 1.0, out);
  return out.to(dictionary.scalar_type());
}

torch::Tensor sparse_residual(const torch::Tensor& dictionary, const OmpResult& codes,
                              const torch::Tensor& signals) {
  LFNET_CHECK(signals.dim() == 2 && signals.size(0) == codes.signals() &&
                  signals.size(1) == dictionary.size(0),
              "sparse_residual: signals must be (", codes.signals(), ", ", dictionary.size(0),
              "), got ", signals.sizes());
  auto out = signals.to(torch::kFloat64, /*non_blocking=*/false, /*copy=*/true).contiguous();
  accumulate_codes(dictionary, codes, -1.0, out);
  return out;
}

double omp_patch_flops(double m, double d, double k, double atoms) {
  return 2 * m * k + k * atoms * (atoms + 1) + 2 * d * atoms;
}

}  // namespace lfnet::dict

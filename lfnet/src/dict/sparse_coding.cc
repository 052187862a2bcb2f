#include "lfnet/dict/sparse_coding.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <string_view>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/parallel.h"
#include "lfnet/dict/omp.h"

namespace lfnet::dict {

namespace {
// Rethrows a validation error with the JSON path in front.
template <typename Options>
void validate_at(const Options& o, const std::string& path) {
  try {
    o.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(path + ": " + e.what());
  }
}
}  // namespace

void OmpCodingOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, max_atoms >= 1, "omp.max_atoms must be >= 1, got ", max_atoms);
  LFNET_CHECK_AS(ConfigError, std::isfinite(residual_tolerance),
                 "omp.residual_tolerance must be finite");
}

nlohmann::json OmpCodingOptions::to_json() const { return fields_to_json(*this); }

OmpCodingOptions OmpCodingOptions::from_json(const nlohmann::json& j, const std::string& path) {
  OmpCodingOptions o;
  JsonReader r(j, path);
  read_fields(r, o);
  r.finish();
  validate_at(o, path);
  return o;
}

void AdmmOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, std::isfinite(lambda) && lambda >= 0.0,
                 "admm.lambda must be >= 0, got ", lambda);
  LFNET_CHECK_AS(ConfigError, !relative_lambda || lambda < 1.0,
                 "admm.lambda must be < 1 with relative_lambda (1 gives alpha = 0), got ", lambda);
  LFNET_CHECK_AS(ConfigError, std::isfinite(rho) && rho > 0.0, "admm.rho must be > 0, got ", rho);
  LFNET_CHECK_AS(ConfigError, relaxation >= 1.0 && relaxation <= 1.8,
                 "admm.relaxation must be in [1, 1.8], got ", relaxation);
  LFNET_CHECK_AS(ConfigError, std::isfinite(abs_tolerance) && abs_tolerance >= 0.0,
                 "admm.abs_tolerance must be >= 0, got ", abs_tolerance);
  LFNET_CHECK_AS(ConfigError, std::isfinite(rel_tolerance) && rel_tolerance >= 0.0,
                 "admm.rel_tolerance must be >= 0, got ", rel_tolerance);
  LFNET_CHECK_AS(ConfigError, abs_tolerance > 0.0 || rel_tolerance > 0.0,
                 "admm: abs_tolerance and rel_tolerance cannot both be 0");
  LFNET_CHECK_AS(ConfigError, max_iterations >= 1, "admm.max_iterations must be >= 1, got ",
                 max_iterations);
}

nlohmann::json AdmmOptions::to_json() const { return fields_to_json(*this); }

AdmmOptions AdmmOptions::from_json(const nlohmann::json& j, const std::string& path) {
  AdmmOptions o;
  JsonReader r(j, path);
  read_fields(r, o);
  r.finish();
  validate_at(o, path);
  return o;
}

namespace {
constexpr EnumName<CodingMethod> kCodingMethods[] = {{CodingMethod::kOmp, "omp"},
                                                     {CodingMethod::kAdmm, "admm"}};
}  // namespace

std::string to_string(CodingMethod value) { return name_of(value, kCodingMethods); }
CodingMethod from_string(const std::string& name, CodingMethod) {
  return value_of(name, kCodingMethods);
}

void SparseCodingOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, cache_size >= 0, "cache_size must be >= 0, got ", cache_size);
  omp.validate();
  admm.validate();
}

nlohmann::json SparseCodingOptions::to_json() const { return fields_to_json(*this); }

SparseCodingOptions SparseCodingOptions::from_json(const nlohmann::json& j,
                                                   const std::string& path) {
  SparseCodingOptions o;
  JsonReader r(j, path);
  read_fields(r, o);
  r.finish();
  validate_at(o.omp, path + ".omp");  // the nested object's path first
  validate_at(o.admm, path + ".admm");
  validate_at(o, path);
  return o;
}

int64_t SparseCodingResult::unconverged() const {
  return converged.logical_not().sum().item<int64_t>();
}

SparseCoder::SparseCoder(torch::Tensor dictionary, SparseCodingOptions options)
    : options_(std::move(options)) {
  options_.validate();
  LFNET_CHECK(dictionary.defined() && dictionary.dim() == 2 && dictionary.size(1) >= 1,
              "SparseCoder: the dictionary must be (d, K), got ",
              dictionary.defined() ? dictionary.sizes() : c10::IntArrayRef{});
  dictionary_ = dictionary.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  LFNET_CHECK_AS(NumericalError, torch::isfinite(dictionary_).all().item<bool>(),
                 "SparseCoder: the dictionary has NaN or inf entries");
}

int64_t SparseCoder::factorizations() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return factorizations_;
}

std::shared_ptr<const PreparedOperator> SparseCoder::prepare(const torch::Tensor& patch_matrix) {
  const int64_t d = dictionary_.size(0);
  LFNET_CHECK(patch_matrix.defined() && patch_matrix.dim() == 2 && patch_matrix.size(1) == d &&
                  patch_matrix.size(0) >= 1,
              "SparseCoder: the patch matrix must be (m, ", d, "), got ",
              patch_matrix.defined() ? patch_matrix.sizes() : c10::IntArrayRef{});
  auto a = patch_matrix.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  LFNET_CHECK_AS(NumericalError, torch::isfinite(a).all().item<bool>(),
                 "SparseCoder: the patch matrix has NaN or inf entries");
  const std::string_view bytes(reinterpret_cast<const char*>(a.data_ptr<double>()),
                               static_cast<size_t>(a.numel()) * sizeof(double));
  const size_t key = std::hash<std::string_view>{}(bytes) ^ static_cast<size_t>(a.size(0));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = cache_.begin(); it != cache_.end(); ++it) {
      if (it->first == key && it->second->patch_matrix.sizes() == a.sizes() &&
          torch::equal(it->second->patch_matrix, a)) {
        cache_.splice(cache_.begin(), cache_, it);
        return cache_.front().second;
      }
    }
  }
  auto op = std::make_shared<PreparedOperator>();
  op->patch_matrix = a;
  auto theta = a.mm(dictionary_);  // (m, K)
  auto norms = theta.norm(2, 0);
  // Columns that A (nearly) annihilates cannot be coded; they get scale 0 and a zero column.
  const double largest = norms.max().item<double>();
  auto alive = norms.gt(1e-12 * largest).logical_and(norms.gt(0));
  if (options_.normalize_columns) {
    op->scale = torch::where(alive, norms, torch::zeros_like(norms));
    theta = theta / torch::where(alive, norms, torch::ones_like(norms)).unsqueeze(0);
  } else {
    op->scale = torch::where(alive, torch::ones_like(norms), torch::zeros_like(norms));
  }
  theta.mul_(alive.to(torch::kFloat64).unsqueeze(0));
  op->theta = theta.contiguous();
  if (options_.method == CodingMethod::kOmp) {
    op->gram = op->theta.t().mm(op->theta);
  } else {
    const int64_t m = theta.size(0);
    auto c = op->theta.mm(op->theta.t()) +
             options_.admm.rho * torch::eye(m, torch::kFloat64);  // SPD for rho > 0
    auto l = torch::linalg_cholesky(c);
    op->admm_p = torch::cholesky_solve(op->theta, l);  // (m, K)
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++factorizations_;
  if (options_.cache_size > 0) {
    cache_.emplace_front(key, op);
    while (static_cast<int64_t>(cache_.size()) > options_.cache_size) cache_.pop_back();
  }
  return op;
}

SparseCodingResult SparseCoder::code(const torch::Tensor& patch_matrix,
                                     const torch::Tensor& measurements) {
  auto op = prepare(patch_matrix);
  return code(*op, measurements);
}

SparseCodingResult SparseCoder::code(const PreparedOperator& op,
                                     const torch::Tensor& measurements) const {
  const int64_t m = op.theta.size(0);
  LFNET_CHECK(measurements.defined() && measurements.dim() == 2 && measurements.size(1) == m,
              "SparseCoder: measurements must be (B, m) with m = ", m, " rows of the patch ",
              "matrix, got ", measurements.defined() ? measurements.sizes() : c10::IntArrayRef{});
  auto y = measurements.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  LFNET_CHECK_AS(NumericalError, torch::isfinite(y).all().item<bool>(),
                 "SparseCoder: the measurements have NaN or inf entries");
  SparseCodingResult r = options_.method == CodingMethod::kOmp ? code_omp(op, y) : code_admm(op, y);
  // Last line of defence: a non-finite patch is replaced by zero and reported.
  auto finite = torch::isfinite(r.patches).all(1).logical_and(torch::isfinite(r.residual_sq));
  if (!finite.all().item<bool>()) {
    r.patches.masked_fill_(finite.logical_not().unsqueeze(1), 0.0);
    r.residual_sq = torch::where(finite, r.residual_sq, y.pow(2).sum(1));
    r.converged.logical_and_(finite);
  }
  const auto dtype =
      measurements.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  r.patches = r.patches.to(dtype);
  return r;
}

SparseCodingResult SparseCoder::code_omp(const PreparedOperator& op, const torch::Tensor& y) const {
  const int64_t m = op.theta.size(0);
  OmpOptions o;
  o.max_atoms = options_.omp.max_atoms;
  o.tolerance = options_.omp.residual_tolerance >= 0.0
                    ? options_.omp.residual_tolerance * static_cast<double>(m)
                    : -1.0;
  auto xy = y.mm(op.theta).t();  // (K, B) view of a (B, K) product
  OmpResult codes = batch_omp(op.gram, xy, o, y.pow(2).sum(1));
  SparseCodingResult r;
  // Exact residuals from the normalised codes (the Gram-based update loses digits near 0).
  r.residual_sq = sparse_residual(op.theta, codes, y).pow(2).sum(1);
  // alpha = beta / scale; chosen atoms always have a non-zero scale.
  auto valid = codes.indices.ge(0);
  auto safe_idx = codes.indices.clamp_min(0);
  auto scale = op.scale.index_select(0, safe_idx.reshape({-1})).reshape(safe_idx.sizes());
  codes.values =
      torch::where(valid.logical_and(scale.gt(0)),
                   codes.values / torch::where(scale.gt(0), scale, torch::ones_like(scale)),
                   torch::zeros_like(codes.values));
  r.patches = sparse_combine(dictionary_, codes);
  r.iterations = codes.counts;
  r.nonzeros = codes.values.ne(0).sum(1);
  auto stops = codes.stops.to(torch::kInt64);
  r.converged = stops.eq(static_cast<int64_t>(OmpStop::kMaxAtoms)) |
                stops.eq(static_cast<int64_t>(OmpStop::kTolerance)) |
                stops.eq(static_cast<int64_t>(OmpStop::kResidualOrthogonal)) |
                stops.eq(static_cast<int64_t>(OmpStop::kAllAtoms));
  return r;
}

namespace {

// The smallest relative tolerance that iterations in precision T reach on any BLAS kernel:
// each iteration's two products sum K terms, so x and z carry a relative round-off of about
// eps(T) sqrt(K) that no further iteration removes. Below 10 times that, whether a patch ever
// stops depends on how the kernel orders its sums (float32, K = 1,000: 3.8e-5; patches that
// stalled at 1.0-1.5e-5 on OpenBLAS's SkylakeX kernel and converged on its Haswell one).
template <typename T>
double admm_rel_tolerance_floor(int64_t k) {
  return 10.0 * static_cast<double>(std::numeric_limits<T>::epsilon()) *
         std::sqrt(static_cast<double>(k));
}

// The batched ADMM iterations in precision T. `theta` (m, K) and `p` (m, K) in T; `q0` (B, K)
// = Theta^T y per row, in T, overwritten. Writes z per patch into `alpha` (B, K) float64.
template <typename T>
void admm_iterations(const AdmmOptions& o, const torch::Tensor& theta, const torch::Tensor& p,
                     torch::Tensor q0, std::vector<double> kappa, std::vector<double> tol_scale,
                     torch::Tensor& alpha, torch::Tensor& iterations, torch::Tensor& converged) {
  const int64_t k = theta.size(1), b = q0.size(0);
  const T rho = static_cast<T>(o.rho), inv_rho = static_cast<T>(1.0 / o.rho);
  const T relax = static_cast<T>(o.relaxation);
  const double eps_abs = std::sqrt(static_cast<double>(k)) * o.abs_tolerance;
  const double eps_rel = std::max(o.rel_tolerance, admm_rel_tolerance_floor<T>(k));
  const auto dtype = q0.scalar_type();
  // Patches are rows. The active patches occupy rows [0, active) of the work arrays; a patch
  // that converges leaves by compaction, so the matrix products shrink with the batch.
  auto q = q0.clone();  // Theta^T y + rho (z - u), with z = u = 0
  auto z = torch::zeros({b, k}, dtype);
  auto u = torch::zeros({b, k}, dtype);
  auto t = torch::empty({b, k}, dtype);
  auto pq = torch::empty({b, theta.size(0)}, dtype);
  std::vector<int64_t> ids(b);
  std::iota(ids.begin(), ids.end(), 0);
  std::vector<char> done(b, 0);
  T* pq0 = q0.data_ptr<T>();
  T* pqq = q.data_ptr<T>();
  T* pz = z.data_ptr<T>();
  T* pu = u.data_ptr<T>();
  const T* pt = t.data_ptr<T>();
  double* palpha = alpha.data_ptr<double>();
  int64_t* piter = iterations.data_ptr<int64_t>();
  bool* pconv = converged.data_ptr<bool>();
  const auto p_t = p.t();  // (K, m)
  // Threads only for passes of at least 2^18 values: a thread start costs more than a small
  // pass (and much more on a busy machine), and late iterations have few patches left.
  const int64_t grain = std::max<int64_t>(16, (int64_t{1} << 18) / std::max<int64_t>(k, 1));
  int64_t active = b;
  for (int64_t it = 1; it <= o.max_iterations && active > 0; ++it) {
    // x = (Theta^T Theta + rho I)^-1 q = (q - Theta^T P q) / rho (matrix inversion lemma).
    auto pq_a = pq.narrow(0, 0, active);
    torch::mm_out(pq_a, q.narrow(0, 0, active), p_t);
    auto t_a = t.narrow(0, 0, active);
    torch::mm_out(t_a, pq_a, theta);
    // One fused pass per patch: x, relaxation, soft threshold, dual update, residual norms,
    // and the next right-hand side q.
    parallel_chunks(active, grain, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) {
        const T* qi0 = pq0 + i * k;
        const T* ti = pt + i * k;
        T* qi = pqq + i * k;
        T* zi = pz + i * k;
        T* ui = pu + i * k;
        const T kap = static_cast<T>(kappa[i]);
        const double eps_abs_i = eps_abs * tol_scale[i];
        double r2 = 0, s2 = 0, x2 = 0, z2 = 0, u2 = 0;
        for (int64_t j = 0; j < k; ++j) {
          const T x = (qi[j] - ti[j]) * inv_rho;
          const T z_old = zi[j];
          const T v = relax * x + (T(1) - relax) * z_old + ui[j];
          const T zn = v > kap ? v - kap : (v < -kap ? v + kap : T(0));
          const T un = v - zn;
          r2 += double(x - zn) * double(x - zn);
          s2 += double(zn - z_old) * double(zn - z_old);
          x2 += double(x) * double(x);
          z2 += double(zn) * double(zn);
          u2 += double(un) * double(un);
          zi[j] = zn;
          ui[j] = un;
          qi[j] = qi0[j] + rho * (zn - un);
        }
        // Boyd et al. 2011, 3.3.1: primal and dual residuals against their tolerances.
        const bool primal = std::sqrt(r2) <= eps_abs_i + eps_rel * std::sqrt(std::max(x2, z2));
        const bool dual = o.rho * std::sqrt(s2) <= eps_abs_i + eps_rel * o.rho * std::sqrt(u2);
        done[i] = primal && dual;
      }
    });
    const bool last = it == o.max_iterations;
    // Emit finished patches and compact the rest to the front (w <= i: rows move forward).
    int64_t w = 0;
    for (int64_t i = 0; i < active; ++i) {
      if (done[i] || last) {
        std::copy(pz + i * k, pz + (i + 1) * k, palpha + ids[i] * k);
        piter[ids[i]] = it;
        pconv[ids[i]] = done[i] != 0;
        continue;
      }
      if (w != i) {
        std::copy(pq0 + i * k, pq0 + (i + 1) * k, pq0 + w * k);
        std::copy(pqq + i * k, pqq + (i + 1) * k, pqq + w * k);
        std::copy(pz + i * k, pz + (i + 1) * k, pz + w * k);
        std::copy(pu + i * k, pu + (i + 1) * k, pu + w * k);
        kappa[w] = kappa[i];
        tol_scale[w] = tol_scale[i];
        ids[w] = ids[i];
      }
      ++w;
    }
    active = last ? 0 : w;
  }
}

}  // namespace

SparseCodingResult SparseCoder::code_admm(const PreparedOperator& op,
                                          const torch::Tensor& y) const {
  const AdmmOptions& o = options_.admm;
  const int64_t k = op.theta.size(1), b = y.size(0);
  auto q0 = y.mm(op.theta);                        // Theta^T y per row, (B, K), float64
  std::vector<double> kappa(b, o.lambda / o.rho);  // soft threshold lambda / rho per patch
  // With a relative lambda the absolute tolerance follows the patch's scale too, where that
  // is below 1: otherwise measurements scaled by 1e-6 would meet it in the first iterations
  // and come back "converged" but unsolved.
  std::vector<double> tol_scale(b, 1.0);
  if (o.relative_lambda) {
    auto inf = std::get<0>(q0.abs().max(1)).contiguous();
    for (int64_t i = 0; i < b; ++i) {
      kappa[i] *= inf.data_ptr<double>()[i];
      tol_scale[i] = std::min(1.0, inf.data_ptr<double>()[i]);
    }
  }
  auto alpha = torch::zeros({b, k}, torch::kFloat64);
  auto iterations = torch::full({b}, o.max_iterations, torch::kInt64);
  auto converged = torch::zeros({b}, torch::kBool);
  if (o.double_precision) {
    admm_iterations<double>(o, op.theta, op.admm_p, q0, std::move(kappa), std::move(tol_scale),
                            alpha, iterations, converged);
  } else {
    admm_iterations<float>(o, op.theta.to(torch::kFloat32), op.admm_p.to(torch::kFloat32),
                           q0.to(torch::kFloat32), std::move(kappa), std::move(tol_scale), alpha,
                           iterations, converged);
  }
  SparseCodingResult r;
  r.residual_sq = (alpha.mm(op.theta.t()) - y).pow(2).sum(1);
  r.nonzeros = alpha.ne(0).sum(1);
  auto scale = op.scale.unsqueeze(0);
  auto coef =
      torch::where(scale.gt(0), alpha / torch::where(scale.gt(0), scale, torch::ones_like(scale)),
                   torch::zeros_like(alpha));
  r.patches = coef.mm(dictionary_.t());
  r.iterations = iterations;
  r.converged = converged;
  return r;
}

}  // namespace lfnet::dict

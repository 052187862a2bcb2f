// Per-patch sparse reconstruction of light-field patches from coded measurements,
// y = A D alpha (Marwah et al. 2013): OMP and ADMM-LASSO over the effective dictionary A D.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include "lfnet/core/fields.h"

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>

namespace lfnet::dict {

// OMP on the effective dictionary.
struct OmpCodingOptions {
  int64_t max_atoms = 10;            // atoms per patch
  double residual_tolerance = -1.0;  // also stop when ||A D alpha - y||^2 / m <= this (a noise
                                     // variance per measurement); -1 to 0: off

  template <typename Fields>
  void fields(Fields& f) {
    f("max_atoms", max_atoms, Range::closed(1, 1e6));
    f("residual_tolerance", residual_tolerance, Range::closed(-1, 1e3));
  }
  void validate() const;
  nlohmann::json to_json() const;
  static OmpCodingOptions from_json(const nlohmann::json& j, const std::string& path);
};

// ADMM for the LASSO min 1/2 ||A D alpha - y||^2 + lambda ||alpha||_1 (Boyd et al. 2011,
// section 6.4): x = (Theta^T Theta + rho I)^-1 (Theta^T y + rho (z - u)), z = soft(x + u,
// lambda / rho), u += x - z. A column stops when both residuals are small (Boyd 3.3.1):
//   ||x - z|| <= sqrt(K) abs_tolerance + rel_tolerance max(||x||, ||z||)     (primal)
//   rho ||z - z_prev|| <= sqrt(K) abs_tolerance + rel_tolerance rho ||u||      (dual)
// or after max_iterations, when it is reported as not converged. The estimate is z.
struct AdmmOptions {
  double lambda = 0.01;           // weight of the L1 term
  bool relative_lambda = true;    // lambda times ||Theta^T y||_inf per patch (lambda in (0, 1):
                                  // the fraction of the value that makes alpha = 0), which
                                  // makes the solver independent of the measurements' scale
  double rho = 1.0;               // augmented Lagrangian parameter, fixed so that the
                                  // factorisation is cached; best near 10-100 x lambda
  double relaxation = 1.5;        // over-relaxation in [1, 1.8] (Boyd 3.4.3); 1: plain ADMM
  double abs_tolerance = 1e-4;    // Boyd's ABSTOL; with relative_lambda it is multiplied by
                                  // min(1, ||Theta^T y||_inf), so tiny measurements do not meet
                                  // it before they are solved
  double rel_tolerance = 1e-3;    // Boyd's RELTOL; raised to 10 eps sqrt(K), the round-off
                                  // floor of the iterations' precision (float32, K = 1,000:
                                  // 3.8e-5; float64: 7e-14), so it is reachable on any BLAS
  int64_t max_iterations = 500;   // per patch
  bool double_precision = false;  // float64 iterations; float32 halves the time of the two
                                  // matrix products per iteration (factorisation: float64)

  template <typename Fields>
  void fields(Fields& f) {
    f("lambda", lambda);
    f("relative_lambda", relative_lambda);
    f("rho", rho, Range::above(0, 1e6));
    f("relaxation", relaxation);
    f("abs_tolerance", abs_tolerance, Range::closed(0, 1));
    f("rel_tolerance", rel_tolerance, Range::closed(0, 1));
    f("max_iterations", max_iterations, Range::closed(1, 1e8));
    f("double_precision", double_precision);
  }
  void validate() const;
  nlohmann::json to_json() const;
  static AdmmOptions from_json(const nlohmann::json& j, const std::string& path);
};

// How patches are coded: greedy OMP or the ADMM-LASSO; by name "omp", "admm".
enum class CodingMethod { kOmp, kAdmm };
std::string to_string(CodingMethod value);
CodingMethod from_string(const std::string& name, CodingMethod);

// How patches are coded.
struct SparseCodingOptions {
  CodingMethod method = CodingMethod::kOmp;  // omp or admm
  bool normalize_columns = true;  // code over unit-norm columns of Theta = A D and scale the
                                  // coefficients back (with ADMM: an L1 weighted by the norms)
  int64_t cache_size = 16;        // prepared operators kept, one per distinct A (a mask Phi
                                  // of period T has T^2)
  OmpCodingOptions omp;
  AdmmOptions admm;

  template <typename Fields>
  void fields(Fields& f) {
    f("method", method);
    f("normalize_columns", normalize_columns);
    f("cache_size", cache_size, Range::closed(0, 1e9));
    f("omp", omp);
    f("admm", admm);
  }
  void validate() const;
  nlohmann::json to_json() const;
  static SparseCodingOptions from_json(const nlohmann::json& j, const std::string& path = "$");
};

// Reconstructed patches with per-patch diagnostics. Never NaN: a patch whose coding failed
// numerically is zero and reported as not converged.
struct SparseCodingResult {
  torch::Tensor patches;      // (B, d) light-field patches D alpha, in the measurements' dtype
  torch::Tensor iterations;   // (B) int64: OMP atoms chosen, or ADMM iterations run
  torch::Tensor converged;    // (B) bool: OMP ended normally / ADMM met its tolerances
  torch::Tensor nonzeros;     // (B) int64: non-zero coefficients
  torch::Tensor residual_sq;  // (B) float64: ||A D alpha - y||^2

  int64_t unconverged() const;
};

// The effective dictionary for one patch matrix A and everything the solvers factor once.
struct PreparedOperator {
  torch::Tensor patch_matrix;  // A (m, d), float64, kept to check cache hits exactly
  torch::Tensor theta;         // (m, K) float64: A D, columns normalised if asked
  torch::Tensor scale;         // (K) float64: the norms divided out (1 if not normalising;
                               // 0 for a column A D that is numerically zero)
  torch::Tensor gram;          // (K, K) theta^T theta, for OMP
  torch::Tensor admm_p;        // (m, K) (rho I + theta theta^T)^-1 theta, for ADMM
};

// Codes batches of patches over one dictionary. Patches that share a patch matrix A are coded
// together: one factorisation per A (cached, up to `cache_size` distinct A), matrix-matrix work
// for the batch, columns in parallel over LibTorch's intra-op threads. Thread-safe.
class SparseCoder {
 public:
  // `dictionary` (d, K), atoms as columns.
  SparseCoder(torch::Tensor dictionary, SparseCodingOptions options);

  // Reconstructs the patches with measurements `measurements` (B, m) = A (m, d) x patches.
  SparseCodingResult code(const torch::Tensor& patch_matrix, const torch::Tensor& measurements);

  // The prepared operator for A, from the cache or built (and cached) now.
  std::shared_ptr<const PreparedOperator> prepare(const torch::Tensor& patch_matrix);
  SparseCodingResult code(const PreparedOperator& op, const torch::Tensor& measurements) const;

  const SparseCodingOptions& options() const { return options_; }
  const torch::Tensor& dictionary() const { return dictionary_; }
  // Operators built so far (cache misses), to check that batching shares factorisations.
  int64_t factorizations() const;

 private:
  SparseCodingResult code_omp(const PreparedOperator& op, const torch::Tensor& y) const;
  SparseCodingResult code_admm(const PreparedOperator& op, const torch::Tensor& y) const;

  torch::Tensor dictionary_;  // (d, K) float64
  SparseCodingOptions options_;
  mutable std::mutex mutex_;
  std::list<std::pair<size_t, std::shared_ptr<const PreparedOperator>>> cache_;  // MRU first
  int64_t factorizations_ = 0;
};

}  // namespace lfnet::dict

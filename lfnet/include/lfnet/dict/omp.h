// Batch orthogonal matching pursuit on a Gram matrix (Rubinstein, Zibulevsky & Elad 2008,
// "Efficient Implementation of the K-SVD Algorithm using Batch Orthogonal Matching Pursuit").
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include "lfnet/core/fields.h"

#include <cstdint>
#include <string>

namespace lfnet::dict {

// Stopping rules of one OMP run. At least one of `max_atoms` and `tolerance` must be active.
struct OmpOptions {
  int64_t max_atoms = 10;        // atoms per signal; 0: no limit (then `tolerance` must be set)
  double tolerance = -1.0;       // stop when the squared residual norm <= tolerance; < 0: off
  bool double_precision = true;  // float64 arithmetic inside (float32 when false)

  template <typename Fields>
  void fields(Fields& f) {
    f("max_atoms", max_atoms);
    f("tolerance", tolerance);
    f("double_precision", double_precision);
  }
  void validate() const;
  nlohmann::json to_json() const;
  static OmpOptions from_json(const nlohmann::json& j, const std::string& path = "$");
};

// Why OMP stopped for one signal. The first three are normal ends; the last three are early
// stops on degenerate input (the coefficients are still the least-squares fit on the atoms
// chosen so far, never NaN).
enum class OmpStop : int8_t {
  kMaxAtoms = 0,            // reached `max_atoms`
  kTolerance = 1,           // the squared residual fell to `tolerance`
  kResidualOrthogonal = 2,  // every |<atom, residual>|^2 < eps: nothing left to explain (y = 0)
  kRepeatedAtom = 3,        // the best atom was already chosen (numerical round-off)
  kDependentAtom = 4,  // the best atom is (numerically) in the span of the chosen ones, or zero
  kAllAtoms = 5,       // every atom is in use
};

// A short name for messages and JSON, e.g. "dependent_atom".
std::string to_string(OmpStop stop);

// Sparse codes of B signals, one row per signal, padded to the largest support.
struct OmpResult {
  int64_t atoms = 0;          // K, the dictionary size
  torch::Tensor indices;      // (B, S) int64: chosen atoms in order of selection, -1 padding
  torch::Tensor values;       // (B, S) float64: their coefficients, 0 padding
  torch::Tensor counts;       // (B) int64: atoms chosen per signal
  torch::Tensor stops;        // (B) int8: OmpStop per signal
  torch::Tensor residual_sq;  // (B) float64: squared residual norm; undefined without norms

  int64_t signals() const { return counts.size(0); }
  // Dense coefficients (K, B) float64, as scikit-learn's orthogonal_mp_gram returns them.
  torch::Tensor dense() const;
  // Number of signals whose OMP stopped early on degenerate input.
  int64_t premature() const;
};

// Batch-OMP: for each column b of `xy` = D^T Y (K, B) and the Gram matrix `gram` = D^T D
// (K, K), greedily chooses atoms and refits them by least squares, updating a Cholesky factor
// of the chosen atoms' Gram block one row per atom. `norms_sq` (B) = ||y_b||^2 is required
// with a tolerance and, when given, yields `residual_sq`. Selection, tie-breaking and stopping
// follow scikit-learn's `orthogonal_mp_gram`, which this matches to round-off; unlike it,
// a zero-norm atom stops the signal (kDependentAtom) instead of dividing by zero. Columns
// run in parallel over LibTorch's intra-op threads. Non-finite input throws NumericalError.
OmpResult batch_omp(const torch::Tensor& gram, const torch::Tensor& xy, const OmpOptions& options,
                    const torch::Tensor& norms_sq = {});

// OMP of the rows of `signals` (N, d) over the columns of `dictionary` (d, K), through
// batch_omp with the Gram matrix and correlations computed here in float64.
OmpResult omp(const torch::Tensor& dictionary, const torch::Tensor& signals,
              const OmpOptions& options);

// The linear combinations D * code for each signal: (B, d) in `dictionary`'s dtype, computed
// from the sparse codes (d * S work per signal, not a dense product).
torch::Tensor sparse_combine(const torch::Tensor& dictionary, const OmpResult& codes);

// signals - D * code for each signal: (B, d) float64, with one (B, d) allocation.
torch::Tensor sparse_residual(const torch::Tensor& dictionary, const OmpResult& codes,
                              const torch::Tensor& signals);

// Nominal FLOPs of one patch of Batch-OMP choosing `atoms` atoms from a dictionary of k atoms
// of dimension d, for m measurements: the correlations Theta^T y, the correlation updates
// G[:, chosen] gamma and D alpha.
double omp_patch_flops(double m, double d, double k, double atoms);

}  // namespace lfnet::dict

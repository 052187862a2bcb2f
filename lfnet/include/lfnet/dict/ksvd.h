// K-SVD dictionary learning (Aharon, Elad & Bruckstein 2006) with Batch-OMP sparse coding,
// as used for the light-field atoms of Marwah et al. (SIGGRAPH 2013).
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include "lfnet/core/fields.h"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace lfnet::dict {

// How K-SVD refits one atom and its coefficients to the restricted error E_k (the residual of
// the signals that use atom k, with atom k's contribution added back).
//   approximate: one alternating step, d = E_k g / ||E_k g||, then g = E_k^T d, starting from
//                the current coefficients g (Rubinstein et al. 2008). Never increases the error
//                and costs O(|users| d).
//   exact:       the best rank-1 approximation of E_k from its SVD (the original K-SVD);
//                O(|users| d min(|users|, d)), for small problems and tests.
enum class AtomUpdate { kApproximate, kExact };

// K-SVD settings. Training signals are the rows of an (N, d) matrix.
struct KsvdOptions {
  int64_t atoms = 1000;       // K; 2025 x 1000 float32 atoms are 8.1 MB on disk
  int64_t sparsity = 10;      // atoms per training signal in the sparse coding step
  double target_error = 0.0;  // also stop coding a signal when its mean squared error per
                              // entry is <= this (error-constrained K-SVD); 0: off
  int64_t iterations = 30;    // at most this many iterations (sparse coding + atom update)
  double tolerance = 0.0;     // stop once the coding error's relative decrease over an
                              // iteration is below this; 0: run every iteration
  AtomUpdate atom_update = AtomUpdate::kApproximate;
  uint64_t seed = 0;               // initial atoms (random training signals) and update order
  bool keep_better_codes = false;  // keep a signal's previous code when OMP's new one fits
                                   // it worse (OMP is greedy): the error then never increases
                                   // (without replacements), but escapes local minima less
  bool replace_atoms = true;       // replace unused and near-duplicate atoms after each update
  int64_t min_uses = 4;            // atoms used by fewer signals are replaced (Rubinstein's 4)
  double max_coherence = 0.99;     // an atom with |<d_i, d_j>| above this for some j is replaced

  template <typename Fields>
  void fields(Fields& f) {
    f("atoms", atoms, Range::closed(1, 20000));
    f("sparsity", sparsity);
    f("target_error", target_error, Range::closed(0, 1e3));
    f("iterations", iterations, Range::closed(1, 1e6));
    f("tolerance", tolerance, Range::closed(0, 1));
    f("atom_update", atom_update);
    f("seed", seed);
    f("keep_better_codes", keep_better_codes);
    f("replace_atoms", replace_atoms);
    f("min_uses", min_uses, Range::closed(0, 1e9));
    f("max_coherence", max_coherence);
  }
  void validate() const;
  nlohmann::json to_json() const;
  static KsvdOptions from_json(const nlohmann::json& j, const std::string& path = "$");
};

// "approximate" / "exact"; parsing an unknown name throws ConfigError.
std::string to_string(AtomUpdate update);
AtomUpdate parse_atom_update(const std::string& name);
inline AtomUpdate from_string(const std::string& name, AtomUpdate) {
  return parse_atom_update(name);
}

// What one K-SVD iteration did. Errors are root-mean-square per signal entry.
struct KsvdIteration {
  int64_t iteration = 0;        // 1-based
  double coding_rmse = 0.0;     // ||X - D Gamma|| / sqrt(N d) after the sparse coding step
  double updated_rmse = 0.0;    // the same after the atom updates (before replacements, which
                                // drop the replaced atoms' coefficients until the next coding)
  double relative_error = 0.0;  // ||X - D Gamma|| / ||X|| after the sparse coding step
  double mean_atoms = 0.0;      // mean atoms per signal chosen by OMP
  int64_t unused = 0;           // atoms no signal used in this iteration
  int64_t replaced = 0;         // atoms replaced by worst-represented signals
  int64_t premature = 0;        // signals whose OMP stopped early on degenerate input
  int64_t kept_codes = 0;       // signals that kept the previous code (keep_better_codes)
  double seconds = 0.0;         // wall time of the iteration

  nlohmann::json to_json() const;
};

// Called after every iteration; returning false stops training after that iteration.
using KsvdCallback = std::function<bool(const KsvdIteration&)>;

// A learned dictionary and how training went.
struct KsvdResult {
  torch::Tensor dictionary;            // (d, K) float64, unit-norm columns
  std::vector<KsvdIteration> history;  // one entry per iteration run
  bool converged = false;              // stopped by `tolerance` (not by the iteration limit)
};

// Learns K atoms from the rows of `signals` (N, d), N >= K. `initial` (d, K), optional: the
// starting dictionary (normalised here); otherwise K distinct non-zero training signals drawn
// with `seed`. Each iteration: Batch-OMP codes every signal, then every atom is refitted in a
// random order (seeded) against the running residual, then (with `replace_atoms`) atoms used
// by fewer than `min_uses` signals or nearly duplicating another are replaced by the training
// signals with the largest residuals. Memory: two (N, d) float64 matrices (signals and
// residual; three with keep_better_codes, which keeps the previous residual).
KsvdResult ksvd(const torch::Tensor& signals, const KsvdOptions& options,
                const KsvdCallback& callback = {}, const torch::Tensor& initial = {});

}  // namespace lfnet::dict
